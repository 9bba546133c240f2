"""Semi-real ground truth (o3d_seqcc.evaluation.semireal) and the camera-like change sampler."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_seqcc.errors import InputError
from o3d_seqcc.evaluation.semireal import (
    apply_camera_change,
    coverage_masks,
    evaluate_semireal,
    linear_to_srgb,
    make_semireal,
    srgb_to_linear,
    view_errors,
)
from o3d_seqcc.evaluation.photometric import (
    CAMERA_CHANGE_RANGES,
    HARD_CHANGE_RANGES,
    identity_photometric,
    sample_camera_change,
)
from o3d_seqcc.synthetic import make_synthetic_scene


def test_srgb_transfer_round_trip_and_known_values():
    x = np.linspace(0, 1, 1001)
    np.testing.assert_allclose(linear_to_srgb(srgb_to_linear(x)), x, atol=1e-12)
    assert srgb_to_linear(np.array([0.5]))[0] == pytest.approx(0.21404, abs=1e-5)
    assert linear_to_srgb(np.array([0.0031308]))[0] == pytest.approx(0.0404500, abs=1e-6)


def test_apply_camera_change_in_linear_light(rng):
    img = rng.integers(0, 256, (8, 9, 3)).astype(np.uint8)
    np.testing.assert_array_equal(apply_camera_change(img, identity_photometric()), img)
    grey = np.full((1, 1, 3), 128, np.uint8)  # sRGB 0.502 -> linear 0.2158
    p = {"gain": 1.6, "white_balance": [1.0, 1.0, 1.0], "gamma": [1.0, 1.0, 1.0], "s_curve": 0.0}
    expected = np.rint(255 * linear_to_srgb(np.array([1.6 * srgb_to_linear(np.array([128 / 255]))[0]])))[0]
    assert apply_camera_change(grey, p)[0, 0, 0] == expected == 159
    out16 = apply_camera_change(img.astype(np.uint16) * 257, p)
    assert out16.dtype == np.uint16
    with pytest.raises(InputError, match="RGB"):
        apply_camera_change(img[..., 0], p)


def test_sample_camera_change_covers_its_ranges():
    rng = np.random.default_rng(0)
    draws = [sample_camera_change(rng, **HARD_CHANGE_RANGES) for _ in range(400)]
    gain = np.array([d["gain"] for d in draws])
    gamma = np.array([d["gamma"] for d in draws])
    s = np.array([d["s_curve"] for d in draws])
    wb = np.array([d["white_balance"] for d in draws])
    lo, hi = HARD_CHANGE_RANGES["exposure"]
    assert lo <= gain.min() < lo * 1.05 and hi / 1.05 < gain.max() <= hi  # uniform: reaches both ends
    assert HARD_CHANGE_RANGES["gamma"][0] <= gamma.min() and gamma.max() <= HARD_CHANGE_RANGES["gamma"][1]
    assert 0.0 <= s.min() and 0.55 < s.max() <= 0.6
    assert 0.8 <= wb.min() and wb.max() <= 1.2
    assert np.ptp(gamma, axis=1).mean() > 0.1  # channels drawn independently
    with pytest.raises(InputError, match="exposure"):
        sample_camera_change(rng, exposure=(1.5, 0.5))


def test_make_semireal_hides_a_change_and_keeps_the_reference(rng):
    images = [rng.integers(20, 230, (10, 12, 3)).astype(np.uint8) for _ in range(4)]
    before = [im.copy() for im in images]
    case = make_semireal(images, reference=2, seed=7)
    np.testing.assert_array_equal(case.images[2], images[2])
    assert all(not np.array_equal(case.images[v], images[v]) for v in (0, 1, 3))
    assert case.params[2] == identity_photometric()
    for a, b in zip(images, before):
        np.testing.assert_array_equal(a, b)  # inputs untouched
    again = make_semireal(images, reference=2, seed=7)
    np.testing.assert_array_equal(again.images[3], case.images[3])
    assert not np.array_equal(make_semireal(images, reference=2, seed=8).images[3], case.images[3])
    lo, hi = CAMERA_CHANGE_RANGES["exposure"]
    assert all(lo <= p["gain"] <= hi for p in case.params)
    with pytest.raises(InputError, match="reference"):
        make_semireal(images, reference=4)


def test_view_errors(rng):
    a = rng.integers(0, 256, (6, 8, 3)).astype(np.uint8)
    b = a.copy()
    b[:3] = np.clip(b[:3].astype(int) + 20, 0, 255).astype(np.uint8)
    m = np.ones((6, 8), bool)
    e = view_errors([a, a, b], [a, a, a], [m, m, m], skip=(0,))
    assert np.isnan(e[0]) and e[1] == 0.0 and e[2] > 1.0
    top = np.zeros((6, 8), bool)
    top[3:] = True
    assert view_errors([b], [a], [top])[0] == 0.0  # only the unchanged rows are scored
    assert view_errors([b], [a], [m], stride=2)[0] == pytest.approx(e[2], rel=0.5)
    with pytest.raises(InputError, match="match"):
        view_errors([a], [a], [m[:3]])
    with pytest.raises(InputError, match="stride"):
        view_errors([a], [a], [m], stride=0)


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    """A small synthetic room whose photos are mutually consistent (no photometric change)."""
    return make_synthetic_scene(
        tmp_path_factory.mktemp("semireal") / "s", n_views=5, width=128, height=96, seed=2, photometric="none", cell_size=0.12
    )


def test_coverage_masks_are_the_pixels_that_see_the_mesh(room):
    masks = coverage_masks(room.scene)
    for v, m in enumerate(masks):
        np.testing.assert_array_equal(m, room.load_face_ids(v) >= 0)


def test_evaluate_semireal_on_consistent_photos(room):
    """The originals are consistent: 'none' scores exactly 0 on them and the size of the hidden
    change on the changed ones; seqcc-global undoes most of the change."""
    res = evaluate_semireal(room.scene, methods=["none", "seqcc-global"], seeds=(0, 1), reference=0, t_npm=20, stride=1)
    assert res.reference == 0 and res.seeds == (0, 1)
    assert res.errors["none"].shape == (2, 5) and np.isnan(res.errors["none"][:, 0]).all()
    np.testing.assert_array_equal(res.unchanged["none"][1:], 0.0)
    s = res.summary()
    assert s["none"]["mean_avg"] > 5.0
    assert s["seqcc-global"]["mean_avg"] < 0.3 * s["none"]["mean_avg"], s
    assert s["seqcc-global"]["unchanged_mean"] < 1.5, s
    assert np.nanmean(res.oracle) < 0.5  # undoing exactly the hidden change: quantisation only
    assert set(s["none"]) >= {"mean", "worst", "mean_avg", "worst_max", "unchanged_mean", "unchanged_worst", "seconds"}
    assert s["none"]["invariance_mean"] == pytest.approx(s["none"]["mean_avg"])  # none on the originals is the originals
    assert s["seqcc-global"]["invariance_mean"] < 0.3 * s["none"]["mean_avg"], s


def test_camera_hard_synthetic_scene(tmp_path):
    syn = make_synthetic_scene(tmp_path / "s", n_views=4, width=64, height=48, seed=1, photometric="camera-hard", cell_size=0.3)
    assert syn.metadata["photometric"] == "camera-hard"
    assert syn.transforms["v00"] == identity_photometric()
    lo, hi = HARD_CHANGE_RANGES["exposure"]
    for name in ("v01", "v02", "v03"):
        p = syn.transforms[name]
        assert lo <= p["gain"] <= hi and 0.0 <= p["s_curve"] <= 0.6
        assert not np.array_equal(syn.scene.views[syn.scene.index(name)].load_image(), syn.load_gt(name))


def test_camera_change_lut_and_its_inverse(rng):
    from o3d_seqcc.correction import LutTransform
    from o3d_seqcc.evaluation.semireal import camera_change_lut

    p = {"gain": 1.3, "white_balance": [1.1, 0.9, 1.0], "gamma": [1.2, 0.8, 1.0], "s_curve": 0.4}
    img = (rng.random((40, 50, 3)) * 190).astype(np.uint8)
    changed = apply_camera_change(img, p)
    np.testing.assert_array_equal(LutTransform(camera_change_lut(p)).apply_levels(img), changed)
    back = LutTransform(camera_change_lut(p, size=4096, inverse=True)).apply_levels(changed)
    unclipped = (changed < 255).all(axis=-1)
    assert np.abs(back.astype(int) - img)[unclipped].mean() < 0.2  # 8-bit quantisation only
