"""One visibility (issue 23): the sparse records behind one protocol, dense arrays only through to_dense()."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from o3d_seqcc.errors import InputError
from o3d_seqcc.scene import Mesh
from o3d_seqcc.texturing import select_views
from o3d_seqcc.texturing.data_costs import ScoredVisibility, score_visibility
from o3d_seqcc.visibility.compute import Visibility
from o3d_seqcc.visibility.dense import DenseVisibility, VisibilityLike

ROOT = Path(__file__).resolve().parents[2]


def _strip(rng, n=6):
    """A strip of 2n triangles over 2n+2 vertices in the z=0 plane."""
    x = np.repeat(np.arange(n + 1, dtype=float), 2)
    y = np.tile([0.0, 1.0], n + 1)
    verts = np.stack([x, y, np.zeros_like(x)], 1)
    faces = np.concatenate([[[2 * i, 2 * i + 2, 2 * i + 1], [2 * i + 1, 2 * i + 2, 2 * i + 3]] for i in range(n)])
    return Mesh(vertices=verts, faces=faces, vertex_normals=np.tile([0.0, 0.0, 1.0], (len(verts), 1)))


def test_from_dense_and_to_dense_round_trip(rng):
    mesh = _strip(rng)
    V, F, N = 3, len(mesh.faces), len(mesh.vertices)
    usable = rng.random((V, F)) < 0.6
    usable[:, 0] = True
    area = rng.uniform(1, 50, (V, F)).astype(np.float32)
    cos = rng.uniform(0.2, 1, (V, F)).astype(np.float32)
    uv = rng.uniform(0, 100, (V, N, 2)).astype(np.float32)
    vis = Visibility.from_dense(mesh, usable, uv=uv, area=area, cos_angle=cos, view_names=("a", "b", "c"))
    assert isinstance(vis, VisibilityLike)
    d = vis.to_dense()
    assert isinstance(d, DenseVisibility) and d.usable.shape == (V, F) and d.uv.shape == (V, N, 2)
    np.testing.assert_array_equal(d.usable, usable)
    np.testing.assert_array_equal(d.valid, usable)  # no filter ran
    np.testing.assert_array_equal(d.area, np.where(usable, area, 0))
    np.testing.assert_array_equal(d.cos_angle, np.where(usable, cos, 0))
    np.testing.assert_array_equal(d.uv, uv)
    assert vis.to_dense(projections=False).uv is None
    indptr, faces, a, c = vis.usable_entries()
    assert list(np.diff(indptr)) == list(usable.sum(1)) == list(vis.usable_counts())
    for v in range(V):
        np.testing.assert_array_equal(vis.usable_faces(v), np.flatnonzero(usable[v]))
        np.testing.assert_array_equal(vis.usable_area(v), area[v, usable[v]])
    # the areas of the projections when none are given, view by view
    p = uv[:, mesh.faces].astype(np.float64)
    e1, e2 = p[:, :, 1] - p[:, :, 0], p[:, :, 2] - p[:, :, 0]
    want = (0.5 * np.abs(e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0])).astype(np.float32)
    np.testing.assert_array_equal(Visibility.from_dense(mesh, usable, uv=uv).to_dense().area, np.where(usable, want, 0))
    np.testing.assert_array_equal(Visibility.from_arrays(mesh, uv, usable).to_dense().area, np.where(usable, want, 0))


def test_from_dense_without_projections_serves_the_selection_only(rng):
    mesh = _strip(rng)
    usable = np.ones((2, len(mesh.faces)), bool)
    area = np.stack([np.full(len(mesh.faces), 5.0), np.full(len(mesh.faces), 9.0)])
    vis = Visibility.from_dense(mesh, usable, area=area)
    assert (select_views(vis, method="largest-area") == 1).all()
    with pytest.raises(InputError, match="no vertex projections"):
        vis.vertex_projection(0, [0, 1])
    with pytest.raises(InputError, match="uv= .* or area="):
        Visibility.from_dense(mesh, usable)
    with pytest.raises(InputError, match=r"\(V, F\)"):
        Visibility.from_dense(mesh, usable[0], area=area[0])


def test_the_scored_visibility_is_the_same_protocol(rng):
    mesh = _strip(rng)
    V, F = 3, len(mesh.faces)
    usable = rng.random((V, F)) < 0.7
    vis = Visibility.from_dense(mesh, usable, uv=rng.uniform(0, 50, (V, len(mesh.vertices), 2)))
    scored = score_visibility(vis, None, data_term="area")
    assert isinstance(scored, ScoredVisibility) and isinstance(scored, VisibilityLike)
    for v in range(V):
        np.testing.assert_array_equal(scored.usable_faces(v), vis.usable_faces(v))
        np.testing.assert_array_equal(scored.usable_area(v), vis.usable_area(v))
    np.testing.assert_array_equal(scored.to_dense().usable, vis.to_dense().usable)
    np.testing.assert_array_equal(scored.to_dense().area, vis.to_dense().area)


def test_no_stage_forks_on_the_kind_of_visibility():
    """The library reads every visibility through the protocol: no ``hasattr`` / ``getattr`` test of which
    representation it was given (the dense-array fallbacks of earlier versions)."""
    fork = re.compile(r"hasattr\((self\.)?(vis|visibility)\b|getattr\((self\.)?(vis|visibility), \"(records|usable\w*|"
                      r"area|cos_angle|valid|uv|depth)\"")
    hits = [f"{p.relative_to(ROOT)}:{i}" for p in (ROOT / "o3d_seqcc").rglob("*.py")
            for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if fork.search(line)]
    assert not hits, hits
