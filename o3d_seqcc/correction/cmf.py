"""Colour mapping functions (CMF, paper section 3.6).

A CMF maps the values x of one channel of a target image T to the values y of the same channel
in a source image S (``y ~ f(x)``); it is fitted on corresponding colours (usually the weighted
cells of a joint image histogram, :mod:`o3d_seqcc.correction.jih`) and returned as a lookup table over
evenly spaced inputs in [0, 1]. All values are in [0, 1] (divide 8-bit values by 255).

Methods (``fit_cmf(..., method=...)``, registry :data:`CMF_METHODS`):

``"csvr"`` (default; the paper's composed support vector regressor)
    A linear-kernel SVR and an RBF-kernel SVR (scikit-learn ``SVR``) are fitted on the same
    weighted samples and evaluated on a dense grid (1024 points); the CMF is the linear SVR for
    x < x0 and x > xn and the RBF SVR in [x0, xn], with x0, xn intersections of the two curves.
    ``switch="paper"`` takes the first and last intersection over [0, 1], literally as in the
    paper. That puts the line in charge wherever a curved mapping (gamma, S-curve) crosses it,
    often well inside the data (a gamma of 1.4 was then off by 0.05 near the ends), so the
    default ``switch="support"`` takes the last intersection at or below the lower data-support
    bound (weighted ``support``-quantile of x, 0.5 %) and the first at or above the upper one
    (99.5 %): the RBF wherever data exist, the line only for extrapolation, as the paper
    motivates it. **No intersection** on a side (both rules; with ``"paper"``, fewer than two
    intersections): the switch is at the support bound, and the line is shifted to meet the RBF
    curve there so the CMF stays continuous. ``switch="bounds"`` always switches at the support
    bounds (shifted line outside).
    Hyper-parameters, in [0, 1] units with sample weights normalised to mean 1:
    ``C=1`` (both SVRs), ``epsilon=0.004`` (~1/255), ``gamma=15`` (RBF length scale
    ``1/sqrt(2 gamma)`` ~ 0.18 of the range), ``max_points=256`` weighted samples (~10 ms for
    both SVRs of one channel).
``"linear"``
    Weighted least-squares line.
``"polynomial"``
    Weighted least-squares polynomial (``degree=3``) via its Vandermonde matrix (De Marchi's
    CMF, used by the ``vandermonde`` baseline).
``"isotonic"``
    Weighted isotonic (monotone non-decreasing) regression, interpolated.

Common pre-processing and guards (``guard=True``, the default, for every method):

1. Saturated observations (x or y within ``saturation=1.5/255`` of 0 or 1) are dropped: they
   are censored and would bend the curve (a view that clips at 1 says nothing about how bright
   the other view's pixel would have been).
2. Pairing and aggregation, so the SVRs fit in milliseconds on at most ``max_points`` (256)
   weighted samples. ``pairing="quantile"`` (default): the JIH's two marginal histograms are
   matched, i.e. the weighted quantiles of x at 256 evenly spaced levels are paired with the
   same quantiles of y (:func:`quantile_samples`), and the regressor is fitted on these pairs.
   Why not the joint cells: real correspondences are misregistered by a few pixels (fountain:
   2-17 px), so the source value y at a mapping is the true mapped colour plus texture detail
   from a neighbouring surface point. A regression of y on x (the conditional mean the JIH
   cells estimate) is then flattened toward the mean of y (regression dilution): on fountain
   every edge's CMF compressed the contrast to 0.3-0.9 of the source's, chained along the
   paths, and the corrected images came out as a flat haze -- which the pairwise PSNR /
   CIEDE2000 at the same misregistered mappings *reward* (an MSE-optimal predictor shrinks).
   Misregistration does not change the two views' value distributions over the shared
   surface, so matching the distributions recovers the monotone photometric change without
   attenuation, is symmetric (swapping x and y gives the inverse function) and is exact on clean
   data. ``pairing="joint"``: the paper's literal input, the JIH's joint observations,
   aggregated by ``aggregate="columns"`` (one sample per JIH column: the weighted mean of y in
   the column at the mean x, weighted by the column's count, :func:`o3d_seqcc.correction.jih.column_samples`)
   or ``aggregate="cells"`` (the occupied JIH cells with their counts as weights, merged into at
   most ``max_points`` centroids, :func:`o3d_seqcc.correction.jih.weighted_samples`).
3. Fallbacks, logged at INFO: fewer than ``min_count`` (30) observations left -> identity; the
   target values (x) span less than 4/255 (a constant image) -> offset ``x + mean(y) - mean(x)``.
4. Where the data are sparse (fewer than ``sparse_count`` (20) observations in the 1/32-wide x
   bin around a grid point, linearly interpolated between bin centres) the fitted curve is blended
   toward a line in proportion to the missing support (csvr: its linear SVR, shifted to the RBF
   curve outside the switch points; other methods: the weighted least-squares line), so an RBF
   cannot run wild across gaps and at the ends.
5. Contrast guard (``contrast_guard=0.95``): if the weighted standard deviation of f(x) at the
   observations is below 0.95 times that of y, f is rescaled around the mean of f(x) so the two
   match (:func:`contrast_ratio` is that ratio). With quantile pairing this rarely triggers;
   with ``pairing="joint"`` on noisy correspondences it undoes the regression dilution to first
   order. A CMF never washes an image out.
6. Black point (``black_point=True``): below the darkest well-observed target value (the 0.5 %
   weighted quantile of x, :data:`BLACK_POINT_QUANTILE`) the curve runs straight to (0, 0) -- cameras keep black black, and
   without it a channel's extrapolated line could crush or lift the shadows (fountain view 27:
   green shadows were mapped to 0, turning them red).
7. The curve is clamped to [0, 1] (unless ``clamp=False``) and made monotone non-decreasing by
   isotonic regression on the lookup table, so it cannot fold back.

With ``guard=False`` only the fallbacks of step 3 for degenerate input and the clamp remain (the
baselines use this, with ``pairing="joint"``, to stay faithful to their papers).

Measured with ``benchmarks/table2.py`` (``seqcc``, quantile pairing, against ``seqcc-joint``,
the paper's joint regression): fountain, mean contrast ratio of corrected target over source at
the mappings 1.00 (min 0.90) against 0.65 (min 0.35), pairwise mean CIEDE2000 at the
misregistered mappings 6.86 against 5.39 (none: 7.70) because that score rewards shrinkage.
Which one is right shows on the synthetic room, where the truth is known: with exact poses both
come to ground truth (CIEDE2000 1.17 and 1.33, from 10.49); with the mappings computed from
poses off by 0.5 deg (~2 px, like real data) quantile pairing stays at 1.69 while the joint
regression falls back to 9.17 -- with a pairwise PSNR 3.8 dB *higher* than quantile pairing's.

``symmetric=True`` averages the fit of y on x with the inverse of the fit of x on y (a classic
errors-in-variables correction). It is off by default: on fountain the inverse regression is
far too steep (contrast ratio 1.24, worse than no correction), while quantile pairing is
symmetric by construction.
"""

from __future__ import annotations

import logging
from typing import Callable

import numpy as np

from ..errors import InputError
from .._shared.registry import Registry
from .jih import column_samples, weighted_samples
from .luts import apply_lut, compose_luts, interp_extrapolate  # noqa: F401  (part of this module's API)

__all__ = [
    "CMF_METHODS",
    "apply_lut",
    "compose_luts",
    "contrast_ratio",
    "correlation_ratio",
    "fit_cmf",
    "interp_extrapolate",
    "quantile_samples",
    "register_cmf",
]

logger = logging.getLogger(__name__)

#: share of each tail of the value distributions left out of quantile pairing
QUANTILE_TRIM = 0.002
#: weighted quantile of the target values below which the black point takes over
BLACK_POINT_QUANTILE = 0.005

def register_cmf(name: str) -> Callable[[Callable], Callable]:
    """Decorator registering a CMF fitter ``fn(x, y, w, grid, **options) -> (curve, line)``.

    ``x, y, w`` are the aggregated weighted samples (weights normalised to mean 1), ``grid`` the
    (n_out,) inputs; ``curve`` is the fitted (n_out,) values, ``line`` a linear fit on the grid
    used by the sparse-data guard (or None to use weighted least squares).
    """

    return CMF_METHODS.register(name)


def _wls_line(x: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    sw = w.sum()
    mx, my = (w * x).sum() / sw, (w * y).sum() / sw
    vx = (w * (x - mx) ** 2).sum()
    slope = (w * (x - mx) * (y - my)).sum() / vx if vx > 0 else 0.0
    return float(slope), float(my - slope * mx)


def _wquantile(x: np.ndarray, w: np.ndarray, q: float) -> float:
    o = np.argsort(x)
    cw = np.cumsum(w[o])
    return float(x[o][min(np.searchsorted(cw, q * cw[-1]), len(x) - 1)])


def _fit_linear(x, y, w, grid):
    a, b = _wls_line(x, y, w)
    line = a * grid + b
    return line, line


def _fit_polynomial(x, y, w, grid, *, degree: int = 3):
    degree = int(degree)
    if degree < 1:
        raise ValueError(f"degree must be >= 1, got {degree}")
    degree = min(degree, max(1, np.unique(np.round(x, 6)).size - 1))
    V = np.vander(x, degree + 1)
    sw = np.sqrt(w)
    coef, *_ = np.linalg.lstsq(V * sw[:, None], y * sw, rcond=None)
    return np.vander(grid, degree + 1) @ coef, None


def _fit_isotonic(x, y, w, grid):
    from sklearn.isotonic import IsotonicRegression

    iso = IsotonicRegression(increasing=True, out_of_bounds="clip").fit(x, y, sample_weight=w)
    return iso.predict(grid), None


def _fit_csvr(
    x,
    y,
    w,
    grid,
    *,
    C: float = 1.0,
    epsilon: float = 0.004,
    gamma: float = 15.0,
    switch: str = "support",
    support: float = 0.005,
    n_dense: int = 1024,
):
    from sklearn.svm import SVR

    if switch not in ("support", "paper", "bounds"):
        raise ValueError(f"csvr switch must be 'support', 'paper' or 'bounds', got {switch!r}")
    X = x[:, None]
    lin = SVR(kernel="linear", C=C, epsilon=epsilon).fit(X, y, sample_weight=w)
    rbf = SVR(kernel="rbf", C=C, epsilon=epsilon, gamma=gamma).fit(X, y, sample_weight=w)
    # evaluate both models in numpy (much faster than SVR.predict on a few thousand points)
    a_l, b_l = float(lin.coef_[0, 0]), float(lin.intercept_[0])
    sv, dual, b_r = rbf.support_vectors_[:, 0], rbf.dual_coef_[0], float(rbf.intercept_[0])

    def f_lin(v):
        return a_l * np.asarray(v, dtype=np.float64) + b_l

    def f_rbf(v):
        v = np.asarray(v, dtype=np.float64)
        return np.exp(-gamma * (v[:, None] - sv[None, :]) ** 2) @ dual + b_r

    dense = np.linspace(0.0, 1.0, int(n_dense))
    diff = f_rbf(dense) - f_lin(dense)
    gl, gr = f_lin(grid), f_rbf(grid)
    s = np.sign(diff)
    idx = np.nonzero((s[:-1] * s[1:] < 0) | ((s[:-1] == 0) & (s[1:] != 0)))[0]
    t = np.where(diff[idx] == diff[idx + 1], 0.0, diff[idx] / np.where(diff[idx] == diff[idx + 1], 1.0, diff[idx] - diff[idx + 1]))
    cross = dense[idx] + t * (dense[1] - dense[0])
    lo, hi = _wquantile(x, w, support), _wquantile(x, w, 1.0 - support)
    if switch == "paper" and cross.size >= 2 and cross[-1] > cross[0]:
        x0, xn = float(cross[0]), float(cross[-1])
    elif switch == "bounds":
        x0, xn = lo, hi
    else:
        # switch where the RBF stops being supported by data: the last intersection at or below
        # the lower support bound and the first at or above the upper one; without one, the
        # support bound itself (the line is then shifted to meet the RBF curve there)
        below, above = cross[cross <= lo], cross[cross >= hi]
        x0 = float(below[-1]) if below.size else lo
        xn = float(above[0]) if above.size else hi
        if xn <= x0:
            return gl, gl
    r0, rn = f_rbf(np.array([x0, xn]))
    l0, ln = f_lin(np.array([x0, xn]))
    curve = np.where(grid < x0, gl + (r0 - l0), np.where(grid > xn, gl + (rn - ln), gr))
    logger.debug("csvr: %d intersection(s); RBF on [%.4f, %.4f]", cross.size, x0, xn)
    # the sparse-data guard blends toward the line: use the (shifted) line the CMF extrapolates with
    line = np.where(grid < x0, gl + (r0 - l0), np.where(grid > xn, gl + (rn - ln), gl))
    return curve, line


#: name -> ``fn(x, y, w, grid, **options) -> (curve, linear_or_None)`` on the grid (written out; :func:`register_cmf`
#: adds more)
CMF_METHODS: Registry[Callable] = Registry("CMF method", {
    "linear": _fit_linear,
    "polynomial": _fit_polynomial,
    "isotonic": _fit_isotonic,
    "csvr": _fit_csvr,
})


def fit_cmf(
    x: np.ndarray,
    y: np.ndarray,
    *,
    method: str = "csvr",
    weights: np.ndarray | None = None,
    n_out: int = 256,
    guard: bool = True,
    saturation: float = 1.5 / 255,
    pairing: str = "quantile",
    aggregate: str = "columns",
    max_points: int = 256,
    min_count: float = 30,
    sparse_count: float = 20,
    min_span: float = 4 / 255,
    contrast_guard: float | None = 0.95,
    black_point: bool = True,
    symmetric: bool = False,
    clamp: bool = True,
    **options,
) -> np.ndarray:
    """Fit a colour mapping function ``y ~ f(x)`` and return it as a lookup table.

    Parameters
    ----------
    x : (n,) float array in [0, 1]
        Target image values (the image to correct) at the mappings.
    y : (n,) float array in [0, 1]
        Source image values at the same mappings.
    method : str, default "csvr"
        A name of :data:`CMF_METHODS` (see the module docstring).
    weights : (n,) float array, optional
        Non-negative observation weights, e.g. JIH cell counts (default 1 each).
    n_out : int, default 256
        Lookup-table length (256 for 8-bit images, 4096+ for 16-bit).
    guard : bool, default True
        Apply the sparse-data blend, the contrast guard and the monotonicity guard (module
        docstring).
    saturation : float, default 1.5/255
        Observations with x or y within this distance of 0 or 1 are dropped (0 keeps them).
    pairing : {"joint", "quantile"}, default "quantile"
        ``"joint"``: regress on the joint observations (the paper's JIH). ``"quantile"``: regress
        on the weighted quantiles of x paired with the same quantiles of y (a symmetric,
        errors-in-variables-free pairing that matches the two distributions; module docstring).
    aggregate : {"columns", "cells"}, default "columns"
        How joint observations are reduced before fitting (module docstring, step 2).
    max_points : int, default 256
        Bound on the aggregated weighted samples the regressor sees.
    min_count : float, default 30
        Fewer (weighted) observations -> identity fallback.
    sparse_count : float, default 20
        Observations per 1/32-wide x bin below which the curve is blended toward the line.
    min_span : float, default 4/255
        Smaller spread (1st-99th weighted percentile) of x -> offset fallback.
    contrast_guard : float or None, default 0.95
        When the weighted standard deviation of ``f(x)`` at the observations is below
        ``contrast_guard`` times that of ``y`` (the fit compresses the contrast, e.g. by
        regression dilution on misregistered correspondences), ``f`` is rescaled around the
        mean of ``f(x)`` so the two spreads match (module docstring, step 5). None disables it.
    black_point : bool, default True
        Below the darkest well-observed target value run the curve straight to (0, 0) (module
        docstring, step 6).
    symmetric : bool, default False
        Average the fit of y on x with the inverse of the fit of x on y.
    clamp : bool, default True
        Clip the table to [0, 1]. ``clamp=False`` keeps values beyond (the linear extrapolation
        of a curve whose data stop before 0 or 1, e.g. above the point where the source view
        saturates), so a chain of CMFs composed with :func:`compose_luts` can carry colours a
        middle view clipped to the next view instead of losing them.
    **options
        Method hyper-parameters (csvr: ``C``, ``epsilon``, ``gamma``, ``switch``, ``support``,
        ``n_dense``; polynomial: ``degree``); unknown names raise ``TypeError``.

    Returns
    -------
    numpy.ndarray
        (n_out,) float64 in [0, 1]: ``f`` at ``np.linspace(0, 1, n_out)``; evaluate between
        nodes with :func:`apply_lut` (linear interpolation).

    Raises
    ------
    InputError
        Unknown method or option (lists the valid ones; the option error is also a ``TypeError``).
    ValueError
        Unknown pairing or aggregate (lists the valid ones).
    InputError
        x, y, weights of different lengths, non-finite values, negative weights.

    Examples
    --------
    >>> import numpy as np, o3d_seqcc as sc
    >>> x = np.repeat(np.linspace(0.05, 0.95, 60), 40)  # the image to correct, at the mappings
    >>> lut = sc.fit_cmf(x, 0.8 * x)  # the source is 20 % darker: f(x) = 0.8 x comes back
    >>> lut.shape, round(float(lut[200]), 2), round(0.8 * 200 / 255, 2)
    ((256,), 0.62, 0.63)
    """
    CMF_METHODS.check(method)
    if pairing not in ("joint", "quantile"):
        raise ValueError(f"pairing must be 'joint' or 'quantile', got {pairing!r}")
    if symmetric not in (True, False):
        raise ValueError(f"symmetric must be True or False, got {symmetric!r}")
    CMF_METHODS.check_options(method, options)
    n_out = int(n_out)
    if n_out < 2:
        raise ValueError(f"n_out must be >= 2, got {n_out}")
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    w = np.ones_like(x) if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    if not (x.shape == y.shape == w.shape):
        raise InputError(f"x {x.shape}, y {y.shape} and weights {w.shape} must have the same length")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and np.all(np.isfinite(w))):
        raise InputError("fit_cmf: x, y and weights must be finite (no NaN/inf)")
    if np.any(w < 0):
        raise InputError("fit_cmf: weights must be non-negative")
    grid = np.linspace(0.0, 1.0, n_out)
    x, y = np.clip(x, 0.0, 1.0), np.clip(y, 0.0, 1.0)
    if saturation > 0:
        ok = (x > saturation) & (x < 1 - saturation) & (y > saturation) & (y < 1 - saturation)
        if not ok.all():
            logger.debug("fit_cmf: dropped %.0f saturated observation(s) of %.0f", w[~ok].sum(), w.sum())
        x, y, w = x[ok], y[ok], w[ok]
    common = dict(
        method=method, guard=guard, pairing=pairing, aggregate=aggregate, max_points=max_points, min_count=min_count,
        sparse_count=sparse_count, min_span=min_span, clamp=clamp, options=options,
    )
    curve, fitted = _fit_direction(x, y, w, grid, **common)
    if symmetric and fitted:
        # errors in both variables: the regression of y on x is flattened where x is noisy
        # (regression dilution), the inverse of the regression of x on y is steepened by the
        # same first-order amount; their average cancels it
        back, _ = _fit_direction(y, x, w, grid, **{**common, "clamp": False})  # unclipped: invertible
        back = np.maximum.accumulate(back) + grid * 1e-9  # strictly increasing for the inverse
        curve = 0.5 * curve + 0.5 * interp_extrapolate(grid, back, grid)
    if fitted and guard and contrast_guard is not None and x.size:
        curve = _contrast_guard(curve, grid, x, y, w, float(contrast_guard))
    if fitted and guard and black_point and x.size:
        curve = _anchor_black(curve, grid, x, w)
    if guard:
        if clamp:
            curve = np.clip(curve, 0.0, 1.0)
        from sklearn.isotonic import isotonic_regression

        curve = isotonic_regression(curve, increasing=True)
    return np.clip(curve, 0.0, 1.0) if clamp else curve


def _anchor_black(curve: np.ndarray, grid: np.ndarray, x: np.ndarray, w: np.ndarray, q: float | None = None) -> np.ndarray:
    """Below the darkest well-observed target value, run the curve straight to (0, 0).

    Cameras keep black black (gain, white balance, gamma and S-curves all fix 0), but shadows are
    rarely seen in overlaps, so the fitted curve's extrapolation decides there and a channel's
    line can hit 0 early (crushed, tinted shadows). ``x_lo`` is the weighted ``q`` quantile of x
    (default :data:`BLACK_POINT_QUANTILE`, 0.5 %).
    """
    q = BLACK_POINT_QUANTILE if q is None else q
    order = np.argsort(x)
    cw = np.cumsum(w[order])
    if cw[-1] <= 0:
        return curve
    x_lo = float(x[order][np.searchsorted(cw, q * cw[-1])])
    if x_lo <= grid[1]:
        return curve
    f_lo = float(np.interp(x_lo, grid, curve))
    below = grid < x_lo
    out = curve.copy()
    out[below] = grid[below] * (max(f_lo, 0.0) / x_lo)
    return out


def contrast_ratio(lut: np.ndarray, x: np.ndarray, y: np.ndarray, weights: np.ndarray | None = None) -> float:
    """Spread of the mapped target values over the spread of the source values at the mappings.

    ``std_w(f(x)) / std_w(y)`` with ``f`` the lookup table (weighted standard deviations).
    About 1 for a faithful CMF; below 1 the CMF compresses the contrast (washes the image out),
    as a regression of y on x does when x is noisy. 1 when y is constant.

    Parameters
    ----------
    lut : (L,) float array
    x, y : (n,) float arrays in [0, 1]
    weights : (n,) float array, optional

    Returns
    -------
    float
    """
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    w = np.ones_like(x) if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    sy = _wstd(y, w)
    return float(_wstd(apply_lut(lut, x), w) / sy) if sy > 0 else 1.0


def _wstd(v: np.ndarray, w: np.ndarray) -> float:
    sw = w.sum()
    if sw <= 0:
        return 0.0
    m = (w * v).sum() / sw
    return float(np.sqrt(max((w * (v - m) ** 2).sum() / sw, 0.0)))


def _contrast_guard(curve, grid, x, y, w, threshold: float):
    """Rescale ``curve`` around the mean of f(x) when it compresses the spread of y (see fit_cmf)."""
    fx = np.interp(x, grid, curve)
    sf, sy = _wstd(fx, w), _wstd(y, w)
    if sy <= 0 or sf <= 0 or sf >= threshold * sy:
        return curve
    k = sy / sf
    m = float((w * fx).sum() / w.sum())
    logger.debug("fit_cmf: contrast guard: f compresses the spread to %.0f %%, rescaled by %.3f", 100 * sf / sy, k)
    return m + k * (curve - m)


def _column_median(col: np.ndarray, v: np.ndarray, w: np.ndarray, n: int) -> np.ndarray:
    """Weighted median of ``v`` per integer column ``col`` in [0, n) (0 for empty columns)."""
    o = np.lexsort((v, col))
    cs, vs, ws = col[o], v[o], w[o]
    tot = np.bincount(cs, weights=ws, minlength=n)
    start = np.concatenate([[0.0], np.cumsum(tot)[:-1]])
    cw = np.cumsum(ws) - start[cs]
    half = 0.5 * tot[cs]
    first = (cw >= half) & (cw - ws < half)
    med = np.zeros(n)
    med[cs[first]] = vs[first]
    return med


def _column_inliers(x: np.ndarray, y: np.ndarray, w: np.ndarray, *, columns: int = 64, k: float = 6.0) -> np.ndarray:
    """Mask of observations within ``k`` robust sigmas (1.4826 MAD, at least 2/255) of their x column's median y.

    Removes wrong correspondences (occlusions missed by the filters) before the marginals are
    matched; the spread of misregistered texture stays (it is within a few MADs).
    """
    if x.size == 0:
        return np.ones(0, dtype=bool)
    col = np.clip((x * columns).astype(np.int64), 0, columns - 1)
    med = _column_median(col, y, w, columns)
    dev = np.abs(y - med[col])
    mad = _column_median(col, dev, w, columns)
    return dev <= k * np.maximum(1.4826 * mad[col], 2.0 / 255) + 1e-12


def quantile_samples(
    x: np.ndarray, y: np.ndarray, w: np.ndarray, *, n: int = 256, trim: float = QUANTILE_TRIM
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pair the weighted quantiles of x with the same quantiles of y.

    Parameters
    ----------
    x, y : (m,) float arrays
    w : (m,) non-negative weights
    n : int, default 256
        Number of quantile levels, evenly spaced in ``[trim, 1 - trim]``.
    trim : float, default :data:`QUANTILE_TRIM` (0.002)
        Quantile levels this close to 0 or 1 are left out (isolated extremes). Trimming more
        (3 %) made fountain's worst-registered views' shadows more neutral but cost the clean
        synthetic scene 1.06 -> 2.06 CIEDE2000 to ground truth, so the tails stay in.

    Returns
    -------
    xq, yq, wq : (n,) float64
        Quantiles of x and of y at the same levels; each gets weight ``sum(w) / n``.
    """
    levels = np.linspace(trim, 1.0 - trim, int(n))

    def wq(v):
        o = np.argsort(v, kind="stable")
        cw = np.cumsum(w[o])
        cw = (cw - 0.5 * w[o]) / cw[-1]
        return np.interp(levels, cw, v[o])

    return wq(x), wq(y), np.full(levels.size, w.sum() / levels.size)


def correlation_ratio(x: np.ndarray, y: np.ndarray, w: np.ndarray, *, columns: int = 64) -> float:
    """Weighted correlation ratio eta^2 = var(E[y | x]) / var(y), x binned in ``columns`` bins.

    The share of the source values' variance a function of the target value can explain: close
    to 1 for clean correspondences, low when registration errors pair unrelated colours.
    """
    sw = w.sum()
    if sw <= 0:
        return 0.0
    my = (w * y).sum() / sw
    vy = (w * (y - my) ** 2).sum() / sw
    if vy <= 0:
        return 1.0
    ci = np.clip((x * columns).astype(np.int64), 0, columns - 1)
    n = np.bincount(ci, weights=w, minlength=columns)
    mu = np.bincount(ci, weights=w * y, minlength=columns) / np.maximum(n, 1e-300)
    return float(np.clip((n * (mu - my) ** 2).sum() / sw / vy, 0.0, 1.0))


def _fit_direction(
    x, y, w, grid, *, method, guard, pairing, aggregate, max_points, min_count, sparse_count, min_span, clamp, options,
):
    """Fit y ~ f(x) on the grid; returns ``(curve, fitted)`` (fitted False for a fallback)."""
    fn = CMF_METHODS[method]
    total = float(w.sum())
    if total < min_count:
        logger.info("fit_cmf: only %.0f usable observation(s) (< min_count=%s): identity CMF", total, min_count)
        return grid.copy(), False
    if pairing == "quantile":
        keep = _column_inliers(x, y, w) & _column_inliers(y, x, w)  # symmetric: no bias of either marginal
        xs, ys, ws = quantile_samples(x[keep], y[keep], w[keep], n=min(int(max_points), 256))
    elif aggregate == "columns":
        xs, ys, ws = column_samples(x, y, w, columns=min(int(max_points), 256))
    elif aggregate == "cells":
        xs, ys, ws = weighted_samples(x, y, w, max_points=max_points)
    else:
        raise ValueError(f"aggregate must be 'columns' or 'cells', got {aggregate!r}")
    span = _wquantile(xs, ws, 0.99) - _wquantile(xs, ws, 0.01)
    if span < min_span or np.unique(xs).size < 2:
        off = float((ws * ys).sum() / ws.sum() - (ws * xs).sum() / ws.sum())
        logger.info("fit_cmf: target values are (nearly) constant (span %.4f): offset CMF x %+.4f", span, off)
        return (np.clip(grid + off, 0.0, 1.0) if clamp else grid + off), False
    wn = ws * (ws.size / ws.sum())  # mean 1: C keeps its meaning whatever the counts
    curve, line = fn(xs, ys, wn, grid, **options)
    curve = np.asarray(curve, dtype=np.float64)
    if not np.all(np.isfinite(curve)):
        logger.warning("fit_cmf(method=%r) produced non-finite values: linear fallback", method)
        curve, line = _fit_linear(xs, ys, wn, grid)
    if guard:
        if line is None:
            a, b = _wls_line(xs, ys, wn)
            line = a * grid + b
        # support of the raw observations (quantile samples are spaced by probability already)
        nb = 32
        hist = np.bincount(np.clip((x * nb).astype(np.int64), 0, nb - 1), weights=w, minlength=nb)
        centres = (np.arange(nb) + 0.5) / nb
        support = np.interp(grid, centres, hist)
        alpha = np.clip(support / float(sparse_count), 0.0, 1.0) if sparse_count > 0 else 1.0
        curve = alpha * curve + (1.0 - alpha) * line
    return curve, True
