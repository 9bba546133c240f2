"""The fallback colours' propagation (texturing/fallback.py): front by front, the same numbers as the whole-matrix
iteration it replaces, one pass over the edges."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from o3d_seqcc.texturing.fallback import FALLBACK_GREY, _propagate


def _whole_matrix(values, known, pairs, iters):
    """The definition: every step, every unknown row with a known neighbour takes their mean."""
    n = len(values)
    col, have = np.array(values, float), np.asarray(known, float)
    adj = sp.coo_matrix((np.ones(2 * len(pairs)), (np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]])),
                        shape=(n, n)).tocsr()
    for _ in range(iters):
        ssum, cnt = adj @ (col * have[:, None]), adj @ have
        upd = (have == 0) & (cnt > 0)
        if not upd.any():
            break
        col[upd] = ssum[upd] / cnt[upd, None]
        have[upd] = 1.0
    col[have == 0] = FALLBACK_GREY
    return col


def _grid_pairs(nx: int, ny: int) -> np.ndarray:
    idx = np.arange(nx * ny).reshape(ny, nx)
    return np.concatenate([np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1),
                           np.stack([idx[:-1, :].ravel(), idx[1:, :].ravel()], 1),
                           np.stack([idx[:-1, :-1].ravel(), idx[1:, 1:].ravel()], 1)])


def test_front_by_front_is_the_whole_matrix_iteration(rng):
    pairs = _grid_pairs(120, 80)  # a mesh-like graph: fronts need many steps to cross it
    n = 120 * 80
    known = np.zeros(n, bool)
    known[rng.choice(n, 12, replace=False)] = True
    values = np.where(known[:, None], rng.uniform(0, 255, (n, 3)), 0.0)
    for iters in (3, 40, 256):
        got = _propagate(values, known, pairs, iters=iters)
        np.testing.assert_array_equal(got, _whole_matrix(values, known, pairs, iters))
    short = _propagate(values, known, pairs, iters=3)
    assert (short == FALLBACK_GREY).all(axis=1).sum() > n / 2  # rows no front reached in 3 steps: grey
    assert not (_propagate(values, known, pairs, iters=256) == FALLBACK_GREY).all(axis=1).any()
