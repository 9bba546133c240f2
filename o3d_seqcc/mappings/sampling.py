"""Where a pair's mappings lie on its faces and where they project, for many pairs at once.

A pair's mappings are, face after face, the points of a barycentric pattern (:func:`bary_table`: per
subdivision level, the face's 3 vertices and the centroids of its ``L^2`` sub-triangles); the faces are
grouped by level, ascending within a level. :func:`locate` finds the face and pattern point of picked
mappings from the faces and levels alone (each level's faces are consecutive and hold the same number of
mappings), and :func:`project_points` computes their pixel positions, perspective-correctly, for the
picked mappings of many pairs in one vectorised pass (each face's corners projected once per pair and
view). :class:`~o3d_seqcc.mappings.pairs.PairSource` builds pairs with them.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

__all__ = ["SURFACE_MAX_LEVEL", "bary_table", "centroids", "level_dtype", "locate", "project_points", "tri_area"]

#: surface mode: cap on a face's subdivision level (at most ``SURFACE_MAX_LEVEL**2`` samples per face and pair)
SURFACE_MAX_LEVEL = 64


def centroids(L: int) -> np.ndarray:
    """(L^2, 3) float64 barycentric centroids of the L^2 sub-triangles of a level-L subdivision."""
    i, j = np.meshgrid(np.arange(L), np.arange(L), indexing="ij")
    up = (i + j) <= L - 1
    down = (i + j) <= L - 2
    b1 = np.concatenate([i[up] + 1 / 3, i[down] + 2 / 3]) / L
    b2 = np.concatenate([j[up] + 1 / 3, j[down] + 2 / 3]) / L
    return np.stack([1.0 - b1 - b2, b1, b2], axis=1)


def bary_table(max_level: int, *, vertices: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dense sampling patterns for levels 1..max_level, concatenated.

    Level L has the 3 vertices (first, in face order, as in ``"vertices"`` mode; not with
    ``vertices=False``) followed by the centroids of the L^2 sub-triangles of the level-L
    subdivision of the face (strictly inside the face, so no two faces share a dense sample):
    3 + L^2 points. Returns (table (T, 3) float64 barycentric weights, start (max_level+1,),
    count (max_level+1,)).
    """
    rows = []
    start = np.zeros(max_level + 1, dtype=np.int64)
    count = np.zeros(max_level + 1, dtype=np.int64)
    off = 0
    for L in range(1, max_level + 1):
        w = np.concatenate([np.eye(3), centroids(L)]) if vertices else centroids(L)
        start[L] = off
        count[L] = len(w)
        rows.append(w)
        off += len(w)
    return np.concatenate(rows), start, count


def tri_area(uv: np.ndarray) -> np.ndarray:
    """(m,) float64 areas in px^2 of (m, 3, 2) projected triangles."""
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    return 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def level_dtype(top: int) -> np.dtype:
    """The smallest signed integer dtype holding the levels 0..top and the sentinel -1 (radix-sorted by numpy)."""
    for dt in (np.int8, np.int16, np.int32):
        if top <= np.iinfo(dt).max:
            return np.dtype(dt)
    return np.dtype(np.int64)




def locate(k: np.ndarray, lev: np.ndarray, count: np.ndarray, pick: Callable, *,
           sort: bool = True) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """A pair's number of mappings and where its picked ones are.

    Parameters
    ----------
    k : (m,) int64
        The pair's faces, ascending.
    lev : (m,) small non-negative int
        Their levels (a pair's mappings: the faces by ascending level, ascending within a level).
    count : (levels,) int64
        Mappings per face of each level.
    pick : callable
        ``pick(n)``: the ascending indices of the mappings wanted out of ``n``, or None for all.
    sort : bool, default True
        False when all levels are equal (vertex mode): the faces are then in ``k``'s order.

    Returns
    -------
    n : int
    face, level, point : (s,) int64
        Face, level and point of the level's pattern of every picked mapping (without per-face offsets:
        the faces of one level are consecutive and hold ``count[level]`` mappings each).
    """
    per_level = np.bincount(lev, minlength=len(count))  # faces per level
    start = np.concatenate([[0], np.cumsum(per_level * count)])  # first mapping of each level
    n = int(start[-1])
    idx = pick(n)
    idx = np.arange(n) if idx is None else np.asarray(idx, np.int64).reshape(-1)
    L = np.searchsorted(start, idx, side="right") - 1
    rank, point = np.divmod(idx - start[L], count[L])  # the rank-th face of level L, its point-th mapping
    at = np.concatenate([[0], np.cumsum(per_level)])[L] + rank  # its place among the faces sorted by level
    face = k[np.argsort(lev, kind="stable")[at]] if sort else k[at]
    return n, face, L, point


def project_points(project: Callable, faces: np.ndarray, views: np.ndarray, bounds: np.ndarray, face: np.ndarray,
                   weights: list[np.ndarray]) -> np.ndarray:
    """Pixel positions of points on faces, perspective-correctly, for several runs of points at once.

    Parameters
    ----------
    project : callable
        ``project(v, vertex_ids) -> (uv (n, 2) float32, z (n,) float32)``: vertices' pixel coordinates
        and depths in view ``v`` (:meth:`o3d_seqcc.visibility.Visibility.vertex_projection`).
    faces : (F, 3) int
        The mesh's faces.
    views : (P,) int
        The view of each run (a pair's points in one of its views).
    bounds : (P + 1,) int
        Run ``p``'s points are ``bounds[p]:bounds[p + 1]``.
    face : (M,) int
        Face of every point (a face's points consecutive within a run: its corners projected once).
    weights : three (M,) float64
        Barycentric weights of every point.

    Returns
    -------
    (M, 2) float64
        The projection of ``sum_i w_i X_i``, ``sum_i w_i z_i uv_i / sum_i w_i z_i``, every sum from 0 in the
        order i = 0, 1, 2 (the float64 values of the float32 projections), so a point's position does not
        depend on the others computed with it. One ``project`` call per view.
    """
    if len(face) == 0:
        return np.zeros((0, 2))
    size = np.diff(bounds)
    new = np.ones(len(face), dtype=bool)  # a face's first point in its run
    new[1:] = face[1:] != face[:-1]
    new[bounds[:-1][size > 0]] = True
    first = np.flatnonzero(new)
    inv = np.cumsum(new) - 1
    # the faces grouped by the view they are projected in (a slice each), then gathered per point
    view_u = np.repeat(np.asarray(views, np.int64), size)[first]
    order = np.argsort(view_u, kind="stable")
    cut = np.flatnonzero(np.diff(view_u[order])) + 1
    block = np.empty((9, len(first)))  # per face (in run order) and corner j: z_j u_j, z_j v_j, z_j
    for s0, s1 in zip(np.concatenate([[0], cut]), np.concatenate([cut, [len(order)]])):
        rows = order[s0:s1] if len(cut) else slice(None)  # one view: every face, in order
        uv, z = project(int(view_u[order[s0]]), faces[face[first[rows]]].reshape(-1))
        uv, z = uv.reshape(-1, 3, 2), z.reshape(-1, 3).astype(np.float64)
        for j in range(3):
            block[3 * j, rows] = uv[:, j, 0] * z[:, j]
            block[3 * j + 1, rows] = uv[:, j, 1] * z[:, j]
            block[3 * j + 2, rows] = z[:, j]
    g = block if len(first) == len(face) else np.take(block, inv, axis=1)  # (9, M): per point
    sums = np.empty((3, len(face)))  # sum(w z u), sum(w z v), sum(w z)
    for c in range(3):
        np.multiply(weights[0], g[c], out=sums[c])
        sums[c] += 0.0  # as 0 + w_0 ...: the same signed zeros
        sums[c] += weights[1] * g[3 + c]
        sums[c] += weights[2] * g[6 + c]
    out = np.empty((len(face), 2))
    np.divide(sums[0], sums[2], out=out[:, 0])
    np.divide(sums[1], sums[2], out=out[:, 1])
    return out
