"""Conforming longest-edge bisection of marked faces (Rivara's refinement), vectorised.

:func:`bisect` splits every marked face at the midpoint of its longest edge. A face whose edge
is split must be split along it too, or the mesh gets a T-junction (a crack in any renderer):
the set of split edges is closed first, so that every face with a split edge also splits its
own longest edge (Rivara's longest-edge propagation path), and each face then becomes 2, 3 or
4 triangles by one of the four patterns of a longest-edge bisection followed by the bisection of
the halves at the other split edges. The result is conforming (every new vertex is a vertex of
all the faces around it), keeps the triangles' shapes (the angles of the children are bounded
by those of the parent, Rivara 1984) and lies exactly on the input surface (midpoints of
straight edges, the children of a planar triangle in its plane).

Edges are identified through welded vertex ids (:func:`~o3d_seqcc.geometry.meshops.weld_vertices`), so
an unwelded mesh (three vertices per face, as many exporters write) is split consistently
across its seams too; a midpoint is one new vertex shared by the faces on both sides. The
longest edge of a face is chosen by (length, edge id), the same order on both sides of an
edge (lengths within :data:`LENGTH_TIE` of the mesh's size are ties), so the refinement is
deterministic and does not depend on where the mesh lies. Unsplit faces keep their corners and their order;
the children of a face take its place in the face list (``parent`` is non-decreasing).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .meshops import weld_vertices

__all__ = ["LENGTH_TIE", "Bisection", "bisect"]

#: edge lengths within this fraction of the mesh's size count as equal (ties broken by edge id)
LENGTH_TIE = 1e-6


@dataclass(frozen=True, eq=False)
class Bisection:
    """The result of :func:`bisect`.

    Attributes
    ----------
    vertices : (N + k, 3) float64
        The input vertices, then one new vertex per split edge.
    faces : (F', 3) int64
        Every unsplit face as it was, the children of a split face in its place.
    parent : (F',) int64
        The input face of every face (non-decreasing).
    vertex_normals : (N + k, 3) float64 or None
        Interpolated unit normals (the normalised sum of the edge's end normals).
    edge_vertices : (k, 2) int64
        The input vertices whose midpoint each new vertex is.
    """

    vertices: np.ndarray
    faces: np.ndarray
    parent: np.ndarray
    vertex_normals: np.ndarray | None
    edge_vertices: np.ndarray

    @property
    def n_new_vertices(self) -> int:
        return int(len(self.edge_vertices))


def _edges(faces: np.ndarray, welded: np.ndarray):
    """Unique undirected edges of the faces (by welded ids): per face corner j the edge
    (j, j+1) -> (F, 3) edge ids, and per edge a representative (face, corner)."""
    wf = welded[faces]
    a, b = wf, np.roll(wf, -1, axis=1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    n = int(welded.max()) + 1 if len(welded) else 1
    key = lo.astype(np.int64) * n + hi.astype(np.int64)
    uniq, first, eid = np.unique(key.reshape(-1), return_index=True, return_inverse=True)
    return eid.reshape(-1, 3), first


def bisect(vertices: np.ndarray, faces: np.ndarray, marked: np.ndarray, *,
           vertex_normals: np.ndarray | None = None, welded: np.ndarray | None = None) -> Bisection:
    """Split the marked faces at their longest edges, and their neighbours where needed to stay conforming.

    Parameters
    ----------
    vertices : (N, 3) float64
    faces : (F, 3) int64
    marked : (F,) bool or int indices
        Faces to split (each at least once, at its longest edge).
    vertex_normals : (N, 3) float, optional
        Interpolated to the new vertices.
    welded : (N,) int64, optional
        Welded vertex ids (default :func:`~o3d_seqcc.geometry.meshops.weld_vertices`).

    Returns
    -------
    Bisection
        Does not modify the inputs.
    """
    X = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    F = len(f)
    mk = np.zeros(F, dtype=bool)
    mk[np.asarray(marked, dtype=np.int64) if np.asarray(marked).dtype != bool else np.asarray(marked)] = True
    if not mk.any():
        vn = None if vertex_normals is None else np.asarray(vertex_normals, dtype=np.float64)
        return Bisection(X, f.copy(), np.arange(F, dtype=np.int64), vn, np.zeros((0, 2), np.int64))
    w = weld_vertices(X) if welded is None else np.asarray(welded, dtype=np.int64)
    eid, first = _edges(f, w)
    ef, ec = np.divmod(first, 3)  # representative face and corner of every edge
    p, q = f[ef, ec], f[ef, (ec + 1) % 3]
    length = np.linalg.norm(X[p] - X[q], axis=1)
    # lengths equal to 1e-6 of the mesh's size are ties (broken by edge id): the same choices wherever the
    # mesh lies (1e7 m from the origin, float64 rounding makes equal edges differ by ~1e-9 m)
    quantum = LENGTH_TIE * max(float(np.ptp(X, axis=0).max()) if len(X) else 1.0, 1e-300)
    rank = np.empty(len(length), dtype=np.int64)
    rank[np.lexsort((np.arange(len(length)), np.rint(length / quantum)))] = np.arange(len(length))  # (length, id)
    longest = np.argmax(rank[eid], axis=1)  # local edge j = corners (j, j+1)
    rows = np.arange(F)
    # faces with two welded corners equal have no area: never split (an edge of theirs may be split by a neighbour)
    flat = (w[f][:, 0] == w[f][:, 1]) | (w[f][:, 1] == w[f][:, 2]) | (w[f][:, 2] == w[f][:, 0])
    mk &= ~flat
    split = np.zeros(len(length), dtype=bool)
    split[eid[mk, longest[mk]]] = True
    while True:  # closure: a face with a split edge splits its longest edge (terminates: edges only get added)
        has = split[eid].any(axis=1) & ~flat
        need = eid[has, longest[has]]
        new = ~split[need]
        if not new.any():
            break
        split[need[new]] = True
    new_id = np.full(len(length), -1, dtype=np.int64)
    se = np.flatnonzero(split)
    new_id[se] = len(X) + np.arange(len(se))
    mids = 0.5 * (X[p[se]] + X[q[se]])
    vn_out = None
    if vertex_normals is not None:
        vn = np.asarray(vertex_normals, dtype=np.float64)
        s = vn[p[se]] + vn[q[se]]
        nrm = np.linalg.norm(s, axis=1, keepdims=True)
        s = np.where(nrm > 1e-12, s / np.maximum(nrm, 1e-300), vn[p[se]])
        vn_out = np.concatenate([vn, s])
    # corners rotated so that the longest edge is A -> B and C is opposite
    r = longest
    A, B, C = f[rows, r], f[rows, (r + 1) % 3], f[rows, (r + 2) % 3]
    e_bc, e_ca = eid[rows, (r + 1) % 3], eid[rows, (r + 2) % 3]
    m = new_id[eid[rows, r]]
    cut = split[eid[rows, r]] & ~flat  # closure: a face with any split edge has its longest one split
    bc, ca = split[e_bc], split[e_ca]
    mbc, mca = new_id[e_bc], new_id[e_ca]
    pattern = np.where(cut, 1 + bc.astype(np.int64) + 2 * ca.astype(np.int64), 0)
    parts_f, parts_p, parts_k = [f[pattern == 0]], [np.flatnonzero(pattern == 0)], [np.zeros(int((pattern == 0).sum()),
                                                                                              np.int64)]
    cases = {  # pattern -> children as (corner arrays); windings follow the parent's (A, B, C)
        1: ((A, m, C), (m, B, C)),
        2: ((A, m, C), (m, B, mbc), (m, mbc, C)),
        3: ((A, m, mca), (m, C, mca), (m, B, C)),
        4: ((A, m, mca), (m, C, mca), (m, B, mbc), (m, mbc, C)),
    }
    for code, kids in cases.items():
        sel = np.flatnonzero(pattern == code)
        if not len(sel):
            continue
        for k, (x, y, z) in enumerate(kids):
            parts_f.append(np.stack([x[sel], y[sel], z[sel]], axis=1))
            parts_p.append(sel)
            parts_k.append(np.full(len(sel), k, dtype=np.int64))
    nf = np.concatenate(parts_f)
    par = np.concatenate(parts_p)
    kid = np.concatenate(parts_k)
    order = np.lexsort((kid, par))
    return Bisection(vertices=np.concatenate([X, mids]), faces=nf[order], parent=par[order], vertex_normals=vn_out,
                     edge_vertices=np.stack([p[se], q[se]], axis=1))
