"""The bake adds no blur (issue 19): a photographed plane textured and rendered back reproduces the photo.

Known answers that could fail: one photo of a tilted plane, textured with the library's defaults
(``pipeline.texture``: selection, native-resolution atlas, bake, seam leveling) and ray-cast from
the same camera, gives back the photo (PSNR >= 40 dB, sharpness >= 0.98 of the photo's); the
texels of every chart sit on the photo's pixel grid (integer offsets, x and y at most swapped)
and, at one texel per pixel, hold the photo's pixels exactly.
"""

from __future__ import annotations

import numpy as np
import pytest

import o3d_seqcc as sc
from o3d_seqcc.evaluation.render import raycast, render_textured, sharpness
from o3d_seqcc.scene import Scene, View

from test_texturing import grid_mesh


def _photo(w: int, h: int) -> np.ndarray:
    """A detailed photo (scikit-image's astronaut, area-averaged to w x h: sharp edges, fine texture)."""
    import cv2
    import skimage.data

    img = skimage.data.astronaut()
    return np.ascontiguousarray(cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA))


def _plane_scene(w: int = 320, h: int = 240, *, tilt_deg: float = 12.0, roll_deg: float = 0.0, n: int = 24):
    """A plane (n x n quads on [-1, 1]^2) seen by one camera 3.2 m away, tilted and rolled; its photo."""
    mesh = grid_mesh(n)
    a, r = np.deg2rad(tilt_deg), np.deg2rad(roll_deg)
    Ry = np.array([[np.cos(a), 0, -np.sin(a)], [0, 1, 0], [np.sin(a), 0, np.cos(a)]])
    Rz = np.array([[np.cos(r), -np.sin(r), 0], [np.sin(r), np.cos(r), 0], [0, 0, 1.0]])
    R = Rz @ Ry
    C = np.array([0.05, -0.03, -3.2]) @ Ry  # keeps the plane's centre near the optical axis
    ext = np.eye(4)
    ext[:3, :3], ext[:3, 3] = R, -R @ C
    f = 0.8 * w
    K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])
    photo = _photo(w, h)
    view = View(name="v0", image=None, pixels=photo, intrinsic=K, extrinsic=ext, width=w, height=h)
    return Scene(mesh=mesh, views=(view,)), view, photo


def _psnr(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    d = a[mask].astype(np.float64) - b[mask].astype(np.float64)
    return float(10 * np.log10(255.0 ** 2 / max(np.mean(d * d), 1e-12)))


@pytest.mark.parametrize("roll", [0.0, 25.0])
def test_one_photo_plane_rendered_back_is_the_photo(roll):
    """Defaults end to end (also with the plane's chart tilted in the photo by a rolled camera): the
    render from the photo's camera over the plane (eroded 3 px from its outline) has PSNR >= 40 dB
    against the photo and >= 0.98 of its sharpness."""
    import cv2

    scene, view, photo = _plane_scene(roll_deg=roll)
    res = sc.pipeline.texture(scene, seams=False)
    tm = res.textured
    assert tm.stats["texels_per_pixel"] == 1.0 and tm.stats["density_scale"] == 1.0
    hits = raycast(tm, view)
    img = render_textured(tm, view, hits=hits)
    mask = cv2.erode(hits.mask.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    assert mask.mean() > 0.25  # the plane fills a good part of the photo
    psnr = _psnr(img, photo, mask)
    ratio = sharpness(img, mask) / sharpness(photo, mask)
    assert psnr >= 40.0, psnr
    assert 0.98 <= ratio <= 1.02, ratio


def test_texels_are_the_photos_pixels():
    """Every chart's texel coordinates are its photo coordinates moved by whole texels (x, y at most
    swapped), and the texel under each pixel centre holds that pixel exactly."""
    scene, view, photo = _plane_scene(roll_deg=25.0)
    res = sc.pipeline.texture(scene, seams=False, leveling=False, local_leveling=False)
    tm = res.textured
    vis = res.visibility
    fuv = vis.face_uv(res.selection)  # (F, 3, 2) photo coordinates of every face's corners
    txy = tm.texel_xy()[tm.faces]  # (F, 3, 2) their texel coordinates
    d = txy - fuv
    ds = txy - fuv[..., ::-1]
    straight = np.abs(d - np.rint(d)).max(axis=(1, 2)) < 1e-3
    swapped = np.abs(ds - np.rint(ds)).max(axis=(1, 2)) < 1e-3
    assert np.all(straight | swapped)
    # pixel centres inside the faces -> their texels, which are copies
    seen = res.selection >= 0
    f = np.flatnonzero(seen)
    b = np.full((len(f), 3), 1 / 3)
    p_img = np.einsum("fk,fkd->fd", b, fuv[f])
    p_tex = np.einsum("fk,fkd->fd", b, txy[f])
    px = np.rint(p_img).astype(int)
    tx = np.rint(p_tex + (px - p_img) * np.where(straight[f], 1, 0)[:, None]
                 + (px - p_img)[:, ::-1] * np.where(straight[f], 0, 1)[:, None]).astype(int)
    np.testing.assert_array_equal(tm.texture[tx[:, 1], tx[:, 0]], photo[px[:, 1], px[:, 0]])
