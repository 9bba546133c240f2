"""Baking into the mesh's own UVs (issue 35, ``uv="keep"``): known layouts, known photos, the layout's problems."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_seqcc.errors import InputError
from o3d_seqcc.scene import Mesh
from o3d_seqcc.texturing import select_views
from o3d_seqcc.texturing.own_uv import (_output_vertices, bake_own_uv, check_corner_uv, own_uv_page, split_corner_uv,
                                        uv_problems)
from o3d_seqcc.texturing.settings import TextureSettings

from test_texturing import CAMS, RAW, centroid_error, grid_mesh, project, smooth_images


def _layout(mesh: Mesh, rng) -> np.ndarray:
    """A UV layout of the grid: the plane's (x, y) scaled into [0.05, 0.95]^2, turned by 30 degrees and mirrored in
    x (an artist's unwrap: its texel grid is not the photos' pixel grid)."""
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    xy = mesh.vertices[:, :2] @ np.array([[c, -s], [s, c]]).T
    xy[:, 0] *= -1
    xy = (xy - xy.min(axis=0)) / np.ptp(xy, axis=0).max() * 0.9 + 0.05
    return xy[mesh.faces]


def test_split_faces_take_their_barycentric_uvs():
    v = np.array([[0.0, 0, 0], [2, 0, 0], [0, 2, 0]])
    f = np.array([[0, 1, 2]])
    uv = np.array([[[0.1, 0.2], [0.9, 0.2], [0.1, 0.8]]])
    # the face split at its edges' midpoints into 4 parts
    sv = np.array([[0.0, 0, 0], [2, 0, 0], [0, 2, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    sf = np.array([[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]])
    got = split_corner_uv(sv, sf, np.zeros(4, dtype=np.int64), v, f, uv)
    want = 0.1 + np.stack([sv[sf][..., 0] * 0.4, sv[sf][..., 1] * 0.3], axis=-1) + [0, 0.1]
    np.testing.assert_allclose(got, want, atol=1e-12)
    assert split_corner_uv(v, f, None, v, f, uv) is not None


def test_output_keeps_the_vertices_and_adds_copies_at_uv_seams():
    f = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], dtype=float)
    vi, of, ouv = _output_vertices(f, uv, 4)
    assert np.array_equal(vi, np.arange(4)) and np.array_equal(of, f)  # one UV per vertex: the input as it was
    uv2 = uv.copy()
    uv2[1, 1] = [0.5, 0.5]  # vertex 2 has two UVs: a seam
    vi, of, ouv = _output_vertices(f, uv2, 4)
    assert len(vi) == 5 and np.array_equal(vi[:4], np.arange(4)) and vi[4] == 2
    np.testing.assert_array_equal(vi[of], f)  # the same positions at every corner
    np.testing.assert_array_equal(ouv[of], uv2)  # and the same UVs


def test_uv_problems_counts_zero_area_mirrored_and_overlapping_faces():
    t = np.array([
        [[10, 10], [40, 10], [10, 40]],  # 0: a face
        [[60, 10], [90, 10], [60, 40]],  # 1: another, apart
        [[15, 15], [35, 15], [15, 35]],  # 2: on top of face 0 (a stacked island)
        [[10, 60], [10, 90], [40, 60]],  # 3: mirrored (opposite winding)
        [[70, 70], [80, 80], [90, 90]],  # 4: zero area (a line)
    ], dtype=float)
    p = uv_problems(t.reshape(-1, 2), np.arange(15).reshape(-1, 3), 100, 100)
    assert p["zero_area_faces"] == 1 and p["examples"]["zero_area"] == [4]
    assert p["mirrored_faces"] == 1 and p["examples"]["mirrored"] == [3]
    assert p["overlapping_faces"] == 2 and p["examples"]["overlapping"] == [0, 2]
    assert 150 < p["overlapping_texels"] < 250  # face 2's area (200 texels), less its edge texels


def test_page_gives_the_median_face_one_texel_per_pixel():
    uv = np.array([[[0, 0], [0.01, 0], [0, 0.01]]] * 5, dtype=float)  # UV area 5e-5 each
    fuv = uv * 1000.0  # in the photo: 10 x 10 pixel legs, so 1000 texels across the page is one texel per pixel
    side, tpp, scale = own_uv_page(uv, fuv, np.ones(5, bool), TextureSettings())
    assert side == 1000 and tpp == pytest.approx(1.0) and scale == 1.0
    side, tpp, _ = own_uv_page(uv, fuv * 1.001, np.ones(5, bool), TextureSettings())
    assert side == 1004 and side % 4 == 0  # up to a multiple of 4
    assert own_uv_page(uv, fuv, np.ones(5, bool), TextureSettings(power_of_two=True))[0] == 1024
    with pytest.warns(UserWarning, match=r"density scaled by 0\.512"):
        side, tpp, scale = own_uv_page(uv, fuv, np.ones(5, bool), TextureSettings(atlas_size=512))
    assert side == 512 and scale == pytest.approx(0.512)


def test_uvs_outside_the_square_or_of_the_wrong_shape_are_input_errors():
    with pytest.raises(InputError, match=r"outside \[0, 1\].*UDIM"):
        check_corner_uv(np.full((2, 3, 2), 1.5), 2, where="mesh m.obj")
    with pytest.raises(InputError, match="one \\(u, v\\) per face corner"):
        check_corner_uv(np.zeros((2, 3)), 2)
    with pytest.raises(InputError, match="not finite"):
        check_corner_uv(np.full((1, 3, 2), np.nan), 1)


def test_bake_into_an_artists_layout_reproduces_the_photos(rng):
    """A turned and mirrored layout of a plane: every face centroid's texel is its selected photo's colour at the
    centroid's projection; the output is the input's faces and UVs; the mirrored layout is found (all faces one
    way: none against the majority) and nothing overlaps."""
    mesh = grid_mesh(10)
    vis = project(mesh, CAMS)
    images = smooth_images(rng, CAMS, cell=8)
    lab = select_views(vis, method="largest-area")
    uv = _layout(mesh, rng)
    tm = bake_own_uv(mesh, images, vis, lab, input_mesh=mesh, corner_uv=uv, settings=TextureSettings(**RAW))
    np.testing.assert_array_equal(tm.vertices[tm.faces], mesh.vertices[mesh.faces])
    np.testing.assert_allclose(tm.uv[tm.faces], uv)
    assert tm.stats["uv"] == "keep" and tm.stats["uv_layout"]["overlapping_faces"] == 0
    assert tm.stats["uv_layout"]["mirrored_faces"] == 0 and tm.stats["uv_layout"]["zero_area_faces"] == 0
    assert 1.0 <= tm.stats["face_texels_per_pixel"]["median"] < 1.05  # the side rounded up to a multiple of 4
    H, W = tm.page_shape
    assert H == W and W % 4 == 0
    err = centroid_error(tm, mesh, images, lab)
    assert err.mean() < 2.0 and err.max() < 12.0, (err.mean(), err.max())


def test_bake_into_a_layout_with_overlaps_reports_them(rng):
    mesh = grid_mesh(6)
    vis = project(mesh, CAMS)
    lab = select_views(vis, method="largest-area")
    uv = _layout(mesh, rng)
    # a fold: an inner vertex's UV moved past its neighbour (the faces on that side turn over, the island stays one)
    k = 3 * 7 + 3
    at_k, at_next = (mesh.faces == k), (mesh.faces == k + 1)
    step = uv[at_next][0] - uv[at_k][0]
    uv[at_k] += 1.6 * step
    folded = np.flatnonzero(at_k.any(axis=1))
    tm = bake_own_uv(mesh, smooth_images(rng, CAMS), vis, lab, input_mesh=mesh, corner_uv=uv,
                     settings=TextureSettings(**RAW))
    lay = tm.stats["uv_layout"]
    assert 1 <= lay["mirrored_faces"] < len(folded) and set(lay["examples"]["mirrored"]) <= set(folded.tolist())
    assert lay["overlapping_faces"] >= 2  # a fold lays the turned faces over their neighbours
    assert tm.stats["uv_islands"] == 1
    uv2 = _layout(mesh, rng)
    uv2[1] = uv2[0]  # face 1 stacked on face 0
    tm = bake_own_uv(mesh, smooth_images(rng, CAMS), vis, lab, input_mesh=mesh, corner_uv=uv2,
                     settings=TextureSettings(**RAW))
    assert tm.stats["uv_layout"]["examples"]["overlapping"][:2] == [0, 1]
