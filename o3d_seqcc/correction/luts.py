"""Per-channel lookup tables (LUTs): evaluation, extrapolation and composition along a path.

A LUT is an (L,) float array over L evenly spaced inputs in [0, 1]; values between are
interpolated linearly (:func:`apply_lut`). Colour mapping functions (:mod:`o3d_seqcc.correction.cmf`) are
tabulated as LUTs and composed along a view's correction path (:func:`compose_luts`), so an
image is transformed once, in floating point. A table trusted only over part of its inputs is
continued beyond it as power laws (:func:`extend_curve`) or straight lines (:func:`extend_line`).
"""

from __future__ import annotations

import numpy as np

from ..imaging.arrays import linear_to_srgb, srgb_to_linear

__all__ = ["apply_lut", "compose_luts", "extend_curve", "extend_line", "interp_extrapolate"]


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


def extend_curve(
    lut: np.ndarray, lo: float, hi: float, *, stretch: float = 0.5, beta_range: tuple[float, float] = (0.33, 3.0),
    light: str = "linear",
) -> np.ndarray:
    """Continue a curve beyond its observed input range ``[lo, hi]`` as power laws in linear light.

    With ``x`` and ``f`` in linear light (``light="linear"``: the curve's sRGB-encoded inputs and outputs
    decoded): above ``hi``, ``f(x) = f(hi) (x / hi)^beta_hi``; below ``lo``, ``f(x) = f(lo) (x / lo)^beta_lo``
    (which runs to black, ``f(0) = 0``). Each ``beta`` is the least-squares slope of ``log f`` on ``log x``
    over the ``stretch`` of the observed range next to that end, clipped to ``beta_range``. A camera's change
    of exposure and white balance is a gain in linear light, and with a change of gamma a power law per
    channel, so this continuation is exact for it, where a straight line or a clamp is not; in the encoded
    values (``light="encoded"``) it is only close (sRGB's linear toe and offset bend the power law: on a
    generated room whose reference saw no shadows, 8 levels off in the shadows). Fitted over a long stretch,
    the slope is not at the mercy of the noise of the last few observations.

    Parameters
    ----------
    lut : (L,) float array
        Curve on ``np.linspace(0, 1, L)``; trusted on ``[lo, hi]``.
    lo, hi : float
        Observed input range, ``0 <= lo < hi <= 1`` (NaN: returned unchanged).
    stretch : float, default 0.5
        Share of ``hi - lo`` next to each end over which its slope is fitted.
    beta_range : (float, float), default (0.33, 3.0)
    light : {"linear", "encoded"}, default "linear"
        Where the power laws are: in linear light (sRGB-decoded inputs and outputs) or in the values as given.

    Returns
    -------
    numpy.ndarray
        (L,) float64, monotone non-decreasing, not clipped.
    """
    if light not in ("linear", "encoded"):
        raise ValueError(f"light must be 'linear' or 'encoded', got {light!r}")
    dec, enc = (srgb_to_linear, linear_to_srgb) if light == "linear" else (np.asarray, np.asarray)
    lut = np.asarray(lut, dtype=np.float64)
    out = lut.copy()
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
        return out
    L = lut.size
    grid = np.linspace(0.0, 1.0, L)
    d = max(float(stretch) * (hi - lo), 2.0 / (L - 1))
    eps = 1e-4 if light == "encoded" else 1e-6
    b0, b1 = (float(b) for b in beta_range)

    def loglog_slope(x0: float, x1: float) -> float:
        xs = np.linspace(max(x0, 1e-4), x1, 32)
        ts, fs = dec(xs), dec(np.interp(xs, grid, lut))
        ok = (fs > eps) & (ts > eps)
        if ok.sum() < 2 or np.ptp(np.log(ts[ok])) <= 0:
            return 1.0
        return float(np.clip(np.polyfit(np.log(ts[ok]), np.log(fs[ok]), 1)[0], b0, b1))

    if hi < 1.0:
        up = grid > hi
        f_hi = max(float(dec(np.interp(hi, grid, lut))), eps)
        out[up] = enc(f_hi * (dec(grid[up]) / float(dec(hi))) ** loglog_slope(max(hi - d, lo), hi))
    if lo > 0.0:
        dn = grid < lo
        f_lo = max(float(dec(np.interp(lo, grid, lut))), 0.0)
        out[dn] = enc(f_lo * (dec(grid[dn]) / float(dec(lo))) ** loglog_slope(lo, min(lo + d, hi)))
    return np.maximum.accumulate(out)


def extend_line(lut: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Continue a curve beyond its observed input range ``[lo, hi]`` with its end slopes.

    The straight-line counterpart of :func:`extend_curve` (for comparison with power laws).

    Parameters
    ----------
    lut : (L,) float array
        Curve on ``np.linspace(0, 1, L)``; trusted on ``[lo, hi]``.
    lo, hi : float
        Observed input range (NaN, or fewer than two table entries inside: returned unchanged).

    Returns
    -------
    numpy.ndarray
        (L,) float64, monotone non-decreasing, not clipped.
    """
    lut = np.asarray(lut, dtype=np.float64)
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
        return lut.copy()
    grid = np.linspace(0.0, 1.0, len(lut))
    inside = (grid >= lo) & (grid <= hi)
    if inside.sum() < 2:
        return lut.copy()
    return np.maximum.accumulate(interp_extrapolate(grid, grid[inside], lut[inside]))
