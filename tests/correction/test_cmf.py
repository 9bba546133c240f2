"""Colour mapping functions: known gain / gamma recovery, guards, fallbacks, composition."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_seqcc.correction.cmf import CMF_METHODS, apply_lut, compose_luts, fit_cmf
from o3d_seqcc.errors import InputError
from o3d_seqcc.correction.jih import jih_samples, joint_histogram

GRID = np.linspace(0, 1, 256)
MID = (GRID > 0.05) & (GRID < 0.95)


def _observations(rng, f, n=20000, noise=0.01):
    """x: target values (8-bit quantised), y = f(x) + noise (8-bit quantised)."""
    x = np.round(rng.beta(2, 2, n) * 255) / 255
    y = np.round(np.clip(f(x) + rng.normal(0, noise, n), 0, 1) * 255) / 255
    return x, y


def _fit_from_jih(x, y, **kw):
    h = joint_histogram(x, y)[0]
    xs, ys, w = jih_samples(h)
    return fit_cmf(xs, ys, weights=w, **kw)


@pytest.mark.parametrize(
    "name,f",
    [
        ("gain 0.7", lambda v: 0.7 * v),
        ("gamma 1.4", lambda v: v**1.4),
        ("gamma 1/1.4", lambda v: v ** (1 / 1.4)),
        ("s-curve", lambda v: 0.5 + 0.5 * np.tanh(3 * (v - 0.5)) / np.tanh(1.5)),
    ],
)
def test_csvr_recovers_known_curves(rng, name, f):
    x, y = _observations(rng, f)
    lut = _fit_from_jih(x, y, method="csvr")
    err = np.abs(lut - f(GRID))[MID]
    assert err.max() < 0.015, name  # ~1.5 % of the range, noise sigma is 1 %
    assert err.mean() < 0.005, name
    assert np.all(np.diff(lut) >= 0)


def test_csvr_paper_switch_rule_runs_and_is_continuous(rng):
    x, y = _observations(rng, lambda v: v**1.4)
    lut = fit_cmf(x, y, method="csvr", switch="paper")
    assert np.all(np.isfinite(lut)) and np.all(np.diff(lut) >= 0)
    assert np.abs(np.diff(lut)).max() < 0.03
    # the paper's literal rule keeps the line wherever it crosses the curve: worse at the ends
    default = fit_cmf(x, y, method="csvr")
    truth = GRID**1.4
    assert np.abs(default - truth)[MID].max() <= np.abs(lut - truth)[MID].max() + 1e-9


def test_csvr_no_intersection_uses_rbf_on_support_and_shifted_line(rng):
    # data only on a narrow support, on a curve the line does not cross inside [lo, hi]
    x = np.round(rng.uniform(0.4, 0.6, 5000) * 255) / 255
    y = 0.1 + 0.5 * x
    # C=10: on 50 columns the default C=1 leaves the RBF a little loose (~0.03)
    lut = fit_cmf(x, y, method="csvr", switch="paper", C=10.0)
    inside = (GRID > 0.42) & (GRID < 0.58)
    assert np.abs(lut - (0.1 + 0.5 * GRID))[inside].max() < 0.01
    # outside the support: continuous, monotone, still a straight continuation (slope ~0.5)
    assert np.abs(np.diff(lut)).max() < 0.01
    assert lut[-1] - lut[int(0.7 * 255)] == pytest.approx(0.5 * (1 - 0.7 * 255 / 255), abs=0.03)


@pytest.mark.parametrize("method", ["linear", "polynomial", "isotonic", "csvr"])
def test_every_method_recovers_a_gain(rng, method):
    x, y = _observations(rng, lambda v: 0.7 * v, noise=0.005)
    lut = fit_cmf(x, y, method=method)
    assert np.abs(lut - 0.7 * GRID)[MID].max() < 0.02


def test_polynomial_recovers_cubic_exactly(rng):
    x = rng.random(3000)
    f = lambda v: 0.1 + 0.5 * v + 0.2 * v**2 + 0.15 * v**3  # noqa: E731
    lut = fit_cmf(x, f(x), method="polynomial", degree=3, guard=False, saturation=0, max_points=10**6)
    np.testing.assert_allclose(lut, f(GRID), atol=2e-3)


def test_sparse_data_guard(rng):
    # dense data on [0.1, 0.3] and [0.7, 0.9], nothing in between, a gain of 0.8
    x = np.concatenate([rng.uniform(0.1, 0.3, 3000), rng.uniform(0.7, 0.9, 3000)])
    y = 0.8 * x + rng.normal(0, 0.005, x.size)
    lut = fit_cmf(x, y, method="csvr", gamma=200)
    # a narrow RBF (gamma=200) sags back toward its intercept in the gap; the guard keeps the line
    assert np.abs(lut - 0.8 * GRID).max() < 0.03
    raw = fit_cmf(x, y, method="csvr", gamma=200, guard=False)
    assert np.abs(raw - 0.8 * GRID).max() > 2 * np.abs(lut - 0.8 * GRID).max()


def test_outliers_do_not_pull_the_curve(rng):
    x, y = _observations(rng, lambda v: 0.7 * v, noise=0.005)
    k = len(x) // 20  # 5 % wrong correspondences (occlusions)
    y = y.copy()
    y[:k] = rng.random(k)
    lut = fit_cmf(x, y, method="csvr")
    assert np.abs(lut - 0.7 * GRID)[MID].max() < 0.03


def test_fold_back_is_prevented(rng):
    x = rng.random(5000)
    y = 0.5 + 0.3 * np.sin(6 * x)  # not monotone
    for method in ("csvr", "polynomial"):
        lut = fit_cmf(x, y, method=method)
        assert np.all(np.diff(lut) >= -1e-12) and lut.min() >= 0 and lut.max() <= 1


def test_constant_target_gives_offset():
    x = np.full(500, 0.5)
    y = np.full(500, 0.6)
    lut = fit_cmf(x, y)
    assert apply_lut(lut, 0.5) == pytest.approx(0.6, abs=1e-9)
    np.testing.assert_allclose(np.diff(lut)[:100], 1 / 255)


def test_saturated_observations_are_dropped(rng):
    # the source clips at 1 for x > 0.7: y = min(1, x / 0.7)
    x, y = _observations(rng, lambda v: np.minimum(1.0, v / 0.7), noise=0.003)
    lut = fit_cmf(x, y)
    low = (GRID > 0.05) & (GRID < 0.6)
    assert np.abs(lut - GRID / 0.7)[low].max() < 0.02
    assert lut[-1] == pytest.approx(1.0)


@pytest.mark.parametrize("value", [0.0, 1.0])
def test_fully_saturated_or_too_few_gives_identity(value):
    lut = fit_cmf(np.full(1000, value), np.full(1000, 0.5))
    np.testing.assert_allclose(lut, GRID)
    lut = fit_cmf(np.array([0.2, 0.5]), np.array([0.3, 0.6]))
    np.testing.assert_allclose(lut, GRID)


def test_16bit_lut_length(rng):
    x, y = _observations(rng, lambda v: v**1.4)
    lut = fit_cmf(x, y, n_out=4096)
    assert lut.shape == (4096,)
    assert np.abs(lut - np.linspace(0, 1, 4096) ** 1.4)[200:3900].max() < 0.015


def test_errors():
    with pytest.raises(ValueError, match="csvr"):
        fit_cmf(np.zeros(3), np.zeros(3), method="nope")
    with pytest.raises(TypeError, match="bogus"):
        fit_cmf(np.zeros(3), np.zeros(3), method="csvr", bogus=1)
    with pytest.raises(InputError):
        fit_cmf(np.zeros(3), np.zeros(4))
    with pytest.raises(InputError):
        fit_cmf(np.array([np.nan, 0.1]), np.zeros(2))
    with pytest.raises(InputError):
        fit_cmf(np.zeros(2), np.zeros(2), weights=np.array([1.0, -1.0]))
    assert {"csvr", "linear", "polynomial", "isotonic"} <= set(CMF_METHODS)


def test_compose_equals_applying_one_by_one(rng):
    luts = [np.clip(np.linspace(0, 1, 256) ** g * a, 0, 1) for g, a in ((1.3, 0.9), (0.8, 1.1), (1.1, 1.0))]
    v = rng.random(1000)
    seq = v
    for lut in luts:
        seq = apply_lut(lut, seq)
    comp = compose_luts(luts, n_out=4096)
    np.testing.assert_allclose(apply_lut(comp, v), seq, atol=2e-4)
    np.testing.assert_allclose(compose_luts([], n_out=5), np.linspace(0, 1, 5))


def test_symmetric_fit_undoes_regression_dilution(rng):
    # noisy target values flatten the regression of y on x; the symmetric fit is not flattened
    t = rng.uniform(0.1, 0.9, 20000)
    x = np.clip(t + rng.normal(0, 0.05, t.size), 0, 1)
    y = np.clip(0.8 * t + 0.1 + rng.normal(0, 0.05, t.size), 0, 1)
    sel = (GRID > 0.2) & (GRID < 0.8)
    slope = lambda lut: np.polyfit(GRID[sel], lut[sel], 1)[0]  # noqa: E731
    fwd = slope(fit_cmf(x, y, method="linear", pairing="joint", contrast_guard=None))
    sym = slope(fit_cmf(x, y, method="linear", pairing="joint", contrast_guard=None, symmetric=True))
    assert fwd < 0.775  # attenuated by the reliability ratio var(t) / var(x) ~ 0.955
    assert sym == pytest.approx(0.8, abs=0.015) and abs(sym - 0.8) < abs(fwd - 0.8)


def test_unclamped_tables_compose_through_a_clipped_view():
    g = np.linspace(0, 1, 256)
    up = g * 1.5  # a view that would clip above 2/3, kept unclamped
    down = g / 1.5
    np.testing.assert_allclose(compose_luts([up, down], extrapolate=True), g, atol=1e-9)
    clipped = compose_luts([up, down])
    assert clipped[-1] == pytest.approx(1 / 1.5)
    x = np.linspace(0, 1, 50)
    y = 1.5 * x
    lut = fit_cmf(x[x < 0.6], y[x < 0.6], method="linear", clamp=False, min_count=5, saturation=0)
    assert lut[-1] == pytest.approx(1.5, abs=1e-6)


def _misregistered(rng, g, shift=(3, 2), n=30000):
    """Target x = I(p), source y = g(I(p + shift)): a textured photo seen through a known tone
    curve ``g`` with a few pixels of registration error (unrelated texture detail paired)."""
    import skimage.data

    img = 0.05 + 0.9 * skimage.data.astronaut()[..., 1].astype(np.float64) / 255.0  # unsaturated
    h, w = img.shape
    r = rng.integers(10, h - 10, n)
    c = rng.integers(10, w - 10, n)
    x = img[r, c]
    y = np.round(np.clip(g(img[r + shift[0], c + shift[1]]), 0, 1) * 255) / 255
    return x, y


@pytest.mark.parametrize(
    "name,g",
    [("gain 0.7 + 0.1", lambda v: 0.7 * v + 0.1), ("gamma 1.3", lambda v: v**1.3), ("gain 1.25", lambda v: 1.25 * v)],
)
def test_misregistered_correspondences_are_not_attenuated(rng, name, g):
    from o3d_seqcc.correction.cmf import contrast_ratio

    x, y = _misregistered(rng, g)
    sel = (GRID > 0.15) & (GRID < 0.75)
    slope = lambda lut: np.polyfit(GRID[sel], lut[sel], 1)[0]  # noqa: E731
    true = slope(np.clip(g(GRID), 0, 1))
    lut = fit_cmf(x, y)  # default: quantile pairing, contrast guard
    assert slope(lut) == pytest.approx(true, rel=0.05), name
    assert contrast_ratio(lut, x, y) == pytest.approx(1.0, abs=0.05)
    # the paper's literal joint regression without the guard is flattened (regression dilution)
    raw = fit_cmf(x, y, pairing="joint", contrast_guard=None)
    assert slope(raw) < 0.9 * true and contrast_ratio(raw, x, y) < 0.93
    # the contrast guard alone restores the spread of the joint fit
    guarded = fit_cmf(x, y, pairing="joint")
    ok = (y > 0.01) & (y < 0.99) & (x > 0.01) & (x < 0.99)  # the guard measures unsaturated observations
    assert contrast_ratio(guarded, x[ok], y[ok]) >= 0.95 - 0.01
    assert abs(slope(guarded) - true) < abs(slope(raw) - true)


def test_quantile_pairing_is_exact_on_clean_data_and_symmetric(rng):
    x, y = _observations(rng, lambda v: v**1.4, noise=0.0)
    fwd = fit_cmf(x, y)
    assert np.abs(fwd - GRID**1.4)[MID].max() < 0.01
    back = fit_cmf(y, x)  # swapping the views gives the inverse function
    assert np.abs(apply_lut(back, fwd) - GRID)[MID].max() < 0.02


def test_quantile_samples_and_pairing_option(rng):
    from o3d_seqcc.correction.cmf import quantile_samples

    x = rng.random(1000)
    xq, yq, wq = quantile_samples(x, 2 * x, np.ones_like(x), n=50)
    np.testing.assert_allclose(yq, 2 * xq, atol=1e-9)
    assert wq.sum() == pytest.approx(1000)
    with pytest.raises(ValueError, match="pairing"):
        fit_cmf(x, x, pairing="nope")


def test_correlation_ratio(rng):
    from o3d_seqcc.correction.cmf import correlation_ratio

    x = rng.random(20000)
    clean = x**1.6
    noisy = np.clip(clean + rng.normal(0, 0.3, x.size), 0, 1)
    assert correlation_ratio(x, clean, np.ones_like(x)) > 0.98
    assert correlation_ratio(x, noisy, np.ones_like(x)) < 0.6


def test_contrast_guard_rescales_a_compressing_fit(rng):
    from o3d_seqcc.correction.cmf import contrast_ratio

    # noise in the target values only: the joint regression is flattened
    t = rng.uniform(0.1, 0.9, 20000)
    x = np.clip(t + rng.normal(0, 0.12, t.size), 0, 1)
    y = np.clip(0.9 * t + 0.05, 0, 1)
    flat = fit_cmf(x, y, pairing="joint", contrast_guard=None, saturation=0)
    guarded = fit_cmf(x, y, pairing="joint", saturation=0)
    assert contrast_ratio(flat, x, y) < 0.9
    assert contrast_ratio(guarded, x, y) == pytest.approx(1.0, abs=0.03)
    assert np.all(np.diff(guarded) >= 0) and guarded.min() >= 0 and guarded.max() <= 1


def test_black_point_keeps_shadows_neutral_without_dark_observations(rng):
    """No observation below 0.25: the dark end runs to (0, 0) instead of the fitted line's
    extrapolation, which for a steep curve would crush the shadows to 0 well before black."""
    x = rng.uniform(0.25, 0.95, 4000)
    y = np.clip(1.3 * x - 0.12, 0, 1)  # steep near the data's dark end: the line hits 0 at x ~ 0.09
    lut = fit_cmf(x, y)
    grid = np.linspace(0, 1, lut.size)
    assert lut[0] == pytest.approx(0.0, abs=1e-9)
    dark = (grid > 0.05) & (grid < 0.2)
    assert (lut[dark] > 0.02).all()  # not crushed
    assert np.all(np.diff(lut) >= -1e-12)
    # inside the data the fit is untouched by the anchor
    inside = (grid > 0.35) & (grid < 0.9)
    np.testing.assert_allclose(lut[inside], np.clip(1.3 * grid[inside] - 0.12, 0, 1), atol=0.02)
    free = fit_cmf(x, y, black_point=False)
    assert (free[dark] < lut[dark]).any()
