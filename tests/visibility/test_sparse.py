"""Sparse per-view visibility, its dense views, frustum culling, pair counts and lazy images (issue 15)."""

from __future__ import annotations

import pickle

import cv2
import numpy as np
import pytest

from _mapping_scenes import box, look_at, make_scene, merge, plane
from o3d_seqcc.correction import CorrectedImages, correct
from o3d_seqcc.imaging.sequences import FloatImages, SceneImages
from o3d_seqcc.io.images import image_dtype, read_image
from o3d_seqcc.mappings.compute import compute_mappings
from o3d_seqcc.geometry.meshops import face_adjacency
from o3d_seqcc.mappings.counting import shared_counts
from o3d_seqcc.texturing import select_views
from o3d_seqcc.visibility import compute as visibility
from o3d_seqcc.visibility.per_view import CHUNK_FACES, VisibilityJob
from o3d_seqcc.visibility.compute import FACE_UV_STEPS, Visibility, compute_visibility


@pytest.fixture(scope="module")
def wide_scene(tmp_path_factory):
    """A 28,800-face floor with a box on it; two close cameras see a corner each, one sees it all."""
    v, f = merge(plane(120, size=4.0), box((-0.3, -0.3, 0.0), (0.2, 0.3, 0.5)))
    cams = [
        look_at((-1.4, -1.2, 0.9), (-1.3, -1.0, 0.0), up=(0.0, 1.0, 0.0)),
        look_at((-1.0, -1.3, 0.8), (-1.1, -1.0, 0.0), up=(0.0, 1.0, 0.0)),
        look_at((1.3, 1.2, 1.0), (1.2, 1.1, 0.0), up=(0.0, 1.0, 0.0)),
        look_at((0.2, 0.1, 5.0), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0)),
    ]
    return make_scene(tmp_path_factory.mktemp("wide"), (v, f), cams, depth="map")


def test_frustum_culling_gives_the_records_of_the_full_computation(wide_scene, monkeypatch):
    vis = compute_visibility(wide_scene)
    mesh = vis.mesh
    assert len(mesh.faces) > 4 * CHUNK_FACES
    job = VisibilityJob(wide_scene.views, mesh.vertices, mesh.faces, mesh.face_normals, np.zeros(len(mesh.faces), bool),
                        vis.options)
    culled = [job.candidates(v) for v in wide_scene.views]
    assert culled[0] is not None and len(culled[0]) < 0.5 * len(mesh.faces)  # the close views look at a corner
    assert culled[3] is None  # the far view sees everything: no culling
    monkeypatch.setattr(VisibilityJob, "candidates", lambda self, view: None)
    full = compute_visibility(wide_scene)
    for a, b in zip(vis.records, full.records):
        for name in ("faces", "flags", "area", "cos_angle"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert a.info == b.info and a.n_rays == b.n_rays
    assert vis.stats["usable"] == full.stats["usable"] > 0 and vis.stats["occluded"] > 0
    for v, cand in enumerate(culled[:3]):  # every valid face lies in a kept chunk
        assert np.isin(vis.records[v].faces, cand).all()


@pytest.mark.parametrize("cache", [True, False])
def test_records_are_sparse_and_match_their_dense_views(wide_scene, cache, monkeypatch):
    if not cache:  # projections of only the vertices asked for (the path of large meshes)
        monkeypatch.setattr(visibility, "CACHE_BYTES", 0)
    vis = compute_visibility(wide_scene)
    st = vis.stats
    # 13 bytes per valid face-view incidence (id, filter bits, area, cosine), nothing per unseen face
    assert vis.nbytes == 13 * st["valid"]
    assert st["valid"] < 0.5 * vis.n_views * vis.n_faces
    indptr, faces, area, cos = vis.usable_entries()
    rows = np.repeat(np.arange(vis.n_views), np.diff(indptr))
    U = np.zeros((vis.n_views, vis.n_faces), bool)
    U[rows, faces] = True
    np.testing.assert_array_equal(U, vis.usable)
    np.testing.assert_array_equal(area, vis.area[rows, faces])
    np.testing.assert_array_equal(cos, vis.cos_angle[rows, faces])
    assert (vis.area[~vis.valid] == 0).all() and not vis.usable.flags.writeable
    np.testing.assert_array_equal(vis.usable_counts(), vis.usable.sum(axis=1))
    for v in range(vis.n_views):  # projections on demand equal the dense table, for any subset
        ids = np.unique(vis.mesh.faces[vis.usable_faces(v)])
        uv, z = vis.vertex_projection(v, ids)
        np.testing.assert_array_equal(uv, vis.uv[v][ids])
        np.testing.assert_array_equal(z, vis.depth[v][ids])
    lab = select_views(vis, method="largest-area")
    seen = lab >= 0
    dense = vis.uv[lab[seen][:, None], vis.mesh.faces[seen]]  # face_uv: the same, rounded to 1/256 px
    np.testing.assert_array_equal(vis.face_uv(lab)[seen], np.round(dense * FACE_UV_STEPS) / FACE_UV_STEPS)
    # pickling (a Dask worker's copy) drops the dense caches and keeps the records
    blob = pickle.dumps(vis)
    assert len(blob) < vis.nbytes + 20 * len(vis.mesh.faces) * 3 * 8
    back = pickle.loads(blob)
    assert "usable" not in back.__dict__
    np.testing.assert_array_equal(back.usable, vis.usable)


def test_selection_from_records_equals_selection_from_dense_arrays(wide_scene):
    vis = compute_visibility(wide_scene)
    d = vis.to_dense(projections=False)
    dense = Visibility.from_dense(vis.mesh, np.array(d.usable), area=np.array(d.area), cos_angle=np.array(d.cos_angle))
    adj = face_adjacency(vis.mesh.faces, vis.mesh.vertices)
    for method, opts in (("largest-area", {}), ("random", {}), ("mrf", {"adjacency": adj}),
                         ("mrf", {"adjacency": adj, "data_term": "log-area-cos", "smoothness": 1.5})):
        a = select_views(vis, method=method, seed=5, **opts)
        b = select_views(dense, method=method, seed=5, **opts)
        np.testing.assert_array_equal(a, b)
        seen = a >= 0
        assert vis.usable[a[seen], np.flatnonzero(seen)].all()
    # largest-area, by brute force over the dense arrays (ties to the lowest view)
    score = np.where(dense.usable, dense.area, -np.inf)
    want = np.where(dense.usable.any(0), np.argmax(score, axis=0), -1)
    np.testing.assert_array_equal(select_views(vis, method="largest-area"), want)


@pytest.mark.parametrize("weighted", [False, True])
def test_shared_counts_packed_and_sparse_agree_with_brute_force(rng, weighted):
    V, n = 23, 3001
    M = rng.random((V, n)) < rng.uniform(0.02, 0.4, size=(V, 1))
    rows = [np.flatnonzero(r) for r in M]
    w = rng.integers(1, 40, size=n) if weighted else None
    want = (M * (1 if w is None else w)).astype(np.int64) @ M.T.astype(np.int64)
    for method in ("packed", "sparse", "auto"):
        np.testing.assert_array_equal(shared_counts(rows, n, w, method=method), want)


def test_dense_mappings_counts_from_records(wide_scene):
    vis = compute_visibility(wide_scene)
    for mode in ("vertices", "dense"):
        maps = compute_mappings(wide_scene, visibility=vis, mappings=mode)
        for k in maps.pairs:
            assert maps.pairs[k].n == maps.counts[k]


def test_image_dtype_from_headers_and_lazy_images(tmp_path, rng):
    img8 = rng.integers(0, 256, size=(20, 30, 3), dtype=np.uint8)
    img16 = rng.integers(0, 65536, size=(20, 30, 3), dtype=np.uint16)
    cv2.imwrite(str(tmp_path / "a.png"), img8)
    cv2.imwrite(str(tmp_path / "b.png"), img16)
    cv2.imwrite(str(tmp_path / "c.jpg"), img8)
    cv2.imwrite(str(tmp_path / "d.tif"), img16)
    for name in ("a.png", "b.png", "c.jpg", "d.tif"):
        assert image_dtype(tmp_path / name) == read_image(tmp_path / name).dtype
    # a float cache of at most two images keeps at most two
    imgs = [rng.random((10, 10, 3)) for _ in range(5)]
    fl = FloatImages(imgs, cache_bytes=2 * imgs[0].nbytes)
    for i in range(5):
        np.testing.assert_array_equal(fl[i], imgs[i])
    assert len(fl._cache) == 2 and fl[-1] is fl[4]


def test_correct_with_lazy_images_equals_eager(wide_scene, tmp_path, rng):
    from dataclasses import replace

    from o3d_seqcc import Scene

    views = []
    for i, v in enumerate(wide_scene.views):  # coloured images with a different gain per view
        img = np.clip(rng.normal(120 + 15 * i, 30, size=(v.height, v.width, 3)), 0, 255).astype(np.uint8)
        p = tmp_path / f"{v.name}.png"
        cv2.imwrite(str(p), img)
        views.append(replace(v, image=p))
    scene = Scene(wide_scene.mesh, tuple(views))
    maps = compute_mappings(scene)
    eager = correct(scene, mappings=maps, images=[v.load_image() for v in scene.views], t_npm=20)
    lazy_in = SceneImages(scene.views)
    assert len(pickle.dumps(lazy_in)) < 4000  # the views, not the pixels
    lazy = correct(scene, mappings=maps, images=lazy_in, t_npm=20)
    assert isinstance(lazy.images, CorrectedImages) and isinstance(eager.images, list)
    for a, b in zip(eager.images, lazy.images):
        np.testing.assert_array_equal(a, b)
    assert lazy.images.dtypes() == [np.dtype(np.uint8)] * len(views)
