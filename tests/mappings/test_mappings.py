"""Pairwise mappings: correctness on a plane, dense mode, split / subset, I/O, CLI, real data."""

from __future__ import annotations

import numpy as np
import pytest

from _mapping_scenes import H, W, box, down_cameras, look_at, make_scene, merge, plane
from o3d_seqcc.errors import InputError
from o3d_seqcc.mappings.compute import MODES, Mappings, PairMapping, compute_mappings
from o3d_seqcc.imaging.arrays import sample_colors
from o3d_seqcc.io.mappings_npz import load_mappings, save_mappings
from o3d_seqcc.evaluation.render import plot_pair
from o3d_seqcc.visibility.compute import compute_visibility, project_points


@pytest.fixture(scope="module")
def plane_scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("plane")
    cams = down_cameras() + [look_at((0.1, 0.3, 2.2), (0.0, 0.1, 0.0), up=(0.0, 1.0, 0.0))]
    return make_scene(root, plane(24), cams, depth="map")


@pytest.fixture(scope="module")
def occluder_scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("occ")
    pv, pf = plane(30)
    return make_scene(root, merge((pv, pf), box((-0.25, -0.2, 0.6), (0.15, 0.2, 0.9))), down_cameras(), depth="map")


def plane_hit(view, uv):
    """World points on z = 0 seen through pixels uv (analytic ray-plane intersection)."""
    K, E = view.intrinsic, view.extrinsic
    R, t = E[:3, :3], E[:3, 3]
    d = np.stack([(uv[:, 0] - K[0, 2]) / K[0, 0], (uv[:, 1] - K[1, 2]) / K[1, 1], np.ones(len(uv))], 1) @ R
    C = -R.T @ t
    s = -C[2] / d[:, 2]
    return C + d * s[:, None]


# ------------------------------------------------------------------------------------------
# sample_colors
# ------------------------------------------------------------------------------------------


def test_sample_colors_bilinear_on_gradient(rng):
    Hh, Ww = 20, 30
    y, x = np.mgrid[0:Hh, 0:Ww].astype(np.float64)
    img = np.stack([3 * x + 5 * y, 2 * x, 100 - y], -1)
    uv = rng.uniform([0, 0], [Ww - 1, Hh - 1], size=(200, 2))
    got = sample_colors(img, uv)
    exp = np.stack([3 * uv[:, 0] + 5 * uv[:, 1], 2 * uv[:, 0], 100 - uv[:, 1]], -1)
    np.testing.assert_allclose(got, exp, atol=1e-9)
    near = sample_colors(img, uv, interpolation="nearest")
    xi, yi = np.floor(uv[:, 0] + 0.5), np.floor(uv[:, 1] + 0.5)
    np.testing.assert_allclose(near[:, 1], 2 * xi)
    np.testing.assert_allclose(near[:, 2], 100 - yi)
    # uint8 in its own units; the outer half pixel is clamped to the border pixel
    u8 = np.clip(img, 0, 255).astype(np.uint8)
    c = sample_colors(u8, np.array([[-0.4, -0.4], [Ww - 0.6, Hh - 0.6], [1.5, 0.0]]))
    assert c.dtype == np.float64
    np.testing.assert_allclose(c[0], u8[0, 0])
    np.testing.assert_allclose(c[1], u8[-1, -1])
    np.testing.assert_allclose(c[2], (u8[0, 1].astype(float) + u8[0, 2]) / 2)
    assert sample_colors(u8.astype(np.uint16) * 257, np.array([[0.0, 0.0]]))[0, 0] == 0
    with pytest.raises(ValueError, match="interpolation"):
        sample_colors(img, uv, interpolation="cubic")
    with pytest.raises(ValueError, match="NaN"):
        sample_colors(img, np.array([[np.nan, 1.0]]))
    with pytest.raises(ValueError, match="shape"):
        sample_colors(img, np.zeros((3, 3)))


# ------------------------------------------------------------------------------------------
# correctness
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", MODES)
def test_plane_mappings_are_exact(plane_scene, mode):
    M = compute_mappings(plane_scene, mappings=mode)
    assert M.mode == mode and M.n_views == 3 and M.view_names == ("v0", "v1", "v2")
    assert set(M.pairs) == {(0, 1), (0, 2), (1, 2)}
    mesh = M.visibility.mesh
    for (a, b), pm in M.pairs.items():
        assert a < b and pm.a == a and pm.b == b and pm.n > 100
        if mode == "surface":  # counted in pixels of shared surface; the vertices and samples inside faces
            assert pm.n >= 3 * len(np.unique(pm.face_ids)) and M.counts[(a, b)] > pm.n / 9
        else:
            assert pm.n == M.counts[(a, b)]
        assert pm.uv_a.dtype == np.float64 and pm.uv_a.shape == (pm.n, 2) and pm.face_ids.dtype == np.int64
        # inside both images
        for uv in (pm.uv_a, pm.uv_b):
            assert (uv >= -0.5).all() and (uv[:, 0] < W - 0.5).all() and (uv[:, 1] < H - 0.5).all()
        # the plane point seen through uv_a projects to uv_b (the plane homography)
        va, vb = plane_scene.views[a], plane_scene.views[b]
        P = plane_hit(va, pm.uv_a)
        uv_b, _ = project_points(P, vb.intrinsic, vb.extrinsic)
        np.testing.assert_allclose(uv_b, pm.uv_b, atol=1e-3)
        # and the mapping's own world point lies in its face and projects to both
        X = M.world_points(a, b)
        np.testing.assert_allclose(project_points(X, va.intrinsic, va.extrinsic)[0], pm.uv_a, atol=1e-3)
        tri = mesh.vertices[mesh.faces[pm.face_ids]]
        assert (X[:, 0] >= tri[:, :, 0].min(1) - 1e-9).all() and (X[:, 0] <= tri[:, :, 0].max(1) + 1e-9).all()
        # every face of the pair is usable in both views
        assert M.visibility.usable[a, pm.face_ids].all() and M.visibility.usable[b, pm.face_ids].all()


def test_vertices_mode_is_the_paper_definition(plane_scene):
    M = compute_mappings(plane_scene, mappings="vertices")
    vis = M.visibility
    for (a, b), pm in M.pairs.items():
        shared = np.flatnonzero(vis.usable[a] & vis.usable[b])
        np.testing.assert_array_equal(pm.face_ids, np.repeat(shared, 3))
        np.testing.assert_allclose(pm.uv_a, vis.uv[a][vis.mesh.faces[shared]].reshape(-1, 2))
        assert M.counts[(a, b)] == 3 * len(shared)
    # symmetric access
    p10 = M.pair(1, 0)
    np.testing.assert_array_equal(p10.uv_a, M.pairs[(0, 1)].uv_b)
    assert M.count(1, 0) == M.counts[(0, 1)]
    assert M.pair(0, 0 + 1).n == M.total - M.counts[(0, 2)] - M.counts[(1, 2)]


def test_dense_has_more_mappings_and_the_same_precision(occluder_scene):
    mv = compute_mappings(occluder_scene, mappings="vertices")
    md = compute_mappings(occluder_scene, mappings="dense", visibility=mv.visibility)
    assert md.total >= 4 / 3 * mv.total  # at least the centroid of each face
    assert set(md.counts) == set(mv.counts)
    for key in mv.pairs:
        pv, pd = mv.pairs[key], md.pairs[key]
        assert set(pd.face_ids.tolist()) == set(pv.face_ids.tolist())
        # dense includes the vertex mappings (weights equal to a basis vector)
        is_vertex = (pd.weights == 1.0).any(1)
        assert is_vertex.sum() == pv.n
        # exactness on the plane part (faces before the box): plane homography
        va, vb = occluder_scene.views[key[0]], occluder_scene.views[key[1]]
        on_plane = pd.face_ids < 2 * 30 * 30
        P = plane_hit(va, pd.uv_a[on_plane])
        uv_b, _ = project_points(P, vb.intrinsic, vb.extrinsic)
        np.testing.assert_allclose(uv_b, pd.uv_b[on_plane], atol=1e-3)
        # no mapping on the plane is hidden by the box in either view: the world point is the
        # first hit of the ray through uv_a
        Xd = md.world_points(*key)
        assert np.abs(Xd[on_plane, 2]).max() < 1e-9


def test_occluded_faces_get_no_mappings(occluder_scene):
    M = compute_mappings(occluder_scene)
    vis = M.visibility
    pm = M.pairs[(0, 1)]
    assert not vis.occluded[0, pm.face_ids].any() and not vis.occluded[1, pm.face_ids].any()
    # without the z-buffer some mappings would join the plane behind the box in one view to
    # the box in the other
    raw = compute_mappings(occluder_scene, filters=("depth", "oblique"))
    raw_noz = compute_mappings(occluder_scene, filters=())
    assert raw_noz.total > raw.total >= M.total
    assert M.filter_stats["occluded"] > 0


def test_no_overlap_raises(tmp_path):
    cams = [
        look_at((-3.0, 0.0, 1.0), (-3.0, 0.0, 0.0), up=(0.0, 1.0, 0.0)),
        look_at((3.0, 0.0, 1.0), (3.0, 0.0, 0.0), up=(0.0, 1.0, 0.0)),
    ]
    v, f = plane(40, size=8.0)
    scene = make_scene(tmp_path, (v, f), cams, depth=None)
    with pytest.raises(InputError, match="no overlap"):
        compute_mappings(scene)


def test_bad_arguments(plane_scene):
    with pytest.raises(ValueError, match="vertices, dense"):
        compute_mappings(plane_scene, mappings="pixels")
    vis = compute_visibility(plane_scene)
    with pytest.raises(TypeError, match="max_angle"):
        compute_mappings(plane_scene, visibility=vis, max_angle=60)
    with pytest.raises(TypeError):
        compute_mappings(plane_scene, max_angel=60)
    from o3d_seqcc.scene import Scene

    two = Scene(plane_scene.mesh, plane_scene.views[:2])
    with pytest.raises(InputError, match="recompute"):
        compute_mappings(two, visibility=vis)
    assert compute_mappings(None, visibility=vis).counts == compute_mappings(plane_scene).counts


# ------------------------------------------------------------------------------------------
# split, subset, hand-built mappings
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", MODES)
def test_split_by_face(plane_scene, mode):
    M = compute_mappings(plane_scene, mappings=mode)
    fit, test = M.split(0.25, seed=3)
    faces_all = M.faces()
    f_fit, f_test = fit.faces(), test.faces()
    assert len(np.intersect1d(f_fit, f_test)) == 0
    np.testing.assert_array_equal(np.union1d(f_fit, f_test), faces_all)
    assert abs(len(f_test) - 0.25 * len(faces_all)) <= 1
    for key in M.pairs:
        pf, pt = fit.pair(*key), test.pair(*key)
        if mode == "surface":  # areas: each part's count is rounded, and the smaller view may differ by part
            assert fit.count(*key) + test.count(*key) == pytest.approx(M.counts[key], rel=0.02, abs=2)
        else:
            assert fit.count(*key) + test.count(*key) == M.counts[key]
            assert pf.n == fit.count(*key) and pt.n == test.count(*key)
        assert not np.isin(pf.face_ids, f_test).any()
    # deterministic, and the same on materialised (non-lazy) mappings
    fit2, test2 = M.split(0.25, seed=3)
    np.testing.assert_array_equal(test2.faces(), f_test)
    if mode != "surface":  # (surface: faces smaller than a sample may hold none, so the materialised face list differs)
        fit3, test3 = M.materialize().split(0.25, seed=3)
        np.testing.assert_array_equal(test3.faces(), f_test)
        assert fit3.counts == fit.counts
    assert not np.array_equal(M.split(0.25, seed=4)[1].faces(), f_test)
    with pytest.raises(ValueError):
        M.split(1.0)


@pytest.mark.parametrize("mode", MODES)
def test_thinned_many_is_thinned_pair_by_pair(occluder_scene, mode):
    """The pairs planned together and their picked mappings computed in one vectorised pass (batches split
    anywhere, pairs of the same first view sharing its face levels) are bit for bit one thinned pair at a
    time: strided picks, all mappings, none."""
    import o3d_seqcc.mappings.pairs as pairs_mod

    scene = occluder_scene
    vis = compute_visibility(scene)
    m = compute_mappings(scene, visibility=vis, mappings=mode)
    keys = list(m.pairs)
    rng = np.random.default_rng(5)
    for pick in (lambda n: np.sort(rng.choice(n, min(n, 37), replace=False)), lambda n: None,
                 lambda n: np.zeros(0, np.int64)):
        state = rng.bit_generator.state
        want = [pairs_mod.thinned(m.pairs, k, pick) for k in keys]
        for batch, mappings in ((1, 10**6), (3, 50), (len(keys), 10**6)):
            rng.bit_generator.state = state
            old = pairs_mod.BATCH_MAPPINGS
            pairs_mod.BATCH_MAPPINGS = mappings
            try:
                got = list(pairs_mod.thinned_many(m.pairs, keys, pick, batch_pairs=batch, n_jobs=2))
            finally:
                pairs_mod.BATCH_MAPPINGS = old
            assert len(got) == len(want)
            for (n0, p0), (n1, p1) in zip(want, got):
                assert n0 == n1 and p0.key == p1.key
                for name in ("uv_a", "uv_b", "face_ids", "weights"):
                    x, y = getattr(p0, name), getattr(p1, name)
                    assert (x is None) == (y is None) and (x is None or (x.dtype == y.dtype and np.array_equal(x, y)))


@pytest.mark.parametrize("cells", [3, 30])
def test_surface_levels_are_the_smaller_projections_levels(tmp_path, cells):
    """A pair's faces and their sampling levels, from the two views' levels (each view's computed once), are
    the level of the smaller of the face's two projected areas (the definition), face by face."""
    from o3d_seqcc.mappings.sampling import SURFACE_MAX_LEVEL, tri_area

    scene = make_scene(tmp_path, plane(cells), down_cameras() + [look_at((0.6, 0.5, 1.5), (0.0, 0.0, 0.0))])
    vis = compute_visibility(scene)
    m = compute_mappings(scene, visibility=vis, mappings="surface")
    src, faces = m.pairs.source, np.asarray(vis.mesh.faces)
    for a, b in m.pairs:
        k, lev = src._pair_levels(a, b)
        assert np.array_equal(k, src.faces(a, b))
        area = [tri_area(vis.vertex_projection(v, faces[k].reshape(-1))[0].reshape(-1, 3, 2).astype(np.float64))
                for v in (a, b)]
        m_ = np.minimum(*area) / src.spacing**2
        want = np.where(m_ >= 1.0, np.clip(np.rint(np.sqrt(np.maximum(m_, 1.0))), 1, SURFACE_MAX_LEVEL), 0)
        assert np.array_equal(lev, want) and lev.max() >= (2 if cells == 3 else 0)


def test_subset(plane_scene):
    M = compute_mappings(plane_scene)
    S = M.subset([(2, 0)])
    assert list(S.pairs) == [(0, 2)] and S.counts == {(0, 2): M.counts[(0, 2)]}
    np.testing.assert_array_equal(S.pairs[(0, 2)].uv_a, M.pairs[(0, 2)].uv_a)
    assert S.n_views == 3 and S.view_names == M.view_names
    assert M.materialize().subset([(0, 1)]).counts == {(0, 1): M.counts[(0, 1)]}
    with pytest.raises(ValueError):
        M.subset([(0, 7)])
    with pytest.raises(ValueError):
        M.subset([(1, 1)])


def test_hand_built_mappings():
    uv = np.array([[1.0, 2.0], [3.0, 4.0]])
    pm = PairMapping(2, 0, uv, uv + 1, [5, 6])
    M = Mappings(pairs={(2, 0): pm}, view_names=("a", "b", "c"))
    assert list(M.pairs) == [(0, 2)]
    np.testing.assert_array_equal(M.pairs[(0, 2)].uv_a, uv + 1)
    assert M.counts == {(0, 2): 2} and M.n_views == 3 and M.total == 2
    assert M.pair(0, 1).n == 0
    fit, test = M.split(0.5, seed=0)
    assert fit.total + test.total == 2
    with pytest.raises(ValueError):
        PairMapping(0, 1, uv, uv, [1, 2, 3])


# ------------------------------------------------------------------------------------------
# I/O, figure, CLI
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", ["compact", "arrays"])
@pytest.mark.parametrize("mode", MODES)
def test_save_load_round_trip(plane_scene, tmp_path, fmt, mode):
    M = compute_mappings(plane_scene, mappings=mode)
    fit, _ = M.split(0.3, seed=1)
    for src in (M, fit):
        p = save_mappings(src, tmp_path / f"m_{fmt}.npz", format=fmt)
        L = load_mappings(p)
        assert L.view_names == src.view_names and L.mode == src.mode and L.counts == src.counts
        assert L.filter_stats["usable"] == src.filter_stats["usable"]
        for key in src.pairs:
            a, b = src.pairs[key], L.pairs[key]
            np.testing.assert_array_equal(a.face_ids, b.face_ids)
            np.testing.assert_allclose(a.uv_a, b.uv_a, atol=1e-3)
            np.testing.assert_allclose(a.uv_b, b.uv_b, atol=1e-3)
        L.split(0.5)  # loaded mappings are fully functional
    with pytest.raises(ValueError):
        save_mappings(M.materialize(), tmp_path / "x.npz", format="compact")


def test_load_rejects_other_files(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_mappings(tmp_path / "missing.npz")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(InputError, match="not a mappings file"):
        load_mappings(tmp_path / "other.npz")
    (tmp_path / "junk.npz").write_bytes(b"nope")
    with pytest.raises(InputError):
        load_mappings(tmp_path / "junk.npz")


def test_plot_pair(occluder_scene, tmp_path):
    M = compute_mappings(occluder_scene)
    p = plot_pair(occluder_scene, M, "v1", 0, tmp_path / "fig.png")
    from PIL import Image

    with Image.open(p) as im:
        w, h = im.size
    assert h > 1.5 * w  # four rows of two panels
    p2 = plot_pair(occluder_scene, M.materialize().subset([(0, 1)]), 0, 1, tmp_path / "one.png", stages=False)
    assert p2.stat().st_size > 0


def test_cli_mappings(occluder_scene, tmp_path, capsys):
    from o3d_seqcc.cli import main

    root = occluder_scene.mesh.parent
    out = tmp_path / "maps.npz"
    rc = main(["mappings", str(root / "scene.json"), "--out", str(out), "--plot", "v0,v1", "--max-angle", "80"])
    assert rc == 0
    assert "mappings_total" in capsys.readouterr().out
    L = load_mappings(out)
    assert L.counts == compute_mappings(occluder_scene, max_angle=80).counts
    assert (tmp_path / "maps_v0_v1.png").is_file()
    assert main(["-q", "mappings", str(root), "--out", str(out)]) == 2  # an existing file needs --overwrite
    rc = main(["-q", "mappings", str(root), "--out", str(out), "--mode", "dense", "--plot", str(tmp_path / "figs"),
               "--arrays", "--disable", "depth", "--overwrite"])
    assert rc == 0 and load_mappings(out).mode == "dense"
    assert len(list((tmp_path / "figs").glob("mappings_v0_v1.png"))) == 1
    assert main(["-q", "mappings", str(root), "--out", str(out), "--plot", "v0,nope", "--overwrite"]) == 2
    assert "valid names" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------
# real data
# ------------------------------------------------------------------------------------------


def test_fountain_counts_and_depth_agreement(fountain_scene):
    M = compute_mappings(fountain_scene, mappings="vertices")  # the paper's filter acts at the vertices
    c = np.array(list(M.counts.values()))
    n_pairs = 33 * 32 // 2
    assert len(c) > 0.9 * n_pairs
    assert (c > 400).sum() > 0.8 * n_pairs
    st = M.filter_stats
    for k in ("occluded", "depth_inconsistent", "oblique"):
        assert 0 < st[k] < st["valid"]
    # for the pair with the most mappings, the mesh depth at the mapped pixels agrees with both
    # depth maps
    a, b = max(M.counts, key=M.counts.get)
    X = M.world_points(a, b)
    pm = M.pairs[(a, b)]
    for v, uv in ((a, pm.uv_a), (b, pm.uv_b)):
        view = fountain_scene.views[v]
        D = view.load_depth()
        _, z = project_points(X, view.intrinsic, view.extrinsic)
        r = np.clip(np.floor(uv[:, 1] + 0.5), 0, view.height - 1).astype(int)
        col = np.clip(np.floor(uv[:, 0] + 0.5), 0, view.width - 1).astype(int)
        d = D[r, col]
        ok = d > 0
        assert ok.mean() > 0.8
        rel = np.abs(d[ok] - z[ok]) / z[ok]
        assert np.median(rel) < 0.02
        assert (np.abs(d[ok] - z[ok]) <= np.maximum(0.05, 0.03 * z[ok])).all()
