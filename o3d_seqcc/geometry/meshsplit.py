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
the children of a face take its place in the face list (``parent`` is non-decreasing). :func:`coarsen`
undoes bisections where all the parts qualify (the split faces' parts no photo sees).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .meshops import bounds, row_norms, weld_vertices

__all__ = ["LENGTH_TIE", "Bisection", "bisect", "coarsen"]

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


def _edges(wf: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Unique undirected edges of faces with welded corners ``wf`` (ids below ``n``).

    Returns
    -------
    eid : (F, 3) int64
        The edge (j, j+1) of every face corner j; edges numbered in the order of their keys.
    first : (E,) int64
        Every edge's first (face, corner), as ``3 * face + corner``, in the faces' order.
    perm, ptr : (3F,) int64, (E+1,) int64
        The corners of edge ``e`` are ``perm[ptr[e]:ptr[e+1]]`` (in no particular order).
    """
    a, b = wf, np.roll(wf, -1, axis=1)
    key = (np.minimum(a, b).astype(np.int64) * n + np.maximum(a, b).astype(np.int64)).reshape(-1)
    perm = np.argsort(key)
    sk = key[perm]
    new = np.ones(len(sk), dtype=bool)
    new[1:] = sk[1:] != sk[:-1]
    ptr = np.append(np.flatnonzero(new), len(sk))
    eid = np.empty(len(sk), dtype=np.int64)
    eid[perm] = np.cumsum(new) - 1
    first = np.minimum.reduceat(perm, ptr[:-1]) if len(perm) else perm  # the first corner of each edge
    return eid.reshape(-1, 3), first, perm, ptr


def _longest(eid: np.ndarray, length: np.ndarray) -> np.ndarray:
    """(F,) the local edge of every face that is largest by (length, edge id), the first on a tie (an edge twice).

    The per-face comparison of the three edges of what ``argmax(rank[eid])`` gives for the edges'
    ranks by (length, id); NaN lengths (rank last, then by id) are ranked through a sort.
    """
    if not np.isfinite(length).all():
        rank = np.empty(len(length), dtype=np.int64)
        rank[np.lexsort((np.arange(len(length)), length))] = np.arange(len(length))
        return np.argmax(rank[eid], axis=1)
    q = length[eid]
    best = np.zeros(len(eid), dtype=np.int64)
    bq, be = q[:, 0], eid[:, 0]
    for j in (1, 2):
        up = (q[:, j] > bq) | ((q[:, j] == bq) & (eid[:, j] > be))
        best[up] = j
        bq, be = np.where(up, q[:, j], bq), np.where(up, eid[:, j], be)
    return best


def _close(X: np.ndarray, f: np.ndarray, wf: np.ndarray, mk: np.ndarray, quantum: float, n: int) -> dict:
    """The longest-edge closure of the marked faces ``mk`` among the faces ``f`` (welded corners ``wf``).

    Exact for every face whose edges have all their faces among ``f`` (:func:`bisect`'s region):
    an edge's length is taken at its first (face, corner), its rank is (length in :data:`LENGTH_TIE`
    quanta, key), both as over the whole mesh. The closure follows the newly split edges to the
    faces around them (the faces of an edge from its corners), not every face at each step.
    """
    eid, first, perm, ptr = _edges(wf, n)
    ef, ec = np.divmod(first, 3)  # representative face and corner of every edge
    p, q = f[ef, ec], f[ef, (ec + 1) % 3]
    length = np.rint(row_norms(X[p] - X[q]) / quantum)  # in quanta: ties within LENGTH_TIE
    longest = _longest(eid, length)  # local edge j = corners (j, j+1)
    # faces with two welded corners equal have no area: never split (an edge of theirs may be split by a neighbour)
    flat = (wf[:, 0] == wf[:, 1]) | (wf[:, 1] == wf[:, 2]) | (wf[:, 2] == wf[:, 0])
    mk = mk & ~flat
    split = np.zeros(len(p), dtype=bool)
    front = eid[mk, longest[mk]]  # (repeats only repeat a little work)
    split[front] = True
    while len(front):  # closure: a face with a split edge splits its longest edge (terminates: edges only get added)
        cnt = ptr[front + 1] - ptr[front]
        at = np.repeat(ptr[front] - np.cumsum(cnt) + cnt, cnt) + np.arange(int(cnt.sum()))
        fc = perm[at] // 3  # the faces around the edges split last
        fc = fc[~flat[fc]]
        need = eid[fc, longest[fc]]
        front = need[~split[need]]
        split[front] = True
    has = split[eid].any(axis=1) & ~flat
    return {"eid": eid, "p": p, "q": q, "longest": longest, "flat": flat, "split": split, "involved": has | mk}


#: children of a face per pattern (1 + split edge BC + 2 * split edge CA; 0 = unsplit)
_N_KIDS = np.array([1, 2, 3, 3, 4], dtype=np.int64)


#: rings of faces added around the faces that need a whole-mesh neighbourhood (fewer regrowths of the region)
_RINGS = 2


def _region(wf: np.ndarray, touch: np.ndarray) -> np.ndarray:
    """Ascending ids of the faces with a welded corner in ``touch``."""
    return np.flatnonzero(touch[wf[:, 0]] | touch[wf[:, 1]] | touch[wf[:, 2]])


def _grow(wf: np.ndarray, touch: np.ndarray, faces: np.ndarray) -> None:
    """Add the corners of ``faces`` and of :data:`_RINGS` rings of faces around them to ``touch``."""
    touch[wf[faces]] = True
    for _ in range(_RINGS):
        touch[wf[_region(wf, touch)]] = True


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

    Notes
    -----
    The work follows the faces split, not the mesh: the closure runs on a *region*, the faces
    with a corner in a set ``T`` of welded vertices (first the corners of the marked faces and of
    their neighbours). A face whose corners are all in ``T`` has every face across its edges in the
    region, so its edges' lengths, ranks and first (face, corner) are those of the whole mesh; while
    the closure reaches a face that is not such (marked, or with a split edge), its corners join
    ``T`` and the region grows. The result is the whole mesh's closure (every face with a split
    edge is in the region, and the closure is closed there), at the cost of a few passes of
    elementwise work over the faces.
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
    # lengths equal to 1e-6 of the mesh's size are ties (broken by edge id): the same choices wherever the
    # mesh lies (1e7 m from the origin, float64 rounding makes equal edges differ by ~1e-9 m)
    lo, hi = bounds(X) if len(X) else (np.zeros(1), np.ones(1))
    quantum = LENGTH_TIE * max(float(np.max(hi - lo)), 1e-300)  # the largest extent (np.ptp)
    n = int(w.max()) + 1 if len(w) else 1
    wf = w[f]
    touch = np.zeros(n, dtype=bool)
    _grow(wf, touch, mk)  # the marked faces and rings around them: their edges' faces all in the region
    while True:
        reg = _region(wf, touch)
        c = _close(X, f[reg], wf[reg], mk[reg], quantum, n)
        loose = c["involved"] & ~touch[wf[reg]].all(axis=1)  # edges maybe not all in the region: grow it
        if not loose.any():
            break
        _grow(wf, touch, reg[loose])
    eid, split, flat, r = c["eid"], c["split"], c["flat"], c["longest"]
    new_id = np.full(len(split), -1, dtype=np.int64)
    se = np.flatnonzero(split)  # in the order of the edges' keys, as over the whole mesh
    new_id[se] = len(X) + np.arange(len(se))
    p, q = c["p"][se], c["q"][se]
    mids = 0.5 * (X[p] + X[q])
    vn_out = None
    if vertex_normals is not None:
        vn = np.asarray(vertex_normals, dtype=np.float64)
        s = vn[p] + vn[q]
        nrm = np.linalg.norm(s, axis=1, keepdims=True)
        s = np.where(nrm > 1e-12, s / np.maximum(nrm, 1e-300), vn[p])
        vn_out = np.concatenate([vn, s])
    # corners rotated so that the longest edge is A -> B and C is opposite
    fr = f[reg]
    rows = np.arange(len(reg))
    A, B, C = fr[rows, r], fr[rows, (r + 1) % 3], fr[rows, (r + 2) % 3]
    e_bc, e_ca = eid[rows, (r + 1) % 3], eid[rows, (r + 2) % 3]
    m = new_id[eid[rows, r]]
    cut = split[eid[rows, r]] & ~flat  # closure: a face with any split edge has its longest one split
    bc, ca = split[e_bc], split[e_ca]
    mbc, mca = new_id[e_bc], new_id[e_ca]
    pattern = np.where(cut, 1 + bc.astype(np.int64) + 2 * ca.astype(np.int64), 0)
    count = np.ones(F, dtype=np.int64)
    count[reg] = _N_KIDS[pattern]
    start = np.cumsum(count) - count  # the children of a face take its place, in the order below
    nf = np.repeat(f, count, axis=0)  # unsplit faces as they were
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
        at = start[reg[sel]]
        for k, (x, y, z) in enumerate(kids):
            nf[at + k] = np.stack([x[sel], y[sel], z[sel]], axis=1)
    return Bisection(vertices=np.concatenate([X, mids]), faces=nf, parent=np.repeat(np.arange(F, dtype=np.int64), count),
                     vertex_normals=vn_out, edge_vertices=np.stack([p, q], axis=1))


def coarsen(faces: np.ndarray, welded: np.ndarray, ends: np.ndarray,
            unseen: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undo the bisections whose every part is unseen (the reverse of :func:`bisect`).

    A vertex ``m`` made as the midpoint of edge ``(p, q)`` (``ends[m]``) is removed when every
    face around it is unseen and they pair up, per apex ``C``, as the two halves ``(A, m, C)`` and
    ``(m, B, C)`` of a face ``(A, B, C)`` with ``{A, B} = {p, q}`` (welded ids): on both sides of
    the edge at once, so the mesh stays conforming. The newest midpoints go first, repeatedly,
    until none qualifies. After the first pass only the midpoints whose faces changed (corners of
    a merged face) or that lost a face to a newer one are looked at again: the others' faces are as
    they were, so they still do not qualify.

    Parameters
    ----------
    faces : (F, 3) int64
    welded : (N,) int64
        Welded vertex ids.
    ends : (N, 2) int64
        The vertices whose midpoint each vertex is (``Bisection.edge_vertices`` of the
        bisections that made it), ``-1`` for a vertex that is no midpoint.
    unseen : (F,) bool
        The faces that may be merged.

    Returns
    -------
    faces : (F', 3) int64
        The unchanged faces in their order, each merged face where its first half was.
    origin : (F',) int64
        Index into ``faces`` of an unchanged face, -1 for a merged one.
    rep : (F',) int64
        One input face each output face is (part of), for its attributes (parent, normal).
    """
    w = np.asarray(welded)
    f0 = np.asarray(faces, dtype=np.int64)
    F0, cap = len(f0), 2 * len(f0) + 1  # a merge removes two faces and adds one: at most F0 merges
    pool = np.empty((cap, 3), dtype=np.int64)  # the faces, merged ones appended; dead ones stay, not alive
    pool[:F0] = f0
    origin = np.full(cap, -1, dtype=np.int64)
    origin[:F0] = np.arange(F0)
    rep = origin.copy()
    pos = origin.astype(np.float64)
    dark = np.zeros(cap, dtype=bool)
    dark[:F0] = unseen
    alive = np.zeros(cap, dtype=bool)
    alive[:F0] = True
    n = F0
    seen_v = np.zeros(len(w), dtype=bool)
    seen_v[f0[~dark[:F0]].reshape(-1)] = True
    is_mid = (ends[:, 0] >= 0) & ~seen_v  # a midpoint with a seen face never qualifies: its faces stay
    active = is_mid.copy()
    nm, span = len(w), int(w.max()) + 1
    while True:
        cur = pool[:n]
        fi, j = np.nonzero(active[cur] & alive[:n, None])
        if not len(fi):
            break
        flat = cur.reshape(-1)
        m = flat[3 * fi + j]
        o1, o2 = flat[3 * fi + (j + 1) % 3], flat[3 * fi + (j + 2) % 3]
        wp, wq = w[ends[m, 0]], w[ends[m, 1]]
        e1 = (w[o1] == wp) | (w[o1] == wq)
        e2 = (w[o2] == wp) | (w[o2] == wq)
        follow, precede = e1 & ~e2, e2 & ~e1  # (m, B, C) / (A, m, C)
        ok = dark[fi] & (follow ^ precede)
        apex = np.where(follow, o2, o1)
        end = np.where(follow, o1, o2)
        key = m * span + w[apex]
        uk, g = np.unique(key, return_inverse=True)
        n_pre = np.bincount(g, weights=precede & ok, minlength=len(uk))
        n_fol = np.bincount(g, weights=follow & ok, minlength=len(uk))
        n_all = np.bincount(g, minlength=len(uk))
        good_g = (n_pre == 1) & (n_fol == 1) & (n_all == 2)
        bad_m = np.bincount(m, weights=~good_g[g], minlength=nm) > 0
        n_groups = np.bincount(uk // span, minlength=nm)
        cand = ~bad_m & (n_groups >= 1) & (n_groups <= 2)
        cand_pair = cand[m]
        if not cand_pair.any():
            break
        owner = np.full(n, -1, dtype=np.int64)  # a face with two candidate midpoints: the newest takes it
        np.maximum.at(owner, fi[cand_pair], m[cand_pair])
        lost = np.bincount(m[cand_pair], weights=owner[fi[cand_pair]] != m[cand_pair], minlength=nm) > 0
        take = cand_pair & ~lost[m]
        if not take.any():
            break
        gi = g[take]
        order = np.argsort(gi, kind="stable")
        fi_t, gi_t = fi[take][order], gi[order]
        pre_t, end_t, apex_t = precede[take][order], end[take][order], apex[take][order]
        # two entries per group, sorted by group: the "precede" half gives A, the "follow" half B
        first = np.flatnonzero(np.r_[True, gi_t[1:] != gi_t[:-1]])
        a_idx = np.where(pre_t[first], first, first + 1)
        b_idx = np.where(pre_t[first], first + 1, first)
        h0, h1 = fi_t[a_idx], fi_t[b_idx]
        k = len(first)
        pool[n:n + k] = np.stack([end_t[a_idx], end_t[b_idx], apex_t[first]], axis=1)  # the merged faces
        rep[n:n + k] = rep[h0]
        pos[n:n + k] = np.minimum(pos[h0], pos[h1])
        dark[n:n + k] = True
        alive[n:n + k] = True
        alive[h0] = alive[h1] = False
        active = np.zeros(nm, dtype=bool)
        active[pool[n:n + k].reshape(-1)] = True
        active[m[cand_pair & ~take]] = True
        active &= is_mid
        n += k
    keep = np.flatnonzero(alive[:n])
    order = keep[np.argsort(pos[keep], kind="stable")]
    return pool[order], origin[order], rep[order]
