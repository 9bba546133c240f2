"""Small charts packed together in one block with a narrower gutter (issue 35).

On a fine mesh most charts are tiny: on Fountain 300k, 7505 of its 7713 charts are at most 16 texels on their
longer side; they hold 4.6 % of the triangles' texels but, each with its 4-texel gutter on every side, 31 % of
the padded area. A gutter of ``padding`` texels keeps a chart's mip levels up to log2(padding) free of its
neighbours' colours; a chart of s texels is itself no more than s / 2^L texels at level L, so the wide gutter
buys a tiny chart little. :func:`pack_with_block` packs the charts of at most ``small_charts`` texels (at the
asked density) alone, at ``small_padding``, into one tight block (xatlas, :func:`~o3d_seqcc.texturing.packing.pack_charts`),
then packs the block as one rectangular chart among the large ones at the full ``padding``, and moves every
small chart by the block's placement (x and y swapped where xatlas turned the block): each small chart's texel
grid is still its photo's pixel grid, moved by whole texels.

The block is used when it packs at the asked density; when a budget lowers the density (the block's texels
would no longer be whole texels of the page) or there are too few small charts to gain anything, the charts
are packed as before, each on its own.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import Any, Callable

import numpy as np

__all__ = ["MIN_BLOCK_CHARTS", "pack_with_block", "small_chart_mask"]

logger = logging.getLogger("o3d_seqcc.texturing.packing")

#: fewer small charts than this are packed each on its own (a block of a few saves nothing)
MIN_BLOCK_CHARTS = 32


def small_chart_mask(uv: np.ndarray, faces: np.ndarray, chart: np.ndarray, side: float) -> np.ndarray:
    """(C,) bool: the charts whose extent in ``uv`` units is at most ``side`` on its longer side."""
    uv = np.asarray(uv, dtype=np.float64)
    chart = np.asarray(chart, dtype=np.int64)
    n = int(chart.max()) + 1 if len(chart) else 0
    vc = np.full(len(uv), -1, dtype=np.int64)
    vc[np.asarray(faces, dtype=np.int64)] = chart[:, None]
    ok = vc >= 0
    lo = np.full((n, 2), np.inf)
    hi = np.full((n, 2), -np.inf)
    np.minimum.at(lo, vc[ok], uv[ok])
    np.maximum.at(hi, vc[ok], uv[ok])
    span = np.where(np.isfinite(hi - lo), hi - lo, 0.0)
    return span.max(axis=1, initial=0.0) <= side


def _sub(uv: np.ndarray, faces: np.ndarray, chart: np.ndarray, keep_face: np.ndarray):
    """The sub-mesh of the faces ``keep_face``: (its vertices' ids in ``uv``, uv, faces, chart ids 0..)."""
    fs = np.flatnonzero(keep_face)
    f = np.asarray(faces, dtype=np.int64)[fs]
    used = np.unique(f)
    remap = np.full(len(uv), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    ch = np.unique(np.asarray(chart)[fs], return_inverse=True)[1].reshape(-1)
    return used, np.asarray(uv, dtype=np.float64)[used], remap[f], ch


def pack_with_block(uv: np.ndarray, faces: np.ndarray, chart: np.ndarray, pack: Callable[..., Any], *,
                    small_charts: int, small_padding: int, texels_per_pixel, **options) -> Any:
    """``pack(uv, faces, chart, texels_per_pixel=..., **options)`` with the small charts in one block.

    Parameters
    ----------
    uv, faces, chart
        As :func:`~o3d_seqcc.texturing.packing.pack_charts`'s.
    pack : callable
        The packer (:func:`~o3d_seqcc.texturing.packing.pack_charts` or the speculating one).
    small_charts : int
        Charts of at most this many texels on their longer side (at the asked density) go into the block; 0: none.
    small_padding : int
        The block's gutters (>= 0, at most ``options["padding"]``).
    texels_per_pixel, **options
        :func:`~o3d_seqcc.texturing.packing.pack_charts`'s.

    Returns
    -------
    Packing
        As ``pack``'s (:class:`~o3d_seqcc.texturing.packing.Packing`); ``log`` records the block (its charts and
        size).
    """
    req = 1.0 if isinstance(texels_per_pixel, str) else float(texels_per_pixel)
    padding = int(options.get("padding", 4))
    if small_charts <= 0 or small_padding >= padding or not len(faces):
        return pack(uv, faces, chart, texels_per_pixel=texels_per_pixel, **options)
    small = small_chart_mask(uv, faces, chart, small_charts / req)
    n_small = int(small.sum())
    if n_small < MIN_BLOCK_CHARTS or n_small == len(small):
        return pack(uv, faces, chart, texels_per_pixel=texels_per_pixel, **options)
    chart = np.asarray(chart, dtype=np.int64)
    small_face = small[chart]
    s_used, s_uv, s_faces, s_chart = _sub(uv, faces, chart, small_face)
    blk = pack(s_uv, s_faces, s_chart, texels_per_pixel=req, atlas_size="auto", overflow="pages",
               padding=int(small_padding), power_of_two=False, **{k: options[k] for k in ("pack_effort",) if k in options})
    if blk.pages != 1 or blk.texels_per_pixel != req:
        return pack(uv, faces, chart, texels_per_pixel=texels_per_pixel, **options)
    W, H = int(blk.width), int(blk.height)
    b_used, b_uv, b_faces, b_chart = _sub(uv, faces, chart, ~small_face)
    # the block as a rectangle chart of W x H texels, its corner at a half texel (the block's texel centres then
    # land on the page's), away from the other charts in uv
    at = np.floor(b_uv.max(axis=0) * req) + 16.5 if len(b_uv) else np.array([0.5, 0.5])
    rect = (at + np.array([[0.0, 0.0], [W, 0.0], [W, H], [0.0, H]])) / req
    n = len(b_uv)
    m_uv = np.vstack([b_uv, rect])
    m_faces = np.vstack([b_faces, [[n, n + 1, n + 2], [n, n + 2, n + 3]]])
    m_chart = np.r_[b_chart, [b_chart.max(initial=-1) + 1] * 2]
    main = pack(m_uv, m_faces, m_chart, texels_per_pixel=texels_per_pixel, **options)
    if main.texels_per_pixel < req * 0.999:  # a budget lowered the density: the block's texels are no longer whole
        return pack(uv, faces, chart, texels_per_pixel=texels_per_pixel, **options)
    corner = main.txy[n:n + 4]
    swapped = abs(corner[1, 1] - corner[0, 1]) > abs(corner[1, 0] - corner[0, 0])
    q = blk.txy + 0.5  # block positions from its corner
    if swapped:
        q = q[:, ::-1]
    txy = np.zeros((len(uv), 2))
    page = np.zeros(len(uv), dtype=np.int64)
    txy[b_used], page[b_used] = main.txy[:n], main.page[:n]
    txy[s_used], page[s_used] = corner[0] + q, main.page[n]
    log = list(main.log) + [f"block: {n_small} charts of at most {small_charts} texels, {W}x{H} at padding "
                            f"{int(small_padding)}{', turned' if swapped else ''}"]
    logger.info("packing: %d small charts in a %dx%d block (padding %d)", n_small, W, H, int(small_padding))
    return replace(main, txy=txy, page=page, log=log)
