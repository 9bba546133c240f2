"""Tests of o3d_seqcc.evaluation.metrics: CIEDE2000 on Sharma et al. (2005), PSNR known answers, summaries."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from o3d_seqcc.errors import InputError
from o3d_seqcc.mappings.compute import Mappings, PairMapping
from o3d_seqcc.evaluation.metrics import PSNR_CAP_DB, Evaluation, blur_images, evaluate, image_delta_e, psnr
from o3d_seqcc.imaging.arrays import ciede2000, rgb_to_lab
from o3d_seqcc.imaging.arrays import delta_e_2000 as delta_e_2000_rgb
from o3d_seqcc.imaging.arrays import img_as_float as to_unit_float

# Sharma, Wu & Dalal (2005), "The CIEDE2000 color-difference formula: implementation notes,
# supplementary test data, and mathematical observations", Color Res. Appl. 30(1), Table 1:
# L1, a1, b1, L2, a2, b2, Delta E 2000 (published to 4 decimals).
SHARMA = np.array(
    [
        [50.0000, 2.6772, -79.7751, 50.0000, 0.0000, -82.7485, 2.0425],
        [50.0000, 3.1571, -77.2803, 50.0000, 0.0000, -82.7485, 2.8615],
        [50.0000, 2.8361, -74.0200, 50.0000, 0.0000, -82.7485, 3.4412],
        [50.0000, -1.3802, -84.2814, 50.0000, 0.0000, -82.7485, 1.0000],
        [50.0000, -1.1848, -84.8006, 50.0000, 0.0000, -82.7485, 1.0000],
        [50.0000, -0.9009, -85.5211, 50.0000, 0.0000, -82.7485, 1.0000],
        [50.0000, 0.0000, 0.0000, 50.0000, -1.0000, 2.0000, 2.3669],
        [50.0000, -1.0000, 2.0000, 50.0000, 0.0000, 0.0000, 2.3669],
        [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0009, 7.1792],
        [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0010, 7.1792],
        [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0011, 7.2195],
        [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0012, 7.2195],
        [50.0000, -0.0010, 2.4900, 50.0000, 0.0009, -2.4900, 4.8045],
        [50.0000, -0.0010, 2.4900, 50.0000, 0.0010, -2.4900, 4.8045],
        [50.0000, -0.0010, 2.4900, 50.0000, 0.0011, -2.4900, 4.7461],
        [50.0000, 2.5000, 0.0000, 50.0000, 0.0000, -2.5000, 4.3065],
        [50.0000, 2.5000, 0.0000, 73.0000, 25.0000, -18.0000, 27.1492],
        [50.0000, 2.5000, 0.0000, 61.0000, -5.0000, 29.0000, 22.8977],
        [50.0000, 2.5000, 0.0000, 56.0000, -27.0000, -3.0000, 31.9030],
        [50.0000, 2.5000, 0.0000, 58.0000, 24.0000, 15.0000, 19.4535],
        [50.0000, 2.5000, 0.0000, 50.0000, 3.1736, 0.5854, 1.0000],
        [50.0000, 2.5000, 0.0000, 50.0000, 3.2972, 0.0000, 1.0000],
        [50.0000, 2.5000, 0.0000, 50.0000, 1.8634, 0.5757, 1.0000],
        [50.0000, 2.5000, 0.0000, 50.0000, 3.2592, 0.3350, 1.0000],
        [60.2574, -34.0099, 36.2677, 60.4626, -34.1751, 39.4387, 1.2644],
        [63.0109, -31.0961, -5.8663, 62.8187, -29.7946, -4.0864, 1.2630],
        [61.2901, 3.7196, -5.3901, 61.4292, 2.2480, -4.9620, 1.8731],
        [35.0831, -44.1164, 3.7933, 35.0232, -40.0716, 1.5901, 1.8645],
        [22.7233, 20.0904, -46.6940, 23.0331, 14.9730, -42.5619, 2.0373],
        [36.4612, 47.8580, 18.3852, 36.2715, 50.5065, 21.2231, 1.4146],
        [90.8027, -2.0831, 1.4410, 91.1528, -1.6435, 0.0447, 1.4441],
        [90.9257, -0.5406, -0.9208, 88.6381, -0.8985, -0.7239, 1.5381],
        [6.7747, -0.2908, -2.4247, 5.8714, -0.0985, -2.2286, 0.6377],
        [2.0776, 0.0795, -1.1350, 0.9033, -0.0636, -0.5514, 0.9082],
    ]
)


# --------------------------------------------------------------------------- hand-built mappings
def _Mappings(pairs: dict, n_views: int, view_names: tuple = ()) -> Mappings:
    return Mappings(pairs=pairs, n_views=n_views, view_names=view_names)


def _identity_pair(a: int, b: int, h: int, w: int, n: int | None = None, rng=None) -> PairMapping:
    """Mappings between the same pixels (integer centres) of two views."""
    yy, xx = np.mgrid[0:h, 0:w]
    uv = np.stack([xx.ravel(), yy.ravel()], axis=1).astype(np.float64)
    if n is not None:
        uv = uv[(rng or np.random.default_rng(0)).choice(len(uv), n, replace=False)]
    return PairMapping(a, b, uv, uv.copy(), np.arange(len(uv), dtype=np.int64))


# --------------------------------------------------------------------------- CIEDE2000
def test_ciede2000_sharma_reference_data():
    got = ciede2000(SHARMA[:, 0:3], SHARMA[:, 3:6])
    assert got.shape == (34,)
    np.testing.assert_allclose(got, SHARMA[:, 6], atol=1e-4, rtol=0)
    # symmetric
    np.testing.assert_allclose(ciede2000(SHARMA[:, 3:6], SHARMA[:, 0:3]), got, atol=1e-9)


def test_rgb_to_lab_white_black_and_grey():
    lab = rgb_to_lab(np.array([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0], [0.5, 0.5, 0.5]]))
    np.testing.assert_allclose(lab[0], [100.0, 0.0, 0.0], atol=0.02)
    np.testing.assert_allclose(lab[1], [0.0, 0.0, 0.0], atol=1e-6)
    assert abs(lab[2, 0] - 53.39) < 0.05  # sRGB 0.5 -> L* 53.39
    assert np.all(delta_e_2000_rgb(np.full((5, 3), 0.3), np.full((5, 3), 0.3)) == 0)


# --------------------------------------------------------------------------- PSNR
def test_psnr_known_answers():
    a = np.full((100, 3), 0.5)
    assert psnr(a, a + 0.1) == pytest.approx(20.0, abs=1e-9)
    assert psnr(a, a - 0.01) == pytest.approx(40.0, abs=1e-9)
    assert psnr(a * 255, a * 255 + 25.5, peak=255.0) == pytest.approx(20.0, abs=1e-9)
    assert psnr(a, a) == math.inf
    assert math.isnan(psnr(np.zeros((0, 3)), np.zeros((0, 3))))


def test_to_unit_float_scales_by_dtype():
    assert to_unit_float(np.array([255], np.uint8))[0] == 1.0
    assert to_unit_float(np.array([65535], np.uint16))[0] == 1.0
    with pytest.raises(InputError):
        to_unit_float(np.array([1], np.int32))


# --------------------------------------------------------------------------- evaluate
def _constant_views(values, h=6, w=8, dtype=np.float64):
    out = []
    for v in values:
        im = np.empty((h, w, 3))
        im[:] = v
        if dtype == np.uint8:
            im = np.round(im * 255).astype(np.uint8)
        elif dtype == np.uint16:
            im = np.round(im * 65535).astype(np.uint16)
        out.append(im)
    return out


def test_evaluate_constant_offset_gives_20db_and_8_16_bit_agree():
    rng = np.random.default_rng(3)
    base = rng.uniform(0.1, 0.8, (12, 16, 3))
    imgs = [base, base + 0.1]
    m = _Mappings({(0, 1): _identity_pair(0, 1, 12, 16)}, 2)
    ev = evaluate(imgs, m)
    assert ev.n_pairs == 1 and ev.pairs[0].n == 12 * 16
    assert ev.pairs[0].psnr == pytest.approx(20.0, abs=1e-9)
    expected_de = delta_e_2000_rgb(base.reshape(-1, 3), (base + 0.1).reshape(-1, 3)).mean()
    assert ev.pairs[0].ciede2000 == pytest.approx(expected_de, rel=1e-12)
    # 8-bit and the same values as 16-bit (x 257) score identically
    b8 = np.round(base * 200).astype(np.uint8)
    imgs8 = [b8, b8 + np.uint8(51)]  # offset 51/255 = 0.2 -> 13.979 dB
    imgs16 = [im.astype(np.uint16) * 257 for im in imgs8]
    e8, e16 = evaluate(imgs8, m), evaluate(imgs16, m)
    assert e8.pairs[0].psnr == pytest.approx(20 * math.log10(1 / 0.2), abs=1e-9)
    assert e16.pairs[0].psnr == pytest.approx(e8.pairs[0].psnr, abs=1e-9)
    assert e16.pairs[0].ciede2000 == pytest.approx(e8.pairs[0].ciede2000, abs=1e-9)


def test_evaluate_summaries_mean_weighted_std_and_cap():
    # views: constant colours; pair RMS differences 0.1, 0.01, 0.09 and an identical pair
    imgs = _constant_views([0.5, 0.6, 0.51, 0.5], h=10, w=10)
    rng = np.random.default_rng(0)
    counts = {(0, 1): 10, (0, 2): 30, (1, 2): 60, (0, 3): 5}
    m = _Mappings({k: _identity_pair(*k, 10, 10, n, rng) for k, n in counts.items()}, 4, ("p", "q", "r", "s"))
    ev = evaluate(imgs, m)
    assert isinstance(ev, Evaluation)
    by = {(p.a, p.b): p for p in ev.pairs}
    assert by[(0, 1)].psnr == pytest.approx(20.0)
    assert by[(0, 2)].psnr == pytest.approx(40.0)
    assert by[(1, 2)].psnr == pytest.approx(20 * math.log10(1 / 0.09))
    assert by[(0, 3)].psnr == math.inf and by[(0, 3)].ciede2000 == 0.0
    keys = sorted(counts)
    vals = np.array([min(by[k].psnr, PSNR_CAP_DB) for k in keys])
    w = np.array([counts[k] for k in keys], float)
    assert ev.psnr.mean == pytest.approx(vals.mean())
    assert ev.psnr.weighted_mean == pytest.approx((vals * w).sum() / w.sum())
    assert ev.psnr.std == pytest.approx(vals.std())
    de = np.array([by[k].ciede2000 for k in keys])
    assert ev.ciede2000.weighted_mean == pytest.approx((de * w).sum() / w.sum())
    assert by[(0, 2)].ciede2000 == pytest.approx(
        float(delta_e_2000_rgb(np.array([0.5] * 3), np.array([0.51] * 3))), rel=1e-9
    )
    assert ev.n_mappings == sum(counts.values())
    # JSON-safe (inf -> null), names included, a readable table
    d = ev.to_dict()
    text = json.dumps(d, allow_nan=False)
    assert '"a_name": "p"' in text and d["pairs"][keys.index((0, 3))]["psnr"] is None
    t = ev.table(title="demo")
    assert "PSNR" in t and "CIEDE2000" in t and "demo" in t
    # subset, min_n
    sub = evaluate(imgs, m, pairs=[(2, 1)])
    assert [(p.a, p.b) for p in sub.pairs] == [(1, 2)]
    big = evaluate(imgs, m, min_n=20)
    assert {(p.a, p.b) for p in big.pairs} == {(0, 2), (1, 2)} and set(big.skipped) == {(0, 1), (0, 3)}


def test_evaluate_bad_input():
    imgs = _constant_views([0.5, 0.6])
    m = _Mappings({(0, 1): _identity_pair(0, 1, 6, 8)}, 2)
    with pytest.raises(InputError, match="2 views"):
        evaluate(imgs[:1], m)
    with pytest.raises(InputError, match="RGB"):
        evaluate([imgs[0][..., 0], imgs[1]], m)
    with pytest.raises(InputError, match="no mappings"):
        evaluate(imgs, m, pairs=[(0, 5)])
    with pytest.raises(ValueError, match="bilinear"):
        evaluate(imgs, m, interpolation="cubic")
    ev = evaluate(imgs, m, min_n=10_000)
    assert ev.n_pairs == 0 and math.isnan(ev.psnr.mean)


def test_image_delta_e_and_blur():
    rng = np.random.default_rng(1)
    gt = rng.integers(0, 256, (20, 30, 3), dtype=np.uint8)
    assert image_delta_e(gt, gt) == 0.0
    other = gt.copy()
    other[:10] = 0
    mask = np.zeros((20, 30), bool)
    mask[10:] = True
    assert image_delta_e(other, gt, mask=mask) == 0.0
    assert image_delta_e(other, gt) > 0
    b = blur_images([gt], 1.5)[0]
    assert b.dtype == np.uint8 and b.shape == gt.shape and not np.array_equal(b, gt)
    assert blur_images([gt], 0)[0] is gt


# --------------------------------------------------------------------------- held-out protocol
def _gained_setup(V=3, h=24, w=32):
    rng = np.random.default_rng(7)
    base = rng.uniform(0.15, 0.6, (h, w, 3))
    gains = np.array([[1.0, 1.0, 1.0], [1.3, 1.1, 0.9], [0.8, 0.9, 1.2]])[:V]
    images = [np.round(base * g * 255).astype(np.uint8) for g in gains]
    pairs = {(a, b): _identity_pair(a, b, h, w) for a in range(V) for b in range(a + 1, V)}
    return images, _Mappings(pairs, V, tuple(f"v{i}" for i in range(V)))


def test_holdout_split_is_disjoint_by_face():
    _, maps = _gained_setup()
    fit, test = maps.split(0.5, seed=0)
    for k in maps.pairs:
        f_fit = set(fit.pairs[k].face_ids.tolist())
        f_test = set(test.pairs[k].face_ids.tolist())
        assert not f_fit & f_test
        assert len(f_fit) + len(f_test) == maps.pairs[k].n
        assert 0.3 < len(f_test) / maps.pairs[k].n < 0.7


def test_evaluate_method_in_sample_and_held_out():
    import o3d_seqcc.correction  # noqa: F401
    from o3d_seqcc.evaluation.fit import evaluate_method

    images, maps = _gained_setup()
    none = evaluate_method(images, maps, method="none", reference=0, holdout=0.5, t_npm=10)
    direct = evaluate(images, maps)
    assert none.in_sample.psnr == direct.psnr and none.in_sample.ciede2000 == direct.ciede2000
    assert none.reference == 0 and none.held_out is not None
    # the held-out evaluation scores only the test faces: about half of the mappings
    assert 0.3 < none.held_out.n_mappings / direct.n_mappings < 0.7
    gc = evaluate_method(images, maps, method="gain-compensation", reference=0, holdout=0.5, t_npm=10, sigma_g=1e3)
    for ev in (gc.in_sample, gc.held_out):
        assert ev.psnr.mean > none.in_sample.psnr.mean + 15  # gains recovered up to 8-bit rounding
        assert ev.ciede2000.mean < 0.5
    d = gc.to_dict()
    assert d["method"] == "gain-compensation" and d["held_out"]["n_pairs"] == 3
    json.dumps(d, allow_nan=False)
    no_ho = evaluate_method(images, maps, method="none", reference=0, holdout=0.0, t_npm=10)
    assert no_ho.held_out is None
    with pytest.raises(InputError):
        evaluate_method(images, maps, method="none", holdout=1.0)


def test_evaluate_batching_does_not_change_results(monkeypatch):
    import o3d_seqcc.evaluation.metrics as metrics

    images, maps = _gained_setup()
    full = evaluate(images, maps)
    monkeypatch.setattr(metrics, "_BATCH", 100)  # flush after every pair
    small = evaluate(images, maps)
    assert [(p.a, p.b, p.n) for p in small.pairs] == [(p.a, p.b, p.n) for p in full.pairs]
    np.testing.assert_allclose([p.psnr for p in small.pairs], [p.psnr for p in full.pairs], rtol=1e-12)
    np.testing.assert_allclose([p.ciede2000 for p in small.pairs], [p.ciede2000 for p in full.pairs], rtol=1e-12)


def test_delta_e_matches_colour_science():
    """scikit-image (ours) against colour-science, an independent implementation: same CIEDE2000
    up to the sRGB / D65 constants the two libraries round differently (~1e-4 in Lab)."""
    import colour

    rng = np.random.default_rng(0)
    a = rng.random((2000, 3))
    b = np.clip(a + rng.normal(0, 0.1, a.shape), 0, 1)
    a[:3] = 0.0  # black (hue undefined)
    with colour.utilities.suppress_warnings(colour_usage_warnings=True):
        lab_a, lab_b = colour.XYZ_to_Lab(colour.sRGB_to_XYZ(a)), colour.XYZ_to_Lab(colour.sRGB_to_XYZ(b))
        ref = colour.delta_E(lab_a, lab_b, method="CIE 2000")
    np.testing.assert_allclose(rgb_to_lab(a), lab_a, atol=0.05)
    np.testing.assert_allclose(ciede2000(lab_a, lab_b), ref, atol=1e-9)  # the same formula on the same Lab
    d = np.abs(delta_e_2000_rgb(a, b) - ref)
    assert d.mean() < 2e-3 and np.percentile(d, 99) < 0.02, (d.mean(), np.percentile(d, 99))


def test_thin_indices_are_evenly_spaced_and_strictly_increasing():
    from o3d_seqcc.evaluation.metrics import thin_indices

    assert thin_indices(10, None) is None and thin_indices(10, 10) is None and thin_indices(3, 7) is None
    np.testing.assert_array_equal(thin_indices(11, 3), [0, 5, 10])
    for n in (8, 9, 101, 1000, 7919):
        for k in (1, 2, 7, 8):
            idx = thin_indices(n, k)
            if idx is None:
                continue
            assert len(idx) == k and idx[0] == 0 and (k == 1 or idx[-1] == n - 1) and np.all(np.diff(idx) > 0)


def test_before_after_thinned_scores_weight_pairs_by_their_full_counts():
    from o3d_seqcc.evaluation.metrics import contrast_ratios
    from o3d_seqcc.evaluation.table2 import before_after

    images, maps = _gained_setup()  # 3 views x 768 mappings per pair
    paths = {0: [0], 1: [1, 0], 2: [2, 1, 0]}
    full = before_after(images, images[:1] * 3, maps, paths)
    thin = before_after(images, images[:1] * 3, maps, paths, max_per_pair=50)
    assert "max_per_pair" not in full["before"] and thin["before"]["max_per_pair"] == 50
    assert thin["before"]["n_scored"] == 3 * 50
    assert thin["before"]["n_mappings"] == full["before"]["n_mappings"] == 3 * 768
    # a constant gain: every mapping of a pair says the same, so 50 of them give the pair's full score
    for k in ("psnr", "ciede2000"):
        for s in ("mean", "weighted_mean", "std"):
            assert thin["before"][k][s] == pytest.approx(full["before"][k][s], rel=0.02, abs=0.02), (k, s)
    assert full["after"]["psnr"]["mean"] == 100.0  # identical images after: capped
    # contrast: target = the view farther from the reference; view 2 is 0.8/0.9/1.2 of view 0, view 1 1.3/1.1/0.9
    ratios = contrast_ratios(images, maps, paths)
    assert len(ratios) == 3 == full["contrast"]["before"]["n_pairs"]
    assert ratios[0] == pytest.approx(np.mean([1.3, 1.1, 0.9]), rel=0.02)  # (0, 1): target 1, source 0
    assert full["contrast"]["before"]["mean"] == pytest.approx(ratios.mean())
    assert full["contrast"]["after"]["mean"] == pytest.approx(1.0)


def test_before_after_reads_lazy_images_once_per_set_with_the_same_numbers():
    """Lazy image sequences: each view is read once per image set (sampled at all its pairs' mappings, the
    contrast ratios from the same samples), and Table 2 is the one of the image lists, to the bit."""
    from o3d_seqcc.evaluation.table2 import before_after
    from o3d_seqcc.imaging.sequences import ImageSequence

    class Counted(ImageSequence):
        def __init__(self, images):
            self.images, self.reads = images, []

        def __len__(self):
            return len(self.images)

        def _load(self, i):
            self.reads.append(i)
            return self.images[i]

        def dtypes(self):  # as a file sequence: from the headers, no read
            return [im.dtype for im in self.images]

    images, maps = _gained_setup()
    corrected = [np.clip(im.astype(np.int64) * 3 // 4 + 9, 0, 255).astype(im.dtype) for im in images]
    paths = {0: [0], 1: [1, 0], 2: [2, 1, 0]}
    for cap in (None, 50):
        want = before_after(images, corrected, maps, paths, max_per_pair=cap, per_pair=True)
        lazy = Counted(images), Counted(corrected)
        got = before_after(*lazy, maps, paths, max_per_pair=cap, per_pair=True)
        assert json.dumps(got) == json.dumps(want)
        assert got["contrast"]["before"]["n_pairs"] == 3
        for seq in lazy:
            assert sorted(seq.reads) == [0, 1, 2], seq.reads
