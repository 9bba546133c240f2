"""The conforming bisection's region-local closure gives the whole-mesh algorithm's result, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_seqcc.geometry.meshops import weld_vertices
from o3d_seqcc.geometry.meshsplit import LENGTH_TIE, bisect


def _reference_bisect(X, f, marked, vertex_normals=None, welded=None):
    """The whole-mesh algorithm (every edge of the mesh ranked, the closure iterated over every face)."""
    X = np.asarray(X, dtype=np.float64)
    f = np.asarray(f, dtype=np.int64)
    F = len(f)
    mk = np.zeros(F, dtype=bool)
    mk[marked] = True
    w = weld_vertices(X) if welded is None else welded
    wf = w[f]
    a, b = wf, np.roll(wf, -1, axis=1)
    n = int(w.max()) + 1
    key = np.minimum(a, b) * n + np.maximum(a, b)
    _, first, eid = np.unique(key.reshape(-1), return_index=True, return_inverse=True)
    eid = eid.reshape(-1, 3)
    ef, ec = np.divmod(first, 3)
    p, q = f[ef, ec], f[ef, (ec + 1) % 3]
    length = np.linalg.norm(X[p] - X[q], axis=1)
    quantum = LENGTH_TIE * max(float(np.ptp(X, axis=0).max()), 1e-300)
    rank = np.empty(len(length), dtype=np.int64)
    rank[np.lexsort((np.arange(len(length)), np.rint(length / quantum)))] = np.arange(len(length))
    longest = np.argmax(rank[eid], axis=1)
    rows = np.arange(F)
    flat = (wf[:, 0] == wf[:, 1]) | (wf[:, 1] == wf[:, 2]) | (wf[:, 2] == wf[:, 0])
    mk &= ~flat
    split = np.zeros(len(length), dtype=bool)
    split[eid[mk, longest[mk]]] = True
    while True:
        has = split[eid].any(axis=1) & ~flat
        need = eid[has, longest[has]]
        if split[need].all():
            break
        split[need] = True
    new_id = np.full(len(length), -1, dtype=np.int64)
    se = np.flatnonzero(split)
    new_id[se] = len(X) + np.arange(len(se))
    mids = 0.5 * (X[p[se]] + X[q[se]])
    vn_out = None
    if vertex_normals is not None:
        vn = np.asarray(vertex_normals, dtype=np.float64)
        s = vn[p[se]] + vn[q[se]]
        nrm = np.linalg.norm(s, axis=1, keepdims=True)
        vn_out = np.concatenate([vn, np.where(nrm > 1e-12, s / np.maximum(nrm, 1e-300), vn[p[se]])])
    r = longest
    A, B, C = f[rows, r], f[rows, (r + 1) % 3], f[rows, (r + 2) % 3]
    e_bc, e_ca = eid[rows, (r + 1) % 3], eid[rows, (r + 2) % 3]
    m = new_id[eid[rows, r]]
    cut = split[eid[rows, r]] & ~flat
    mbc, mca = new_id[e_bc], new_id[e_ca]
    pattern = np.where(cut, 1 + split[e_bc].astype(np.int64) + 2 * split[e_ca].astype(np.int64), 0)
    parts_f, parts_p, parts_k = [f[pattern == 0]], [np.flatnonzero(pattern == 0)], [np.zeros((pattern == 0).sum(), int)]
    cases = {1: ((A, m, C), (m, B, C)), 2: ((A, m, C), (m, B, mbc), (m, mbc, C)),
             3: ((A, m, mca), (m, C, mca), (m, B, C)), 4: ((A, m, mca), (m, C, mca), (m, B, mbc), (m, mbc, C))}
    for code, kids in cases.items():
        sel = np.flatnonzero(pattern == code)
        for k, (x, y, z) in enumerate(kids):
            parts_f.append(np.stack([x[sel], y[sel], z[sel]], axis=1))
            parts_p.append(sel)
            parts_k.append(np.full(len(sel), k))
    nf, par, kid = np.concatenate(parts_f), np.concatenate(parts_p), np.concatenate(parts_k)
    order = np.lexsort((kid, par))
    return np.concatenate([X, mids]), nf[order], par[order], vn_out, np.stack([p[se], q[se]], axis=1)


def _terrain(rng, n: int, jitter: float):
    """An (n x n) grid of squares as triangles (diagonals in both directions), heights and positions jittered."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    X = np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1).astype(np.float64)
    X += jitter * rng.normal(size=X.shape)
    v = lambda a, b: a * (n + 1) + b  # noqa: E731
    a, b = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a, b = a.ravel(), b.ravel()
    flip = rng.random(a.size) < 0.5
    t1 = np.where(flip[:, None], np.stack([v(a, b), v(a + 1, b), v(a + 1, b + 1)], 1),
                  np.stack([v(a, b), v(a + 1, b), v(a, b + 1)], 1))
    t2 = np.where(flip[:, None], np.stack([v(a, b), v(a + 1, b + 1), v(a, b + 1)], 1),
                  np.stack([v(a + 1, b), v(a + 1, b + 1), v(a, b + 1)], 1))
    return X, np.concatenate([t1, t2])


def _unwelded(rng, X, f, noise: float):
    """Three vertices per face, each copy moved by ``noise`` (well below the welding tolerance)."""
    Xu = X[f.reshape(-1)] * (1.0 + noise * rng.normal(size=(f.size, 3)))
    return Xu, np.arange(f.size).reshape(-1, 3)


@pytest.mark.parametrize("rings", [0, 2])
@pytest.mark.parametrize("case", ["grid", "jittered", "unwelded", "degenerate"])
def test_bisect_equals_the_whole_mesh_algorithm_over_rounds(rng, monkeypatch, case, rings):
    """Rounds of random marks (few, so the region is local; many, so it is most of the mesh), ties in edge
    length (a regular grid), unwelded copies that differ in their last bits, zero-area faces: the same vertices,
    faces, parents, normals and midpoint ends as the whole-mesh algorithm; also with no rings around the marked
    faces, so that the closure leaves the first region and the region grows (counted)."""
    import o3d_seqcc.geometry.meshsplit as meshsplit

    monkeypatch.setattr(meshsplit, "_RINGS", rings)
    closes = []
    close = meshsplit._close
    monkeypatch.setattr(meshsplit, "_close", lambda *a: closes.append(1) or close(*a))
    X, f = _terrain(rng, 30, 0.0 if case == "grid" else 0.2)
    if case == "unwelded":
        X, f = _unwelded(rng, X, f, 1e-14)
    if case == "degenerate":
        f = np.concatenate([f, f[:40, [0, 0, 1]]])
    vn = rng.normal(size=X.shape)
    welded = weld_vertices(X)
    for frac in (0.002, 0.01, 0.3, 0.002, 0.05):
        marked = np.flatnonzero(rng.random(len(f)) < frac)
        got = bisect(X, f, marked, vertex_normals=vn, welded=welded)
        ref = _reference_bisect(X, f, marked, vertex_normals=vn, welded=welded)
        for a, b in zip((got.vertices, got.faces, got.parent, got.vertex_normals, got.edge_vertices), ref):
            np.testing.assert_array_equal(a, b)
            assert a.dtype == b.dtype
        X, f, vn = got.vertices, got.faces, got.vertex_normals
        welded = np.concatenate([welded, welded.max() + 1 + np.arange(got.n_new_vertices)])
    assert (len(closes) > 5) == (rings == 0)  # without rings the region had to grow


def test_longest_edge_by_face_equals_the_argmax_of_the_ranks(rng):
    """Lengths with many ties, faces with an edge twice, and NaN lengths: the per-face comparison picks what the
    argmax of the edges' (length, id) ranks picks."""
    from o3d_seqcc.geometry.meshsplit import _longest

    E = 500
    eid = rng.integers(0, E, size=(4000, 3))
    eid[:300, 1] = eid[:300, 0]
    for nan in (False, True):
        length = rng.integers(0, 6, size=E).astype(np.float64)
        if nan:
            length[rng.integers(0, E, 20)] = np.nan
        rank = np.empty(E, dtype=np.int64)
        rank[np.lexsort((np.arange(E), length))] = np.arange(E)
        np.testing.assert_array_equal(_longest(eid, length), np.argmax(rank[eid], axis=1))
