"""``seqcc-global``: the sequential correction refined jointly over every graph edge (the default method).

The paper's sequential correction (``method="seqcc"``) fits one colour mapping function per
edge of each view's Dijkstra path to the reference and composes them: every edge's error is
carried to all views behind it, and a view is corrected only over the values its path edges
observed. ``method="seqcc-global"`` (:func:`method_seqcc_global`) refines a sequential
estimate the way global bundle adjustment follows incremental structure-from-motion:

1. :func:`~o3d_seqcc.correction.methods.edge_summaries.edge_observations`: for **every** edge of the
   colour-correction graph (not only the path tree), and every pair under its threshold that shares at
   least half of ``t_npm`` (``edge_fraction``), the colours at the pair's mappings, wrong
   correspondences dropped, summarised per channel by their matched quantiles.
2. :func:`sequential_start`: the sequential estimate along the paper's paths (by default each
   path edge's quantile-quantile curve from step 1; ``init="seqcc"`` uses the full CSVR fit).
3. :func:`~o3d_seqcc.correction.methods.joint_curves.linear_start` then
   :func:`~o3d_seqcc.correction.methods.joint_curves.refine_curves`: least squares on the corrected
   values over all edges (convex; a little contracted by the noise), then the robust bundle
   adjustment of per-view, per-channel responses over all edges, in the measured values, which
   no common contraction of the curves can lower; the corrections are the responses' inverses.
   The measured values are a view's own through a monotone table (``values=``): its sequential
   estimate from step 2 (a camera's change of the view's values then moves them only as much as
   it moves that estimate), none, or its histogram normaliser
   (:mod:`~o3d_seqcc.correction.methods.value_space`); ``values="auto"`` (the default) solves in
   the first two without every third edge off the paths and keeps the values in which those
   held-out edges agree better. A view whose edges its sequential estimate fits better than its
   joint curve keeps the former (``guard``).
4. :func:`~o3d_seqcc.correction.luts.extend_curve`: beyond the values any edge of a view observed, the
   correction continues as a power law ``f(x) = f(x_b) (x / x_b)^beta`` with ``beta`` its
   log-log slope over the last observed stretch -- the shape of a gamma-type camera response,
   which a change of exposure, white balance and gamma keeps exactly -- instead of a clamp or a
   straight line; below the darkest observation it runs to black ``(0, 0)`` the same way. Values
   inside the range a view's *other* edges observed come from them through step 3.

Every edge's residual before and after the correction is kept in ``ctx.edge_residuals`` (the
report's table; :meth:`~o3d_seqcc.correction.CorrectionResult.out_of_line`).
"""

from __future__ import annotations

import logging

import numpy as np

from ..luts import extend_curve, extend_line
from ..base import CorrectionContext, IdentityTransform, LutTransform, lut_per_path
from .edge_summaries import CLIPPED, EdgeObservations, edge_observations, edge_quantiles
from .joint_curves import linear_start, observed_support, refine_curves
from .seqcc import _method_seqcc, colour_inliers, quantile_luts
from .value_space import LOG_LIGHT_FLOOR, log_light, log_light_inverse

__all__ = ["method_seqcc_global", "sequential_start"]

logger = logging.getLogger(__name__)

#: the values the joint solve can work in (``values=`` of :func:`method_seqcc_global`)
VALUE_SPACES = ("auto", "sequential", "own", "normalised")


def sequential_start(
    ctx: CorrectionContext,
    *,
    init: str = "quantile",
    obs: EdgeObservations | None = None,
    outlier_k: float | None = 3.0,
    light: str = "linear",
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
    light : {"linear", "encoded"}, default "linear"
        Where the power laws continuing each edge's curve are (:func:`~o3d_seqcc.correction.luts.extend_curve`).
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
                out[c] = extend_curve(np.interp(grid, x, qs[c]), x[0], x[-1], light=light)
            return out

        transforms = lut_per_path(ctx, edge_lut, n_jobs=n_jobs)
    else:
        raise ValueError(f"init must be 'seqcc', 'quantile' or 'identity', got {init!r}")
    for v, tr in enumerate(transforms):
        if isinstance(tr, LutTransform):
            start[v] = np.stack([np.interp(grid, np.linspace(0.0, 1.0, tr.lut.shape[1]), tr.lut[c]) for c in range(3)])
    return start


def _corrected(obs: EdgeObservations, curves: np.ndarray, views: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(E, 3, P) each edge's quantiles ``q`` of ``views`` through their curves (V, 3, L) (linear interpolation)."""
    L = curves.shape[2]
    x = np.clip(q, 0.0, 1.0) * (L - 1)
    i0 = np.minimum(np.floor(x).astype(np.int64), L - 2)
    f = x - i0
    ch = np.arange(3)[None, :, None]
    vv = views[:, None, None]
    return curves[vv, ch, i0] * (1.0 - f) + curves[vv, ch, i0 + 1] * f


def _edge_rms(obs: EdgeObservations, xa: np.ndarray, xb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each edge's root-mean-square difference of its two sides' (E, 3, P) values over the levels neither side has
    censored, and the edges that have any: ``(rms (E,), valid (E,))``."""
    seen = np.stack([np.stack(obs.observed(c), axis=0) for c in range(3)], axis=2)  # (2, E, 3, P)
    both = seen[0] & seen[1]
    cnt = np.maximum(both.sum(axis=(1, 2)), 1)
    rms = np.sqrt(np.where(both, (xa - xb) ** 2, 0.0).sum(axis=(1, 2)) / cnt)
    return rms, (obs.n > 0) & both.any(axis=(1, 2))


def _joint_worse(obs: EdgeObservations, joint: np.ndarray, sequential: np.ndarray) -> np.ndarray:
    """(V,) views whose edges the joint curves fit worse than the view's sequential estimate would, the other views
    keeping their joint curves: each edge's :func:`_edge_rms` of its two corrected quantiles (in the reference's
    values), averaged over the view's edges with weights sqrt(mappings)."""
    V = joint.shape[0]
    ja, jb = _corrected(obs, joint, obs.a, obs.qa), _corrected(obs, joint, obs.b, obs.qb)
    sa, sb = _corrected(obs, sequential, obs.a, obs.qa), _corrected(obs, sequential, obs.b, obs.qb)
    joint_rms, valid = _edge_rms(obs, ja, jb)
    w = np.sqrt(obs.n.astype(np.float64)) * valid

    def per_view(rms_a: np.ndarray, rms_b: np.ndarray) -> np.ndarray:  # each view's edges, a side's and b side's
        return np.bincount(obs.a, weights=w * rms_a, minlength=V) + np.bincount(obs.b, weights=w * rms_b, minlength=V)

    seq_a, seq_b = _edge_rms(obs, sa, jb)[0], _edge_rms(obs, ja, sb)[0]  # view a's, view b's sequential estimate
    ones = np.ones(len(w))
    return (per_view(ones, ones) > 0) & (per_view(seq_a, seq_b) < per_view(joint_rms, joint_rms))


def _edge_residuals(obs: EdgeObservations, transforms: list, lut_size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every edge's :func:`_edge_rms` of its matched quantiles, in 8-bit levels, in the photos' own values and
    through ``transforms``: ``(before, after, valid)`` (E,)."""
    grid = np.linspace(0.0, 1.0, int(lut_size))
    final = np.stack([tr.lut if isinstance(tr, LutTransform) else np.broadcast_to(grid, (3, grid.size))
                      for tr in transforms])
    before, valid = _edge_rms(obs, obs.qa, obs.qb)
    after = _edge_rms(obs, _corrected(obs, final, obs.a, obs.qa), _corrected(obs, final, obs.b, obs.qb))[0]
    return before * 255.0, after * 255.0, valid


def _held_out(obs: EdgeObservations, paths: dict) -> np.ndarray:
    """(E,) every third edge off the paths' tree (the sequential estimate does not use them)."""
    tree = {(min(p[i], p[i + 1]), max(p[i], p[i + 1])) for p in paths.values() for i in range(len(p) - 1)}
    off = [e for e in range(len(obs.a)) if (min(obs.a[e], obs.b[e]), max(obs.a[e], obs.b[e])) not in tree and obs.n[e] > 0]
    out = np.zeros(len(obs.a), dtype=bool)
    out[off[1::3]] = True
    return out


def _residual_score(obs: EdgeObservations, transforms: list, lut_size: int) -> float:
    """Mean residual after ``transforms`` over the edges of ``obs``, each weighted by the square root of its mapping
    count: what ``values="auto"`` compares on its held-out edges."""
    _, after, valid = _edge_residuals(obs, transforms, lut_size)
    w = np.sqrt(obs.n.astype(np.float64)) * valid
    return float((after * w).sum() / max(w.sum(), 1e-300))


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    """The weighted median of ``values`` (the smallest value whose cumulative weight reaches half)."""
    order = np.argsort(values)
    cw = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cw, 0.5 * cw[-1])])


def clipped_levels(obs: EdgeObservations, transforms: list, lut_size: int, *, min_count: int = 20) -> list:
    """The corrections with each view's clipped end levels mapped to what they hide, in the reference's values.

    A photo that clipped a channel holds one level (0 or 255) for a range of true values; a curve continued from
    the values below the clip maps that level to the bottom (top) of the range. Here each view's clipped level
    goes to the weighted median, over its edges with at least ``min_count`` clipped mappings, of what it stands
    for on each (:func:`~o3d_seqcc.correction.methods.edge_summaries.clipped_ends`: the other view's value in the
    middle of the clipped ranks) through the other view's correction; weights: the clipped mappings. The level
    never moves below (above) the correction of the levels next to it. Measured on Fountain's 11-photo subset
    (``benchmarks/colour_invariance.py``): two photos whose hidden change clipped a fifth of their blue.

    Parameters
    ----------
    obs : EdgeObservations
        Summaries with :attr:`~EdgeObservations.clipped` (none: ``transforms`` returned as they are).
    transforms : list
        One per view; :class:`LutTransform` curves on ``np.linspace(0, 1, lut_size)``, others the identity.
    lut_size : int
    min_count : int, default 20

    Returns
    -------
    list
        New transforms (the inputs are not modified).
    """
    if obs.clipped is None or not len(obs.a):
        return list(transforms)
    grid = np.linspace(0.0, 1.0, int(lut_size))
    luts = [tr.lut if isinstance(tr, LutTransform) else None for tr in transforms]
    ends = (grid <= CLIPPED, grid >= 1.0 - CLIPPED)
    out = list(transforms)
    for v, lut in enumerate(luts):
        if lut is None:
            continue
        new = lut.copy()
        for c in range(3):
            for end in (0, 1):
                vals, wts = [], []
                for side, (mine, other) in enumerate(((obs.a, obs.b), (obs.b, obs.a))):
                    for e in np.flatnonzero(mine == v):
                        share, y = obs.clipped[e, side, c, end]
                        count = share * obs.n[e]
                        if count < min_count:
                            continue
                        o_lut = luts[int(other[e])]
                        vals.append(float(np.interp(y, grid, o_lut[c])) if o_lut is not None else float(y))
                        wts.append(count)
                if not vals or not ends[end].any() or ends[end].all():
                    continue
                est = _weighted_median(np.asarray(vals), np.asarray(wts, dtype=np.float64))
                sel = ends[end]
                if end == 1:
                    new[c, sel] = max(est, float(new[c, ~sel].max()))
                else:
                    new[c, sel] = min(est, float(new[c, ~sel].min()))
        if not np.array_equal(new, lut):
            out[v] = LutTransform(np.clip(new, 0.0, 1.0))
    return out


def _record_residuals(ctx: CorrectionContext, obs: EdgeObservations, transforms: list) -> None:
    """``ctx.edge_residuals``: every edge's residual before and after the correction (:func:`_edge_residuals`)."""
    before, after, valid = _edge_residuals(obs, transforms, ctx.lut_size)
    for e in np.flatnonzero(valid):
        a, b = int(obs.a[e]), int(obs.b[e])
        ctx.edge_residuals[(min(a, b), max(a, b))] = (round(float(before[e]), 3), round(float(after[e]), 3))


def method_seqcc_global(
    ctx: CorrectionContext,
    *,
    init: str = "quantile",
    knots: int = 11,
    levels: int = 64,
    smooth: float = 1e-3,
    prior: float = 1e-6,
    prior_direct: float | None = 1e-3,
    iterations: int = 10,
    edge_robust_c: float | None = 2.0,
    edge_weight: str = "sqrt",
    max_mappings: int | None = 16000,
    outlier_k: float | None = 1.0,
    extrapolate: str = "power",
    light: str = "linear",
    support_tail: float = 0.01,
    values: str = "auto",
    own_light: float | None = LOG_LIGHT_FLOOR,
    own_margin: float = 0.1,
    outlier_rounds: int | None = 5,
    refine: bool = True,
    edge_fraction: float = 0.5,
    guard: bool = True,
    clip_levels: bool = True,
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
    levels : int, default 64
        Quantile levels per edge and channel (>= 4); 64 measured steadier than 32 on the generated
        6 MP scene with occluders (``benchmarks/colour_invariance.py``).
    smooth : float, default 1e-3
        Weight of the responses' second differences.
    prior : float, default 1e-6
        Weight of the pull toward the start.
    prior_direct : float or None, default 1e-3
        The pull toward the start of the views whose path to the reference is one edge (their curve was
        measured directly, not composed); None: ``prior`` for every view. The joint solve moves them only where
        the other edges' evidence outweighs that measurement, the views further away as freely as before (the
        drift along their paths is what the joint solve removes). Measured (``benchmarks/colour_invariance.py``,
        README): invariance on Fountain 0.35 -> 0.32 (worst photo 1.09 -> 0.93), on its 11-photo subset 0.56 ->
        0.44 (1.48 -> 0.80: the robust edge weights of one photo whose neighbours disagree with it in blue had
        flipped with a camera's clipping of 1 % of its blue), on its 9-photo subset 0.46 -> 0.47; the generated
        rooms' invariance the same, the hard one's truth 1.99 -> 2.17; 3e-4 and 3e-3 were worse on two sets.
    iterations : int, default 10
        Levenberg-Marquardt iterations per channel and phase.
    edge_robust_c : float or None, default 2.0
        Cauchy scale of the per-edge weights, in median edge residuals (None: no robust phase).
    edge_weight : {"sqrt", "equal", "count"}, default "sqrt"
        Each edge's share of the data term.
    max_mappings : int or None, default 16000
        Mappings used per edge at most (>= 10; None: all), evenly strided over the pair's list. Measured
        (``benchmarks/colour_invariance.py``, ``edge_fraction=0.5``, the mean invariance of hidden-change seeds
        0-3) with 8000 / 12000 / 16000 / 24000: Fountain 0.34 / 0.32 / 0.32 / 0.31, its 11-photo subset 0.40 /
        0.37 / 0.36 / 0.36, its 9-photo subset 0.37 / 0.34 / 0.35 / 0.35, the generated 6 MP room 0.57 / 0.53 /
        0.53 / 0.54, the one with occluders 0.47 / 0.49 / 0.48 / 0.48. The synthetic hard room (320x240, every
        edge under 12000 mappings) moves with the subsample alone: 0.553 (worst photo 1.00) with 8000 strided,
        0.553-0.606 (0.99-1.24) with 8000 drawn at random under six seeds, 0.577 (1.20) with all of them.
    outlier_k : float or None, default 1.0
        Wrong correspondences dropped beyond this many robust sigmas (> 0; None keeps all): of the colours' ranks
        with ``outlier_rounds``, of view b's values without (3.0 was that rule's default). Measured with the rank
        rule (``benchmarks/colour_invariance.py``, seed 0): 1 / 1.5 / 2 gave the generated 6 MP room with occluders
        invariance 0.51 / 1.23 (its value space flipped for one photo set) / 0.70 and truth 0.63 / 1.58 / 1.57,
        Fountain's worst photo 1.08 / 0.94 / 1.01, the hard room 0.58 / 0.67 / 0.60.
    extrapolate : {"power", "line", "none"}, default "power"
        Beyond each view's observed values: power laws (:func:`o3d_seqcc.correction.luts.extend_curve`),
        the end slopes (:func:`o3d_seqcc.correction.luts.extend_line`, for comparison) or the inverse
        response's own flat ends.
    light : {"linear", "encoded"}, default "linear"
        Where those power laws are: in linear light (the sRGB-encoded values decoded; a camera's exposure and
        white balance are gains there, with a gamma a power law exactly) or in the encoded values. Measured
        (``benchmarks/colour_invariance.py``, hidden changes in linear light): on the generated 6 MP room, whose
        reference shares no shadows with the photo next to it, invariance 0.65 -> 0.58 (the shadows of its
        farthest photo 7.7 levels off -> 6.0); the Fountain sets and the hard synthetic room (changes in the
        encoded values) within 0.02.
    support_tail : float, default 0.01
        Share of each end of a view's pooled observations not counted as observed.
    values : {"auto", "sequential", "own", "normalised"}, default "auto"
        The values the joint solve works in, each view's own through a monotone table: its
        sequential estimate (step 2: the solve starts from the identity in values that already
        sit near the reference's, and a camera's monotone change of a view's values moves them
        only as much as it moves the sequential estimate); the photos' own values (no table); or
        each view's histogram normaliser toward the reference
        (:mod:`~o3d_seqcc.correction.methods.value_space`: no monotone change moves those values,
        the outlier pass included). The correction is the solved curve after the view's table.
        ``"auto"`` solves in the sequential and in the own values without every third edge off the
        paths' tree, keeps the values in which those held-out edges agree better (each edge's
        residual, :attr:`CorrectionResult.edge_residuals
        <o3d_seqcc.correction.CorrectionResult.edge_residuals>`, averaged with weights
        sqrt(mappings); all edges, in-sample, when none is off the tree) and solves there on every
        edge: no truth needed, two more bundle adjustments. Measured
        (``benchmarks/colour_invariance.py``, README): the sequential values win on Fountain, its
        11-photo subset and the generated 6 MP rooms, the own values on the hard synthetic room and
        a small distorted room; the held-out residual picks the winner on all but the 9-photo
        Fountain subset (the in-sample residual missed the distorted room). The normalised values
        undo most of a hidden change on Fountain but move consistent generated photos away from
        their truth (content that differs between views makes the histogram match a poor start).
    own_light : float or None, default :data:`~o3d_seqcc.correction.methods.value_space.LOG_LIGHT_FLOOR`
        The solve in the photos' own values works in log linear light with this floor
        (:func:`~o3d_seqcc.correction.methods.value_space.log_light`): a response made of exposure, white balance and
        gamma is a straight line there, so the responses' smoothness penalty costs nothing for what cameras do and
        continues it into the shadows and highlights that only edges far from the reference observe. None: the
        encoded values. Measured (``benchmarks/colour_invariance.py``, README): the hard synthetic room against its
        truth 0.76 -> 0.55 (worst photo 1.70 -> 1.00), its shadows 2-3 levels off -> under 1; the generated 6 MP
        room with occluders 1.10 / 4.28 -> 0.49 / 0.67; in the sequential values too (tried) it moved that room
        0.69 -> 1.6.
    own_margin : float, default 0.1
        ``values="auto"`` takes the own values only when their held-out residual is below ``1 - own_margin`` times
        the sequential values' (in [0, 1)). The sequential values move with a camera's change only as much as the
        sequential estimate does; a near tie between the two spaces flipped between a photo set and the same set
        under a camera change (Fountain's 9-photo subset: held-out residuals 6.42 against 6.54 chose one space,
        6.50 against 6.54 the other). The own values won by 30-70 % where they were better.
    outlier_rounds : int or None, default 5
        The edges' outlier pass (``outlier_k``) on the colours' ranks, which no monotone change of either view
        moves, with this many rounds after the first (>= 0): each measures every mapping against the pair's
        inliers of the round before (:func:`~o3d_seqcc.correction.methods.edge_summaries.rank_inliers`), until at
        most one in a thousand changes; an occluder or a highlight the mesh lacks that covers a tenth of a pair's
        surface bends the first pass's quantile curve toward itself. None: one pass, residuals in view b's values.
        Measured (``benchmarks/colour_invariance.py``, README): the generated 6 MP room with occluders and
        highlights, its truth 2.18 / 3.96 -> 0.63 / 1.11 (the held-out edges' residual 8.1 -> about 1 level).
    edge_fraction : float, default 0.5
        The joint solve also takes the pairs that share at least this fraction of ``t_npm`` (in (0, 1]; the paths
        and the sequential estimate keep the graph's ``t_npm``): a pair under the graph's threshold still
        measures the values it shares, each edge weighted by the square root of its count, and it can be the only
        one that sees a group of photos' shadows beside a photo near the reference. 1: the graph's edges only.
        Measured (``benchmarks/colour_invariance.py``, seeds 0-3): the generated 6 MP room with occluders, whose
        photos 2-4 meet the reference's side in their shadows only through a pair at 78 % of ``t_npm``,
        invariance 0.49 / 0.57 / 0.49 / 0.69 (worst photo 1.57) -> 0.47 / 0.48 / 0.48 / 0.47 (0.93), truth 0.63 /
        0.71 / 0.62 / 0.77 -> 0.50 / 0.53 / 0.52 / 0.50; 0.2 and 0.1 gave the same there and Fountain's full set
        0.35 (0.34 with 0.5).
    refine : bool, default True
        Refine the sequential estimate jointly over every edge (the linear start and the bundle
        adjustment); False: the sequential estimate alone (each path's quantile-quantile curves
        composed, in ``values``), continued beyond each view's observed values.
    guard : bool, default True
        A view whose edges the joint curves fit worse than its sequential estimate would (the others keeping
        their joint curves; root-mean-square differences of the corrected quantiles, in the reference's values)
        keeps its sequential estimate: the joint refinement never leaves a view less consistent with its
        neighbours than its sequential step (not with ``values="normalised"``, whose sequential estimate is in
        other values). Measured (``benchmarks/colour_invariance.py``, seeds 0-3, with ``edge_fraction=0.5``):
        Fountain and its subsets unchanged (no view kept), room-6mp's invariance 0.47 / 0.57 / 0.57 / 0.50 ->
        0.47 / 0.55 / 0.57 / 0.49, room-6mp-hard's truth 0.50 / 0.55 / 0.51 / 0.56 -> 0.47 / 0.54 / 0.49 / 0.56.
        Off in issue 34's third pass, when without the pairs under the graph's threshold it kept the sequential
        estimate of photos whose joint curve was far nearer the truth (room-6mp-hard: one photo 1.0 -> 4.3
        CIEDE2000 from the truth) and its per-photo choice flipped between a photo set and the same set under a
        camera change (that room's invariance 0.53 -> 1.12).
    clip_levels : bool, default True
        Map each view's clipped end levels (0 and 255) to the middle of the true values they hide
        (:func:`clipped_levels`) instead of the end of its continued curve.
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
    if own_light is not None and not float(own_light) > 0:
        raise ValueError(f"own_light must be > 0 (linear light) or None, got {own_light!r}")
    if not 0.0 <= float(own_margin) < 1.0:
        raise ValueError(f"own_margin must lie in [0, 1), got {own_margin!r}")
    if outlier_rounds is not None and not (isinstance(outlier_rounds, (int, np.integer)) and outlier_rounds >= 0):
        raise ValueError(f"outlier_rounds must be an integer >= 0 or None, got {outlier_rounds!r}")
    if values not in VALUE_SPACES:
        raise ValueError(f"values must be one of {', '.join(VALUE_SPACES)}, got {values!r}")
    if extrapolate not in ("power", "line", "none"):
        raise ValueError(f"extrapolate must be 'power', 'line' or 'none', got {extrapolate!r}")
    if light not in ("linear", "encoded"):
        raise ValueError(f"light must be 'linear' or 'encoded', got {light!r}")
    if outlier_k is not None and not float(outlier_k) > 0:
        raise ValueError(f"outlier_k must be > 0 (robust sigmas) or None, got {outlier_k}")
    if not (isinstance(levels, (int, np.integer)) and levels >= 4):
        raise ValueError(f"levels must be an integer >= 4, got {levels!r}")
    if max_mappings is not None and not int(max_mappings) >= 10:
        raise ValueError(f"max_mappings must be >= 10 or None, got {max_mappings!r}")
    if not 0.0 < float(edge_fraction) <= 1.0:
        raise ValueError(f"edge_fraction must lie in (0, 1], got {edge_fraction!r}")
    if ctx.graph is not None:
        edges = {(min(a, b), max(a, b)) for a, b in ctx.graph.edges()}
    else:
        edges = {(min(a, b), max(a, b)) for (a, b), c in ctx.mappings.counts.items() if c >= ctx.t_npm}
    weak = float(edge_fraction) * ctx.t_npm  # the pairs under the graph's threshold that the joint solve takes
    edges = sorted(edges | {(min(a, b), max(a, b)) for (a, b), c in ctx.mappings.counts.items() if a != b and c >= weak})
    edges = [(a, b) for a, b in edges if a in ctx.paths and b in ctx.paths]
    if values == "normalised":
        own_obs, norm_obs = edge_observations(ctx, edges, levels=levels, max_mappings=max_mappings,
                                              outlier_k=outlier_k, outlier_rounds=outlier_rounds,
                                              normalise_to=ctx.reference, n_jobs=n_jobs)
    else:
        own_obs = norm_obs = edge_observations(ctx, edges, levels=levels, max_mappings=max_mappings,
                                               outlier_k=outlier_k, outlier_rounds=outlier_rounds, n_jobs=n_jobs)
    sequential = sequential_start(ctx, init=init, obs=norm_obs, outlier_k=outlier_k, light=light, n_jobs=n_jobs)
    if prior_direct is not None:  # the views one edge from the reference: their curve was measured directly
        prior = np.where([len(ctx.paths.get(v, ())) == 2 for v in range(len(ctx.images))], float(prior_direct),
                         float(prior))
    opts = dict(knots=knots, smooth=smooth, prior=prior, iterations=iterations, edge_robust_c=edge_robust_c,
                edge_weight=edge_weight, support_tail=support_tail, extrapolate=extrapolate, light=light, refine=refine,
                guard=guard, own_light=own_light)
    if values == "auto":  # both, and the one whose edges agree better after it
        held = _held_out(own_obs, ctx.paths)
        if held.any():
            fit = own_obs.subset(~held)
            tried = {sp: _solve(ctx, fit, sequential, space=sp, **opts) for sp in ("sequential", "own")}
            scores = {sp: _residual_score(own_obs.subset(held), out, ctx.lut_size) for sp, out in tried.items()}
        else:
            tried = {sp: _solve(ctx, own_obs, sequential, space=sp, **opts) for sp in ("sequential", "own")}
            scores = {sp: _residual_score(own_obs, out, ctx.lut_size) for sp, out in tried.items()}
        chosen = "own" if scores["own"] < (1.0 - float(own_margin)) * scores["sequential"] else "sequential"
        logger.info("seqcc-global: values='auto' chose the %s values (edge residuals after: %s; %d held out)", chosen,
                    ", ".join(f"{sp} {sc:.3f}" for sp, sc in scores.items()), int(held.sum()))
        out = tried[chosen] if not held.any() else _solve(ctx, own_obs, sequential, space=chosen, **opts)
    else:
        out = _solve(ctx, norm_obs, sequential, space=values, **opts)
    if clip_levels:
        out = clipped_levels(own_obs, out, ctx.lut_size)
    _record_residuals(ctx, own_obs, out)
    return out


def _solve(ctx: CorrectionContext, obs: EdgeObservations, sequential: np.ndarray, *, space: str, knots: int,
           smooth: float, prior: float | np.ndarray, iterations: int, edge_robust_c: float | None, edge_weight: str,
           support_tail: float, extrapolate: str, light: str, refine: bool, guard: bool,
           own_light: float | None = None) -> list:
    """The joint solve (steps 3-4) in one value space (:data:`VALUE_SPACES`): one transform per view.

    ``obs`` are the summaries in the views' own values (in the normalised values for ``space="normalised"``) and
    ``sequential`` the sequential estimate from them (V, 3, L). ``own_light``: the floor of the log linear light
    the own values are solved in (None: the encoded values).
    """
    from threadpoolctl import threadpool_limits

    n, L = len(ctx.images), int(ctx.lut_size)
    grid = np.linspace(0.0, 1.0, L)
    start, observations = sequential, obs
    in_light = space == "own" and refine and own_light is not None
    if space == "sequential" and refine:  # the solve in the sequential estimate's values, from the identity
        obs = obs.through(sequential)
        start = np.broadcast_to(grid, sequential.shape).copy()
    elif in_light:  # the own values in log linear light, from the sequential estimate there
        obs = obs.through(np.broadcast_to(log_light(grid, own_light), sequential.shape))
        start = log_light(np.stack([[np.interp(log_light_inverse(grid, own_light), grid, sequential[v, c])
                                     for c in range(3)] for v in range(n)]), own_light)
    if refine:
        with threadpool_limits(1, user_api="blas"):
            start = linear_start(obs, n_views=n, reference=ctx.reference, init=start, knots=knots, lut_size=L,
                                 smooth=smooth)
        res = refine_curves(
            obs, n_views=n, reference=ctx.reference, init=start, knots=knots, lut_size=L, smooth=smooth, prior=prior,
            iterations=iterations, edge_robust_c=edge_robust_c, edge_weight=edge_weight, support_tail=support_tail,
        )
        curves, supports, solved = res.luts.copy(), res.support.copy(), res.solved
    else:
        curves, supports = start.copy(), observed_support(obs, n_views=n, tail=support_tail)
        solved = np.isin(np.arange(n), list(ctx.paths))
    ramp = np.arange(L) * 1e-12
    if in_light:  # back to encoded values, after the views' tables
        curves = log_light_inverse(curves, own_light)
    if obs.normalisers is not None and (space == "sequential" or in_light):  # the solved curves after the views' tables
        for v in range(n):
            norm = obs.normalisers[v]
            curves[v] = np.stack([np.interp(norm[c], grid, curves[v, c]) for c in range(3)])
            supports[v] = np.stack([np.interp(supports[v, c], norm[c] + ramp, grid) for c in range(3)])
    kept = np.zeros(n, dtype=bool)
    if refine and guard and space != "normalised":
        kept = _joint_worse(observations, curves, sequential) & solved
        kept[ctx.reference] = False
        curves[kept] = sequential[kept]
        supports[kept] = observed_support(observations, n_views=n, tail=support_tail)[kept]
    if kept.any():
        logger.info("seqcc-global: %d view(s) keep their sequential estimate (the joint curve fits their edges "
                    "worse): %s", int(kept.sum()), np.flatnonzero(kept).tolist())
    out: list = []
    for v in range(n):
        if v == ctx.reference or v not in ctx.paths:
            out.append(IdentityTransform())
            continue
        lut, support = curves[v].copy(), supports[v]
        if obs.normalisers is not None and space == "normalised":  # after the view's histogram normaliser
            norm = obs.normalisers[v]
            lut = np.stack([np.interp(norm[c], grid, lut[c]) for c in range(3)])
            support = np.stack([np.interp(support[c], norm[c] + ramp, grid) for c in range(3)])
        if extrapolate != "none" and solved[v]:
            for c in range(3):
                lo, hi = support[c]
                lut[c] = (extend_curve(lut[c], lo, hi, light=light) if extrapolate == "power"
                          else extend_line(lut[c], lo, hi))
        out.append(LutTransform(np.clip(lut, 0.0, 1.0)))
    return out

