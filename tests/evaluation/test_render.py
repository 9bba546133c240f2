"""Tests of o3d_seqcc.evaluation.render: ray-cast textured renders, selection colouring, sharpness, gradient similarity."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from o3d_seqcc.errors import InputError
from o3d_seqcc.evaluation.render import (
    gradient_similarity,
    raycast,
    render_selection,
    render_textured,
    selection_palette,
    sharpness,
)
from o3d_seqcc.scene import View

import trimesh
import PIL.Image as PIL
import open3d  # noqa: F401

W, H = 160, 80


def plane_and_camera(seed: int = 0):
    """Plane z = 0, x in [0, 2], y in [0, 1] (two triangles), a random texture of W x H texels,
    and a camera at (1, 0.5, -2) looking along +z whose pixel centres land on the texel centres."""
    rng = np.random.default_rng(seed)
    tex = rng.integers(0, 256, size=(H, W, 3), dtype=np.uint8)
    v = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], float)
    uv = np.c_[v[:, 0] / 2, 1 - v[:, 1]]  # image row 0 (world y = 0) at the texture's top (v = 1)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    mesh = trimesh.Trimesh(v, f, visual=trimesh.visual.TextureVisuals(uv=uv, image=PIL.fromarray(tex)), process=False)
    ext = np.eye(4)
    ext[:3, 3] = -np.array([1.0, 0.5, -2.0])
    fx = W / 2 * 2  # plane half-width 1 at depth 2 covers W / 2 pixels
    K = np.array([[fx, 0, (W - 1) / 2], [0, fx, (H - 1) / 2], [0, 0, 1]])
    view = View(name="top", image="unused.png", intrinsic=K, extrinsic=ext, width=W, height=H)
    return mesh, tex, view


def test_render_reproduces_texture(tmp_path):
    mesh, tex, view = plane_and_camera()
    img = render_textured(mesh, view)
    assert img.shape == (H, W, 3) and img.dtype == np.uint8
    diff = np.abs(img.astype(int) - tex.astype(int))
    assert diff.max() <= 1, diff.max()
    # the same through a GLB file
    path = tmp_path / "plane.glb"
    mesh.export(path)
    assert np.abs(render_textured(path, view).astype(int) - tex.astype(int)).max() <= 1


def test_raycast_depth_and_background():
    mesh, _, view = plane_and_camera()
    hits = raycast(mesh, view)
    assert hits.mask.all()
    np.testing.assert_allclose(hits.depth, 2.0, atol=1e-5)
    np.testing.assert_allclose(hits.bary.sum(-1), 1.0, atol=1e-5)
    assert np.all(hits.cos_angle != 0)
    # move the camera sideways: the right part of the image sees nothing
    ext = np.array(view.extrinsic)
    ext[0, 3] -= 1.0  # camera centre x = 2: the plane covers the left half only
    v2 = View(name="side", image="unused.png", intrinsic=view.intrinsic, extrinsic=ext, width=W, height=H)
    img = render_textured(mesh, v2, background=(0, 0, 255))
    assert np.all(img[:, W // 2 + 1 :] == [0, 0, 255])
    assert raycast(mesh, v2).mask[:, : W // 2 - 1].all()


def test_backface_culling():
    mesh, _, view = plane_and_camera()
    flipped = trimesh.Trimesh(mesh.vertices, mesh.faces[:, ::-1], visual=mesh.visual, process=False)
    a = render_textured(mesh, view, cull_backfaces=True, background=(1, 2, 3))
    b = render_textured(flipped, view, cull_backfaces=True, background=(1, 2, 3))
    assert (np.all(a == [1, 2, 3], axis=-1).all()) != (np.all(b == [1, 2, 3], axis=-1).all())


def test_render_selection_colours_faces():
    mesh, _, view = plane_and_camera()
    img = render_selection((mesh.vertices, mesh.faces), np.array([0, 3]), view, n_views=4, shade=False)
    pal = selection_palette(4)
    hits = raycast(mesh, view)
    for face, k in [(0, 0), (1, 3)]:
        px = img[hits.face_ids == face]
        assert len(px) and np.all(px == pal[k])
    unseen = render_selection(mesh, np.array([-1, -1]), view, unseen_color=(9, 9, 9), shade=False)
    assert np.all(unseen == 9)
    with pytest.raises(InputError, match="faces"):
        render_selection(mesh, np.array([0]), view)


def test_palette_distinct():
    pal = selection_palette(24)
    assert pal.shape == (24, 3) and pal.dtype == np.uint8
    assert len({tuple(c) for c in pal}) == 24


def test_sharpness_blur_lower():
    rng = np.random.default_rng(1)
    img = cv2.resize(rng.integers(0, 256, (60, 80, 3), dtype=np.uint8), (320, 240), interpolation=cv2.INTER_NEAREST)
    blurred = cv2.GaussianBlur(img, (0, 0), 2.0)
    mask = np.zeros(img.shape[:2], bool)
    mask[20:200, 30:300] = True
    s, b = sharpness(img, mask), sharpness(blurred, mask)
    assert b < 0.5 * s
    # 16-bit version of the same image measures the same
    np.testing.assert_allclose(sharpness(img.astype(np.uint16) * 257, mask), s, rtol=1e-6)
    with pytest.raises(InputError):
        sharpness(img, np.zeros(img.shape[:2], bool))


def _lettering() -> np.ndarray:
    """A wall with dark lettering (like Fountain's "HAROLD HATCH"): smooth texture, antialiased strokes."""
    rng = np.random.default_rng(0)
    wall = 170 + cv2.GaussianBlur(rng.normal(0, 12, (120, 360, 3)), (0, 0), 3)
    img = np.clip(wall, 0, 255).astype(np.uint8)
    cv2.putText(img, "HAROLD HATCH", (12, 75), cv2.FONT_HERSHEY_SIMPLEX, 1.5, (40, 35, 30), 3, cv2.LINE_AA)
    return img


def test_gradient_similarity_known_answers():
    img = _lettering()
    mask = np.ones(img.shape[:2], bool)
    # the photo itself scores 1, also as 16-bit; an offset changes no gradient; a gain k on the
    # contrast scores 2k / (1 + k^2)
    assert gradient_similarity(img, img, mask) == pytest.approx(1.0, abs=1e-9)
    assert gradient_similarity(img.astype(np.uint16) * 257, img) == pytest.approx(1.0, abs=1e-6)
    f = img.astype(np.float64) / 255.0
    assert gradient_similarity(f + 0.1, f, mask) == pytest.approx(1.0, abs=1e-6)
    assert gradient_similarity(0.6 * f + 0.2, f, mask) == pytest.approx(2 * 0.6 / (1 + 0.36), abs=1e-5)
    # a blurred copy scores lower, the more blurred the lower
    g = [gradient_similarity(cv2.GaussianBlur(img, (0, 0), s), img, mask) for s in (0.7, 1.0, 2.0)]
    assert 0.95 > g[0] > g[1] > g[2] > 0.3
    # a misregistration within max_shift is forgiven (a real scan's render is a few pixels off its
    # photo); without the search, or shifted further, the copy scores lower, the further the lower
    assert gradient_similarity(np.roll(img, 1, axis=1), img, mask) > 0.999
    assert gradient_similarity(np.roll(img, (3, -2), axis=(1, 0)), img, mask) > 0.999
    g0 = [gradient_similarity(np.roll(img, d, axis=1), img, mask, max_shift=0) for d in (1, 2, 4)]
    assert 0.9 > g0[0] > g0[1] > g0[2]
    g = [gradient_similarity(np.roll(img, d, axis=1), img, mask) for d in (6, 9)]
    assert 0.5 > g[0] > g[1]
    # doubled edges (the lettering twice, 3 px apart, as at a misregistered seam) raise the
    # variance of the Laplacian above the photo's but lower the similarity
    doubled = np.minimum(img, np.roll(img, 3, axis=1))
    assert sharpness(doubled, mask) > sharpness(img, mask)
    assert gradient_similarity(doubled, img, mask) < 0.8
    # half the wall from a photo misregistered by 6 px: a seam through the lettering
    seam = img.copy()
    seam[:, 180:] = np.roll(img, 6, axis=1)[:, 180:]
    assert sharpness(seam, mask) > 0.99 * sharpness(img, mask)
    assert gradient_similarity(seam, img, mask) < 0.8
    # noise added to the photo scores lower; a flat image scores 0
    noisy = np.clip(img + np.random.default_rng(1).normal(0, 20, img.shape[:2])[..., None], 0, 255).astype(np.uint8)
    assert sharpness(noisy, mask) > sharpness(img, mask) and gradient_similarity(noisy, img, mask) < 0.9
    assert gradient_similarity(np.full_like(img, 99), img, mask) == 0.0


def test_gradient_similarity_mask_and_errors():
    img = _lettering()
    left = np.zeros(img.shape[:2], bool)
    left[:, :168] = True
    seam = img.copy()
    seam[:, 180:] = np.roll(img, 6, axis=1)[:, 180:]
    # only the masked pixels count: the seam's right half is outside the mask
    assert gradient_similarity(seam, img, left) == pytest.approx(1.0, abs=1e-9)
    assert gradient_similarity(seam, img) < 0.8
    with pytest.raises(InputError, match="one size"):
        gradient_similarity(img[:, :100], img)
    with pytest.raises(InputError, match="mask shape"):
        gradient_similarity(img, img, left[:, :100])
    with pytest.raises(InputError, match="no tile"):
        gradient_similarity(img, img, np.zeros(img.shape[:2], bool))
    with pytest.raises(InputError, match="no tile"):
        gradient_similarity(img, np.full_like(img, 7))
    with pytest.raises(InputError, match="window"):
        gradient_similarity(img, img, window=2)
    with pytest.raises(InputError, match="integer"):
        gradient_similarity(img, img, max_shift=1.5)


def test_supersampled_render_is_box_filtered():
    mesh, tex, view = plane_and_camera()
    img = render_textured(mesh, view, supersample=2)
    # the plane fills the view: 2x2 rays per pixel sample the texture at +-0.25 px, whose
    # bilinear average is a 2x2-tap blur of the texture (interior pixels)
    t = tex.astype(np.float64)
    k = np.array([0.25, 0.5, 0.25])
    blur = cv2.sepFilter2D(t, -1, k, k, borderType=cv2.BORDER_REPLICATE)
    inner = (slice(2, -2), slice(2, -2))
    # bilinear at +-1/4 px: weights (3/4, 1/4) on each side -> mean of the two = (1/8, 3/4, 1/8)
    k2 = np.array([0.125, 0.75, 0.125])
    expect = cv2.sepFilter2D(t, -1, k2, k2, borderType=cv2.BORDER_REPLICATE)
    assert np.abs(img[inner] - expect[inner]).max() <= 1.0
    assert np.abs(img[inner] - blur[inner]).mean() > np.abs(img[inner] - expect[inner]).mean()
    with pytest.raises(InputError):
        render_textured(mesh, view, supersample=0)


def test_resized_view_renders_the_same_picture_smaller():
    from o3d_seqcc.evaluation.render import resized_view, supersampled_view

    mesh, tex, view = plane_and_camera()
    half = resized_view(view, W // 2)
    assert (half.width, half.height) == (W // 2, H // 2)
    # the same field of view: a half-size render is the full one averaged over 2 x 2 blocks
    full = render_textured(mesh, view).astype(float)
    small = render_textured(mesh, half, supersample=2).astype(float)
    np.testing.assert_allclose(small, full.reshape(H // 2, 2, W // 2, 2, 3).mean(axis=(1, 3)), atol=1.0)
    np.testing.assert_array_equal(supersampled_view(half, 2).intrinsic, view.intrinsic)
    assert resized_view(view, W) is view
    with pytest.raises(InputError, match="positive"):
        resized_view(view, 0)


def test_selection_streamed_in_row_chunks_is_the_whole_cast_coloured(monkeypatch, tmp_path):
    """render_selection without hits casts and colours row chunks: the picture of the one-chunk cast, bit for bit;
    a shared RayCaster (Casters: one per mesh, any thread) casts what a new one casts."""
    from concurrent.futures import ThreadPoolExecutor

    import o3d_seqcc as sc
    from o3d_seqcc.evaluation import render

    sc.make_synthetic_scene(tmp_path / "room", n_views=2, width=160, height=120, cell_size=0.15)
    scene = sc.load_scene(tmp_path / "room")
    mesh, view = scene.load_mesh(), scene.views[0]
    sel = np.random.default_rng(1).integers(-1, 2, len(mesh.faces))
    whole = render.render_selection(mesh, sel, view, n_views=2, hits=render.raycast(mesh, view))
    monkeypatch.setattr(render, "RAY_CHUNK", 1000)  # 6 rows per chunk, the last one short
    assert np.array_equal(render.render_selection(mesh, sel, view, n_views=2), whole)
    casters = render.Casters()
    pair = (mesh.vertices, mesh.faces)
    with ThreadPoolExecutor(4) as pool:
        got = list(pool.map(lambda _: casters.get(pair), range(8)))
    assert all(c is got[0] for c in got) and casters.get((mesh.vertices, mesh.faces)) is got[0]
    assert casters.get(mesh) is not got[0]  # another object: its own caster
    with ThreadPoolExecutor(2) as pool:
        shots = list(pool.map(lambda _: render.render_selection(mesh, sel, view, n_views=2, caster=got[0]), range(4)))
    assert all(np.array_equal(s, whole) for s in shots)
    hits = render.raycast(mesh, view, caster=got[0])
    assert np.array_equal(hits.face_ids, render.raycast(mesh, view).face_ids)


def test_the_written_palette_is_the_greedy_choice():
    from o3d_seqcc.evaluation import render

    full = render._distinct_palette(64)
    assert np.array_equal(render._PALETTE, full)
    for n in (1, 2, 5, 33, 64):
        assert np.array_equal(render._distinct_palette(n), full[:n])
        assert np.array_equal(selection_palette(n), full[:n])
    assert np.array_equal(selection_palette(70), np.resize(full, (70, 3)))
