"""Tests of o3d_seqcc.correction.methods.global_methods: Brown & Lowe gain compensation and Moulon et al. histogram matching."""

from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest

from o3d_seqcc.correction.methods.global_methods import (
    affine_lut,
    gain_compensation_gains,
    histogram_matching_params,
    overlap_quantiles,
)
from o3d_seqcc.mappings.compute import Mappings, PairMapping

GAINS = np.array([[1.0, 1.0, 1.0], [1.3, 1.1, 0.9], [0.8, 0.95, 1.15], [1.1, 0.7, 1.05]])
OFFSETS = np.array([[0.0, 0.0, 0.0], [0.05, -0.03, 0.02], [-0.04, 0.06, 0.0], [0.02, 0.01, -0.05]])


def _common_image(rng, h=48, w=64):
    """A smooth-ish random texture in [0.1, 0.6] (room for gains up to 1.6 without clipping)."""
    small = rng.uniform(0.1, 0.6, (h // 8, w // 8, 3))
    return np.clip(cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR), 0, 1)


def _identity_mappings(V: int, h: int, w: int, n_views_pairs=None) -> Mappings:
    yy, xx = np.mgrid[0:h, 0:w]
    uv = np.stack([xx.ravel(), yy.ravel()], axis=1).astype(np.float64)
    pairs = {}
    for a in range(V):
        for b in range(a + 1, V):
            if n_views_pairs is not None and (a, b) not in n_views_pairs:
                continue
            pairs[(a, b)] = PairMapping(a, b, uv, uv, np.arange(len(uv), dtype=np.int64))
    return Mappings(pairs=pairs, n_views=V)


# --------------------------------------------------------------------------- pure solvers
def test_affine_lut():
    lut = affine_lut(np.array([2.0, 1.0, 0.5]), np.array([0.0, 0.1, -0.1]), size=11)
    x = np.linspace(0, 1, 11)
    np.testing.assert_allclose(lut[0], np.clip(2 * x, 0, 1))
    np.testing.assert_allclose(lut[1], np.clip(x + 0.1, 0, 1))
    np.testing.assert_allclose(lut[2], np.clip(0.5 * x - 0.1, 0, 1))


def test_gain_compensation_gains_recovers_known_gains_with_weak_prior():
    rng = np.random.default_rng(0)
    base = _common_image(rng).reshape(-1, 3)
    V = len(GAINS)
    I = np.zeros((V, V, 3))
    N = np.zeros((V, V))
    for a in range(V):
        for b in range(a + 1, V):
            sel = rng.random(len(base)) < 0.5  # a different overlap per pair
            I[a, b] = (GAINS[a] * base[sel]).mean(0)
            I[b, a] = (GAINS[b] * base[sel]).mean(0)
            N[a, b] = N[b, a] = sel.sum()
    g = gain_compensation_gains(I, N, sigma_g=1e3)
    np.testing.assert_allclose(g / g[0], 1.0 / GAINS, rtol=1e-5)
    # the default prior (sigma_g = 0.1) shrinks the correction towards 1 but goes the right way
    g0 = gain_compensation_gains(I, N)
    r = g0 / g0[0] * GAINS  # 1 = perfect
    assert np.all(np.abs(r - 1) < np.abs(GAINS - 1) + 1e-12)


@pytest.mark.parametrize("compensator", ["channels", "gain"])
def test_gain_compensation_matches_opencv_on_the_same_overlaps(compensator):
    """Feed OpenCV's compensator images + masks on one canvas; feed ours the same overlaps.

    Every image sits at corner (0, 0) of the same canvas with its own rectangular mask, so
    OpenCV's overlap of i and j is ``mask_i & mask_j`` -- exactly the pixels we use as the
    pair's mappings. OpenCV weights the gain prior by ``sum_j N_ij`` including ``N_ii`` (the
    mask's own area), which ``prior_weights`` reproduces; with that the gains agree to 1e-6.
    ``GainCompensator`` uses one gain for the Euclidean norm of the RGB vector, so it is
    compared with our solver fed the per-pixel norms.
    """
    rng = np.random.default_rng(1)
    h, w = 48, 64
    base = _common_image(rng, h, w)
    V = len(GAINS)
    images = [np.clip(np.round(base * GAINS[v] * 255), 0, 255).astype(np.uint8) for v in range(V)]
    masks = []
    for v in range(V):  # overlapping rectangles, every pair intersects
        m = np.zeros((h, w), np.uint8)
        x0, y0 = rng.integers(0, 16), rng.integers(0, 12)
        m[y0 : y0 + 30 + rng.integers(0, 6), x0 : x0 + 40 + rng.integers(0, 8)] = 255
        masks.append(m)
    # ours, from the same overlaps (values 0-255 and sigma_n = 10 as OpenCV)
    if compensator == "channels":
        vals = [im.astype(np.float64) for im in images]
        cv = cv2.detail.ChannelsCompensator()
    else:
        vals = [np.linalg.norm(im.astype(np.float64), axis=2)[..., None] for im in images]
        cv = cv2.detail.GainCompensator()
    C = vals[0].shape[2]
    I = np.zeros((V, V, C))
    N = np.zeros((V, V))
    for a in range(V):
        for b in range(a + 1, V):
            inter = (masks[a] > 0) & (masks[b] > 0)
            assert inter.any()
            I[a, b] = vals[a][inter].mean(0)
            I[b, a] = vals[b][inter].mean(0)
            N[a, b] = N[b, a] = inter.sum()
    area = np.array([(m > 0).sum() for m in masks], float)
    ours = gain_compensation_gains(I, N, sigma_n=10.0, sigma_g=0.1, prior_weights=N.sum(1) + area)
    cv.feed([(0, 0)] * V, images, masks)
    theirs = np.array([np.asarray(g).ravel()[:C] for g in cv.getMatGains()])
    np.testing.assert_allclose(ours, theirs, rtol=1e-6)
    # the paper's prior weighting (without N_ii) differs from OpenCV's, but after normalising
    # to the reference (view 0) both agree within a few per cent
    paper = gain_compensation_gains(I, N, sigma_n=10.0, sigma_g=0.1)
    np.testing.assert_allclose(paper / paper[0], theirs / theirs[0], rtol=0.05)


def test_histogram_matching_params_recovers_gain_and_offset():
    rng = np.random.default_rng(2)
    base = _common_image(rng).reshape(-1, 3)
    V = len(GAINS)
    qs = np.linspace(0.05, 0.95, 10)
    qp = {}
    for a in range(V):
        for b in range(a + 1, V):
            sel = rng.random(len(base)) < 0.6
            ca = GAINS[a] * base[sel] + OFFSETS[a]
            cb = GAINS[b] * base[sel] + OFFSETS[b]
            qp[(a, b)] = overlap_quantiles(ca, cb, qs)
    gains, offsets, gamma = histogram_matching_params(qp, V, 0)
    # correction maps view v back to the reference: a_v (g_v x + o_v) + b_v = x
    np.testing.assert_allclose(gains, 1.0 / GAINS, rtol=1e-6)
    np.testing.assert_allclose(offsets, -OFFSETS / GAINS, atol=1e-6)
    np.testing.assert_allclose(gamma, 0.0, atol=1e-9)
    # another reference stays fixed, the others are expressed relative to it
    g2, o2, _ = histogram_matching_params(qp, V, 2)
    np.testing.assert_allclose(g2[2], 1.0)
    np.testing.assert_allclose(o2[2], 0.0)
    np.testing.assert_allclose(g2, GAINS[2] / GAINS, rtol=1e-6)


def test_histogram_matching_params_respects_gain_bounds():
    x = np.linspace(0.1, 0.3, 10)[:, None].repeat(3, 1)
    qp = {(0, 1): (x, 3.0 * x)}  # view 1 would need gain 1/3
    gains, offsets, gamma = histogram_matching_params(qp, 2, 0, gain_bounds=(0.5, 2.0), offset_bounds=(0.0, 0.0))
    np.testing.assert_allclose(gains[1], 0.5)
    assert np.all(gamma > 0)


# --------------------------------------------------------------------------- registered methods
@pytest.fixture
def gained_views():
    """Views = per-channel gain (+ offset) x a common image, identity mappings between all."""
    rng = np.random.default_rng(5)
    h, w = 40, 48
    base = _common_image(rng, h, w)
    return base, h, w


def _correct(images, mappings, method, reference=0, **kw):
    import o3d_seqcc.correction as correction

    return correction.correct(reference=reference, method=method, mappings=mappings, images=images, t_npm=10, **kw)


@pytest.mark.parametrize("method", ["gain-compensation", "histogram-matching"])
def test_methods_registered(method):
    import o3d_seqcc.correction as correction
    assert method in correction.METHODS


@pytest.mark.parametrize("reference", [0, 2])
def test_gain_compensation_method_recovers_gain(gained_views, reference):
    base, h, w = gained_views
    V = len(GAINS)
    images = [np.round(np.clip(base * GAINS[v], 0, 1) * 65535).astype(np.uint16) for v in range(V)]
    maps = _identity_mappings(V, h, w)
    res = _correct(images, maps, "gain-compensation", reference=reference, sigma_g=1e3)
    assert np.array_equal(res.images[reference], images[reference])  # reference unchanged
    target = base * GAINS[reference]
    for v in range(V):
        got = res.images[v].astype(np.float64) / 65535
        np.testing.assert_allclose(got, np.clip(target, 0, 1), atol=2e-3)


@pytest.mark.parametrize("reference", [0, 3])
def test_histogram_matching_method_recovers_gain_and_offset(gained_views, reference):
    base, h, w = gained_views
    V = len(GAINS)
    lin = [base * GAINS[v] + OFFSETS[v] for v in range(V)]
    assert all(0 <= x.min() and x.max() <= 1 for x in lin)
    images = [np.round(x * 65535).astype(np.uint16) for x in lin]
    maps = _identity_mappings(V, h, w)
    res = _correct(images, maps, "histogram-matching", reference=reference)
    assert np.array_equal(res.images[reference], images[reference])
    for v in range(V):
        got = res.images[v].astype(np.float64) / 65535
        np.testing.assert_allclose(got, lin[reference], atol=2e-3)


def test_views_outside_the_reference_component_stay_unchanged(gained_views):
    base, h, w = gained_views
    V = 4
    images = [np.round(np.clip(base * GAINS[v], 0, 1) * 255).astype(np.uint8) for v in range(V)]
    maps = _identity_mappings(V, h, w, n_views_pairs={(0, 1), (2, 3)})
    for method in ("gain-compensation", "histogram-matching"):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # "views stay unchanged"
                res = _correct(images, maps, method, reference=0)
        except ValueError:
            # correct() may refuse a graph with several components; the method itself must not
            continue
        assert np.array_equal(res.images[2], images[2]) and np.array_equal(res.images[3], images[3])
        assert not np.array_equal(res.images[1], images[1])
