"""How much detail a picture holds, and how much of a reference's: the sharpness measures.

- :func:`sharpness`: variance of the Laplacian inside a mask (rewards any high frequency);
- :func:`gradient_similarity`: the SSIM formula on the gradients against a reference, at the best
  small shift per tile (does not reward doubled edges or misregistered seams).

Both take plain arrays: images (H, W, 3) or (H, W), uint8 / uint16 / float in 0..1.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..errors import InputError
from ..imaging.arrays import dtype_scale

__all__ = ["gradient_similarity", "sharpness"]


def sharpness(image: np.ndarray, mask: np.ndarray | None = None, *, erode: int = 2) -> float:
    """Variance of the Laplacian of the grey image inside a mask (a focus / detail measure).

    Parameters
    ----------
    image : (H, W, 3) or (H, W) uint8 / uint16 / float array
        RGB image; integers are scaled to [0, 1] first so 8- and 16-bit images compare.
    mask : (H, W) bool array, optional
        Pixels to use (e.g. the mesh silhouette of a render); default all.
    erode : int, default 2
        Erode the mask by this many pixels so its border (e.g. the silhouette edge against the
        background) does not count.

    Returns
    -------
    float
        Variance of ``cv2.Laplacian`` (3x3) of the grey image over the mask, in [0,1]^2 units.
    """
    img = np.asarray(image)
    img = img.astype(np.float32) / np.float32(dtype_scale(img.dtype))
    grey = (cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img).astype(np.float64)
    lap = cv2.Laplacian(grey, cv2.CV_64F, ksize=1)
    m = np.ones(grey.shape, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if m.shape != grey.shape:
        raise InputError(f"mask shape {m.shape} does not match the image {grey.shape}")
    if erode > 0:
        m = cv2.erode(m.astype(np.uint8), np.ones((2 * erode + 1, 2 * erode + 1), np.uint8), borderValue=0).astype(bool)
    if not m.any():
        raise InputError("sharpness: the (eroded) mask is empty")
    return float(np.var(lap[m]))


def gradient_similarity(
    image: np.ndarray,
    reference: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    erode: int = 2,
    window: int = 24,
    max_shift: int = 3,
) -> float:
    """How much of a reference's detail an image holds, in place: locally registered gradient similarity.

    :func:`sharpness` rewards any high frequency, including edges that are not in the photo: a
    texture that shows an edge twice (two photos misregistered across a seam), aliasing or noise
    raises the variance of the Laplacian. This measure does not. The grey-level gradient fields
    (3 x 3 Sobel) ``g`` of the image and ``h`` of the reference are compared in ``window`` x
    ``window`` tiles, each tile by the SSIM form applied to gradient vectors,
    ``2 <g, h> / (|g|^2 + |h|^2)`` (summed over the tile): 1 only when the image has the
    reference's gradients, same directions and strengths; lower for weaker ones (blur, a faint
    blend), misplaced ones (a doubled edge, a wrong photo) and extra ones (aliasing, noise). The
    image is shifted per tile to its best match within ``max_shift`` pixels (integer steps, then
    half-pixel steps on a 2x cubic upsampling of both), and the result is the mean of the tiles'
    scores weighted by the reference's gradient energy in each (strong edges weigh most, as
    they do for the eye).

    The shift search forgives what is not the texture's fault: a render of a real scan from a
    photo's camera is misregistered with that photo by a few pixels (pose and geometry error),
    differently in different places. Not forgiven: edges misplaced by more, and two parts of a
    tile shifted apart (a seam between misregistered photos). The photo itself scores 1 (and so
    does any offset of it); a gain ``k`` on its contrast scores ``2k / (1 + k^2)`` (0.995 for
    k = 1.1).

    Parameters
    ----------
    image, reference : (H, W, 3) or (H, W) uint8 / uint16 / float arrays
        The render and the photo it is compared with, same size; integers are scaled to [0, 1].
    mask : (H, W) bool array, optional
        Pixels to use (e.g. where the render sees the mesh); default all. Tiles less than half
        inside the (eroded) mask, or where the reference is flat, do not count.
    erode : int, default 2
        Erode the mask by this many pixels (plus ``max_shift + 1``) so its border does not count.
    window : int, default 24
        Tile side in pixels: the scale at which misregistration is forgiven.
    max_shift : int, default 3
        Largest shift searched per tile, pixels (0: no search, the tiles compared in place).

    Returns
    -------
    float
        In [-1, 1]; 0 when ``image`` is flat.

    Raises
    ------
    InputError
        Different sizes, a mask of another shape, no tile inside the (eroded) mask with
        gradients in the reference (or the image smaller than a tile), a bad ``window`` /
        ``max_shift``.
    """

    def grey(x: np.ndarray) -> np.ndarray:
        f = np.asarray(x).astype(np.float32) / np.float32(dtype_scale(np.asarray(x).dtype))
        return (cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) if f.ndim == 3 else f).astype(np.float32)

    def grads(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)

    a, b = grey(image), grey(reference)
    w, r = int(window), int(max_shift)
    if a.shape != b.shape or w < 4 or not 0 <= r <= 16 or r != max_shift:
        raise InputError(f"gradient_similarity: image {a.shape} and reference {b.shape} must have one size, window "
                         f"be >= 4 and max_shift an integer in 0..16 (got {window}, {max_shift})")
    m = np.ones(a.shape, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if m.shape != a.shape:
        raise InputError(f"mask shape {m.shape} does not match the image {a.shape}")
    e = int(erode) + (r + 1 if r else 0)
    if e > 0:
        m = cv2.erode(m.astype(np.uint8), np.ones((2 * e + 1, 2 * e + 1), np.uint8), borderValue=0).astype(bool)
    (H, W), mf = a.shape, m.astype(np.float32)
    nh, nw = H // w, W // w

    def tiles(x: np.ndarray) -> np.ndarray:
        return x[:nh * w, :nw * w].reshape(nh, w, nw, w).sum(axis=(1, 3)).astype(np.float64)

    (ax, ay), (bx, by) = grads(a), grads(b)
    bx, by = bx * mf, by * mf
    eb = tiles(bx * bx + by * by)
    valid = (tiles(mf) >= 0.5 * w * w) & (eb > 1e-12)
    if not valid.any():
        raise InputError("gradient_similarity: no tile inside the (eroded) mask where the reference has gradients")
    # 1. integer shifts: the best per tile (a loop over (2r + 1)^2 shifts, each a few whole-image operations)
    axp, ayp = np.pad(ax, r, mode="edge"), np.pad(ay, r, mode="edge")
    a2p = axp * axp + ayp * ayp
    best, arg = np.full(eb.shape, -np.inf), np.zeros(eb.shape + (2,), dtype=np.int64)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            win = (slice(r + dy, r + dy + H), slice(r + dx, r + dx + W))
            with np.errstate(divide="ignore", invalid="ignore"):  # tiles outside the mask: 0 / 0, not counted
                sim = 2.0 * tiles(axp[win] * bx + ayp[win] * by) / (tiles(a2p[win] * mf) + eb)
            better = sim > best
            best[better], arg[better] = sim[better], (dy, dx)
    # 2. scored on both images upsampled 2x (cubic), the tiles gathered at twice their best shift and, when
    # searching, half a pixel around it
    size = (2 * W, 2 * H)
    (AX, AY), (BX, BY) = (grads(cv2.resize(x, size, interpolation=cv2.INTER_CUBIC)) for x in (a, b))
    P, ti, tj = 2 * r + 1, *np.nonzero(valid)
    AXp, AYp = np.pad(AX, P, mode="edge"), np.pad(AY, P, mode="edge")

    def stack(x: np.ndarray) -> np.ndarray:  # (T, 2w, 2w): the valid tiles of a 2x image
        return x[:nh * 2 * w, :nw * 2 * w].reshape(nh, 2 * w, nw, 2 * w).transpose(0, 2, 1, 3)[ti, tj]

    Mt = stack(cv2.resize(mf, size, interpolation=cv2.INTER_NEAREST))
    BXt, BYt = stack(BX) * Mt, stack(BY) * Mt
    EB = (BXt * BXt + BYt * BYt).sum(axis=(1, 2), dtype=np.float64)
    k, score = np.arange(2 * w), np.full(len(ti), -np.inf)
    for ey, ex in [(y, x) for y in (-1, 0, 1) for x in (-1, 0, 1)] if r else [(0, 0)]:
        ys = (P + 2 * w * ti + 2 * arg[ti, tj, 0] + ey)[:, None] + k
        xs = (P + 2 * w * tj + 2 * arg[ti, tj, 1] + ex)[:, None] + k
        gx, gy = AXp[ys[:, :, None], xs[:, None, :]], AYp[ys[:, :, None], xs[:, None, :]]
        dot = (gx * BXt + gy * BYt).sum(axis=(1, 2), dtype=np.float64)
        ea = ((gx * gx + gy * gy) * Mt).sum(axis=(1, 2), dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            score = np.maximum(score, np.where(EB > 0, 2.0 * dot / (ea + EB), 0.0))
    keep = EB > 1e-12
    return float(np.clip((EB[keep] * score[keep]).sum() / EB[keep].sum(), -1.0, 1.0))
