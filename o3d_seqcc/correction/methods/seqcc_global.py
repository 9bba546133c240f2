"""``seqcc-global``: the sequential correction refined jointly over every graph edge (the default method).

The paper's sequential correction (``method="seqcc"``) fits one colour mapping function per
edge of each view's Dijkstra path to the reference and composes them: every edge's error is
carried to all views behind it, and a view is corrected only over the values its path edges
observed. ``method="seqcc-global"`` (:func:`method_seqcc_global`) refines a sequential
estimate the way global bundle adjustment follows incremental structure-from-motion:

1. :func:`~o3d_seqcc.correction.methods.edge_summaries.edge_observations`: for **every** edge of the
   colour-correction graph (not only the path tree) the colours at the pair's mappings, wrong
   correspondences dropped, summarised per channel by their matched quantiles.
2. :func:`sequential_start`: the sequential estimate along the paper's paths (by default each
   path edge's quantile-quantile curve from step 1; ``init="seqcc"`` uses the full CSVR fit).
3. :func:`~o3d_seqcc.correction.methods.joint_curves.linear_start` then
   :func:`~o3d_seqcc.correction.methods.joint_curves.refine_curves`: least squares on the corrected
   values over all edges (convex; a little contracted by the noise), then the robust bundle
   adjustment of per-view, per-channel responses over all edges, in the measured values, which
   no common contraction of the curves can lower; the corrections are the responses' inverses.
4. :func:`~o3d_seqcc.correction.luts.extend_curve`: beyond the values any edge of a view observed, the
   correction continues as a power law ``f(x) = f(x_b) (x / x_b)^beta`` with ``beta`` its
   log-log slope over the last observed stretch -- the shape of a gamma-type camera response,
   which a change of exposure, white balance and gamma keeps exactly -- instead of a clamp or a
   straight line; below the darkest observation it runs to black ``(0, 0)`` the same way. Values
   inside the range a view's *other* edges observed come from them through step 3.
"""

from __future__ import annotations

import logging

import numpy as np

from ..luts import extend_curve, extend_line
from ..base import CorrectionContext, IdentityTransform, LutTransform, lut_per_path
from .edge_summaries import EdgeObservations, edge_observations, edge_quantiles
from .joint_curves import linear_start, observed_support, refine_curves
from .seqcc import _method_seqcc, colour_inliers, quantile_luts

__all__ = ["method_seqcc_global", "sequential_start"]

logger = logging.getLogger(__name__)

#: ``values="auto"`` solves in the normalised values when the views' histogram normalisers lie at most this many
#: 8-bit levels from their sequential estimates (median view), in their own values otherwise
AUTO_OFFSET = 12.0
#: the values the joint solve can work in (``values=`` of :func:`method_seqcc_global`)
VALUE_SPACES = ("auto", "own", "normalised", "sequential")


def sequential_start(
    ctx: CorrectionContext,
    *,
    init: str = "quantile",
    obs: EdgeObservations | None = None,
    outlier_k: float | None = 3.0,
    n_jobs: int | None = None,
) -> np.ndarray:
    """The sequential estimate the joint refinement starts from, as (V, 3, L) correction curves.

    ``init="quantile"``: along the paper's Dijkstra paths, each edge's quantile-quantile curve,
    continued beyond the pair's values by :func:`~o3d_seqcc.correction.luts.extend_curve`, composed as
    lookup tables (numpy only, no SVR fits); the curves come from ``obs``
    (:func:`~o3d_seqcc.correction.methods.edge_summaries.edge_observations`, which must hold every path
    edge) or, without it, from the colours at the pairs' mappings (wrong correspondences dropped
    as by ``seqcc``). ``init="seqcc"``: the paper's sequential correction (``method="seqcc"``:
    CSVR per path edge); ``"identity"``: no estimate. Views without a path get the identity.

    Parameters
    ----------
    ctx : CorrectionContext
    init : {"quantile", "seqcc", "identity"}, default "quantile"
    obs : EdgeObservations, optional
        Edge summaries holding every path edge (``init="quantile"``).
    outlier_k : float or None, default 3.0
        Outlier pass of the edges without a summary and of ``init="seqcc"``.
    n_jobs : int or None, default None
        joblib threads per edge (joblib semantics).

    Returns
    -------
    (V, 3, lut_size) float64
        Correction curves (view value -> reference value) on ``np.linspace(0, 1, lut_size)``.

    Raises
    ------
    ValueError
        Unknown ``init``.
    """
    n, L = len(ctx.images), int(ctx.lut_size)
    grid = np.linspace(0.0, 1.0, L)
    start = np.broadcast_to(grid, (n, 3, L)).copy()
    if init == "identity":
        return start
    if init == "seqcc":
        transforms = _method_seqcc(ctx, outlier_k=outlier_k, n_jobs=n_jobs)
    elif init == "quantile":
        where = {} if obs is None else {(int(a), int(b)): i for i, (a, b) in enumerate(zip(obs.a, obs.b))}

        def edge_lut(t: int, s: int) -> np.ndarray:
            if (t, s) in where or (s, t) in where:
                i = where[(t, s)] if (t, s) in where else where[(s, t)]
                qt, qs = (obs.qa[i], obs.qb[i]) if (t, s) in where else (obs.qb[i], obs.qa[i])
            else:
                ct, cs = ctx.colors(t, s)
                if outlier_k is not None and len(ct) >= 10:
                    keep = colour_inliers(ct, cs, quantile_luts(ct, cs, n_out=L), k=float(outlier_k))
                    if keep.sum() >= 10:
                        ct, cs = ct[keep], cs[keep]
                qt, qs = edge_quantiles(ct, cs)
            # the quantile-quantile curve, flat beyond the pair's values: continued as power laws
            out = np.empty((3, L))
            for c in range(3):
                x = np.maximum.accumulate(qt[c]) + np.arange(qt.shape[1]) * 1e-9
                out[c] = extend_curve(np.interp(grid, x, qs[c]), x[0], x[-1])
            return out

        transforms = lut_per_path(ctx, edge_lut, n_jobs=n_jobs)
    else:
        raise ValueError(f"init must be 'seqcc', 'quantile' or 'identity', got {init!r}")
    for v, tr in enumerate(transforms):
        if isinstance(tr, LutTransform):
            start[v] = np.stack([np.interp(grid, np.linspace(0.0, 1.0, tr.lut.shape[1]), tr.lut[c]) for c in range(3)])
    return start


def _normaliser_offset(obs: EdgeObservations, normalisers: np.ndarray, sequential: np.ndarray) -> float:
    """Median over views of how far each view's histogram normaliser lies from its sequential estimate, in 8-bit
    levels: the median over the view's own edge quantiles of the two curves' difference, largest channel."""
    L = normalisers.shape[2]
    grid = np.linspace(0.0, 1.0, L)
    offs = []
    for v in np.unique(np.concatenate([obs.a, obs.b])):
        q = np.concatenate([obs.qa[obs.a == v], obs.qb[obs.b == v]])  # (e, 3, P)
        if not q.size or np.allclose(normalisers[v], grid):
            continue
        offs.append(max(float(np.median(np.abs(np.interp(q[:, c], grid, normalisers[v, c])
                                               - np.interp(q[:, c], grid, sequential[v, c])))) for c in range(3)) * 255)
    off = float(np.median(offs)) if offs else 0.0
    logger.info("seqcc-global: normalisers %.2f levels from the sequential estimate (median view)", off)
    return off


def _steepest(lut: np.ndarray, support: np.ndarray, *, window: int = 8) -> float:
    """Largest slope of a (3, L) curve over ``window`` table steps inside each channel's ``support`` (lo, hi)."""
    L = lut.shape[1]
    out = 0.0
    for c in range(3):
        lo, hi = support[c]
        if not (np.isfinite(lo) and np.isfinite(hi)):
            continue
        i0, i1 = int(np.ceil(lo * (L - 1))), int(np.floor(hi * (L - 1)))
        w = min(int(window), max(i1 - i0, 0))
        if w < 1:
            continue
        seg = lut[c, i0 : i1 + 1]
        out = max(out, float(np.max(seg[w:] - seg[:-w])) * (L - 1) / w)
    return out


def method_seqcc_global(
    ctx: CorrectionContext,
    *,
    init: str = "quantile",
    knots: int = 11,
    levels: int = 32,
    smooth: float = 1e-3,
    prior: float = 1e-6,
    iterations: int = 10,
    edge_robust_c: float | None = 2.0,
    edge_weight: str = "sqrt",
    max_mappings: int | None = 8000,
    outlier_k: float | None = 3.0,
    extrapolate: str = "power",
    support_tail: float = 0.01,
    values: str = "own",
    refine: bool = True,
    max_slope: float | None = None,
    n_jobs: int | None = None,
) -> list:
    """``seqcc`` refined jointly over every graph edge, curves extended over the whole range.

    Registered as ``method="seqcc-global"`` (the default of :func:`o3d_seqcc.correction.correct`).
    Steps (module docstring): :func:`~o3d_seqcc.correction.methods.edge_summaries.edge_observations` on
    every edge of the reference's component; the sequential estimate along the paper's paths
    (:func:`sequential_start`); the least-squares estimate over all edges that starts from it
    (:func:`~o3d_seqcc.correction.methods.joint_curves.linear_start`); the robust bundle adjustment
    (:func:`~o3d_seqcc.correction.methods.joint_curves.refine_curves`); then the continuation beyond
    each view's observed values. Views outside the reference's component keep the identity.
    Measured (``benchmarks/table2.py``): see the README's Measured table.

    Parameters
    ----------
    ctx : CorrectionContext
    init : {"quantile", "seqcc", "identity"}, default "quantile"
        Sequential estimate (:func:`sequential_start`).
    knots : int, default 11
        Knots of each view's response (:func:`~o3d_seqcc.correction.methods.joint_curves.refine_curves`).
    levels : int, default 32
        Quantile levels per edge and channel (>= 4).
    smooth : float, default 1e-3
        Weight of the responses' second differences.
    prior : float, default 1e-6
        Weight of the pull toward the start.
    iterations : int, default 10
        Levenberg-Marquardt iterations per channel and phase.
    edge_robust_c : float or None, default 2.0
        Cauchy scale of the per-edge weights, in median edge residuals (None: no robust phase).
    edge_weight : {"sqrt", "equal", "count"}, default "sqrt"
        Each edge's share of the data term.
    max_mappings : int or None, default 8000
        Mappings used per edge at most (>= 10; None: all).
    outlier_k : float or None, default 3.0
        Wrong correspondences dropped beyond this many robust sigmas (> 0; None keeps all).
    extrapolate : {"power", "line", "none"}, default "power"
        Beyond each view's observed values: power laws (:func:`o3d_seqcc.correction.luts.extend_curve`),
        the end slopes (:func:`o3d_seqcc.correction.luts.extend_line`, for comparison) or the inverse
        response's own flat ends.
    support_tail : float, default 0.01
        Share of each end of a view's pooled observations not counted as observed.
    values : {"own", "normalised", "auto", "sequential"}, default "own"
        The values the joint solve works in: the photos' own; each view's colours through its
        histogram normaliser toward the reference (:mod:`~o3d_seqcc.correction.methods.value_space`:
        the solve then sees the same numbers whatever monotone change a camera made, the outlier
        pass included; the correction is the solved curve after the normaliser); ``"auto"``:
        normalised when the views' normalisers lie at most :data:`AUTO_OFFSET` 8-bit levels from
        their sequential estimates (median view), own otherwise; ``"sequential"``: the sequential
        estimate's values. Measured (``benchmarks/colour_invariance.py``, README): normalised
        halves the invariance error on Fountain and its few-view subsets but moves consistent
        generated photos away from their truth, and the ``"auto"`` criterion does not separate a
        small generated room from Fountain, so the default stays the photos' own values.
    refine : bool, default True
        Refine the sequential estimate jointly over every edge (the linear start and the bundle
        adjustment); False: the sequential estimate alone (each path's quantile-quantile curves
        composed, in ``values``), continued beyond each view's observed values.
    max_slope : float or None, default 4.0
        A view whose joint curve rises more than this many times faster than its input over any
        8-level stretch of its observed values (a cliff: a stretch of its colours blown out) keeps
        its sequential estimate instead (None: no check).
    n_jobs : int or None, default None
        joblib threads for the edge summaries and the sequential fit (joblib semantics).

    Returns
    -------
    list of transforms
        :class:`~o3d_seqcc.correction.LutTransform` per solved view, the identity for the
        reference and for views without a path.

    Raises
    ------
    ValueError
        An option out of range.
    """
    if values not in VALUE_SPACES:
        raise ValueError(f"values must be one of {', '.join(VALUE_SPACES)}, got {values!r}")
    if extrapolate not in ("power", "line", "none"):
        raise ValueError(f"extrapolate must be 'power', 'line' or 'none', got {extrapolate!r}")
    if outlier_k is not None and not float(outlier_k) > 0:
        raise ValueError(f"outlier_k must be > 0 (robust sigmas) or None, got {outlier_k}")
    if not (isinstance(levels, (int, np.integer)) and levels >= 4):
        raise ValueError(f"levels must be an integer >= 4, got {levels!r}")
    if max_mappings is not None and not int(max_mappings) >= 10:
        raise ValueError(f"max_mappings must be >= 10 or None, got {max_mappings!r}")
    n, L = len(ctx.images), int(ctx.lut_size)
    if ctx.graph is not None:
        edges = sorted((min(a, b), max(a, b)) for a, b in ctx.graph.edges())
    else:
        edges = sorted(k for k, c in ctx.mappings.counts.items() if c >= ctx.t_npm)
    edges = [(a, b) for a, b in edges if a in ctx.paths and b in ctx.paths]
    obs_norm = None
    if values in ("auto", "normalised"):
        obs, obs_norm = edge_observations(ctx, edges, levels=levels, max_mappings=max_mappings, outlier_k=outlier_k,
                                          normalise_to=ctx.reference, n_jobs=n_jobs)
    else:
        obs = edge_observations(ctx, edges, levels=levels, max_mappings=max_mappings, outlier_k=outlier_k,
                                n_jobs=n_jobs)
    sequential = sequential_start(ctx, init=init, obs=obs, outlier_k=outlier_k, n_jobs=n_jobs)
    grid = np.linspace(0.0, 1.0, L)
    in_paths = np.isin(np.arange(n), list(ctx.paths))
    from threadpoolctl import threadpool_limits

    def candidate(space: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(curves (V, 3, L), supports (V, 3, 2), solved (V,)) of one value space, in the views' own values."""
        if space == "own":
            o, start = obs, sequential
        elif space == "normalised":
            o = obs_norm
            start = sequential_start(ctx, init="quantile", obs=o, outlier_k=outlier_k, n_jobs=n_jobs)
        else:  # "sequential": the solve in the sequential estimate's values, from the identity
            o, start = obs.through(sequential), np.broadcast_to(grid, sequential.shape).copy()
        if refine:
            with threadpool_limits(1, user_api="blas"):
                start = linear_start(o, n_views=n, reference=ctx.reference, init=start, knots=knots, lut_size=L,
                                     smooth=smooth)
            res = refine_curves(
                o, n_views=n, reference=ctx.reference, init=start, knots=knots, lut_size=L, smooth=smooth, prior=prior,
                iterations=iterations, edge_robust_c=edge_robust_c, edge_weight=edge_weight, support_tail=support_tail,
            )
            curves, supports, solved = res.luts.copy(), res.support.copy(), res.solved
        else:
            curves, supports, solved = start.copy(), observed_support(o, n_views=n, tail=support_tail), in_paths
        if o.normalisers is not None:  # the solved curve after the view's normaliser, its support in the view's values
            ramp = np.arange(L) * 1e-12
            for v in range(n):
                norm = o.normalisers[v]
                curves[v] = np.stack([np.interp(norm[c], grid, curves[v, c]) for c in range(3)])
                supports[v] = np.stack([np.interp(supports[v, c], norm[c] + ramp, grid) for c in range(3)])
        return curves, supports, solved

    if values == "auto":
        spaces = ("normalised",) if _normaliser_offset(obs, obs_norm.normalisers, sequential) <= AUTO_OFFSET else ("own",)
    else:
        spaces = (values,)
    cands = [candidate(sp) for sp in spaces]
    own_support = observed_support(obs, n_views=n, tail=support_tail)
    out: list = []
    for v in range(n):
        if v == ctx.reference or v not in ctx.paths:
            out.append(IdentityTransform())
            continue
        # the first value space whose curve has no cliff; else the sequential estimate
        lut, support, extend = sequential[v].copy(), own_support[v], True
        for sp, (curves, supports, solved) in zip(spaces, cands):
            if not solved[v]:
                continue
            if max_slope is None or _steepest(curves[v], supports[v]) <= float(max_slope):
                lut, support, extend = curves[v].copy(), supports[v], True
                break
            logger.info("seqcc-global: view %d's curve in the %s values stretches a stretch of its values more than "
                        "%g times", v, sp, float(max_slope))
        if extrapolate != "none" and extend:
            for c in range(3):
                lo, hi = support[c]
                lut[c] = extend_curve(lut[c], lo, hi) if extrapolate == "power" else extend_line(lut[c], lo, hi)
        out.append(LutTransform(np.clip(lut, 0.0, 1.0)))
    return out

