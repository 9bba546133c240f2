"""Sub-pixel meshes (issue 36): most faces smaller than a pixel in every photo are warned about once, with the share
and a decimation target; a mesh the photos resolve is not."""

from __future__ import annotations

import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from o3d_seqcc.errors import O3dSeqccWarning
from o3d_seqcc.visibility.subpixel import subpixel_faces, warn_subpixel


def test_largest_projection_over_the_views_decides():
    rec = [SimpleNamespace(faces=np.array([0, 1, 2]), area=np.array([0.2, 0.5, 9.0], np.float32)),
           SimpleNamespace(faces=np.array([1, 3]), area=np.array([2.0, 0.1], np.float32))]
    s = subpixel_faces(rec, 5)  # face 4 is seen by no view
    assert s["seen_faces"] == 4 and s["share"] == pytest.approx(0.5)  # faces 0 and 3; face 1 is 2 px^2 in view 1
    assert s["median_px2"] == pytest.approx(np.median([0.2, 2.0, 9.0, 0.1]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not warn_subpixel(s)  # half is not most


def test_a_mesh_finer_than_its_photos_is_warned_about_once(tmp_path):
    from o3d_seqcc.synthetic import make_synthetic_scene
    from o3d_seqcc.visibility.compute import compute_visibility

    tiny = make_synthetic_scene(tmp_path / "tiny", n_views=4, width=24, height=18, seed=0)
    with pytest.warns(O3dSeqccWarning, match=r"\d+% of the \d+ faces the photos see .* smaller than a pixel") as rec:
        vis = compute_visibility(tiny.scene, split_faces=False)
    assert sum("smaller than a pixel" in str(w.message) for w in rec) == 1
    s = vis.stats["subpixel"]
    assert s["share"] > 0.5 and 0 < s["suggested_faces"] < s["seen_faces"]
    fine = make_synthetic_scene(tmp_path / "fine", n_views=4, width=320, height=240, seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        vis = compute_visibility(fine.scene, split_faces=False)
    assert not [w for w in caught if "smaller than a pixel" in str(w.message)]
    assert vis.stats["subpixel"]["share"] < 0.5


def test_a_mesh_that_is_a_few_pixels_is_not_told_to_decimate_to_a_handful_of_faces():
    # 40 seen faces of 0.05 px^2: all of it is 2 px^2; "decimate to about 1 faces" is no advice
    s = subpixel_faces([SimpleNamespace(faces=np.arange(40), area=np.full(40, 0.05, np.float32))], 40)
    assert s["suggested_faces"] == 1
    with pytest.warns(O3dSeqccWarning, match="only a few pixels in the photos") as rec:
        assert warn_subpixel(s)
    assert "decimate" not in str(rec[0].message)
    # a big mesh of sub-pixel faces still gets its decimation target
    s = subpixel_faces([SimpleNamespace(faces=np.arange(40_000), area=np.full(40_000, 0.5, np.float32))], 40_000)
    with pytest.warns(O3dSeqccWarning, match="decimate the mesh to about 5000 faces"):
        assert warn_subpixel(s)
