"""Projection, validity and the three filters (z-buffering, depth consistency, oblique)."""

from __future__ import annotations

import logging

import cv2
import numpy as np
import pytest

from _mapping_scenes import H, K, W, box, down_cameras, grid, look_at, make_scene, merge, plane, render_depth
from o3d_seqcc.errors import InputError
from o3d_seqcc.scene import Mesh, Scene, View
from o3d_seqcc.visibility.compute import FILTERS, compute_visibility, depth_from_point_cloud, project_points


def unproject(E: np.ndarray, uv: np.ndarray, z: np.ndarray) -> np.ndarray:
    """World points at pixel uv and camera depth z."""
    uv = np.atleast_2d(uv).astype(float)
    xc = np.stack([(uv[:, 0] - K[0, 2]) / K[0, 0] * z, (uv[:, 1] - K[1, 2]) / K[1, 1] * z, z * np.ones(len(uv))], 1)
    R, t = E[:3, :3], E[:3, 3]
    return (xc - t) @ R


def check_invariants(vis) -> None:
    for m in (vis.occluded, vis.depth_inconsistent, vis.oblique):
        assert not (m & ~vis.valid).any()
    assert np.array_equal(vis.usable, vis.valid & ~vis.occluded & ~vis.depth_inconsistent & ~vis.oblique)
    st = vis.stats
    assert st["usable"] == vis.usable.sum() and st["valid"] == vis.valid.sum()
    assert st["cumulative"]["+oblique"] == st["usable"]
    assert sum(e["usable"] for e in st["per_view"]) == st["usable"]
    V, F = vis.valid.shape
    N = len(vis.mesh.vertices)
    assert vis.uv.shape == (V, N, 2) and vis.uv.dtype == np.float32
    assert vis.depth.shape == (V, N) and vis.area.shape == (V, F) and vis.cos_angle.shape == (V, F)
    assert (vis.area[~vis.valid] == 0).all() and (vis.area[vis.valid] >= 0).all()


# ------------------------------------------------------------------------------------------
# projection and validity
# ------------------------------------------------------------------------------------------


def test_project_points_pixel_centre_convention(rng):
    E = look_at((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0))
    uv, z = project_points(np.array([[0.0, 0.0, 0.0]]), K, E)
    np.testing.assert_allclose(uv[0], [K[0, 2], K[1, 2]], atol=1e-12)
    np.testing.assert_allclose(z, [2.0])
    # round trip through unproject at random pixels and depths
    uv0 = rng.uniform([-0.5, -0.5], [W - 0.5, H - 0.5], size=(50, 2))
    z0 = rng.uniform(0.5, 5.0, 50)
    uv1, z1 = project_points(np.concatenate([unproject(E, u[None], np.array([zz])) for u, zz in zip(uv0, z0)]), K, E)
    np.testing.assert_allclose(uv1, uv0, atol=1e-9)
    np.testing.assert_allclose(z1, z0, atol=1e-12)
    # behind the camera -> NaN
    uv2, z2 = project_points(np.array([[0.0, 0.0, 3.0]]), K, E)
    assert z2[0] < 0 and np.isnan(uv2).all()


def test_validity_at_image_borders_and_behind_camera(tmp_path):
    E = look_at((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0))
    z = 2.0
    tris = [
        [(10, 10), (20, 10), (10, 20)],  # inside
        [(-0.5, 10), (5, 10), (0, 20)],  # vertex exactly on the left border -> inside
        [(-0.51, 10), (5, 10), (0, 20)],  # a vertex just outside -> invalid
        [(W - 0.51, 30), (W - 5, 30), (W - 3, 40)],  # right border, inside
        [(W - 0.5, 30), (W - 5, 30), (W - 3, 40)],  # x = W - 0.5 is outside -> invalid
        [(30, H - 0.5), (35, H - 5), (40, H - 3)],  # bottom border outside -> invalid
        [(30, -0.5), (40, 5), (35, 5)],  # top border inside
    ]
    verts, faces = [], []
    for k, t in enumerate(tris):
        P = unproject(E, np.array(t, float), np.full(3, z))
        # wind so that the normal faces the camera (+z)
        n = np.cross(P[1] - P[0], P[2] - P[0])
        if n[2] < 0:
            P = P[[0, 2, 1]]
        verts.append(P)
        faces.append(np.arange(3) + 3 * k)
    # a face behind the camera (z_world = 3 > camera at 2, camera looks down)
    verts.append(np.array([[0.0, 0.0, 3.0], [0.1, 0.0, 3.0], [0.0, 0.1, 3.0]]))
    faces.append(np.arange(3) + 3 * len(tris))
    v, f = np.concatenate(verts), np.stack(faces)
    scene = make_scene(tmp_path, (v, f), [E], depth=None)
    vis = compute_visibility(scene, filters=(), split_faces=False)  # the paper's rule, per input face
    assert vis.valid[0].tolist() == [True, True, False, True, False, False, True, False]
    assert np.isnan(vis.uv[0, -3:]).all()
    check_invariants(vis)
    # projected area of the first triangle: 10 x 10 / 2 px^2
    assert vis.area[0, 0] == pytest.approx(50.0, rel=1e-5)


def test_degenerate_faces_excluded_and_counted(tmp_path):
    v, f = plane(8)
    f = np.concatenate([f, [[0, 1, 1], [0, 0, 0]]])  # two zero-area faces
    scene = make_scene(tmp_path, (v, f), down_cameras(), depth=None)
    vis = compute_visibility(scene)
    assert vis.stats["degenerate_faces"] == 2
    assert not vis.valid[:, -2:].any()
    check_invariants(vis)


def test_mesh_without_normals(tmp_path):
    v, f = plane(8)
    scene = make_scene(tmp_path, (v, f), down_cameras(), depth=None, mesh_normals=False)
    vis = compute_visibility(scene, split_faces=False)  # load_mesh computes normals
    assert vis.usable.any()
    # a Mesh given without usable vertex normals: computed from the winding
    m = Mesh(vertices=v, faces=f, vertex_normals=None)
    vis2 = compute_visibility(scene, mesh=m, split_faces=False)
    assert np.array_equal(vis.usable, vis2.usable)
    assert vis2.mesh.vertex_normals.shape == v.shape


# ------------------------------------------------------------------------------------------
# z-buffering
# ------------------------------------------------------------------------------------------


def _segment_hits_box(C, P, lo, hi):
    """(n,) bool: segment C -> P (excluding the end) passes through the axis-aligned box."""
    d = P - C
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - C) / d
        t2 = (hi - C) / d
    tmin = np.nanmax(np.minimum(t1, t2), axis=1)
    tmax = np.nanmin(np.maximum(t1, t2), axis=1)
    return (tmax >= tmin) & (tmin < 0.999) & (tmax > 0)


def test_occluder_hides_faces_behind_it(tmp_path):
    pv, pf = plane(30)
    lo, hi = np.array([-0.25, -0.2, 0.6]), np.array([0.15, 0.2, 0.9])
    v, f = merge((pv, pf), box(lo, hi))
    cams = down_cameras()
    scene = make_scene(tmp_path, (v, f), cams, depth=None)
    vis = compute_visibility(scene)
    check_invariants(vis)
    n_plane = len(pf)
    for i, E in enumerate(cams):
        C = -E[:3, :3].T @ E[:3, 3]
        hit = _segment_hits_box(C, pv, lo, hi)  # per plane vertex
        # expected rule: a face is occluded when any of its vertices is hidden
        exp = hit[pf].any(1) & vis.valid[i, :n_plane]
        got = vis.occluded[i, :n_plane]
        assert exp.sum() > 20, "the occluder must hide a good part of the plane"
        disagree = (exp != got).sum()
        assert disagree <= 0.02 * exp.sum(), (i, disagree, exp.sum())
        # faces far from the shadow stay visible and usable
        assert vis.usable[i, :n_plane][vis.valid[i, :n_plane] & ~exp].mean() > 0.95
        # the box top is seen, its bottom is back-facing -> oblique, not usable
        assert vis.usable[i, n_plane + 2 : n_plane + 4].all()
        assert vis.oblique[i, n_plane : n_plane + 2][vis.valid[i, n_plane : n_plane + 2]].all()
    # the two views see different shadows -> different occluded sets
    assert (vis.occluded[0] != vis.occluded[1]).any()


def test_big_face_partly_hidden_is_occluded(tmp_path):
    # two big triangles (a 1.2 x 1.2 m square) and a thin pole in front of it: all four
    # corners are visible, the interior test points catch the pole
    pv, pf = plane(1, size=1.2)
    pole = box((0.1, -0.13, 0.2), (0.16, -0.07, 1.0))
    v, f = merge((pv, pf), pole)
    E = look_at((0.0, 0.05, 2.4), (0.0, 0.05, 0.0), up=(0.0, 1.0, 0.0))
    scene = make_scene(tmp_path, (v, f), [E], depth=None)
    vis = compute_visibility(scene, occlusion_spacing=4.0, split_faces=False)  # the filter on the input's faces
    assert vis.valid[0, :2].all()
    assert vis.occluded[0, :2].any()
    vis0 = compute_visibility(scene, occlusion_spacing=0, split_faces=False)  # vertices only
    assert not vis0.occluded[0, :2].any()


# ------------------------------------------------------------------------------------------
# depth consistency
# ------------------------------------------------------------------------------------------

SHIFT = (slice(20, 40), slice(30, 55))  # rows, cols of the region whose depth is shifted


def _shift(i, D):
    if i == 0:
        D = D.copy()
        D[SHIFT] += 0.30
    return D


@pytest.mark.parametrize("source", ["map", "cloud"])
def test_depth_disagreement_is_detected(tmp_path, source):
    v, f = plane(30)
    cams = down_cameras()
    scene = make_scene(tmp_path, (v, f), cams, depth=source, depth_edit=_shift)
    vis = compute_visibility(scene)
    check_invariants(vis)
    assert [e["depth_source"] for e in vis.stats["per_view"]] == [{"map": "depth", "cloud": "point_cloud"}[source]] * 2
    # expected: faces with a vertex whose nearest pixel is in the shifted region
    uv = vis.uv[0].astype(np.float64)
    ok = np.isfinite(uv).all(1)
    c = np.clip(np.floor(uv[:, 0] + 0.5), 0, W - 1).astype(int)
    r = np.clip(np.floor(uv[:, 1] + 0.5), 0, H - 1).astype(int)
    in_region = ok & (r >= SHIFT[0].start) & (r < SHIFT[0].stop) & (c >= SHIFT[1].start) & (c < SHIFT[1].stop)
    exp = vis.valid[0] & in_region[f].any(1)
    got = vis.depth_inconsistent[0]
    assert exp.sum() > 30
    if source == "map":
        assert np.array_equal(got, exp)
    else:  # sparse cloud + inpainting: the region's border may move by a pixel or two
        assert (got & exp).sum() >= 0.9 * exp.sum()
        core = vis.valid[0] & in_region[f].all(1)
        assert got[core].all()
        assert (got & ~exp).sum() <= 0.15 * exp.sum()
    # view 1 was not edited: (almost) nothing inconsistent
    assert vis.depth_inconsistent[1].sum() <= 0.01 * vis.valid[1].sum()
    # a looser threshold accepts the 30 cm shift
    vis2 = compute_visibility(scene, depth_atol=0.4)
    assert not vis2.depth_inconsistent[0].any()


def test_view_without_depth_skips_filter_with_log(tmp_path, caplog):
    scene = make_scene(tmp_path, plane(10), down_cameras(), depth=None)
    with caplog.at_level(logging.INFO, logger="o3d_seqcc.visibility"):
        vis = compute_visibility(scene)
    assert "neither a depth map nor a point cloud" in caplog.text
    assert not vis.depth_inconsistent.any()
    assert vis.stats["views_without_depth"] == ["v0", "v1"]


def test_depth_map_wrong_size_or_dtype_raises(tmp_path):
    scene = make_scene(tmp_path, plane(10), down_cameras(), depth="map")
    p = scene.views[0].depth
    cv2.imwrite(str(p), np.zeros((H // 2, W // 2), np.uint16))
    with pytest.raises(InputError, match=str(p.name)):
        compute_visibility(scene)
    cv2.imwrite(str(p), np.zeros((H, W), np.uint8))
    with pytest.raises(InputError, match="dtype"):
        compute_visibility(scene)


def test_point_cloud_far_from_mesh_warns(tmp_path):
    def far(i, D):
        return np.where(D > 0, D + 1.0, 0.0)  # the whole cloud 1 m behind the mesh

    scene = make_scene(tmp_path, plane(12), down_cameras(), depth="cloud", depth_edit=far)
    with pytest.warns(UserWarning, match="disagree"):
        vis = compute_visibility(scene)
    assert vis.stats["per_view"][0]["depth_disagreement"] > 0.9


def test_depth_from_point_cloud_nearest_and_fill():
    E = look_at((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0))
    pts = np.concatenate([unproject(E, np.array([[10.0, 10.0]]), np.array([z])) for z in (3.0, 2.0, 2.5)])
    D = depth_from_point_cloud(pts, K, E, W, H, fill_radius=0)
    assert D[10, 10] == pytest.approx(2.0)
    assert (D > 0).sum() == 1
    # a plane with a 3 x 3 pixel hole: filled by Navier-Stokes inpainting with ~ the plane depth
    D0 = render_depth(*plane(4), E)
    u, vv = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    hole = (np.abs(u - 40) <= 1) & (np.abs(vv - 30) <= 1)
    keep = (D0 > 0) & ~hole
    P = unproject(E, np.stack([u[keep], vv[keep]], 1), D0[keep])
    D1 = depth_from_point_cloud(P, K, E, W, H)
    assert (D1[hole] > 0).all()
    np.testing.assert_allclose(D1[hole], 2.0, atol=0.01)
    np.testing.assert_allclose(D1[keep], D0[keep], atol=1e-9)


# ------------------------------------------------------------------------------------------
# oblique faces
# ------------------------------------------------------------------------------------------


def test_grazing_wall_is_oblique(tmp_path):
    # camera at the origin looking along +y; a frontal wall, a wall seen at ~80 degrees, and a
    # wall facing away
    E = look_at((0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    frontal = grid((-0.3, 3.0, -0.2), (0.6, 0, 0), (0, 0, 0.4), 4, 4)  # normal -y (towards the camera)
    # grazing: a wall in the plane x = 0.5 from y = 2 to 4 (normal -x), seen at > 75 deg
    grazing = grid((0.5, 2.0, -0.2), (0, 0, 0.4), (0, 2.0, 0), 2, 8)
    away = grid((-0.3, 2.0, -0.2), (0, 0, 0.4), (0.6, 0, 0), 2, 2)  # normal +y: seen from behind
    parts = [frontal, grazing, away]
    v, f = merge(*parts)
    scene = make_scene(tmp_path, (v, f), [E], depth=None)
    vis = compute_visibility(scene, filters=("oblique",))
    n0, n1 = len(frontal[1]), len(grazing[1])
    sl = [slice(0, n0), slice(n0, n0 + n1), slice(n0 + n1, len(f))]
    assert vis.valid[0][sl[0]].all() and vis.valid[0][sl[1]].sum() > 4 and vis.valid[0][sl[2]].all()
    assert not vis.oblique[0][sl[0]].any()
    assert vis.oblique[0][sl[1]][vis.valid[0][sl[1]]].all()
    assert vis.oblique[0][sl[2]].all()  # back-facing
    assert (vis.cos_angle[0][sl[2]] < 0).all() and (vis.cos_angle[0][sl[0]] > 0.9).all()
    # a larger max_angle keeps the grazing wall (seen at 76-86 deg) partly; 89 keeps all of it
    vis89 = compute_visibility(scene, filters=("oblique",), max_angle=89.9)
    assert not vis89.oblique[0][sl[1]].any()
    # two-sided: the back-facing wall is frontal
    vis2 = compute_visibility(scene, filters=("oblique",), two_sided=True)
    assert not vis2.oblique[0][sl[2]].any()


def test_oblique_reference_axis_vs_ray(tmp_path):
    # a small face at the image border, facing the camera centre: 0 deg to the ray, ~28 deg to the axis
    E = look_at((0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    d = np.array([np.tan(np.radians(28.0)), 1.0, 0.0])
    d /= np.linalg.norm(d)
    c = 2.0 * d
    e1 = np.cross(d, [0, 0, 1.0]) * 0.05
    e2 = np.array([0, 0, 0.05])
    v, f = grid(c - (e1 + e2) / 2, e1, e2, 1, 1)
    if np.cross(v[f[0, 1]] - v[f[0, 0]], v[f[0, 2]] - v[f[0, 0]]) @ d > 0:
        f = f[:, [0, 2, 1]]
    scene = make_scene(tmp_path, (v, f), [E], depth=None)
    ray = compute_visibility(scene, filters=("oblique",), max_angle=20.0, oblique_reference="ray")
    axis = compute_visibility(scene, filters=("oblique",), max_angle=20.0, oblique_reference="axis")
    assert ray.valid[0].all()
    assert not ray.oblique[0].any()
    assert axis.oblique[0].all()


# ------------------------------------------------------------------------------------------
# bad input, options, determinism
# ------------------------------------------------------------------------------------------


def test_view_looking_away_warns_and_all_away_raises(tmp_path):
    cams = down_cameras() + [look_at((0.0, 0.0, 2.0), (0.0, 0.0, 5.0), up=(0.0, 1.0, 0.0))]
    scene = make_scene(tmp_path / "a", plane(10), cams, depth=None)
    with pytest.warns(UserWarning, match="sees no face"):
        vis = compute_visibility(scene)
    assert vis.stats["views_seeing_nothing"] == ["v2"]
    assert not vis.valid[2].any()
    away = Scene(scene.mesh, scene.views[2:])
    with pytest.warns(UserWarning), pytest.raises(InputError, match="no overlap"):
        compute_visibility(away)


def test_bad_options():
    scene = Scene(
        "/nonexistent.ply",
        (View(name="v", image="x.png", intrinsic=K, extrinsic=np.eye(4), width=W, height=H),),
    )
    with pytest.raises(ValueError, match="oblique"):
        compute_visibility(scene, filters=("oblique", "bogus"))
    with pytest.raises(ValueError, match="ray"):
        compute_visibility(scene, oblique_reference="normal")
    with pytest.raises(ValueError, match="max_angle"):
        compute_visibility(scene, max_angle=0)
    with pytest.raises(TypeError):
        compute_visibility(scene, max_angel=70)
    assert set(FILTERS) == {"occlusion", "depth", "oblique"}


def test_parallel_equals_serial(tmp_path):
    pv, pf = plane(20)
    v, f = merge((pv, pf), box((-0.2, -0.2, 0.5), (0.1, 0.2, 0.8)))
    scene = make_scene(tmp_path, (v, f), down_cameras(), depth="map", depth_edit=_shift)
    a = compute_visibility(scene, n_jobs=1)
    b = compute_visibility(scene, n_jobs=2)
    for name in ("valid", "occluded", "depth_inconsistent", "oblique", "usable", "uv", "area"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    masks = a.stage_masks()
    assert list(masks) == ["valid", "+occlusion", "+depth", "+oblique"]
    assert np.array_equal(masks["+oblique"], a.usable)


def test_depth_edge_margin_drops_faces_near_depth_discontinuities(tmp_path):
    v, f = plane(30)
    scene = make_scene(tmp_path, (v, f), down_cameras(), depth="map", depth_edit=_shift)
    base = compute_visibility(scene)
    wide = compute_visibility(scene, depth_edge_margin=3)
    assert not (base.depth_inconsistent & ~wide.depth_inconsistent).any()
    extra = wide.depth_inconsistent[0] & ~base.depth_inconsistent[0]
    assert extra.sum() > 5
    # the extra faces have a vertex within 3 px (nearest pixel) of the shifted region
    uv = wide.uv[0].astype(np.float64)
    c = np.floor(uv[:, 0] + 0.5)
    r = np.floor(uv[:, 1] + 0.5)
    dr = np.maximum(np.maximum(SHIFT[0].start - r, r - (SHIFT[0].stop - 1)), 0)
    dc = np.maximum(np.maximum(SHIFT[1].start - c, c - (SHIFT[1].stop - 1)), 0)
    near = np.maximum(dr, dc) <= 3 + 1  # the discontinuity lies between two pixels
    assert near[f[extra]].any(1).all()
    # view 1 has no discontinuity: unchanged
    assert np.array_equal(base.depth_inconsistent[1], wide.depth_inconsistent[1])
