"""Joint image histograms and their weighted samples."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_seqcc.errors import InputError
from o3d_seqcc.correction.jih import column_samples, jih_samples, joint_histogram, weighted_samples


def test_counts_known_answer():
    t = np.array([[0, 10, 255], [0, 10, 255], [1, 10, 0]], dtype=np.uint8)
    s = np.array([[5, 10, 255], [5, 11, 255], [5, 10, 0]], dtype=np.uint8)
    h = joint_histogram(t, s, bits=8)
    assert h.shape == (3, 256, 256) and h.dtype == np.int64
    assert h[0, 0, 5] == 2 and h[0, 1, 5] == 1 and h[0].sum() == 3
    assert h[1, 10, 10] == 2 and h[1, 10, 11] == 1
    assert h[2, 255, 255] == 2 and h[2, 0, 0] == 1


def test_float_input_quantised_like_integers(rng):
    t = rng.integers(0, 256, (1000, 3))
    s = rng.integers(0, 256, (1000, 3))
    h_int = joint_histogram(t, s)
    h_float = joint_histogram(t / 255.0, s / 255.0)
    np.testing.assert_array_equal(h_int, h_float)
    assert joint_histogram(t // 4, s // 4, bits=6).shape == (3, 64, 64)


def test_bad_input():
    with pytest.raises(InputError):
        joint_histogram(np.zeros((5, 3)), np.zeros((4, 3)))
    with pytest.raises(InputError):
        joint_histogram(np.full((5, 3), 300), np.zeros((5, 3), int))
    with pytest.raises(InputError):
        joint_histogram(np.full((5, 3), np.nan), np.zeros((5, 3)))


def test_samples_conserve_counts_and_centroids(rng):
    x = rng.random(5000)
    y = np.clip(0.8 * x + 0.05 + rng.normal(0, 0.01, x.size), 0, 1)
    h = joint_histogram(x, y)[0]
    xs, ys, w = jih_samples(h)
    assert w.sum() == 5000 and np.all(w > 0)
    xs2, ys2, w2 = jih_samples(h, max_points=100)
    assert len(w2) <= 100 and w2.sum() == 5000
    # centroids keep the weighted means exactly
    assert np.average(xs2, weights=w2) == pytest.approx(np.average(xs, weights=w))
    assert np.average(ys2, weights=w2) == pytest.approx(np.average(ys, weights=w))
    # and the relation y = 0.8 x + 0.05 survives the merging
    a, b = np.polyfit(xs2, ys2, 1, w=np.sqrt(w2))
    assert a == pytest.approx(0.8, abs=0.01) and b == pytest.approx(0.05, abs=0.01)


def test_weighted_samples_drop_zero_weights():
    xs, ys, w = weighted_samples(np.array([0.1, 0.1, 0.9]), np.array([0.2, 0.2, 0.5]), np.array([1.0, 2.0, 0.0]))
    assert len(w) == 1 and w[0] == 3.0 and xs[0] == pytest.approx(0.1) and ys[0] == pytest.approx(0.2)


def test_column_samples_are_column_means(rng):
    x = np.round(rng.random(20000) * 255) / 255
    y = np.clip(0.6 * x + 0.1 + rng.normal(0, 0.02, x.size), 0, 1)
    xs, ys, w = column_samples(x, y)
    assert len(xs) <= 256 and w.sum() == pytest.approx(x.size)
    # each sample is the mean of its column (columns hold one 8-bit level here)
    for k in (10, 100, 200):
        sel = np.isclose(x, xs[k])
        assert ys[k] == pytest.approx(y[sel].mean()) and w[k] == sel.sum()
    # robust variant: wrong correspondences are dropped per column
    y2 = y.copy()
    y2[:2000] = 0.99
    xs2, ys2, _ = column_samples(x, y2, clip_k=3.0)
    assert np.abs(ys2 - (0.6 * xs2 + 0.1)).max() < 0.02
    xs3, ys3, _ = column_samples(x, y2)
    assert np.abs(ys3 - (0.6 * xs3 + 0.1)).max() > 0.03
