"""Filling an atlas page's empty texels smoothly from the baked ones: pull-push (issues 13, 21).

The texels no chart and no gutter reaches (:mod:`~o3d_seqcc.texturing.bake`) take a smooth
continuation of the baked colours, so that bilinear filtering and every mip level read no
black: :func:`push_pull_fill`, on a page in row bands on threads (the same values for any
number of threads).
"""

from __future__ import annotations

import numpy as np

from .._shared.parallel import thread_map

__all__ = ["push_pull_fill"]


#: rows of a full-resolution page handled at a time by :func:`push_pull_fill` (even)
FILL_BAND_ROWS = 1024


def _as_uint8(values: np.ndarray) -> np.ndarray:
    """``clip(rint(values), 0, 255)`` as uint8 for non-negative float32 values (OpenCV's rounding to nearest even and
    saturation: the same numbers, one pass)."""
    import cv2

    return cv2.convertScaleAbs(np.ascontiguousarray(values)).reshape(values.shape)


def push_pull_fill(img: np.ndarray, mask: np.ndarray, *, copy: bool = True, threads: int = 1) -> np.ndarray:
    """Fill texels outside ``mask`` with smooth colours from the masked ones (pull-push).

    Pull: area-averaged pyramid of colour x coverage and coverage. Push: from the coarsest
    level up, ``filled = c + (1 - w) * upsampled`` (``c`` is the coverage-weighted colour mean,
    ``w`` the coverage), and at full resolution only the empty texels are replaced.

    On a page of even sides (power-of-two atlases) the full-resolution level is never held as
    floats: its 2 x 2 averages and the last upsampling are made :data:`FILL_BAND_ROWS` rows at a
    time, every value as the whole-page OpenCV call gives it (an exact halving or doubling
    depends on the 2 x 2 / 2-row neighbourhood only); 16 bytes per texel less at the peak.

    Parameters
    ----------
    img : (H, W, 3) uint8
    mask : (H, W) bool
        Texels to keep.

    copy : bool, default True
        Fill a copy; False fills ``img`` itself (for a caller that drops the unfilled image).
    threads : int, default 1
        The full-resolution bands pulled and pushed side by side (the same values).

    Returns
    -------
    (H, W, 3) uint8
        A new image (``img`` with ``copy=False``).
    """
    import cv2

    H, W = mask.shape
    B = FILL_BAND_ROWS
    banded = H % 2 == 0 and W % 2 == 0 and H > B
    if banded:  # level 1 from bands of the full-resolution colour x coverage
        m = np.empty((H // 2, W // 2), dtype=np.float32)
        c = np.empty((H // 2, W // 2, 3), dtype=np.float32)
        def pull(r: int, m1: np.ndarray = m, c1: np.ndarray = c) -> None:  # band by band into the level
            hb = min(B, H - r) // 2
            mb = mask[r:r + B].astype(np.float32)
            m1[r // 2:r // 2 + hb] = cv2.resize(mb, (W // 2, hb), interpolation=cv2.INTER_AREA)
            cb = img[r:r + B].astype(np.float32)
            cb *= mb[..., None]
            c1[r // 2:r // 2 + hb] = cv2.resize(cb, (W // 2, hb), interpolation=cv2.INTER_AREA)

        thread_map(pull, range(0, H, B), threads, name="o3d_seqcc-fill")
        levels = [(c, m)]
    else:
        m = mask.astype(np.float32)
        c = img.astype(np.float32)
        c *= m[..., None]
        levels = []
    while min(m.shape) > 1:
        hh, ww = (m.shape[0] + 1) // 2, (m.shape[1] + 1) // 2
        c = cv2.resize(c, (ww, hh), interpolation=cv2.INTER_AREA)
        m = cv2.resize(m, (ww, hh), interpolation=cv2.INTER_AREA)
        levels.append((c, m))
    if not levels:
        return img.copy() if copy else img
    c, m = levels[-1]
    filled = c / np.maximum(m, 1e-12)[..., None]
    for c, m in reversed(levels[:-1]):
        up = cv2.resize(filled, (m.shape[1], m.shape[0]), interpolation=cv2.INTER_LINEAR)
        wgt = np.clip(m, 0.0, 1.0)
        np.subtract(1.0, wgt, out=wgt)
        up *= wgt[..., None]
        up += c  # c + up * (1 - clip(m, 0, 1)), in place
        filled = up
        del wgt
    del levels, c, m
    out = img.copy() if copy else img
    if not banded:
        up = cv2.resize(filled, (W, H), interpolation=cv2.INTER_LINEAR)
        np.copyto(out, _as_uint8(up), where=~mask[..., None])
        return out
    h2 = filled.shape[0]

    def push(r: int) -> None:  # output rows r .. r1 read level-1 rows r/2 - 1 .. r1/2 (clamped at the page)
        r1 = min(H, r + B)
        s0, s1 = max(r // 2 - 1, 0), min(r1 // 2 + 1, h2)
        up = cv2.resize(filled[s0:s1], (W, 2 * (s1 - s0)), interpolation=cv2.INTER_LINEAR)[r - 2 * s0:r1 - 2 * s0]
        np.copyto(out[r:r1], _as_uint8(up), where=~mask[r:r1, :, None])

    thread_map(push, range(0, H, B), threads, name="o3d_seqcc-fill")
    return out

