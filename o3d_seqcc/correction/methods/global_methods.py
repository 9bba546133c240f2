"""Global multi-image colour-correction baselines of the paper's Table 1 (algorithms 5 and 6).

Both are *global*: they use every view pair with at least ``t_npm`` mappings at once (not the
graph's paths) and give each view one affine function per channel, returned as
:class:`~o3d_seqcc.correction.base.LutTransform`. Both fix the reference view (identity); views
with no pair of ``>= t_npm`` mappings in the reference's connected component stay unchanged.

``"gain-compensation"`` (Table 1 #5)
    Brown & Lowe (2007), "Automatic panoramic image stitching using invariant features",
    IJCV 74(1), section 6. One gain ``g_i`` per view and channel minimising ::

        e = 1/2 sum_i sum_{j != i} N_ij [ (g_i I_ij - g_j I_ji)^2 / sigma_n^2 + (1 - g_i)^2 / sigma_g^2 ]

    with ``N_ij`` the number of mappings of pair (i, j) and ``I_ij`` the mean value of view i
    over them (colours in [0, 1]). Setting the gradient to zero gives a small V x V linear
    system per channel (:func:`gain_compensation_gains`). Defaults are the paper's
    ``sigma_n = 10`` and ``sigma_g = 0.1`` on 8-bit values, i.e. ``sigma_n = 10/255`` on [0, 1].
    The prior pulls every gain towards 1; afterwards all gains of a channel are divided by
    the reference's gain so the reference stays unchanged (the result only changes by that
    common factor). OpenCV's ``cv2.detail.ChannelsCompensator`` solves the same system with
    the prior weighted by ``sum_j N_ij`` *including* ``N_ii`` = the image's own mask area;
    ``prior_weights`` reproduces that (see the tests).

``"histogram-matching"`` (Table 1 #6)
    Moulon, Duisit & Monasse (2013), "Global multiple-view color consistency", CVMP. One gain
    and offset ``(a_i, b_i)`` per view and channel. For every pair (i, j) and quantile ``q``
    of the two overlap histograms (the colours at the pair's mappings in each view) a
    constraint ``|a_i Q_i(q) + b_i - a_j Q_j(q) - b_j| <= gamma``; ``gamma`` is minimised (an
    L-infinity linear programme, ``scipy.optimize.linprog`` with HiGHS) with the reference
    fixed at ``a = 1, b = 0`` and bounded gains / offsets. An L-infinity optimum is rarely
    unique (only the worst constraints are active), so by default (``refine=True``) a second
    programme keeps ``gamma`` at its optimum (+0.1 %) and minimises the sum of the absolute
    residuals (lexicographic L-inf then L1), which fixes the views the worst pair does not
    constrain.
"""

from __future__ import annotations

import logging
import numpy as np

from ..base import IdentityTransform, LutTransform
from ...errors import InputError

__all__ = [
    "affine_lut",
    "gain_compensation",
    "gain_compensation_gains",
    "histogram_matching",
    "histogram_matching_params",
    "overlap_quantiles",
]

logger = logging.getLogger(__name__)

#: Number of LUT entries of the affine transforms (exact for affine maps up to the clip kink).
LUT_SIZE = 4096


def affine_lut(gain: np.ndarray, offset: np.ndarray | None = None, *, size: int = LUT_SIZE) -> np.ndarray:
    """Per-channel affine map ``clip(gain * x + offset, 0, 1)`` as a lookup table.

    Parameters
    ----------
    gain : (3,) float array
    offset : (3,) float array, optional
        Default zeros.
    size : int, default :data:`LUT_SIZE`
        Number of evenly spaced inputs in [0, 1].

    Returns
    -------
    numpy.ndarray
        (3, size) float64 in [0, 1].
    """
    gain = np.asarray(gain, dtype=np.float64).reshape(3, 1)
    offset = np.zeros((3, 1)) if offset is None else np.asarray(offset, dtype=np.float64).reshape(3, 1)
    x = np.linspace(0.0, 1.0, int(size))[None, :]
    return np.clip(gain * x + offset, 0.0, 1.0)


# ----------------------------------------------------------------------------- pair statistics
def _component_pairs(ctx) -> tuple[list[tuple[int, int]], set[int]]:
    """Pairs with n >= t_npm inside the reference's connected component, and that component."""
    import networkx as nx

    counts = ctx.mappings.counts
    pairs = sorted((int(a), int(b)) for (a, b), n in counts.items() if n >= ctx.t_npm and a != b)
    g = nx.Graph()
    g.add_nodes_from(range(int(ctx.mappings.n_views)))
    g.add_edges_from(pairs)
    comp = set(nx.node_connected_component(g, int(ctx.reference)))
    pairs = [p for p in pairs if p[0] in comp]
    left = sorted(set(range(int(ctx.mappings.n_views))) - comp)
    if left:
        logger.warning(
            "%d view(s) have no chain of pairs with >= %d mappings to the reference %d and stay unchanged: %s",
            len(left), ctx.t_npm, ctx.reference, left,
        )
    return pairs, comp


# ----------------------------------------------------------------------------- gain compensation
def gain_compensation_gains(
    I: np.ndarray,
    N: np.ndarray,
    *,
    sigma_n: float = 10.0 / 255.0,
    sigma_g: float = 0.1,
    prior_weights: np.ndarray | None = None,
) -> np.ndarray:
    """Brown & Lowe (2007) gains from overlap statistics (one linear solve per channel).

    Parameters
    ----------
    I : (V, V, C) float array
        ``I[i, j, c]``: mean of channel c of view i over its overlap with view j (any scale,
        but ``sigma_n`` is in the same units). Diagonal ignored.
    N : (V, V) array
        Symmetric overlap sizes (number of mappings); 0 = no overlap. Diagonal ignored.
    sigma_n : float, default 10/255
        Standard deviation of the normalised intensity error (10 on 8-bit values).
    sigma_g : float, default 0.1
        Standard deviation of the gain prior around 1.
    prior_weights : (V,) array, optional
        Weight of each view's prior term; default ``sum_{j != i} N_ij`` (Brown & Lowe).
        OpenCV's compensators use ``sum_j N_ij`` including the view's own area ``N_ii``.

    Returns
    -------
    numpy.ndarray
        (V, C) float64 gains (not normalised). Views without overlap get gain 1.
    """
    I = np.asarray(I, dtype=np.float64)
    N = np.asarray(N, dtype=np.float64).copy()
    V = N.shape[0]
    if N.shape != (V, V) or I.shape[:2] != (V, V) or I.ndim != 3:
        raise ValueError(f"gain_compensation_gains: I must be (V, V, C) and N (V, V); got {I.shape}, {N.shape}")
    np.fill_diagonal(N, 0.0)
    alpha = 1.0 / sigma_n**2
    beta = 1.0 / sigma_g**2
    P = N.sum(axis=1) if prior_weights is None else np.asarray(prior_weights, dtype=np.float64)
    gains = np.ones((V, I.shape[2]))
    active = P > 0
    if not active.any():
        return gains
    idx = np.flatnonzero(active)
    Na = N[np.ix_(idx, idx)]
    for c in range(I.shape[2]):
        Iij = I[np.ix_(idx, idx)][:, :, c]  # mean of i over overlap with j
        Iji = Iij.T  # mean of j over overlap with i
        A = -2.0 * alpha * Na * Iij * Iji
        A[np.diag_indices_from(A)] = 2.0 * alpha * (Na * Iij**2).sum(axis=1) + beta * P[idx]
        b = beta * P[idx]
        gains[idx, c] = np.linalg.solve(A, b)
    return gains


def gain_compensation(
    ctx,
    *,
    sigma_n: float = 10.0 / 255.0,
    sigma_g: float = 0.1,
    lut_size: int = LUT_SIZE,
) -> list:
    """Table 1 #5: Brown & Lowe (2007) global gain compensation, per channel.

    Parameters
    ----------
    ctx : o3d_seqcc.correction.CorrectionContext
    sigma_n : float, default 10/255
        Intensity-error standard deviation on [0, 1] colours.
    sigma_g : float, default 0.1
        Gain prior standard deviation.
    lut_size : int, default 4096

    Returns
    -------
    list of Transform
        One per view: ``LutTransform`` of ``x * g_i / g_ref`` (clipped), identity for the
        reference and for views outside the reference's component.
    """
    V = int(ctx.mappings.n_views)
    ref = int(ctx.reference)
    pairs, comp = _component_pairs(ctx)
    if not pairs:
        logger.warning("gain-compensation: no pair with >= %d mappings; all views unchanged", ctx.t_npm)
        return [IdentityTransform() for _ in range(V)]
    I = np.zeros((V, V, 3))
    N = np.zeros((V, V))
    for a, b in pairs:
        ca, cb = ctx.colors(a, b)
        I[a, b] = ca.mean(axis=0)
        I[b, a] = cb.mean(axis=0)
        N[a, b] = N[b, a] = len(ca)
    gains = gain_compensation_gains(I, N, sigma_n=sigma_n, sigma_g=sigma_g)
    gref = gains[ref]
    if np.any(gref <= 0):
        raise InputError(f"gain-compensation: reference view {ref} got a non-positive gain {gref}; its images are black?")
    gains = gains / gref
    out = []
    for v in range(V):
        if v == ref or v not in comp:
            out.append(IdentityTransform())
        else:
            out.append(LutTransform(affine_lut(gains[v], size=lut_size)))
    logger.info("gain-compensation gains (ref %d): min %s max %s", ref, gains.min(0).round(3), gains.max(0).round(3))
    return out


# ----------------------------------------------------------------------------- histogram matching
def overlap_quantiles(ca: np.ndarray, cb: np.ndarray, quantiles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel quantiles of the two sides of an overlap.

    Parameters
    ----------
    ca, cb : (n, 3) float arrays
        Colours of the pair's mappings in view a and view b.
    quantiles : (Q,) float array in [0, 1]

    Returns
    -------
    (Q, 3), (Q, 3) float64
    """
    q = np.asarray(quantiles, dtype=np.float64)
    return np.quantile(ca, q, axis=0), np.quantile(cb, q, axis=0)


def histogram_matching_params(
    quantile_pairs: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    n_views: int,
    reference: int,
    *,
    gain_bounds: tuple[float, float] = (0.5, 2.0),
    offset_bounds: tuple[float, float] = (-0.5, 0.5),
    refine: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Moulon et al. (2013) L-infinity gain/offset estimation, one LP per channel.

    Parameters
    ----------
    quantile_pairs : dict (a, b) -> (Qa (Q, C), Qb (Q, C))
        Quantiles of each overlap in view a and in view b.
    n_views : int
    reference : int
        Fixed at gain 1, offset 0.
    gain_bounds, offset_bounds : (float, float)
        Bounds of the other views' gains and offsets (offsets in [0, 1] colour units).
    refine : bool, default True
        Second LP: keep gamma at its optimum (+0.1 %) and minimise the sum of |residuals|.

    Returns
    -------
    gains : (V, C) float64
    offsets : (V, C) float64
        Views that appear in no pair keep gain 1, offset 0.
    gamma : (C,) float64
        The optimal L-infinity residual per channel.
    """
    from scipy.optimize import linprog
    from scipy.sparse import coo_matrix, hstack, identity, vstack

    V = int(n_views)
    keys = sorted(quantile_pairs)
    if not keys:
        raise ValueError("histogram_matching_params: no pairs")
    C = np.asarray(quantile_pairs[keys[0]][0]).shape[1]
    gains = np.ones((V, C))
    offsets = np.zeros((V, C))
    gammas = np.zeros(C)
    # residual rows r_k = a_i Qi + b_i - a_j Qj - b_j, variables [a_0..a_V-1, b_0..b_V-1]
    rows_i, rows_j, qi_list, qj_list = [], [], [], []
    for a, b in keys:
        Qa, Qb = (np.asarray(x, dtype=np.float64) for x in quantile_pairs[(a, b)])
        rows_i.append(np.full(len(Qa), a))
        rows_j.append(np.full(len(Qa), b))
        qi_list.append(Qa)
        qj_list.append(Qb)
    ri = np.concatenate(rows_i)
    rj = np.concatenate(rows_j)
    Qi = np.concatenate(qi_list)
    Qj = np.concatenate(qj_list)
    K = len(ri)
    k = np.arange(K)
    bounds = [gain_bounds] * V + [offset_bounds] * V
    bounds[reference] = (1.0, 1.0)
    bounds[V + reference] = (0.0, 0.0)
    used = np.zeros(V, bool)
    used[ri] = used[rj] = True
    for v in np.flatnonzero(~used):  # unconstrained views: pin them, they stay unchanged
        bounds[v] = (1.0, 1.0)
        bounds[V + v] = (0.0, 0.0)
    for c in range(C):
        data = np.concatenate([Qi[:, c], np.ones(K), -Qj[:, c], -np.ones(K)])
        cols = np.concatenate([ri, V + ri, rj, V + rj])
        R = coo_matrix((data, (np.tile(k, 4), cols)), shape=(K, 2 * V)).tocsr()
        one = np.ones((K, 1))
        # stage 1: min gamma s.t. R x - gamma <= 0, -R x - gamma <= 0
        A = vstack([hstack([R, -one]), hstack([-R, -one])]).tocsr()
        cost = np.zeros(2 * V + 1)
        cost[-1] = 1.0
        res = linprog(cost, A_ub=A, b_ub=np.zeros(2 * K), bounds=bounds + [(0, None)], method="highs")
        if res.status != 0:
            raise InputError(f"histogram-matching: linear programme failed for channel {c}: {res.message}")
        gamma = float(res.x[-1])
        x = res.x[: 2 * V]
        if refine:
            # stage 2 (equality form, interior point: ~10x faster than the inequality form here):
            # min sum(u + v) s.t. R x - u + v = 0, 0 <= u, v <= gamma (1 + 1e-3) + 1e-9
            Ik = identity(K, format="csr")
            A2 = hstack([R, -Ik, Ik]).tocsr()
            cost2 = np.concatenate([np.zeros(2 * V), np.ones(2 * K)])
            tmax = gamma * (1.0 + 1e-3) + 1e-9
            res2 = linprog(
                cost2, A_eq=A2, b_eq=np.zeros(K), bounds=bounds + [(0, tmax)] * (2 * K), method="highs-ipm"
            )
            if res2.status == 0:
                x = res2.x[: 2 * V]
            else:  # pragma: no cover - stage 1 solution is feasible for stage 2
                logger.warning("histogram-matching: refinement LP failed (%s); keeping the L-inf solution", res2.message)
        gains[:, c] = x[:V]
        offsets[:, c] = x[V:]
        gammas[c] = gamma
    return gains, offsets, gammas


def histogram_matching(
    ctx,
    *,
    n_quantiles: int = 10,
    quantile_range: tuple[float, float] = (0.05, 0.95),
    gain_bounds: tuple[float, float] = (0.5, 2.0),
    offset_bounds: tuple[float, float] = (-0.5, 0.5),
    refine: bool = True,
    lut_size: int = LUT_SIZE,
) -> list:
    """Table 1 #6: Moulon et al. (2013) global gain + offset from overlap histogram quantiles.

    Parameters
    ----------
    ctx : o3d_seqcc.correction.CorrectionContext
    n_quantiles : int, default 10
        Quantiles per overlap and channel, evenly spaced over ``quantile_range``.
    quantile_range : (float, float), default (0.05, 0.95)
        Robust range (the extreme tails carry mismatched / saturated pixels).
    gain_bounds : (float, float), default (0.5, 2.0)
    offset_bounds : (float, float), default (-0.5, 0.5)
        Bounds for the non-reference views (offsets in [0, 1] colour units).
    refine : bool, default True
        Lexicographic L-inf then L1 (see the module docstring).
    lut_size : int, default 4096

    Returns
    -------
    list of Transform
        ``LutTransform`` of ``clip(a x + b)`` per view; identity for the reference and views
        outside its component.
    """
    V = int(ctx.mappings.n_views)
    ref = int(ctx.reference)
    lo, hi = quantile_range
    if not (0.0 <= lo < hi <= 1.0) or n_quantiles < 2:
        raise InputError(f"histogram-matching: need 0 <= lo < hi <= 1 and n_quantiles >= 2, got {quantile_range}, {n_quantiles}")
    qs = np.linspace(lo, hi, int(n_quantiles))
    pairs, comp = _component_pairs(ctx)
    if not pairs:
        logger.warning("histogram-matching: no pair with >= %d mappings; all views unchanged", ctx.t_npm)
        return [IdentityTransform() for _ in range(V)]
    qp = {}
    for a, b in pairs:
        ca, cb = ctx.colors(a, b)
        qp[(a, b)] = overlap_quantiles(ca, cb, qs)
    gains, offsets, gamma = histogram_matching_params(
        qp, V, ref, gain_bounds=gain_bounds, offset_bounds=offset_bounds, refine=refine
    )
    logger.info("histogram-matching: L-inf residual per channel %s", gamma.round(4))
    out = []
    for v in range(V):
        if v == ref or v not in comp:
            out.append(IdentityTransform())
        else:
            out.append(LutTransform(affine_lut(gains[v], offsets[v], size=lut_size)))
    return out

