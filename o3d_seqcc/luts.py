"""Per-channel lookup tables (LUTs): evaluation, extrapolation and composition along a path.

A LUT is an (L,) float array over L evenly spaced inputs in [0, 1]; values between are
interpolated linearly (:func:`apply_lut`). Colour mapping functions (:mod:`o3d_seqcc.cmf`) are
tabulated as LUTs and composed along a view's correction path (:func:`compose_luts`), so an
image is transformed once, in floating point.
"""

from __future__ import annotations

import numpy as np

__all__ = ["apply_lut", "compose_luts", "interp_extrapolate"]


def interp_extrapolate(x: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """``np.interp`` with linear extrapolation beyond ``xp`` (end segments' slopes) instead of clamping."""
    x = np.asarray(x, dtype=np.float64)
    out = np.interp(x, xp, fp)
    lo, hi = x < xp[0], x > xp[-1]
    if lo.any():
        d = xp[1] - xp[0]
        out[lo] = fp[0] + (x[lo] - xp[0]) * ((fp[1] - fp[0]) / d if d > 0 else 0.0)
    if hi.any():
        d = xp[-1] - xp[-2]
        out[hi] = fp[-1] + (x[hi] - xp[-1]) * ((fp[-1] - fp[-2]) / d if d > 0 else 0.0)
    return out


def apply_lut(lut: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Evaluate a lookup table over evenly spaced inputs in [0, 1] at ``values`` (linear interp).

    Parameters
    ----------
    lut : (L,) float array
    values : array of floats in [0, 1] (any shape; clipped to [0, 1])

    Returns
    -------
    numpy.ndarray
        Same shape as ``values``, float64.
    """
    lut = np.asarray(lut, dtype=np.float64)
    grid = np.linspace(0.0, 1.0, lut.shape[-1])
    return np.interp(np.clip(values, 0.0, 1.0), grid, lut)


def compose_luts(luts: list[np.ndarray], *, n_out: int | None = None, extrapolate: bool = False) -> np.ndarray:
    """Compose lookup tables applied in order: ``luts[-1](...luts[1](luts[0](x)))``.

    Parameters
    ----------
    luts : list of (L_i,) float arrays
        Each over evenly spaced inputs in [0, 1]; the first is applied first.
    n_out : int, optional
        Length of the result (default: the first table's length).
    extrapolate : bool, default False
        Intermediate values outside [0, 1] (tables fitted with ``clamp=False``) are passed on
        and evaluated by linear extrapolation of the next table; only the result is clipped.
        When False every step is clipped to [0, 1].

    Returns
    -------
    numpy.ndarray
        (n_out,) float64 in [0, 1]; the identity table when ``luts`` is empty (needs ``n_out``).
    """
    if not luts and n_out is None:
        raise ValueError("compose_luts needs n_out when no table is given")
    n = int(n_out if n_out is not None else len(luts[0]))
    out = np.linspace(0.0, 1.0, n)
    for lut in luts:
        lut = np.asarray(lut, dtype=np.float64)
        if extrapolate:
            out = interp_extrapolate(out, np.linspace(0.0, 1.0, lut.shape[-1]), lut)
        else:
            out = apply_lut(np.clip(lut, 0.0, 1.0), out)
    return np.clip(out, 0.0, 1.0)
