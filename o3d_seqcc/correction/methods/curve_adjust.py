"""One channel's robust Levenberg-Marquardt bundle adjustment of the joint curves (the solver of
:func:`~o3d_seqcc.correction.methods.joint_curves.refine_curves`), and the piecewise-linear curve helpers it shares.

:class:`ChannelProblem` holds one channel's data (the edges' quantile observations, the unknowns' layout, the
starting curves), :class:`Solver` the solver's settings; :func:`adjust_channel` solves it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

__all__ = ["ChannelProblem", "Solver", "adjust_channel", "continue_above_data", "highest_latent", "knot_index",
           "monotone"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class ChannelProblem:
    """One channel of the joint curve refinement, as :func:`~o3d_seqcc.correction.methods.joint_curves.refine_curves`
    lays it out.

    ``a``, ``b`` (E,): the views of each edge; ``ma``, ``mb`` (E, P): their quantile values; ``seen`` (2, E, P):
    which are not censored (:meth:`~o3d_seqcc.correction.methods.edge_summaries.EdgeObservations.observed`);
    ``keep_e`` (E,) the edges kept, ``base_w`` (E,) their weights; ``col`` (V,): each view's unknown block (-1:
    fixed), ``free`` (F,) the free views; ``phi`` (V, K): starting responses (the reference's the identity);
    ``start_luts`` (V, L): starting corrections, which place the latents; ``uk`` (K,) the knots, ``grid`` (L,) the
    lookup tables' values, ``D`` and ``reg_block`` the smoothing operator and its block (K, K), or each free
    view's (F, K, K) when their priors differ; ``channel`` 0-2.
    """

    a: np.ndarray
    b: np.ndarray
    ma: np.ndarray
    mb: np.ndarray
    seen: np.ndarray
    keep_e: np.ndarray
    base_w: np.ndarray
    col: np.ndarray
    free: np.ndarray
    phi: np.ndarray
    start_luts: np.ndarray
    uk: np.ndarray
    grid: np.ndarray
    D: np.ndarray
    reg_block: np.ndarray
    channel: int


@dataclass(frozen=True)
class Solver:
    """The solver's settings (:func:`~o3d_seqcc.correction.methods.joint_curves.refine_curves` documents each)."""

    smooth: float
    prior: np.ndarray  # (F,) each free view's pull toward its start
    anchor: np.ndarray  # (K,) the black anchor's weight per knot
    iterations: int
    plain_iterations: int
    edge_robust_c: float | None
    monotone_steps: bool


def knot_index(x: np.ndarray, knots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segment index and fraction of ``x`` (clipped to the knots' range) on piecewise-linear knots."""
    K = knots.size
    k0 = np.clip(np.searchsorted(knots, x, side="right") - 1, 0, K - 2)
    f = (np.clip(x, knots[0], knots[-1]) - knots[k0]) / (knots[k0 + 1] - knots[k0])
    return k0, f


def monotone(rows: np.ndarray) -> np.ndarray:
    """Each row made non-decreasing: the mean of its running maximum and its reverse running
    minimum (unchanged where already monotone; vectorised, unlike isotonic regression)."""
    return 0.5 * (np.maximum.accumulate(rows, axis=-1) + np.minimum.accumulate(rows[..., ::-1], axis=-1)[..., ::-1])


def highest_latent(u_rows: np.ndarray, r_col: np.ndarray, F: int) -> np.ndarray:
    """(F,) the highest latent (reference value) any row of each free view reached (-1 where none)."""
    out = np.full(F, -1.0)
    free_rows = r_col >= 0
    np.maximum.at(out, r_col[free_rows], u_rows[free_rows])
    return out


def continue_above_data(phi: np.ndarray, knots: np.ndarray, top: np.ndarray) -> np.ndarray:
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


def adjust_channel(problem: ChannelProblem, solver: Solver):
    """Levenberg-Marquardt bundle adjustment of one channel (see
    :func:`~o3d_seqcc.correction.methods.joint_curves.refine_curves`).

    ``seen``: the (E, P) masks of the quantiles of view a and of view b that are not censored
    (:meth:`EdgeObservations.observed`). ``phi`` (V, K): starting responses (the reference's the identity); ``start_luts`` (V, L):
    starting corrections, which place the latents. Returns ``(phi, edge rms residual (E,),
    edge weights (E,))`` or None when no edge has an uncensored observation.
    """
    from scipy.linalg import block_diag, cho_factor, cho_solve

    a, b, ma, mb, seen, keep_e = problem.a, problem.b, problem.ma, problem.mb, problem.seen, problem.keep_e
    base_w, col, free, phi, start_luts = problem.base_w, problem.col, problem.free, problem.phi, problem.start_luts
    uk, grid, D, reg_block, channel = problem.uk, problem.grid, problem.D, problem.reg_block, problem.channel
    smooth, prior, anchor, iterations = solver.smooth, solver.prior, solver.anchor, solver.iterations
    plain_iterations, edge_robust_c, monotone_steps = solver.plain_iterations, solver.edge_robust_c, solver.monotone_steps

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
    reg_full = block_diag(*reg_block) if reg_block.ndim == 3 else np.kron(np.eye(F), reg_block)
    one_prior = bool(np.all(prior == prior[0])) if F else True

    def prior_cost(d):  # one weight: the plain sum (the same sums as a scalar prior)
        return float(prior[0]) * np.sum(d * d) if one_prior else np.sum(prior[:, None] * d * d)
    ew = np.ones(E)

    def evaluate(phi_, u_):
        k0, fr = knot_index(np.take(u_, r_lat), uk)
        at = r_view * K + k0  # phi_[r_view, k0], phi_[r_view, k0 + 1] from the flat array
        p0, p1 = np.take(phi_, at), np.take(phi_, at + 1)
        return p0 * (1.0 - fr) + p1 * fr - r_meas, k0, fr, (p1 - p0) / (uk[k0 + 1] - uk[k0])

    def cost(r, phi_, w_):  # r: evaluate(phi_, u_)[0]
        d = phi_[free] - phi_start
        return float(
            np.sum(w_ * r * r) + smooth * np.sum((phi_[free] @ D.T) ** 2) + prior_cost(d)
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
        gp += (smooth * (phi[free] @ D.T) @ D + prior[:, None] * (phi[free] - phi_start) + anchor * phi[free]).reshape(-1)


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
                ph[free] = monotone(ph[free])
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
    phi[free] = monotone(continue_above_data(phi[free], uk, highest_latent(u[r_lat], r_col, F)))
    return phi, residual, ew

