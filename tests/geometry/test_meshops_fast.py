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
