"""Shared counts and areas (paper 3.1): per pair of views, how much of the surface both see.

Vertex and dense mode count mappings (:func:`shared_counts`: bit-packed AND + popcount over every
pair of rows, or a sparse product when each column is held by few rows); surface mode counts
pixels, the area of the surface both views see in the view where it is smaller
(:func:`shared_area`), which is the same on a 300-face and a 3M-face mesh of one scene. Both work
on per-view rows of ascending face ids; :meth:`~o3d_seqcc.mappings.pairs.PairSource.counts` calls
them with a visibility's usable faces.
"""

from __future__ import annotations

import logging

import numpy as np

__all__ = ["shared_area", "shared_counts"]

logger = logging.getLogger(__name__)


def _packed(rows: list[np.ndarray], n: int) -> np.ndarray:
    """(V, ceil(n / 64)) uint64 bit rows of the index lists ``rows`` over ``n`` columns."""
    words = (n + 63) // 64
    P = np.zeros((len(rows), words * 8), dtype=np.uint8)
    row = np.zeros(n, dtype=bool)
    for v, ids in enumerate(rows):
        row[:] = False
        row[ids] = True
        P[v, : (n + 7) // 8] = np.packbits(row)
    return P.view(np.uint64)


def shared_counts(rows: list[np.ndarray], n: int, weights: np.ndarray | None = None, *,
                  method: str = "auto") -> np.ndarray:
    """(V, V) int64: per pair of rows, the (weighted) number of columns both hold.

    Parameters
    ----------
    rows : list of (k_v,) int arrays
        Ascending column ids of every row (e.g. the faces usable in every view).
    n : int
        Number of columns.
    weights : (n,) int array, optional
        Integer weight per column (default 1).
    method : {"auto", "packed", "sparse"}, default "auto"

    Exact integers either way; the cheaper of two methods is used: bit-packed AND + popcount
    over every pair of rows (cost ~ V^2 n / 64) or the sparse product ``U diag(w) U^T`` (cost
    ~ the sum over columns of their row count squared, which stays linear in the views when each
    column is held by a bounded number of rows, as in a large site).
    """
    V = len(rows)
    if V == 0:
        return np.zeros((0, 0), dtype=np.int64)
    lengths = np.array([len(r) for r in rows], dtype=np.int64)
    indices = np.concatenate(rows).astype(np.int64) if lengths.sum() else np.zeros(0, np.int64)
    degree = np.bincount(indices, minlength=n)
    levels = np.unique(weights[indices]) if weights is not None and len(indices) else np.array([1])
    dense_cost = V * (V + 1) / 2 * ((n + 63) // 64) * len(levels)
    sparse_cost = 8.0 * float((degree.astype(np.float64) ** 2).sum())
    if method not in ("auto", "packed", "sparse"):
        raise ValueError(f"unknown method {method!r}; valid: 'auto', 'packed', 'sparse'")
    if method == "sparse" or (method == "auto" and sparse_cost < dense_cost):
        from scipy.sparse import csr_matrix

        indptr = np.concatenate([[0], np.cumsum(lengths)])
        w = np.ones(len(indices), np.int64) if weights is None else np.asarray(weights, np.int64)[indices]
        U = csr_matrix((w, indices, indptr), shape=(V, n))
        B = csr_matrix((np.ones(len(indices), np.int64), indices, indptr), shape=(V, n))
        return np.asarray((U @ B.T).toarray(), dtype=np.int64)
    C = np.zeros((V, V), dtype=np.int64)
    for L in levels:
        sub = rows if weights is None else [r[weights[r] == L] for r in rows]
        P = _packed(sub, n)
        part = np.zeros((V, V), dtype=np.int64)
        for a in range(V):
            part[a, a:] = np.bitwise_count(P[a] & P[a:]).sum(axis=1, dtype=np.int64)
        C += int(L) * (np.triu(part) + np.triu(part, 1).T)
    return C


def shared_area(rows: list[np.ndarray], areas: list[np.ndarray], n: int) -> np.ndarray:
    """(V, V) float64: ``M[a, b]`` = the summed ``areas[a]`` of the columns of row ``a`` that row ``b`` also holds.

    Parameters
    ----------
    rows : list of (k_v,) int arrays
        Ascending column ids of every row (the faces usable in every view).
    areas : list of (k_v,) float arrays
        A value per entry of ``rows`` (the faces' projected areas in px^2 in that view).
    n : int
        Number of columns.

    One sparse product ``A B^T`` (``A`` holds the areas, ``B`` ones): cost ~ the sum over
    columns of their row count squared, linear in the views when each face is seen by a bounded
    number of them. ``min(M, M.T)`` is the area of the surface two views share, in pixels of
    the view where it is smaller.
    """
    from scipy.sparse import csr_matrix

    V = len(rows)
    if V == 0:
        return np.zeros((0, 0), dtype=np.float64)
    lengths = np.array([len(r) for r in rows], dtype=np.int64)
    indptr = np.concatenate([[0], np.cumsum(lengths)])
    idx = np.concatenate(rows).astype(np.int64) if lengths.sum() else np.zeros(0, np.int64)
    val = np.concatenate(areas).astype(np.float64) if lengths.sum() else np.zeros(0)
    A = csr_matrix((val, idx, indptr), shape=(V, n))
    B = csr_matrix((np.ones(len(idx)), idx, indptr), shape=(V, n))
    return np.asarray((A @ B.T).toarray(), dtype=np.float64)
