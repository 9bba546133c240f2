"""Per-view colour curves solved jointly over every graph edge (no drift along paths).

The paper's sequential correction composes one colour mapping function per path edge: every
edge's error is carried to all views behind it. This module solves all views' per-channel
curves at once from the edge summaries of :mod:`~o3d_seqcc.correction.methods.edge_summaries`, the way
global bundle adjustment follows incremental structure-from-motion:

- :func:`linear_start`: least squares on the corrected values over all edges (convex, no view
  far off; a little contracted toward grey by the noise);
- :func:`refine_curves`: robust Levenberg-Marquardt bundle adjustment of one monotone response
  per view and channel (the "cameras", the reference's fixed to the identity) and one latent
  reference-space colour per edge and quantile level (the "points"), with residuals in the
  measured values, which no common contraction of the curves can lower; the corrections are the
  responses' inverses.

``method="seqcc-global"`` (:mod:`~o3d_seqcc.correction.methods.seqcc_global`) runs them in that order.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ..._shared.parallel import LocalExecutor
from .curve_adjust import ChannelProblem, Solver, adjust_channel, knot_index, monotone
from .edge_summaries import SATURATION, EdgeObservations

__all__ = ["BLACK_WEIGHT", "SATURATION", "RefineResult", "linear_start", "observed_support", "refine_curves"]

logger = logging.getLogger(__name__)

#: weight of the black anchor of :func:`refine_curves` (a view's response at reference black is
#: 0), relative to one edge's data term: stiff
BLACK_WEIGHT = 1e3


@dataclass(frozen=True, eq=False)
class RefineResult:
    """Output of :func:`refine_curves`.

    Attributes
    ----------
    luts : (V, 3, L) float64
        Per view and channel the correction curve (view value -> reference value) on
        ``np.linspace(0, 1, L)``, the inverse of ``response``; flat beyond the response's range
        (see :func:`o3d_seqcc.correction.luts.extend_curve`). The reference's is the identity; views not solved keep ``init``.
    response : (V, 3, K) float64
        Per view and channel the estimated response: the view's value at each knot of the
        reference's value range (``knots``); the reference's is the identity.
    knots : (K,) float64
        Knot positions in [0, 1] (reference values).
    support : (V, 3, 2) float64
        Lowest and highest value of each view's channel observed by any edge (NaN: none).
    edge_weights : (E,) float64
        Final robust weight of each edge (1 = fully trusted; the lowest over the channels).
    residual : (E, 3) float64
        Root-mean-square residual of each edge and channel at the solution, in the views' value
        units.
    solved : (V,) bool
        Views whose curves were solved (connected to the reference through the edges).
    """

    luts: np.ndarray
    response: np.ndarray
    knots: np.ndarray
    support: np.ndarray
    edge_weights: np.ndarray
    residual: np.ndarray
    solved: np.ndarray


def _component(a: np.ndarray, b: np.ndarray, n_views: int, reference: int) -> np.ndarray:
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    g = sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(n_views, n_views))
    _, lab = connected_components(g, directed=False)
    return lab == lab[reference]


def _invert(response: np.ndarray, knots: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Inverse of a non-decreasing piecewise-linear response on ``grid`` (flat beyond its range)."""
    r = np.maximum.accumulate(response) + np.arange(response.size) * 1e-9
    return np.interp(grid, r, knots)


def _start(name: str, n_views: int, reference: int, init: np.ndarray | None, knots: int, lut_size: int):
    """What both solvers start from: the sizes checked, ``init`` (default the identity) as a float
    array and resampled on the output grid, the reference's curves the identity.

    Returns ``(n_views, reference, K, L, grid, init, luts)``.
    """
    n_views, reference, K, L = int(n_views), int(reference), int(knots), int(lut_size)
    if not 0 <= reference < n_views:
        raise InputError(f"{name}: reference {reference} out of range 0..{n_views - 1}")
    if K < 3 or L < 2:
        raise InputError(f"{name}: knots must be >= 3 and lut_size >= 2, got {K} and {L}")
    grid = np.linspace(0.0, 1.0, L)
    if init is None:
        init = np.broadcast_to(grid, (n_views, 3, L))
    init = np.asarray(init, dtype=np.float64)
    if init.ndim != 3 or init.shape[:2] != (n_views, 3) or init.shape[2] < 2:
        raise InputError(f"{name}: init must be (n_views, 3, L) with L >= 2, got {init.shape}")
    g0 = np.linspace(0.0, 1.0, init.shape[2])
    luts = np.stack([[np.interp(grid, g0, init[v, c]) for c in range(3)] for v in range(n_views)])
    luts[reference] = grid
    return n_views, reference, K, L, grid, init, luts


def _unknowns(name: str, obs: EdgeObservations, n_views: int, reference: int, edge_weight: str = "sqrt"):
    """The views solved (the reference's connected component), the edges used, the free views
    and each view's unknown index (-1: fixed), and each edge's weight (0 for unused edges):
    proportional to the square root of its mapping count relative to the median edge ("sqrt"),
    equal, or proportional to the count.

    Returns ``(comp, keep_e, free, col, weights)``.
    """
    if np.any(obs.a == obs.b) or min(obs.a.min(), obs.b.min()) < 0 or max(obs.a.max(), obs.b.max()) >= n_views:
        raise InputError(f"{name}: edges must join two different views in range 0..n_views-1")
    comp = _component(obs.a, obs.b, n_views, reference)
    keep_e = comp[obs.a] & comp[obs.b] & (obs.n > 0)
    free = np.flatnonzero(comp & (np.arange(n_views) != reference))
    col = -np.ones(n_views, dtype=np.int64)
    col[free] = np.arange(free.size)
    n = obs.n.astype(np.float64)
    med = max(float(np.median(n[keep_e])) if keep_e.any() else 1.0, 1.0)
    w = {"sqrt": np.sqrt(n / med), "equal": np.ones(len(n)), "count": n / med}[edge_weight]
    return comp, keep_e, free, col, np.where(keep_e, w, 0.0)


def refine_curves(
    obs: EdgeObservations,
    *,
    n_views: int,
    reference: int,
    init: np.ndarray | None = None,
    knots: int = 11,
    lut_size: int = 256,
    smooth: float = 1e-3,
    prior: float | np.ndarray = 1e-6,
    iterations: int = 10,
    plain_iterations: int = 3,
    edge_robust_c: float | None = 2.0,
    edge_weight: str = "sqrt",
    black: bool = True,
    support_tail: float = 0.01,
    knot_power: float = 1.5,
    monotone_steps: bool = False,
) -> RefineResult:
    """Solve all views' per-channel curves jointly over all edges (robust bundle adjustment).

    The model is the one of bundle adjustment: each edge's quantile level ``p`` is a latent
    colour ``u`` in the reference's value range (a "point"), and each view ``v`` has a
    response ``g_v`` (a "camera": piecewise linear on ``knots`` knots in [0, 1], the
    reference's fixed to the identity) that maps it to the values the views measured::

        min  sum_e w_e sum_p [ (g_a(u_ep) - Q_a(p))^2 + (g_b(u_ep) - Q_b(p))^2 ]
             + smooth * sum_v ||D2 g_v||^2 + prior * ||g - g_init||^2 + black * sum_v g_v(0)^2

    Residuals are in the measured values, so -- unlike least squares on the corrected values
    ``f_a(Q_a) - f_b(Q_b)`` (:func:`linear_start`), which every noisy edge pays less for when
    all curves contract toward grey (on fountain's 511 edges the slopes fell to 0.6-0.8) -- no
    common contraction or stretch of the curves lowers the cost. Levenberg-Marquardt steps on
    ``(g, u)`` with the latents eliminated by their Schur complement (each latent touches two
    views, so the reduced system has ``views x knots`` unknowns, assembled in time linear in
    the number of edges), first plain least squares to convergence, then with per-edge Cauchy
    weights (``edge_robust_c`` times the median edge residual) that down-weight edges the
    others contradict. The corrections are the inverses ``f_v = g_v^{-1}`` (made monotone).

    The adjustment is not convex: from a start with views far off (a sequential estimate whose
    paths cross a misregistered edge) a response can fold and keep its latents on the wrong
    branch. Start it from :func:`linear_start`, which has no view far off.

    Parameters
    ----------
    obs : EdgeObservations
        Matched quantiles of every edge (:func:`~o3d_seqcc.correction.methods.edge_summaries.edge_observations`).
    n_views : int
    reference : int
        View whose response is the identity.
    init : (V, 3, L0) float array, optional
        Starting correction curves (view value -> reference value) on ``np.linspace(0, 1,
        L0)``: their inverses start the responses and they place the latents; also a weak
        prior (``prior``). Default: the identity.
    knots : int, default 11
        Knots of each response, at ``linspace(0, 1, knots) ** knot_power``. Fewer knots follow
        less of each edge's noise (fountain, semi-real error 2.96 with 13, 2.87 with 11, 2.83
        with 9), more follow strong S-curves better (hard synthetic room, 0.58 / 0.60 / 0.67
        to ground truth): 11 is the compromise.
    lut_size : int, default 256
        Length of the returned correction tables.
    smooth : float, default 1e-3
        Weight of the squared second differences of each response (divided by the knot
        spacing, relative to even spacing), relative to one edge's data term (each edge's
        residuals sum to twice its weight).
    prior : float or (V,) float array, default 1e-6
        Weight of the squared distance of each knot value to the start (one for every view, or each view's).
    iterations : int, default 10
        Levenberg-Marquardt iterations per channel and phase (each phase stops earlier when
        the cost improves by less than 0.01 %).
    edge_robust_c : float or None, default 2.0
        Cauchy scale of the per-edge weights, in median edge residuals (each residual divided by its response's
        slope there: in reference units, which a monotone change of a view's values does not move); None: no
        second phase.
    edge_weight : {"sqrt", "equal", "count"}, default "sqrt"
        Each edge's share of the data term: proportional to the square root of its mapping
        count (relative to the median edge), equal, or proportional to the count.
    black : bool, default True
        Responses start at black (``g_v(0) = 0``, a stiff spring of weight
        :data:`BLACK_WEIGHT`): cameras keep black black. Without it a view whose shadows are
        bluer than the reference's got a blue response starting at 55/255 and its shadows'
        blue crushed to 0 (fountain view 30).
    support_tail : float, default 0.01
        :attr:`RefineResult.support` leaves out this share of each end of a view's pooled
        observations (a few edges' extreme quantiles are not support; beyond it
        :func:`o3d_seqcc.correction.luts.extend_curve` takes over).
    knot_power : float, default 1.5
        Knot placement exponent: denser knots in the shadows, where gamma-type responses bend
        most (with evenly spaced knots and the black spring, a gamma of 0.67 was 3 levels off
        in the first segment).
    monotone_steps : bool, default False
        Project the responses onto monotone ones after every step (slower convergence; the
        final responses are made monotone either way).

    Returns
    -------
    RefineResult
    """
    if edge_weight not in ("sqrt", "equal", "count"):
        raise ValueError(f"edge_weight must be 'sqrt', 'equal' or 'count', got {edge_weight!r}")
    n_views, reference, K, L, grid, init, luts = _start("refine_curves", n_views, reference, init, knots, lut_size)
    uk = np.linspace(0.0, 1.0, K) ** float(knot_power)
    E = len(obs.a)
    g0 = np.linspace(0.0, 1.0, init.shape[2])
    response = np.stack([[_invert(np.maximum.accumulate(init[v, c]), g0, uk) for c in range(3)] for v in range(n_views)])
    response[reference] = uk
    support = np.full((n_views, 3, 2), np.nan)
    residual = np.zeros((E, 3))
    ew_out = np.ones(E)
    solved = np.zeros(n_views, dtype=bool)
    solved[reference] = True
    if E == 0:
        return RefineResult(luts, response, uk, support, ew_out, residual, solved)
    comp, keep_e, free, col, base_w = _unknowns("refine_curves", obs, n_views, reference, edge_weight)
    solved = comp.copy()
    F = free.size
    # second differences divided by the knot spacing (exactly 0 on straight lines), scaled so
    # that evenly spaced knots give the plain [1, -2, 1]
    h = np.diff(uk) * (K - 1)
    D = np.zeros((K - 2, K))
    i = np.arange(K - 2)
    D[i, i], D[i, i + 1], D[i, i + 2] = 1.0 / h[:-1], -(1.0 / h[:-1] + 1.0 / h[1:]), 1.0 / h[1:]
    # black: cameras keep black black -- every response starts at 0 (a stiff spring on knot 0)
    anchor = np.zeros(K)
    anchor[0] = BLACK_WEIGHT if black else 0.0
    prior_free = np.broadcast_to(np.asarray(prior, dtype=np.float64), (n_views,))[free].copy()
    if np.all(prior_free == float(np.max(prior_free, initial=0.0))):
        reg_block = smooth * (D.T @ D) + float(np.max(prior_free, initial=0.0)) * np.eye(K) + np.diag(anchor)
    else:  # each free view's own pull toward its start
        reg_block = np.stack([smooth * (D.T @ D) + p * np.eye(K) + np.diag(anchor) for p in prior_free])
    ew_all = np.ones((3, E))
    from threadpoolctl import threadpool_limits

    solver = Solver(smooth=smooth, prior=prior_free, anchor=anchor, iterations=int(iterations),
                    plain_iterations=int(plain_iterations), edge_robust_c=edge_robust_c, monotone_steps=monotone_steps)

    # small dense systems: one BLAS thread (threaded BLAS on a busy 2-core machine was 100x slower)
    def channel(c: int):
        return None if F == 0 else adjust_channel(ChannelProblem(
            a=obs.a, b=obs.b, ma=obs.qa[:, c, :], mb=obs.qb[:, c, :], seen=obs.observed(c), keep_e=keep_e,
            base_w=base_w, col=col, free=free, phi=response[:, c, :].copy(), start_luts=luts[:, c, :], uk=uk,
            grid=grid, D=D, reg_block=reg_block, channel=c), solver)

    with threadpool_limits(1, user_api="blas"):  # the three channels side by side (independent solves)
        fits = LocalExecutor(min(3, LocalExecutor().threads())).map(channel, range(3), desc="refine curves",
                                                                   unit="channel")
    for c, fit in enumerate(fits):
        support[:, c] = _support(obs, c, keep_e, n_views, support_tail)
        if fit is None:
            continue
        phi, residual[:, c], ew_all[c] = fit
        response[:, c, :] = phi
        for v in free:
            luts[v, c] = _invert(phi[v], uk, grid)
    ew_out = ew_all.min(axis=0)
    logger.debug(
        "refine_curves: %d edge(s), %d free view(s); median edge rms %.4f; %d edge(s) weighted below 0.5",
        int(keep_e.sum()), F, float(np.median(residual[keep_e])) if keep_e.any() else 0.0, int((ew_out < 0.5).sum()),
    )
    return RefineResult(luts, response, uk, support, ew_out, residual, solved)


def linear_start(
    obs: EdgeObservations, *, n_views: int, reference: int, init: np.ndarray | None = None, knots: int = 11,
    lut_size: int = 256, smooth: float = 1e-3, prior: float = 1e-4,
) -> np.ndarray:
    """Least squares on the corrected values over all edges: a convex, start-free global estimate.

    Each view's correction ``f_v`` (piecewise linear on ``knots`` evenly spaced knots, the
    reference's the identity) minimises ``sum_e w_e sum_p (f_a(Q_a(p)) - f_b(Q_b(p)))^2`` plus
    second-difference smoothing and a weak prior to ``init``: one sparse linear system per
    channel, no local minima, no drift along paths. It is biased -- the noise of the quantiles
    makes all curves contract a little toward grey, which the bundle adjustment of
    :func:`refine_curves` (started from it) undoes -- but unlike a sequential estimate it
    has no view far off, so the adjustment starts in the right basin.

    Parameters
    ----------
    obs : EdgeObservations
    n_views : int
    reference : int
    init : (V, 3, L0) float array, optional
        Prior curves (e.g. :func:`~o3d_seqcc.correction.methods.seqcc_global.sequential_start`); default the identity.
    knots : int, default 11
        Knots of each curve, evenly spaced.
    lut_size : int, default 256
    smooth : float, default 1e-3
        Weight of the squared second differences of the knot values (each edge's data term
        sums to its weight).
    prior : float, default 1e-4
        Weight of the squared distance of each knot value to ``init``.

    Returns
    -------
    (V, 3, lut_size) float64
        Correction curves (view value -> reference value), monotone; views outside the
        reference's component keep ``init`` (or the identity).
    """
    n_views, reference, K, L, grid, _, out = _start("linear_start", n_views, reference, init, knots, lut_size)
    kx = np.linspace(0.0, 1.0, K)
    E, P = len(obs.a), obs.qa.shape[2]
    if E == 0:
        return out
    _, keep_e, free, col, w_e = _unknowns("linear_start", obs, n_views, reference)
    if free.size == 0:
        return out
    U = free.size * K
    D = np.diff(np.eye(K), n=2, axis=0)
    reg = np.kron(np.eye(free.size), smooth * (D.T @ D) + prior * np.eye(K))
    import scipy.sparse as sp

    for c in range(3):
        xa, xb = obs.qa[:, c, :], obs.qb[:, c, :]
        oka, okb = obs.observed(c)
        ok = oka & okb & keep_e[:, None]
        e_idx = np.broadcast_to(np.arange(E)[:, None], (E, P))[ok]
        R = e_idx.size
        if R == 0:
            continue
        rows, cols, vals = [], [], []
        rhs = np.zeros(R)
        for vv, x, sign in ((obs.a[e_idx], xa[ok], 1.0), (obs.b[e_idx], xb[ok], -1.0)):
            k0, f = knot_index(x, kx)
            fr = col[vv] >= 0
            for off, wt in ((0, 1.0 - f), (1, f)):
                rows.append(np.flatnonzero(fr))
                cols.append((col[vv] * K + k0 + off)[fr])
                vals.append((sign * wt)[fr])
            ref = vv == reference
            rhs[ref] -= sign * x[ref]
        A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(R, U))
        cnt = np.bincount(e_idx, minlength=E).astype(np.float64)
        w = w_e[e_idx] / np.maximum(cnt[e_idx], 1.0)
        t0 = np.stack([np.interp(kx, grid, out[v, c]) for v in free]).reshape(-1)
        N = (A.T @ A.multiply(w[:, None]).tocsr()).toarray() + reg
        theta = np.linalg.solve(N, A.T @ (w * rhs) + prior * t0)
        th = monotone(theta.reshape(free.size, K))
        for i, v in enumerate(free):
            out[v, c] = np.interp(grid, kx, th[i])
    return out


def observed_support(obs: EdgeObservations, *, n_views: int, tail: float = 0.01) -> np.ndarray:
    """(V, 3, 2) lowest and highest value of each view's channels that its edges observed (uncensored), without
    the sparsest ``tail`` share of its pooled edge quantiles at each end (NaN: none observed), as
    :attr:`RefineResult.support`."""
    keep_e = obs.n > 0
    return np.stack([_support(obs, c, keep_e, int(n_views), float(tail)) for c in range(3)], axis=1)


def _support(obs: EdgeObservations, c: int, keep_e: np.ndarray, n_views: int, tail: float) -> np.ndarray:
    """(V, 2) observed range of channel c per view: its pooled edge quantiles (uncensored)
    without their sparsest ``tail`` share at each end (a few edges' extreme quantiles)."""
    vals, views = [], []
    for vv, mm, seen in zip((obs.a, obs.b), (obs.qa[:, c, :], obs.qb[:, c, :]), obs.observed(c)):
        ok = seen & keep_e[:, None]
        vals.append(mm[ok])
        views.append(np.broadcast_to(vv[:, None], mm.shape)[ok])
    vals, views = np.concatenate(vals), np.concatenate(views)
    order = np.lexsort((vals, views))
    vals, views = vals[order], views[order]
    first = np.searchsorted(views, np.arange(n_views))
    count = np.bincount(views, minlength=n_views)
    out = np.full((n_views, 2), np.nan)
    for v in np.flatnonzero(count):
        out[v] = np.quantile(vals[first[v] : first[v] + count[v]], [tail, 1.0 - tail])
    return out
