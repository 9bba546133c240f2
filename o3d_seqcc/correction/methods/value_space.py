"""A per-view change of variables that makes the joint solve blind to each photo's own tone curve.

Every camera change the correction must undo -- exposure, white balance, per-channel gamma, a
tone curve -- is, per channel, a monotone map ``h_v`` of the photo's values. The quantiles of
``h_v(X)`` are ``h_v`` of the quantiles of ``X``, so the edge summaries move with the change, but
a curve fitted to them in the photo's own values does not: its knots, its smoothness penalty,
its outlier test and its censoring all sit at fixed values, and a change stretches or squeezes
the data under them (measured: the semi-real invariance of ``seqcc-global`` on Fountain, 0.74
mean, 3.60 worst photo, seed 0).

:func:`histogram_normalisers_from_colours` gives every view a monotone table ``T_v = Q_ref o F_v``: the view's
own distribution ``F_v`` over its co-visible surface (the colours at all of its edges' mappings,
mid-ranks of tied values) followed by the reference's quantile
function ``Q_ref`` over its own co-visible surface. ``T_v(h_v(x)) = T_v(x)`` for any monotone ``h_v`` (up to 8-bit
quantisation and clipping), so a solve run on ``T_v``-mapped colours sees the same numbers
whatever the camera did; the correction of view ``v`` is then the solved curve composed with
``T_v``. ``T_v`` is only a change of variables: it brings each view near the reference's scale,
and the joint solve (:mod:`~o3d_seqcc.correction.methods.joint_curves`) finds the rest.

:func:`log_light` and :func:`log_light_inverse` are the change of variables of the solve in the photos' own values:
the sRGB-encoded values decoded to linear light, then ``log(1 + light / floor)`` scaled to [0, 1]. There a
camera's exposure and white balance are shifts and a gamma is a slope, so a response made of those is a straight
line: the joint solve's piecewise-linear responses and their smoothness penalty (second differences) then cost
nothing for what cameras do and continue it into values no edge observed (a photo's shadows that only photos far
from the reference share).
"""

from __future__ import annotations

import numpy as np

from ...imaging.arrays import linear_to_srgb, srgb_to_linear

__all__ = ["LOG_LIGHT_FLOOR", "histogram_normaliser", "histogram_normalisers_from_colours", "log_light",
           "log_light_inverse", "map_rows"]

#: the default ``floor`` of :func:`log_light`: linear light below it is compressed (sensor noise and the 8-bit
#: steps of the darkest levels; 1e-3 is level 0.8 of 255 in sRGB)
LOG_LIGHT_FLOOR = 1e-3


def log_light(values: np.ndarray, floor: float = LOG_LIGHT_FLOOR) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> ``log(1 + linear / floor) / log(1 + 1 / floor)`` in [0, 1] (module docstring).

    Parameters
    ----------
    values : float array in [0, 1]
        Any shape (clipped to [0, 1]).
    floor : float, default :data:`LOG_LIGHT_FLOOR`
        Linear light at which the logarithm starts (> 0): a gain is a shift above it.

    Returns
    -------
    float64 array, same shape, monotone increasing, 0 at 0 and 1 at 1.
    """
    f = float(floor)
    if not f > 0:
        raise ValueError(f"log_light: floor must be > 0, got {floor!r}")
    return np.log1p(srgb_to_linear(values) / f) / np.log1p(1.0 / f)


def log_light_inverse(values: np.ndarray, floor: float = LOG_LIGHT_FLOOR) -> np.ndarray:
    """The inverse of :func:`log_light` (values clipped to [0, 1]): sRGB-encoded values in [0, 1], float64."""
    f = float(floor)
    if not f > 0:
        raise ValueError(f"log_light_inverse: floor must be > 0, got {floor!r}")
    y = np.clip(np.asarray(values, dtype=np.float64), 0.0, 1.0)
    return np.clip(linear_to_srgb(np.expm1(y * np.log1p(1.0 / f)) * f), 0.0, 1.0)


def _mid_ranks(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct values of a row and their mid-rank CDF positions in (0, 1) (one sort, no hashing)."""
    x = np.sort(np.asarray(values, dtype=np.float64))
    n = x.size
    first = np.flatnonzero(np.concatenate([[True], x[1:] != x[:-1]]))
    counts = np.diff(np.append(first, n))
    return x[first], (first + 0.5 * counts) / n


def histogram_normaliser(view: np.ndarray, reference: np.ndarray, *, lut_size: int = 256) -> np.ndarray:
    """The table ``T = Q_ref o F_view`` of one view, per channel (module docstring).

    Parameters
    ----------
    view, reference : (3, n) and (3, m) float arrays in [0, 1]
        A view's and the reference's colours over their co-visible surface, channels as rows
        (n, m >= 1).
    lut_size : int, default 256
        Length of the table (inputs ``linspace(0, 1, lut_size)``).

    Returns
    -------
    (3, lut_size) float64 in [0, 1]
        Monotone non-decreasing; linear between the view's observed values, flat beyond them.
    """
    view = np.asarray(view, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    if view.ndim != 2 or view.shape[0] != 3 or reference.ndim != 2 or reference.shape[0] != 3:
        raise ValueError(f"histogram_normaliser: need (3, n) colour rows, got {view.shape} and {reference.shape}")
    if view.shape[1] == 0 or reference.shape[1] == 0:
        raise ValueError("histogram_normaliser: need at least one colour of the view and of the reference")
    grid = np.linspace(0.0, 1.0, int(lut_size))
    out = np.empty((3, grid.size))
    for c in range(3):
        rvals, rpos = _mid_ranks(reference[c])
        vals, pos = _mid_ranks(view[c])
        target = np.interp(pos, rpos, rvals)
        out[c] = np.interp(grid, vals, target) if vals.size > 1 else np.full(grid.size, target[0])
    return np.maximum.accumulate(out, axis=1)


def histogram_normalisers_from_colours(
    colours: dict[int, np.ndarray], *, reference: int, n_views: int, lut_size: int = 256,
) -> np.ndarray:
    """:func:`histogram_normaliser` of every view toward ``reference`` from the colours sampled at all of its edges'
    mappings; the reference's table, and those of views without colours, are the identity.

    Parameters
    ----------
    colours : dict of int to (3, n) float arrays
        Each view's colours at all of its edges' mappings, channels as rows.
    reference : int
    n_views : int
    lut_size : int, default 256

    Returns
    -------
    (n_views, 3, lut_size) float64
    """
    grid = np.linspace(0.0, 1.0, int(lut_size))
    out = np.broadcast_to(grid, (int(n_views), 3, grid.size)).copy()
    ref = colours.get(int(reference))
    if ref is None or ref.shape[1] == 0:
        return out
    for v, cv in colours.items():
        if int(v) != int(reference) and cv.shape[1]:
            out[int(v)] = histogram_normaliser(cv, ref, lut_size=lut_size)
    return out


def map_rows(lut: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(3, L) table applied to (3, n) colour rows (linear interpolation), float32 like the samples."""
    grid = np.linspace(0.0, 1.0, lut.shape[1])
    return np.stack([np.interp(rows[c], grid, lut[c]) for c in range(3)]).astype(np.float32)
