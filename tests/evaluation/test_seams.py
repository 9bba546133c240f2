"""Tests of the seam metric (o3d_seqcc.evaluation.seams) on synthetic textured planes with known seams."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from o3d_seqcc.errors import InputError
from o3d_seqcc.imaging.arrays import delta_e_2000
from o3d_seqcc.evaluation.seams import seam_metric
from o3d_seqcc.texturing import load_textured_mesh, sample_texture

import trimesh
import PIL.Image as PIL

RED = np.array([200, 30, 30], dtype=np.uint8)
GREEN = np.array([40, 180, 60], dtype=np.uint8)


def two_chart_plane(n: int = 4, left=RED, right=GREEN, tex_size: int = 64, smooth: bool = False):
    """A 2n x n grid of quads on z = 0 (x in [0, 2], y in [0, 1]), split in two UV charts.

    The left half (x <= 1) maps to the left half of the texture, the right half to the right
    half, with a gap between the charts; vertices on x = 1 are duplicated (one copy per chart),
    as in any OBJ with UV seams. Returns (trimesh.Trimesh, texture uint8).
    """
    verts, uvs, faces = [], [], []
    for chart, (x0, u0) in enumerate([(0.0, 0.05), (1.0, 0.55)]):
        base = len(verts)
        for j in range(n + 1):
            for i in range(n + 1):
                verts.append([x0 + i / n, j / n, 0.0])
                uvs.append([u0 + 0.4 * i / n, 0.05 + 0.9 * j / n])
        for j in range(n):
            for i in range(n):
                a = base + j * (n + 1) + i
                b, c, d = a + 1, a + n + 2, a + n + 1
                faces += [[a, b, c], [a, c, d]]
    tex = np.empty((tex_size, tex_size, 3), dtype=np.uint8)
    if smooth:
        # a horizontal ramp continuous across the charts in 3D: colour depends on y (v) only
        ramp = np.linspace(100, 160, tex_size).astype(np.uint8)[::-1]
        tex[:] = np.stack([ramp, 255 - ramp, np.full_like(ramp, 100)], axis=1)[:, None, :]
    else:
        tex[:, : tex_size // 2] = left
        tex[:, tex_size // 2 :] = right
    visual = trimesh.visual.TextureVisuals(uv=np.array(uvs), image=PIL.fromarray(tex))
    mesh = trimesh.Trimesh(np.array(verts, float), np.array(faces), visual=visual, process=False)
    return mesh, tex


def _on_chart_seam(mesh, rep) -> np.ndarray:
    """(n_edges,) bool: measured edges lying on x = 1 (between the charts)."""
    tm = load_textured_mesh(mesh)
    # merged ids number the groups of positions equal to merge_tol in the order of their first vertex (as
    # seam_metric's weld_vertices does)
    q = np.round(tm.vertices / 1e-6).astype(np.int64)
    _, first = np.unique(q, axis=0, return_index=True)
    pos = tm.vertices[np.sort(first)]
    return np.all(np.isclose(pos[rep.edges][:, :, 0], 1.0), axis=1)


def expected_seam_de() -> float:
    return float(delta_e_2000(RED / 255.0, GREEN / 255.0))


def test_sample_texture_texel_centres():
    tex = np.zeros((2, 4, 3), np.uint8)
    tex[0, 1] = [255, 0, 0]  # top row, second column
    tex[1, 3] = [0, 255, 0]  # bottom row, last column
    uv = np.array([[(1 + 0.5) / 4, 1 - 0.5 / 2], [(3 + 0.5) / 4, 1 - 1.5 / 2], [2 / 4, 1 - 0.5 / 2]])
    c = sample_texture(tex, uv)
    np.testing.assert_allclose(c[0], [1, 0, 0])
    np.testing.assert_allclose(c[1], [0, 1, 0])
    np.testing.assert_allclose(c[2], [0.5, 0, 0])  # halfway between texel 1 (red) and texel 2 (black)


def test_constant_texture_has_no_seams():
    mesh, _ = two_chart_plane(left=RED, right=RED)
    rep = seam_metric(mesh)
    assert rep.n_edges > 0
    assert rep.mean < 1e-6 and rep.p99 < 1e-6 and rep.frac_above_5 == 0.0


def test_smooth_texture_continuous_across_charts_is_near_zero():
    mesh, _ = two_chart_plane(n=8, smooth=True, tex_size=256)
    rep = seam_metric(mesh, keep_per_edge=True, merge_tol=1e-6)
    assert rep.mean < 0.5, rep
    assert rep.frac_above_5 == 0.0
    # the edges between the two charts (x = 1) see the same colour on both sides
    on_seam = _on_chart_seam(mesh, rep)
    assert on_seam.sum() == 8
    assert rep.per_edge[on_seam].max() < 0.5


def test_two_colour_charts_known_seam():
    n = 4
    mesh, _ = two_chart_plane(n=n)
    rep = seam_metric(mesh, keep_per_edge=True, merge_tol=1e-6)
    # interior edges of the 2n x n grid (each quad split in two): all edges minus boundary edges
    W, H = 2 * n, n
    n_interior = W * (H + 1) + (W + 1) * H + W * H - 2 * (W + H)
    assert rep.n_edges == n_interior
    assert rep.n_boundary_edges == 2 * (W + H)
    de = expected_seam_de()
    assert de > 5
    # edges on x = 1 are the chart seam: they carry the red/green difference, the others 0
    on_seam = _on_chart_seam(mesh, rep)
    assert on_seam.sum() == n
    np.testing.assert_allclose(rep.per_edge[on_seam], de, rtol=1e-6)
    np.testing.assert_allclose(rep.per_edge[~on_seam], 0.0, atol=1e-6)
    np.testing.assert_allclose(rep.mean, n * de / n_interior, rtol=1e-6)
    np.testing.assert_allclose(rep.frac_above_5, n / n_interior)
    # only the chart seam is a UV seam; its mean is the known difference
    np.testing.assert_array_equal(rep.is_seam, on_seam)
    assert rep.n_seam_edges == n
    np.testing.assert_allclose(rep.seam_mean, de, rtol=1e-6)
    d = rep.to_dict()
    assert "per_edge" not in d and json.dumps(d)


@pytest.mark.parametrize("ext", [".obj", ".glb"])
def test_files_written_by_trimesh(tmp_path: Path, ext: str):
    n = 4
    mesh, _ = two_chart_plane(n=n)
    path = tmp_path / f"plane{ext}"
    mesh.export(path)
    assert path.is_file()
    rep_file = seam_metric(path)
    rep_mem = seam_metric(mesh)
    assert rep_file.n_edges == rep_mem.n_edges
    np.testing.assert_allclose(rep_file.mean, rep_mem.mean, rtol=1e-3)
    np.testing.assert_allclose(rep_file.frac_above_5, rep_mem.frac_above_5)


def test_vertex_colours(tmp_path: Path):
    mesh, _ = two_chart_plane(n=2)
    colors = np.tile(np.array([[10, 200, 30, 255]], np.uint8), (len(mesh.vertices), 1))
    vc = trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_colors=colors, process=False)
    rep = seam_metric(vc)
    assert rep.mean < 1e-6


def test_cli_seams(tmp_path: Path, capsys):
    from o3d_seqcc.cli import main

    mesh, _ = two_chart_plane(n=2)
    path = tmp_path / "plane.glb"
    mesh.export(path)
    out = tmp_path / "seams.json"
    assert main(["seams", str(path), "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert d["n_edges"] > 0 and d["frac_above_5"] > 0
    assert "mean" in json.loads(capsys.readouterr().out)


def test_bad_input(tmp_path: Path):
    with pytest.raises(InputError, match="not found"):
        seam_metric(tmp_path / "nope.obj")
    bare = trimesh.Trimesh(np.eye(3), [[0, 1, 2]], process=False)
    with pytest.raises(InputError, match="neither a texture"):
        seam_metric(bare)
    mesh, _ = two_chart_plane(n=2)
    with pytest.raises(InputError, match="offset"):
        seam_metric(mesh, offset=0.0)
    with pytest.raises(InputError, match="offset"):
        seam_metric(mesh, offset=-1.0)
    # a single textured triangle: no interior edge
    one = trimesh.Trimesh(
        np.eye(3), [[0, 1, 2]], visual=trimesh.visual.TextureVisuals(uv=np.eye(3)[:, :2], image=mesh.visual.material.image),
        process=False,
    )
    with pytest.raises(InputError, match="no interior edge"):
        seam_metric(one)


def single_chart_photo_plane(n: int = 8, tex_size: int = 128, seed: int = 0, split: bool = False):
    """A 2 x 1 plane of 2n x n quads mapped onto ONE UV chart of a noisy "photo" texture."""
    rng = np.random.default_rng(seed)
    verts, uvs, faces = [], [], []
    for j in range(n + 1):
        for i in range(2 * n + 1):
            verts.append([i / n, j / n, 0.0])
            uvs.append([0.05 + 0.9 * i / (2 * n), 0.05 + 0.9 * j / n])
    for j in range(n):
        for i in range(2 * n):
            a = j * (2 * n + 1) + i
            b, c, d = a + 1, a + 2 * n + 2, a + 2 * n + 1
            faces += [[a, b, c], [a, c, d]]
    verts, uvs, faces = np.array(verts, float), np.array(uvs), np.array(faces)
    if split:  # split vertices (one copy per face, same UVs): still one continuous chart
        verts, uvs = verts[faces.reshape(-1)], uvs[faces.reshape(-1)]
        faces = np.arange(len(verts)).reshape(-1, 3)
    tex = rng.integers(0, 256, size=(tex_size, tex_size, 3), dtype=np.uint8)  # texel-level detail
    visual = trimesh.visual.TextureVisuals(uv=uvs, image=PIL.fromarray(tex))
    return trimesh.Trimesh(verts, faces, visual=visual, process=False)


@pytest.mark.parametrize("split", [False, True])
@pytest.mark.parametrize("offset", [0.5, 1.0])
def test_photo_textured_single_chart_scores_zero(split, offset):
    """Edges inside a chart (same UVs on both sides) carry no seam, whatever the texture detail."""
    mesh = single_chart_photo_plane(split=split)
    rep = seam_metric(mesh, offset=offset, keep_per_edge=True)
    assert rep.n_edges > 0 and rep.n_seam_edges == 0
    assert rep.mean == 0.0 and rep.p99 == 0.0 and rep.frac_above_5 == 0.0
    assert not rep.is_seam.any()


@pytest.mark.parametrize("offset", [0.5, 1.0, 2.0])
def test_known_jump_independent_of_offset(offset):
    """Constant-colour charts: the seam value is the colours' CIEDE2000 at any inward offset."""
    mesh, _ = two_chart_plane(n=4, tex_size=128)
    rep = seam_metric(mesh, offset=offset, keep_per_edge=True, merge_tol=1e-6)
    np.testing.assert_allclose(rep.per_edge[rep.is_seam], expected_seam_de(), rtol=1e-6)
    assert rep.offset == offset


def test_offset_is_in_texels():
    """A chart textured with a 1-texel border of another colour: half a texel inside reads the
    border blended 50/50 with the interior; two texels inside reads the interior only."""
    n, size = 4, 64
    mesh, tex = two_chart_plane(n=n, left=RED, right=RED, tex_size=size)
    # chart 1 spans u in [0.55, 0.95]: paint the texel column at its left edge (u = 0.55) green
    col = int(np.floor(0.55 * size))
    tex = tex.copy()
    tex[:, col] = GREEN
    mesh.visual = trimesh.visual.TextureVisuals(uv=mesh.visual.uv, image=PIL.fromarray(tex))
    far = seam_metric(mesh, offset=2.0, keep_per_edge=True, merge_tol=1e-6)
    np.testing.assert_allclose(far.per_edge[far.is_seam], 0.0, atol=1e-6)
    near = seam_metric(mesh, offset=0.1, keep_per_edge=True, merge_tol=1e-6)
    assert near.per_edge[near.is_seam].min() > 5.0


def test_vertex_colour_jump(tmp_path: Path):
    mesh, _ = two_chart_plane(n=2)
    tm = load_textured_mesh(mesh)
    colors = np.where(tm.vertices[:, :1] <= 1.0 - 1e-9, RED, GREEN).astype(np.uint8)
    # vertices on x = 1 exist twice (one per chart): give the left chart's copies RED
    left_chart = np.arange(len(tm.vertices)) < len(tm.vertices) // 2
    colors[left_chart] = RED
    vc = trimesh.Trimesh(tm.vertices, tm.faces, vertex_colors=np.c_[colors, np.full(len(colors), 255)], process=False)
    rep = seam_metric(vc, keep_per_edge=True, merge_tol=1e-6)
    assert rep.n_seam_edges == 2
    np.testing.assert_allclose(rep.per_edge[rep.is_seam], expected_seam_de(), rtol=1e-6)


def test_selection_seams_of_several_image_sets_are_each_sets_seams():
    from o3d_seqcc.evaluation.seams import selection_seams, selection_seams_of
    from o3d_seqcc.scene import View

    rng = np.random.default_rng(4)
    g = np.stack(np.meshgrid(np.linspace(0, 1, 12), np.linspace(0, 1, 12)), -1).reshape(-1, 2)
    v = np.c_[g, np.zeros(len(g))]
    q = np.arange(144).reshape(12, 12)[:-1, :-1].reshape(-1)
    f = np.concatenate([np.stack([q, q + 1, q + 13], 1), np.stack([q, q + 13, q + 12], 1)])
    K = np.array([[80.0, 0, 39.5], [0, 80.0, 39.5], [0, 0, 1]])
    views = []
    for i in range(3):
        ext = np.eye(4)
        ext[:3, 3] = -np.array([0.5 + 0.05 * i, 0.5, -1.0])
        views.append(View(name=f"v{i}", image="x.png", intrinsic=K, extrinsic=ext, width=80, height=80))
    sel = rng.integers(-1, 3, len(f))
    sets = {"a": [rng.integers(0, 256, (80, 80, 3), dtype=np.uint8) for _ in views],
            "b": [rng.random((80, 80, 3)) for _ in views]}
    both = selection_seams_of(v, f, sel, views, sets)
    assert len(both["a"].delta_e) > 10
    for k, imgs in sets.items():
        one = selection_seams(v, f, sel, views, imgs)
        for name in ("delta_e", "segments", "faces"):
            assert np.array_equal(getattr(both[k], name), getattr(one, name)), (k, name)


def test_photo_colors_in_bands_of_rows_are_the_whole_images_remap(monkeypatch):
    """photo_colors converts REMAP_BAND_ROWS rows at a time for OpenCV's remap: the values of the whole image's."""
    from o3d_seqcc.evaluation import seams
    from o3d_seqcc.scene import View

    rng = np.random.default_rng(7)
    K = np.array([[90.0, 0, 59.5], [0, 90.0, 44.5], [0, 0, 1]])
    views = [View(name=f"v{i}", image="x.png", intrinsic=K, extrinsic=np.eye(4), width=120, height=90) for i in range(2)]
    n = 4000
    uv = np.c_[rng.uniform(-3, 123, n), rng.uniform(-3, 93, n)]
    uv[:200, 1] = np.repeat(np.arange(0, 90, 9), 20) + rng.choice([-1e-3, 0.0, 0.97, 0.999, 0.9999], 200)  # band edges
    pts = np.c_[(uv - K[:2, 2]) / 90.0, np.ones(n)]
    ids = rng.integers(-1, 2, n)
    sets = [[rng.integers(0, 256, (90, 120, 3), dtype=np.uint8) for _ in views],
            [rng.integers(0, 65536, (90, 120, 3), dtype=np.uint16) for _ in views]]
    monkeypatch.setattr(seams, "REMAP_BAND_ROWS", 10 ** 6)
    whole = seams.photo_colors(views, pts, ids, *sets)
    for rows in (1, 7, 9, 16):
        monkeypatch.setattr(seams, "REMAP_BAND_ROWS", rows)
        banded = seams.photo_colors(views, pts, ids, *sets)
        assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(whole, banded)), rows
    assert np.isnan(whole[0][ids < 0]).all() and not np.isnan(whole[0][ids >= 0]).any()
