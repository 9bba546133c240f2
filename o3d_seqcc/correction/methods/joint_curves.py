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


def _knot_index(x: np.ndarray, knots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segment index and fraction of ``x`` (clipped to the knots' range) on piecewise-linear knots."""
    K = knots.size
    k0 = np.clip(np.searchsorted(knots, x, side="right") - 1, 0, K - 2)
    f = (np.clip(x, knots[0], knots[-1]) - knots[k0]) / (knots[k0 + 1] - knots[k0])
    return k0, f


def _monotone(rows: np.ndarray) -> np.ndarray:
    """Each row made non-decreasing: the mean of its running maximum and its reverse running
    minimum (unchanged where already monotone; vectorised, unlike isotonic regression)."""
    return 0.5 * (np.maximum.accumulate(rows, axis=-1) + np.minimum.accumulate(rows[..., ::-1], axis=-1)[..., ::-1])


def _highest_latent(u_rows: np.ndarray, r_col: np.ndarray, F: int) -> np.ndarray:
    """(F,) the highest latent (reference value) any row of each free view reached (-1 where none)."""
    out = np.full(F, -1.0)
    free_rows = r_col >= 0
    np.maximum.at(out, r_col[free_rows], u_rows[free_rows])
    return out


def _continue_above_data(phi: np.ndarray, knots: np.ndarray, top: np.ndarray) -> np.ndarray:
    """Responses (F, K) continued above the knots their data reached: a knot above the segment that holds a view's
    highest latent ``top`` is constrained by nothing but the smoothing, which Levenberg-Marquardt's damping leaves
    near its start (measured on Fountain: a response falling from 149 to 99 above its data, whose monotone
    projection then flattened its supported top and made the correction a cliff to white). Those knots follow the
    straight line from the last supported knot, as steep as the last supported segment or as the response's mean
    slope up to there, whichever is steeper (a view whose top fell short of the reference's does not become a
    cliff to white), and at least a quarter as steep as the reference. Rows whose ``top`` is negative (no data)
    are left as they are."""
    out = phi.copy()
    K = knots.size
    for i in np.flatnonzero(top >= 0):
        k = int(min(max(np.searchsorted(knots, top[i], side="left"), 1), K - 1))  # upper knot of top's segment
        if k >= K - 1:
            continue
        last = (out[i, k] - out[i, k - 1]) / (knots[k] - knots[k - 1])
        mean = (out[i, k] - out[i, 0]) / (knots[k] - knots[0])
        out[i, k + 1 :] = out[i, k] + max(last, mean, 0.25) * (knots[k + 1 :] - knots[k])
    return out


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
    prior: float = 1e-6,
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
    prior : float, default 1e-6
        Weight of the squared distance of each knot value to the start.
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
    reg_block = smooth * (D.T @ D) + prior * np.eye(K) + np.diag(anchor)
    ew_all = np.ones((3, E))
    from threadpoolctl import threadpool_limits

    # small dense systems: one BLAS thread (threaded BLAS on a busy 2-core machine was 100x slower)
    def channel(c: int):
        return None if F == 0 else _adjust_channel(
            obs.a, obs.b, obs.qa[:, c, :], obs.qb[:, c, :], obs.observed(c), keep_e, base_w, col, free, response[:, c, :].copy(),
            luts[:, c, :], uk, grid, D, reg_block, smooth=smooth, prior=prior, anchor=anchor,
            iterations=int(iterations), plain_iterations=int(plain_iterations), edge_robust_c=edge_robust_c,
            monotone_steps=monotone_steps, channel=c,
        )

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
            k0, f = _knot_index(x, kx)
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
        th = _monotone(theta.reshape(free.size, K))
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


def _adjust_channel(
    a, b, ma, mb, seen, keep_e, base_w, col, free, phi, start_luts, uk, grid, D, reg_block, *,
    smooth, prior, anchor, iterations, plain_iterations, edge_robust_c, monotone_steps, channel,
):
    """Levenberg-Marquardt bundle adjustment of one channel (see :func:`refine_curves`).

    ``seen``: the (E, P) masks of the quantiles of view a and of view b that are not censored
    (:meth:`EdgeObservations.observed`). ``phi`` (V, K): starting responses (the reference's the identity); ``start_luts`` (V, L):
    starting corrections, which place the latents. Returns ``(phi, edge rms residual (E,),
    edge weights (E,))`` or None when no edge has an uncensored observation.
    """
    from scipy.linalg import cho_factor, cho_solve

    E, P = ma.shape
    K = uk.size
    F = free.size
    U = F * K
    oka = seen[0] & keep_e[:, None]
    okb = seen[1] & keep_e[:, None]
    lat = oka | okb
    e_lat = np.broadcast_to(np.arange(E)[:, None], (E, P))[lat]
    J = e_lat.size
    if J == 0:
        return None
    # residual rows: one per valid (latent, side)
    oa, ob = oka[lat], okb[lat]
    r_lat = np.concatenate([np.flatnonzero(oa), np.flatnonzero(ob)])
    r_view = np.concatenate([a[e_lat][oa], b[e_lat][ob]])
    r_meas = np.concatenate([ma[lat][oa], mb[lat][ob]])
    r_edge = e_lat[r_lat]
    r_col = col[r_view]
    is_free = r_col >= 0
    fr_rows = np.flatnonzero(is_free)
    rows_per_edge = np.bincount(r_edge, minlength=E).astype(np.float64)
    w0 = base_w[r_edge] / np.maximum(rows_per_edge[r_edge], 1.0) * 2.0  # each edge's rows sum to 2 w_e
    phi_start = phi[free].copy()
    # latents start at the mean of their sides' starting corrections
    corr = np.empty(r_view.size)
    for v in np.unique(r_view):
        sel = r_view == v
        corr[sel] = np.interp(r_meas[sel], grid, start_luts[v])
    u = np.bincount(r_lat, weights=corr, minlength=J) / np.maximum(np.bincount(r_lat, minlength=J), 1)
    # each latent's rows: the first and (if both sides are valid) the second
    order = np.argsort(r_lat, kind="stable")
    starts = np.searchsorted(r_lat[order], np.arange(J))
    two = np.bincount(r_lat, minlength=J) == 2
    first = order[starts]
    second = order[np.minimum(starts + 1, len(order) - 1)]
    reg_full = np.kron(np.eye(F), reg_block)
    ew = np.ones(E)

    def evaluate(phi_, u_):
        k0, fr = _knot_index(np.take(u_, r_lat), uk)
        at = r_view * K + k0  # phi_[r_view, k0], phi_[r_view, k0 + 1] from the flat array
        p0, p1 = np.take(phi_, at), np.take(phi_, at + 1)
        return p0 * (1.0 - fr) + p1 * fr - r_meas, k0, fr, (p1 - p0) / (uk[k0 + 1] - uk[k0])

    def cost(r, phi_, w_):  # r: evaluate(phi_, u_)[0]
        d = phi_[free] - phi_start
        return float(
            np.sum(w_ * r * r) + smooth * np.sum((phi_[free] @ D.T) ** 2) + prior * np.sum(d * d)
            + np.sum(anchor * phi_[free] ** 2)
        )

    mu = 1e-4
    # two phases: a few plain least-squares steps from the start, then per-edge robust weights
    # (re-estimated every iteration) to convergence
    robust, it_phase = edge_robust_c is not None and plain_iterations == 0, 0
    state = evaluate(phi, u)  # (r, k0, fr, slope) at (phi, u): an accepted step's evaluation carries over
    for it in range(plain_iterations + iterations):
        r, k0, fr, sl = state
        if robust:
            # in reference units (a residual over its response's slope): a camera change of the view's values does
            # not change which edges the others contradict
            rr = r / np.maximum(sl, 0.05)
            e_rms = np.sqrt(np.bincount(r_edge, weights=rr * rr, minlength=E) / np.maximum(rows_per_edge, 1.0))
            m = float(np.median(e_rms[rows_per_edge > 0])) + 1e-9
            ew = 1.0 / (1.0 + (e_rms / (float(edge_robust_c) * m)) ** 2)
        w = w0 * ew[r_edge]
        # Jacobian: d r / d phi_v[k0], phi_v[k0+1] = (1 - fr), fr (free views only); d r / d u = slope
        ci0 = r_col * K + k0
        idx = np.where(is_free[:, None], np.stack([ci0, ci0 + 1], axis=1), -1)  # (R, 2) phi columns, -1: fixed
        vals = np.stack([1.0 - fr, fr], axis=1)
        # H_pp is block diagonal (each row touches one view's knots)
        gp = np.zeros(U)
        h_idx, h_val = [], []
        for p_ in range(2):
            gp += np.bincount(idx[fr_rows, p_], weights=(w * vals[:, p_] * r)[fr_rows], minlength=U)
            for q_ in range(2):
                h_idx.append(idx[fr_rows, p_] * U + idx[fr_rows, q_])
                h_val.append((w * vals[:, p_] * vals[:, q_])[fr_rows])
        Hpp = np.bincount(np.concatenate(h_idx), weights=np.concatenate(h_val), minlength=U * U) + reg_full.reshape(-1)
        gp += (smooth * (phi[free] @ D.T) @ D + prior * (phi[free] - phi_start) + anchor * phi[free]).reshape(-1)


        Huu = np.bincount(r_lat, weights=w * sl * sl, minlength=J)
        gu = np.bincount(r_lat, weights=w * sl * r, minlength=J)
        # each latent's up-to-4 (phi column, H_pu value)
        hpu = w[:, None] * vals * sl[:, None]
        cols4 = np.concatenate([idx[first], np.where(two[:, None], idx[second], -1)], axis=1)  # (J, 4)
        vals4 = np.where(cols4 >= 0, np.concatenate([hpu[first], hpu[second]], axis=1), 0.0)
        # the fixed columns (-1) sent to a spare column U, dropped after the sums: every entry of a column
        # pair is summed in the same order as over the valid entries alone, without masks
        c4 = np.where(cols4 >= 0, cols4, U)
        pair_idx = (c4[:, :, None] * (U + 1) + c4[:, None, :]).reshape(-1)
        pair_vv = vals4[:, :, None] * vals4[:, None, :]  # (J, 4, 4)
        h0u = float(np.median(Huu[Huu > 0])) if np.any(Huu > 0) else 1.0
        dpp = Hpp[:: U + 1].copy()
        h0p = float(np.median(dpp[dpp > 0])) if np.any(dpp > 0) else 1.0
        c0 = cost(r, phi, w)
        accepted = False
        for _ in range(8):
            # Levenberg-Marquardt: damped latents (one on a flat stretch of a response would
            # otherwise jump) and knots; the latents are eliminated by their Schur complement
            # S = H_pp - H_pu diag(1 / H_uu) H_up, which couples the views sharing latents (edges)
            inv = 1.0 / (Huu + mu * (Huu + h0u))
            sw = (pair_vv * inv[:, None, None]).reshape(-1)  # vals4 vals4^T * inv, entry by entry
            S = Hpp - np.bincount(pair_idx, weights=sw, minlength=(U + 1) ** 2).reshape(U + 1, U + 1)[:U, :U].reshape(-1)
            S[:: U + 1] += mu * (dpp + h0p)
            rhs = -gp + np.bincount(c4.reshape(-1), weights=(vals4 * (inv * gu)[:, None]).reshape(-1), minlength=U + 1)[:U]
            S = S.reshape(U, U)
            try:
                dphi = cho_solve(cho_factor(S, check_finite=False), rhs, check_finite=False)
            except np.linalg.LinAlgError:  # not positive definite (degenerate data): least squares
                dphi = np.linalg.lstsq(S, rhs, rcond=None)[0]
            du = -(gu + (vals4 * np.concatenate([dphi, [0.0]])[cols4]).sum(axis=1)) * inv
            ph = phi.copy()
            ph[free] = phi[free] + dphi.reshape(F, K)
            if monotone_steps:
                ph[free] = _monotone(ph[free])
            un = np.clip(u + du, 0.0, 1.0)
            trial = evaluate(ph, un)
            c1 = cost(trial[0], ph, w)
            if c1 <= c0:
                accepted = True
                mu = max(mu / 3.0, 1e-9)
                break
            mu *= 10.0
        rel = (c0 - c1) / max(c0, 1e-300) if accepted else 0.0
        if accepted:
            phi, u, state = ph, un, trial
            logger.debug("refine_curves: channel %d iteration %d cost %.4e -> %.4e (damping %.1e)", channel, it, c0, c1, mu)
        it_phase += 1
        if robust or edge_robust_c is None:
            if rel < 1e-4 or it_phase >= iterations:
                break
        elif rel < 1e-4 or it_phase >= plain_iterations:
            robust, it_phase = True, 0
    r = state[0]
    logger.debug("refine_curves: channel %d: %d of %d latents at 0, %d at 1", channel, int((u <= 0).sum()), u.size, int((u >= 1).sum()))
    residual = np.sqrt(np.bincount(r_edge, weights=r * r, minlength=E) / np.maximum(rows_per_edge, 1.0))
    phi[free] = _monotone(_continue_above_data(phi[free], uk, _highest_latent(u[r_lat], r_col, F)))
    return phi, residual, ew

