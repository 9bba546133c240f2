"""Masked pixels count nowhere: the faces a mask hides in a photo (known answer), the all-masked photo, the
command line's --masks / --mask-invert, the report's masked share and the Open3D front door's masks=."""

from __future__ import annotations

import json
import warnings
from dataclasses import replace

import numpy as np
import pytest

import o3d_seqcc.synthetic as sc
from o3d_seqcc.cli import main
from o3d_seqcc.errors import InputError, O3dSeqccWarning
from o3d_seqcc.io.images import write_image
from o3d_seqcc.scene import Scene
from o3d_seqcc.visibility.compute import compute_visibility
from o3d_seqcc.visibility.masks import MASK_MARGIN, mask_image, masked_faces, masked_points

W, H = 80, 60


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("vmasks") / "R", n_views=6, width=W, height=H,
                                   cell_size=0.25, layout="two-rings", seen_only=True, photometric="none")


def _write(path, keep: np.ndarray):
    return write_image(path, np.repeat(np.where(keep, 255, 0).astype(np.uint8)[..., None], 3, axis=2))


def _with_mask(scene: Scene, k: int, keep: np.ndarray, path) -> Scene:
    views = list(scene.views)
    views[k] = replace(views[k], mask=_write(path, keep))
    return Scene(scene.mesh, tuple(views))


def _min_u(vis, v: int, faces: np.ndarray) -> np.ndarray:
    return vis.vertex_uv(v, vis.mesh.faces[faces].reshape(-1)).reshape(-1, 3, 2)[..., 0].min(axis=1)


def test_a_mask_excludes_exactly_the_faces_behind_it(room, tmp_path):
    """The left half of v00 masked: no usable face of v00 comes within the margin of it; nothing else changes."""
    keep = np.ones((H, W), dtype=bool)
    keep[:, : W // 2] = False  # columns 0..39: their squares end at u = 39.5
    masked = _with_mask(room.scene, 0, keep, tmp_path / "m.png")
    plain = compute_visibility(room.scene, split_faces=False)
    vis = compute_visibility(masked, split_faces=False)
    edge = W // 2 - 0.5
    # the rule: a face is masked when its bounding box grown by the margin meets a masked pixel's square
    clear = _min_u(plain, 0, plain.usable_faces(0)) - MASK_MARGIN >= edge
    np.testing.assert_array_equal(vis.usable_faces(0), plain.usable_faces(0)[clear])
    assert clear.sum() > 20 and (~clear).sum() > 20
    assert (_min_u(vis, 0, vis.usable_faces(0)) >= edge + MASK_MARGIN).all()  # none touches the left half
    valid = plain.valid_faces(0)
    assert vis.stats["per_view"][0]["masked"] == int((_min_u(plain, 0, valid) - MASK_MARGIN < edge).sum())
    for v in range(1, len(room.scene.views)):  # the other photos: as without the mask
        np.testing.assert_array_equal(vis.usable_faces(v), plain.usable_faces(v))
    assert vis.stats["masked_share"] == {"v00": 0.5} and vis.stats["masked"] == vis.stats["per_view"][0]["masked"]
    assert vis.stats["cumulative"]["+mask"] == vis.stats["usable"]
    assert "masked_share" not in plain.stats["per_view"][0] and plain.stats["masked"] == 0
    # with the faces split (the default): parts clear of the mask are usable, none within the margin
    split = compute_visibility(masked)
    assert (_min_u(split, 0, split.usable_faces(0)) >= edge + MASK_MARGIN).all()
    assert split.usable_counts()[0] > 0


def test_masked_faces_and_points_agree_with_a_brute_force_count(rng):
    keep = rng.random((H, W)) > 0.01
    m = mask_image(type("V", (), {"load_mask": lambda self: keep})())
    assert m.share == pytest.approx((~keep).mean())
    np.testing.assert_array_equal(m.masked(), ~keep)
    u, v = rng.uniform(-0.5, W - 0.5, 300), rng.uniform(-0.5, H - 0.5, 300)
    f = rng.integers(0, 300, (100, 3))
    got = masked_faces(m, u, v, f[:, 0], f[:, 1], f[:, 2], margin=1.5)
    cols, rows = np.arange(W), np.arange(H)
    for k, (a, b, c) in enumerate(f):  # every pixel whose square meets the grown box
        lo_u, hi_u = min(u[a], u[b], u[c]) - 1.5, max(u[a], u[b], u[c]) + 1.5
        lo_v, hi_v = min(v[a], v[b], v[c]) - 1.5, max(v[a], v[b], v[c]) + 1.5
        cs = cols[(cols + 0.5 > lo_u) & (cols - 0.5 <= hi_u)]
        rs = rows[(rows + 0.5 > lo_v) & (rows - 0.5 <= hi_v)]
        assert got[k] == (~keep[np.ix_(rs, cs)]).any(), k
    near = (np.clip(np.floor(v + 0.5), 0, H - 1).astype(int), np.clip(np.floor(u + 0.5), 0, W - 1).astype(int))
    np.testing.assert_array_equal(masked_points(m, u, v), ~keep[near])


def test_a_mask_that_masks_everything_is_warned_about(room, tmp_path):
    masked = _with_mask(room.scene, 1, np.zeros((H, W), dtype=bool), tmp_path / "none.png")
    with pytest.warns(O3dSeqccWarning, match=r"view 'v01': its mask .*none\.png masks every pixel: the view "
                                             r"contributes nothing"):
        vis = compute_visibility(masked, split_faces=False)
    assert vis.usable_counts()[1] == 0 and vis.usable_counts()[0] > 0 and vis.stats["masked_share"]["v01"] == 1.0
    every = Scene(room.scene.mesh, tuple(replace(v, mask_map=np.zeros((H, W), bool)) for v in room.scene.views))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", O3dSeqccWarning)
        with pytest.raises(InputError, match=r"every photo's mask masks every pixel \(6 views\).*--mask-invert"):
            compute_visibility(every, split_faces=False)


def _quarter(tmp_path):
    d = tmp_path / "masks"
    keep = np.ones((H, W), dtype=bool)
    keep[:, : W // 4] = False
    _write(d / "v00.png", keep)  # the other photos have none: used whole (a warning names them)
    return d


def test_cli_masks_and_mask_invert(room, tmp_path, capsys):
    d = _quarter(tmp_path)
    counts = {}
    for name, extra in (("plain", []), ("masks", ["--masks", str(d)]), ("inverted", ["--masks", str(d), "--mask-invert"])):
        assert main(["mappings", str(room.scene.source), "--out", str(tmp_path / f"{name}.npz"), *extra]) == 0
        counts[name] = json.loads(capsys.readouterr().out)["filters (face-view incidences)"]
    assert counts["plain"]["masked"] == 0 < counts["masks"]["masked"] < counts["inverted"]["masked"]  # 1/4, then 3/4
    assert main(["info", str(room.scene.source), "--masks", str(d)]) == 0
    assert "1 with masks" in capsys.readouterr().out


@pytest.mark.slow
def test_run_report_shows_the_masked_share(room, tmp_path):
    d = _quarter(tmp_path)
    out = tmp_path / "out"
    assert main(["-q", "run", str(room.scene.source), "--masks", str(d), "--out", str(out), "--atlas-size", "512",
                 "--no-seams", "--format", "glb"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["visibility_stats"]["masked_share"] == {"v00": 0.25}
    assert rep["scene_options"]["masks"] == str(d.resolve())
    page = (out / "report.html").read_text()
    assert "Masks: the masked area per photo" in page and "<td>25.0 %</td>" in page
    assert main(["-q", "report", str(out), "--output", str(tmp_path / "again.html")]) == 0  # regenerated: the masks
    assert "<td>25.0 %</td>" in (tmp_path / "again.html").read_text()


def test_open3d_api_masks(room):
    import open3d as o3d

    from o3d_seqcc import correct_images, texture_mesh

    mesh = o3d.io.read_triangle_mesh(str(room.scene.mesh))
    images = [v.load_image() for v in room.scene.views]
    cams = ([v.intrinsic for v in room.scene.views], [v.extrinsic for v in room.scene.views])
    keep = np.full((H, W), 255, np.uint8)
    keep[:, : W // 2] = 0
    masks = [keep] + [None] * 5
    _, res = texture_mesh(mesh, images, cams, masks=masks, correct=False, return_result=True, atlas_size=512)
    assert res.visibility.stats["masked_share"] == {"000": 0.5}
    _, rep = correct_images(mesh, images, cams, masks=[o3d.geometry.Image(keep)] + [None] * 5, mask_invert=True,
                            return_report=True)
    assert rep["visibility_stats"]["masked_share"] == {"000": 0.5}
    with pytest.raises(InputError, match=r"masks: give one mask per image"):
        texture_mesh(mesh, images, cams, masks=masks[:2])
    with pytest.raises(InputError, match=r"the mask must be \(60, 80\)"):
        texture_mesh(mesh, images, cams, masks=[keep[:10]] + [None] * 5)
