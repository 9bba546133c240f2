"""Joint image histograms (paper section 3.5).

A joint image histogram (JIH) of a channel counts, for every pairwise mapping, the combination
(target value x, source value y): ``jih[c, x, y]``. The colour mapping function of that channel
is then fitted on the JIH (:mod:`o3d_seqcc.correction.cmf`), which turns the fit cost from "number of
mappings" into "number of occupied cells"; :func:`jih_samples` reduces it further to a bounded
number of weighted samples.
"""

from __future__ import annotations

import logging

import numpy as np

from ..errors import InputError

__all__ = ["column_samples", "joint_histogram", "jih_samples", "weighted_samples"]

logger = logging.getLogger(__name__)


def _quantise(values: np.ndarray, bits: int, what: str) -> np.ndarray:
    v = np.asarray(values)
    if v.ndim == 1:
        v = v[:, None]
    if v.ndim != 2:
        raise InputError(f"{what} must be (n, channels), got shape {v.shape}")
    levels = (1 << bits) - 1
    if np.issubdtype(v.dtype, np.integer):
        if v.size and (v.min() < 0 or v.max() > levels):
            raise InputError(f"{what}: integer values must be in [0, {levels}] for bits={bits}")
        return v.astype(np.int64)
    v = np.asarray(v, dtype=np.float64)
    if not np.all(np.isfinite(v)):
        raise InputError(f"{what} contains NaN/inf")
    return np.clip(np.rint(v * levels), 0, levels).astype(np.int64)


def joint_histogram(target_values: np.ndarray, source_values: np.ndarray, *, bits: int = 8) -> np.ndarray:
    """Per-channel joint image histogram of corresponding colours.

    Parameters
    ----------
    target_values, source_values : (n, C) array
        Colours of the same n mappings in the target image T (x axis) and the source image S
        (y axis). Floats are read as [0, 1] and quantised to ``2**bits`` levels (rounded);
        integers are taken as levels already in ``[0, 2**bits - 1]``. (n,) is read as one channel.
    bits : int, default 8
        Bit depth of the histogram: ``2**bits`` bins per axis (1..12).

    Returns
    -------
    numpy.ndarray
        (C, 2**bits, 2**bits) int64, ``jih[c, x, y]`` = number of mappings whose target value is
        x and source value is y in channel c (C = 3 for RGB).

    Examples
    --------
    >>> import numpy as np, o3d_seqcc as sc
    >>> source = np.arange(256, dtype=np.uint8)
    >>> jih = sc.joint_histogram(source // 2, source)  # target, source
    >>> jih.shape, int(jih.sum()), int(jih[0, 100, 200])  # one channel: (1, 256, 256)
    ((1, 256, 256), 256, 1)
    """
    bits = int(bits)
    if not 1 <= bits <= 12:
        raise InputError(f"bits must be in 1..12 (2**bits bins per axis), got {bits}")
    t = _quantise(target_values, bits, "target_values")
    s = _quantise(source_values, bits, "source_values")
    if t.shape != s.shape:
        raise InputError(f"target_values {t.shape} and source_values {s.shape} must have the same shape")
    nb = 1 << bits
    out = np.empty((t.shape[1], nb, nb), dtype=np.int64)
    for c in range(t.shape[1]):
        out[c] = np.bincount(t[:, c] * nb + s[:, c], minlength=nb * nb).reshape(nb, nb)
    return out


def jih_samples(jih: np.ndarray, *, max_points: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted samples of one channel's JIH: occupied cells with their counts as weights.

    Parameters
    ----------
    jih : (B, B) integer array
        One channel of :func:`joint_histogram`.
    max_points : int, optional
        When more cells are occupied, cells are merged into coarser blocks (2x2, 4x4, ...) until
        at most ``max_points`` remain; a merged cell sits at the count-weighted centroid of its
        fine cells, so no precision is lost to the coarser grid. Default: no merging.

    Returns
    -------
    x, y : (m,) float64 in [0, 1]
        Target and source values (cell centres ``index / (B - 1)``, or centroids).
    w : (m,) float64
        Counts (> 0), summing to the number of mappings.
    """
    jih = np.asarray(jih)
    if jih.ndim != 2 or jih.shape[0] != jih.shape[1]:
        raise InputError(f"jih must be one (B, B) channel, got shape {jih.shape}")
    xi, yi = np.nonzero(jih)
    w = jih[xi, yi].astype(np.float64)
    scale = float(jih.shape[0] - 1) or 1.0
    return weighted_samples(xi / scale, yi / scale, w, max_points=max_points)


def weighted_samples(
    x: np.ndarray,
    y: np.ndarray,
    weights: np.ndarray | None = None,
    *,
    max_points: int | None = None,
    bins: int = 256,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Aggregate (x, y) observations in [0, 1] into at most ``max_points`` weighted samples.

    Observations are binned on a ``bins x bins`` grid (then 2x, 4x, ... coarser while more than
    ``max_points`` cells are occupied); each occupied cell becomes one sample at the
    weight-weighted centroid of its observations with their summed weight.

    Parameters
    ----------
    x, y : (n,) float arrays in [0, 1]
    weights : (n,) float, optional
        Non-negative weights (default 1).
    max_points : int, optional
        Bound on the number of samples (default: no bound beyond the grid).
    bins : int, default 256
        Finest grid.

    Returns
    -------
    x, y, w : (m,) float64
    """
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    w = np.ones_like(x) if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    keep = w > 0
    x, y, w = x[keep], y[keep], w[keep]
    if x.size == 0:
        return x, y, w
    nb = int(bins)
    while True:
        xi = np.clip((x * nb).astype(np.int64), 0, nb - 1)
        yi = np.clip((y * nb).astype(np.int64), 0, nb - 1)
        cell = xi * nb + yi
        uniq, inv = np.unique(cell, return_inverse=True)
        if max_points is None or uniq.size <= max_points or nb <= 2:
            break
        nb //= 2
    sw = np.bincount(inv, weights=w)
    sx = np.bincount(inv, weights=w * x) / sw
    sy = np.bincount(inv, weights=w * y) / sw
    return sx, sy, sw


def column_samples(
    x: np.ndarray,
    y: np.ndarray,
    weights: np.ndarray | None = None,
    *,
    columns: int = 256,
    rows: int = 256,
    clip_k: float = float("inf"),
    min_spread: float = 2.0 / 255,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One weighted sample per occupied JIH column: a robust conditional mean of y given x.

    The observations are histogrammed on a ``columns x rows`` grid (a JIH with float weights).
    In each column, cells farther than ``clip_k`` times the column's weighted median absolute
    deviation (at least ``min_spread``) from the column's weighted median are discarded as
    wrong correspondences; the sample is the weighted mean (x, y) of the remaining
    observations, weighted by their total weight. Vectorised over the whole grid.

    Parameters
    ----------
    x, y : (n,) float arrays in [0, 1]
    weights : (n,) float, optional
        Non-negative weights (default 1).
    columns, rows : int, default 256
        Grid resolution along x and y.
    clip_k : float, default inf
        Outlier rejection threshold in MADs (``inf`` keeps everything: plain column means).
    min_spread : float, default 2/255
        Floor of the MAD, so clean, tight columns keep all their observations.

    Returns
    -------
    x, y, w : (m,) float64, m <= columns
        Column samples sorted by x (only columns with observations).
    """
    x = np.clip(np.asarray(x, dtype=np.float64).ravel(), 0.0, 1.0)
    y = np.clip(np.asarray(y, dtype=np.float64).ravel(), 0.0, 1.0)
    w = np.ones_like(x) if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    keep = w > 0
    x, y, w = x[keep], y[keep], w[keep]
    if x.size == 0:
        return x, y, w
    nc, nr = int(columns), int(rows)
    ci = np.clip((x * nc).astype(np.int64), 0, nc - 1)
    ri = np.clip((y * nr).astype(np.int64), 0, nr - 1)
    cell = ci * nr + ri
    hw = np.bincount(cell, weights=w, minlength=nc * nr).reshape(nc, nr)
    hx = np.bincount(cell, weights=w * x, minlength=nc * nr).reshape(nc, nr)
    hy = np.bincount(cell, weights=w * y, minlength=nc * nr).reshape(nc, nr)
    tot = hw.sum(axis=1)
    occ = tot > 0
    hw, hx, hy, tot = hw[occ], hx[occ], hy[occ], tot[occ]
    centres = (np.arange(nr) + 0.5) / nr
    if np.isfinite(clip_k):
        cw = np.cumsum(hw, axis=1)
        med = centres[np.argmax(cw >= 0.5 * tot[:, None], axis=1)]
        dev = np.abs(centres[None, :] - med[:, None])
        # weighted median of |y - median| per column
        order = np.argsort(dev, axis=1, kind="stable")
        dw = np.cumsum(np.take_along_axis(hw, order, axis=1), axis=1)
        mad = np.take_along_axis(dev, order, axis=1)[np.arange(len(tot)), np.argmax(dw >= 0.5 * tot[:, None], axis=1)]
        limit = clip_k * np.maximum(mad * 1.4826, float(min_spread))
        inl = dev <= limit[:, None] + 0.5 / nr
        hw, hx, hy = hw * inl, hx * inl, hy * inl
        tot = hw.sum(axis=1)
        ok = tot > 0
        hw, hx, hy, tot = hw[ok], hx[ok], hy[ok], tot[ok]
    return hx.sum(axis=1) / tot, hy.sum(axis=1) / tot, tot

