"""The column-wise reductions of geometry.meshops give numpy's axis reductions bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_seqcc.geometry.meshops import bounds, corner_mean, face_normals, oriented_face_normals, row_norms


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a).view(np.uint64 if a.dtype == np.float64 else np.uint32)


def _awkward(rng, shape, dtype=np.float64):
    """Values across magnitudes, with signed zeros, infinities and NaN."""
    a = (rng.normal(size=shape) * 10.0 ** rng.uniform(-8, 8, size=shape)).astype(dtype)
    flat = a.reshape(-1)
    k = flat.size
    flat[rng.integers(0, k, k // 50)] = -0.0
    flat[rng.integers(0, k, k // 50)] = 0.0
    flat[rng.integers(0, k, k // 500)] = np.inf
    flat[rng.integers(0, k, k // 500)] = np.nan
    return a


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_fast_reductions_equal_numpy_bit_for_bit(rng, dtype):
    a = _awkward(rng, (50000, 3), dtype)
    lo, hi = bounds(a)
    np.testing.assert_array_equal(_bits(lo), _bits(a.min(axis=0)))
    np.testing.assert_array_equal(_bits(hi), _bits(a.max(axis=0)))
    fin = a[np.isfinite(a).all(axis=1)]
    np.testing.assert_array_equal(_bits(np.array(bounds(fin))), _bits(np.array((fin.min(axis=0), fin.max(axis=0)))))
    for d in (2, 3):
        b = _awkward(rng, (20000, 7, d), dtype)
        np.testing.assert_array_equal(_bits(row_norms(b)), _bits(np.linalg.norm(b, axis=-1)))
    t = _awkward(rng, (30000, 3, 3), dtype)
    np.testing.assert_array_equal(_bits(corner_mean(t)), _bits(t.mean(axis=1)))


def test_face_normals_keep_their_values(rng):
    """face_normals / oriented_face_normals against their former axis reductions (norm, sums, maxima)."""
    X = rng.normal(size=(3000, 3)) * 10.0 ** rng.uniform(-3, 6, size=(3000, 1))
    X[:10] = X[10]  # zero-area faces
    f = rng.integers(0, len(X), size=(8000, 3))
    vn = rng.normal(size=X.shape)
    tri = X[f]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    n = np.cross(e1, e2)
    norm = np.linalg.norm(n, axis=1)
    edge = np.sqrt(np.maximum.reduce([(e1 * e1).sum(1), (e2 * e2).sum(1), ((e2 - e1) ** 2).sum(1)]))
    deg = norm <= 1e-12 * edge * np.maximum(edge, np.abs(tri).max(axis=(1, 2)))
    ref = np.divide(n, norm[:, None], out=np.zeros_like(n), where=~deg[:, None])
    got, got_deg = face_normals(X, f, rel_tol=1e-12)
    np.testing.assert_array_equal(_bits(got), _bits(ref))
    np.testing.assert_array_equal(got_deg, deg)
    flip = np.einsum("ij,ij->i", ref, vn[f].sum(1)) < 0
    ref[flip] *= -1.0
    on, od, nf = oriented_face_normals(X, f, vn)
    np.testing.assert_array_equal(_bits(on), _bits(ref))
    assert nf == int(flip.sum()) > 0 and deg.any()


def _reference_edge_topology(f):
    """edge_topology as it was: corners by fancy indexing, a stable sort, np.unique of the sorted keys."""
    n_faces = len(f)
    c0 = np.tile(np.arange(3), n_faces)
    c1 = (c0 + 1) % 3
    fid = np.repeat(np.arange(n_faces), 3)
    a, b = f[fid, c0], f[fid, c1]
    ok = a != b
    fid, c0, c1, a, b = fid[ok], c0[ok], c1[ok], a[ok], b[ok]
    swap = a > b
    lo, hi = np.where(swap, b, a), np.where(swap, a, b)
    clo, chi = np.where(swap, c1, c0), np.where(swap, c0, c1)
    key = lo * (int(f.max()) + 1) + hi
    order = np.argsort(key, kind="stable")
    _, start, counts = np.unique(key[order], return_index=True, return_counts=True)
    two = counts == 2
    i0, i1 = order[start[two]], order[start[two] + 1]
    good = fid[i0] != fid[i1]
    i0, i1 = i0[good], i1[good]
    return (fid[i0], clo[i0], chi[i0], fid[i1], clo[i1], chi[i1], np.stack([lo[i0], hi[i0]], axis=1),
            int(np.count_nonzero(counts == 1)), int(np.count_nonzero(counts > 2)))


def test_edge_topology_equals_the_stable_sort_version(rng):
    """Random faces over few vertices (many shared, boundary and non-manifold edges, repeated and degenerate
    corners, a face twice): the same edges, faces and corners in the same order, the same counts."""
    from o3d_seqcc.geometry.meshops import edge_topology

    seen = np.zeros(3, dtype=int)
    for n_vertices in (30, 400, 3000):
        f = rng.integers(0, n_vertices, size=(3000, 3))
        f[:50, 1] = f[:50, 0]
        f[60:70] = f[70:80]
        t = edge_topology(f)
        got = (t.face_a, t.corner_a0, t.corner_a1, t.face_b, t.corner_b0, t.corner_b1, t.edges, t.n_boundary,
               t.n_nonmanifold)
        for a, b in zip(got, _reference_edge_topology(f)):
            np.testing.assert_array_equal(a, b)
        seen += (t.n_nonmanifold, t.n_boundary, len(t.face_a))
    assert (seen > 0).all()
