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
"""

from __future__ import annotations

import numpy as np

__all__ = ["histogram_normaliser", "histogram_normalisers_from_colours", "map_rows"]


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
