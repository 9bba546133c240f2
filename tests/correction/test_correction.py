"""Sequential pairwise colour correction and the pairwise baselines on known photometric changes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from o3d_seqcc.correction.cmf import apply_lut, fit_cmf
from o3d_seqcc.correction import (
    METHODS,
    FunctionTransform,
    IdentityTransform,
    LutTransform,
    correct,
)
from o3d_seqcc.imaging.arrays import img_as_dtype as from_float
from o3d_seqcc.imaging.arrays import img_as_float as to_float
from o3d_seqcc.errors import InputError
from o3d_seqcc.correction.jih import jih_samples, joint_histogram
from o3d_seqcc.mappings.compute import Mappings, PairMapping
from o3d_seqcc.scene import Scene, View

H, W = 48, 64
K = np.array([[50.0, 0, 31.5], [0, 50.0, 23.5], [0, 0, 1]])


def _albedo(rng) -> np.ndarray:
    """Smooth colourful image in [0.03, 0.97]."""
    low = rng.random((6, 8, 3))
    yy, xx = np.mgrid[0:H, 0:W]
    fy, fx = yy / (H - 1) * 5, xx / (W - 1) * 7
    y0, x0 = np.floor(fy).astype(int).clip(0, 4), np.floor(fx).astype(int).clip(0, 6)
    ty, tx = (fy - y0)[..., None], (fx - x0)[..., None]
    img = (
        low[y0, x0] * (1 - ty) * (1 - tx)
        + low[y0 + 1, x0] * ty * (1 - tx)
        + low[y0, x0 + 1] * (1 - ty) * tx
        + low[y0 + 1, x0 + 1] * ty * tx
    )
    img = img + 0.05 * rng.standard_normal(img.shape)
    return 0.03 + 0.94 * np.clip(img, 0, 1)


def _photometric(img: np.ndarray, gain, gamma) -> np.ndarray:
    return np.clip(img * np.asarray(gain), 0, 1) ** np.asarray(gamma)


# view 0: reference look; chain 0-1-2-3 well connected; (0, 3) below t_npm; view 4 isolated
PARAMS = [
    ((1.0, 1.0, 1.0), (1.0, 1.0, 1.0)),
    ((0.8, 0.9, 0.75), (1.2, 0.9, 1.1)),
    ((0.7, 0.85, 0.95), (0.8, 1.3, 1.0)),
    ((0.9, 0.75, 0.8), (1.4, 1.1, 0.85)),
    ((0.6, 0.6, 0.6), (1.0, 1.0, 1.0)),
]
COUNTS = {(0, 1): 3000, (1, 2): 3000, (2, 3): 3000, (0, 3): 100, (3, 4): 50}


def _scene(n: int) -> Scene:
    views = tuple(
        View(name=f"v{i}", image=Path(f"/nonexistent/v{i}.png"), intrinsic=K, extrinsic=np.eye(4), width=W, height=H)
        for i in range(n)
    )
    return Scene(Path("/nonexistent/mesh.ply"), views)


def _mappings(rng, counts=COUNTS, n_views=5) -> Mappings:
    """Pairs map identical pixel coordinates (the views see the same image up to photometry)."""
    pairs = {}
    for (a, b), n in counts.items():
        uv = np.stack([rng.integers(0, W, n), rng.integers(0, H, n)], axis=1).astype(np.float64)
        pairs[(a, b)] = PairMapping(a, b, uv, uv.copy(), np.arange(n) // 3)
    return Mappings(pairs=pairs, view_names=tuple(f"v{i}" for i in range(n_views)), mode="vertices")


@pytest.fixture
def problem(rng):
    albedo = _albedo(rng)
    floats = [_photometric(albedo, g, gm) for g, gm in PARAMS]
    images = [from_float(f, np.uint8) for f in floats]
    return _scene(5), images, _mappings(rng), from_float(albedo, np.uint8)


def _mae(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a.astype(np.float64) - b.astype(np.float64)).mean())


def test_seqcc_recovers_the_reference_colours(problem):
    scene, images, mappings, truth = problem
    before = [_mae(images[v], truth) for v in (1, 2, 3)]
    with pytest.warns(UserWarning, match="v4"):
        res = correct(scene, images=images, mappings=mappings, reference="v0", method="seqcc")
    assert res.reference == 0 and res.method == "seqcc"
    assert res.paths == {0: [0], 1: [1, 0], 2: [2, 1, 0], 3: [3, 2, 1, 0]}
    assert res.unreachable == [4]
    after = [_mae(res.images[v], truth) for v in (1, 2, 3)]
    assert min(before) > 15  # 8-bit levels
    assert max(after) < 2.0, after  # < 2/255 after up to 3 sequential steps
    # reference and unreachable view untouched, bit for bit; inputs not modified
    np.testing.assert_array_equal(res.images[0], images[0])
    np.testing.assert_array_equal(res.images[4], images[4])
    assert isinstance(res.transforms[4], IdentityTransform)
    assert all(im.dtype == np.uint8 for im in res.images)
    assert {e["a"] for e in res.graph_edges} == {0, 1, 2}
    assert set(res.timings) >= {"load_images", "mappings", "graph", "fit", "apply", "total"}


@pytest.mark.filterwarnings("ignore:1 view")
def test_sequential_composition_equals_one_by_one(problem):
    scene, images, mappings, _ = problem
    res = correct(scene, images=images, mappings=mappings, reference=0, method="seqcc", outlier_k=None)  # one fit per edge
    fl = [to_float(im) for im in images]
    img = fl[3].copy()
    for t, s in ((3, 2), (2, 1), (1, 0)):
        pm = mappings.pairs[(min(t, s), max(t, s))]
        uv_t = pm.uv_a if t < s else pm.uv_b
        uv_s = pm.uv_b if t < s else pm.uv_a
        ct = fl[t][uv_t[:, 1].astype(int), uv_t[:, 0].astype(int)]
        cs = fl[s][uv_s[:, 1].astype(int), uv_s[:, 0].astype(int)]
        jih = joint_histogram(ct, cs)
        for c in range(3):
            x, y, w = jih_samples(jih[c])
            img[..., c] = apply_lut(fit_cmf(x, y, weights=w), img[..., c])
    assert isinstance(res.transforms[3], LutTransform)
    assert np.abs(res.images[3].astype(int) - from_float(img, np.uint8).astype(int)).max() <= 1


def test_auto_reference_and_reference_by_index(problem):
    scene, images, mappings, _ = problem
    res = correct(scene, images=images, mappings=mappings, reference="auto", method="none")
    assert res.reference == 1  # chain 0-1-2-3: views 1 and 2 tie, lowest index wins
    res = correct(scene, images=images, mappings=mappings, reference=2, method="none")
    assert res.reference == 2 and res.paths[0] == [0, 1, 2]
    for a, b in zip(res.images, images):
        np.testing.assert_array_equal(a, b)


@pytest.mark.filterwarnings("ignore:1 view")
def test_sixteen_bit_in_sixteen_bit_out(problem, rng):
    scene, images, mappings, truth = problem
    img16 = [im.astype(np.uint16) * 257 for im in images]
    res = correct(scene, images=img16, mappings=mappings, reference="v0")
    assert all(im.dtype == np.uint16 for im in res.images)
    assert res.transforms[1].lut.shape == (3, 4096)
    for v in (1, 2, 3):
        assert _mae(res.images[v] / 257.0, truth) < 2.0


@pytest.mark.parametrize("method", ["reinhard", "root-polynomial", "vandermonde"])
def test_pairwise_baselines_undo_a_known_gain(rng, method):
    albedo = _albedo(rng)
    gains = [(1.0, 1.0, 1.0), (0.8, 0.9, 0.7), (0.9, 0.7, 0.85)]
    images = [from_float(albedo * np.array(g), np.uint8) for g in gains]
    counts = {(0, 1): 3000, (1, 2): 3000}
    res = correct(_scene(3), images=images, mappings=_mappings(rng, counts, 3), reference=0, method=method)
    truth = images[0]
    for v in (1, 2):
        before, after = _mae(images[v], truth), _mae(res.images[v], truth)
        if method == "reinhard":  # global mean/std transfer in log-LMS: an approximation
            assert after < 0.5 * before
        else:  # a per-channel gain is in both models: recovered
            assert after < 1.0, (v, after)
    kind = LutTransform if method == "vandermonde" else FunctionTransform
    assert isinstance(res.transforms[1], kind)


def test_every_registered_method_runs_without_nan(problem):
    scene, images, mappings, _ = problem
    # a constant view and a saturated view join the chain
    images = list(images)
    images[4] = np.full_like(images[4], 255)
    images[3] = np.full_like(images[3], 128)
    maps = _mappings(np.random.default_rng(1), {(0, 1): 3000, (1, 2): 3000, (2, 3): 3000, (3, 4): 3000})
    for method in sorted(METHODS):
        res = correct(scene, images=images, mappings=maps, reference="v0", method=method)
        for im in res.images:
            assert im.dtype == np.uint8 and im.shape == (H, W, 3)
        for tr in res.transforms:
            out = tr.apply(to_float(images[1]))
            assert np.all(np.isfinite(out)) and out.min() >= 0 and out.max() <= 1


@pytest.mark.filterwarnings("ignore:1 view")
def test_seqcc_joint_is_seqcc_with_the_literal_fit(problem):
    """seqcc-joint takes seqcc's options (listed when one is wrong) with no outlier pass by default."""
    import inspect

    scene, images, mappings, _ = problem
    kw = dict(images=images, mappings=mappings, reference=0)
    joint = correct(scene, method="seqcc-joint", **kw)
    literal = correct(scene, method="seqcc", outlier_k=None, cmf_options={"pairing": "joint", "contrast_guard": None}, **kw)
    for a, b in zip(joint.images, literal.images):
        np.testing.assert_array_equal(a, b)
    opts = inspect.signature(METHODS["seqcc-joint"]).parameters
    assert list(opts) == list(inspect.signature(METHODS["seqcc"]).parameters) and opts["outlier_k"].default is None
    with pytest.raises(TypeError, match=r"'seqcc-joint' does not take option 'bogus'; valid: bits, cmf, cmf_options, jih_blur, "
                                         r"n_jobs, outlier_k"):
        correct(scene, method="seqcc-joint", bogus=1, **kw)


def test_bad_input_messages(problem):
    scene, images, mappings, _ = problem
    with pytest.raises(InputError, match="v3"):
        correct(scene, images=images, mappings=mappings, reference="nope")
    with pytest.raises(InputError, match="3000"):
        correct(scene, images=images, mappings=mappings, t_npm=10**6)
    with pytest.raises(InputError, match="no edge"):
        correct(scene, images=images, mappings=mappings, reference="v4")
    with pytest.raises(InputError, match="unknown correction method 'magic'; valid: gain-compensation, "):
        correct(scene, images=images, mappings=mappings, method="magic")
    with pytest.raises(TypeError, match="bogus"):
        correct(scene, images=images, mappings=mappings, bogus=3)
    with pytest.raises(ValueError, match="outlier_k"), pytest.warns(UserWarning, match="no colour-correction path"):
        correct(scene, images=images, mappings=mappings, outlier_k=0)
    with pytest.raises(InputError, match="grey"):
        correct(scene, images=[im[..., 0] for im in images], mappings=mappings)
    with pytest.raises(InputError, match="RGB"):
        correct(scene, images=[np.dstack([im, im[..., :1]]) for im in images], mappings=mappings)
    with pytest.raises(InputError, match="images for"):
        correct(scene, images=images[:3], mappings=mappings)


def test_transforms():
    lut = np.stack([np.linspace(0, 1, 256) ** g for g in (1.0, 2.0, 0.5)])
    t = LutTransform(lut)
    x = np.full((2, 2, 3), 0.25)
    np.testing.assert_allclose(t.apply(x)[0, 0], [0.25, 0.0625, 0.5], atol=1e-4)
    with pytest.raises(ValueError):
        LutTransform(np.zeros((2, 5)))
    f = FunctionTransform(lambda im: im * 3 - 0.5)
    assert f.apply(x).max() == 0.25 and f.apply(np.zeros((1, 1, 3))).min() == 0.0
    np.testing.assert_array_equal(IdentityTransform().apply(x), x)
    np.testing.assert_array_equal(from_float(to_float(np.arange(256, dtype=np.uint8).reshape(1, -1, 1).repeat(3, 2)), np.uint8)[0, :, 0], np.arange(256))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_lut_apply_levels_matches_float_path(rng, dtype):
    top = np.iinfo(dtype).max
    img = rng.integers(0, top + 1, (20, 30, 3)).astype(dtype)
    lut = np.stack([np.linspace(0, 1, 300) ** g for g in (1.3, 0.7, 1.0)])
    t = LutTransform(lut)
    np.testing.assert_array_equal(t.apply_levels(img), from_float(t.apply(to_float(img)), dtype))
    # every level, twice (the tables are kept), and a non-contiguous view (OpenCV's LUT for uint8)
    every = np.arange(top + 1, dtype=dtype)[::-1].reshape(-1, 256, 1).repeat(3, axis=2)
    every[..., 1] = np.roll(every[..., 1], 7)
    for _ in range(2):
        got = t.apply_levels(every)
        assert got.dtype == dtype and got.shape == every.shape
        np.testing.assert_array_equal(got, from_float(t.apply(to_float(every)), dtype))
    np.testing.assert_array_equal(t.apply_levels(img[::2, 1::3]), from_float(t.apply(to_float(img[::2, 1::3])), dtype))


def test_seqcc_on_a_synthetic_room_gets_close_to_ground_truth(tmp_path):
    import o3d_seqcc.synthetic as synthetic
    from o3d_seqcc.io.images import read_image
    from o3d_seqcc.evaluation.metrics import image_delta_e

    ss = synthetic.make_synthetic_scene(tmp_path / "s", n_views=6, width=160, height=120, seed=3)
    scene = ss.scene
    gt = [read_image(ss.gt_images[n]) for n in scene.names]
    masks = [np.load(ss.face_ids[n]) >= 0 for n in scene.names]
    res = {m: correct(scene, reference=0, method=m) for m in ("none", "seqcc")}
    de = {m: np.mean([image_delta_e(r.images[i], gt[i], mask=masks[i]) for i in range(len(gt))]) for m, r in res.items()}
    assert de["seqcc"] < 0.5 * de["none"], de
    assert image_delta_e(res["seqcc"].images[0], gt[0], mask=masks[0]) < 0.5  # the reference stays itself


def test_seqcc_does_not_wash_out_misregistered_views(rng):
    """Mappings misregistered by a few pixels on a textured photo: seqcc recovers a known gain and
    gamma without attenuating the contrast, along a two-step path (view 2 -> 1 -> 0)."""
    import skimage.data

    h, w = 200, 240
    tex = skimage.data.astronaut()[100 : 100 + h, 120 : 120 + w].astype(np.float64) / 255.0
    albedo = 0.04 + 0.8 * tex  # unsaturated, like real albedo
    params = [((1.0, 1.0, 1.0), (1.0, 1.0, 1.0)), ((0.8, 0.9, 0.7), (1.2, 1.0, 0.9)), ((1.1, 0.8, 0.9), (0.9, 1.2, 1.1))]
    images = [from_float(_photometric(albedo, g, gm), np.uint8) for g, gm in params]
    pairs = {}
    for (a, b), (du, dv) in {(0, 1): (3.0, -2.0), (1, 2): (-2.0, 3.0)}.items():
        n = 20000
        uv = np.stack([rng.uniform(8, w - 9, n), rng.uniform(8, h - 9, n)], axis=1)
        pairs[(a, b)] = PairMapping(a, b, uv, uv + [du, dv], np.arange(n) // 3)
    mappings = Mappings(pairs=pairs, view_names=("v0", "v1", "v2"), mode="vertices")
    views = tuple(
        View(name=f"v{i}", image=Path(f"/nonexistent/v{i}.png"), intrinsic=K, extrinsic=np.eye(4), width=w, height=h)
        for i in range(3)
    )
    scene = Scene(Path("/nonexistent/mesh.ply"), views)
    res = correct(scene, images=images, mappings=mappings, reference=0, method="seqcc")
    assert res.paths[2] == [2, 1, 0]
    truth = images[0].astype(np.float64)
    for v in (1, 2):
        out = res.images[v].astype(np.float64)
        for c in range(3):
            # the corrected view has the reference's spread (contrast) and per-level colours
            assert out[..., c].std() / truth[..., c].std() == pytest.approx(1.0, abs=0.05), (v, c)
            slope = np.polyfit(truth[..., c].ravel(), out[..., c].ravel(), 1)[0]
            assert slope == pytest.approx(1.0, abs=0.06), (v, c)
        assert _mae(res.images[v], images[0]) < 4.0


def test_seqcc_stays_close_to_ground_truth_with_pose_error(tmp_path):
    """Mappings from poses rotated by 1 deg (~2 px, like real registration error): seqcc still
    recovers the true colours, while a conditional-mean CMF (vandermonde) that scores well on the
    misregistered pairs themselves drifts back toward the uncorrected error."""
    import o3d_seqcc.synthetic as synthetic
    from o3d_seqcc.io.images import read_image
    from o3d_seqcc.mappings.compute import compute_mappings
    from o3d_seqcc.evaluation.metrics import image_delta_e

    ss = synthetic.make_synthetic_scene(tmp_path / "s", n_views=6, width=160, height=120, seed=3)
    scene = synthetic.perturb_poses(ss.scene, 1.0, seed=0)
    assert not np.allclose(scene.views[1].extrinsic, ss.scene.views[1].extrinsic)
    np.testing.assert_array_equal(scene.views[0].extrinsic, ss.scene.views[0].extrinsic)  # reference kept exact
    mappings = compute_mappings(scene, mappings="dense")
    gt = [read_image(ss.gt_images[n]) for n in scene.names]
    masks = [np.load(ss.face_ids[n]) >= 0 for n in scene.names]
    de = {}
    for m in ("none", "vandermonde", "seqcc"):
        r = correct(scene, reference=0, method=m, mappings=mappings, t_npm=20)
        de[m] = np.mean([image_delta_e(r.images[i], gt[i], mask=masks[i]) for i in range(1, len(gt))])
    assert de["seqcc"] < 0.4 * de["none"], de
    assert de["seqcc"] < 0.6 * de["vandermonde"], de


def test_perturb_poses_rotates_about_the_camera_centre(tmp_path):
    import o3d_seqcc.synthetic as synthetic
    ss = synthetic.make_synthetic_scene(tmp_path / "s", n_views=3, width=64, height=48, seed=1)
    moved = synthetic.perturb_poses(ss.scene, 2.0, seed=5, keep=())
    for v0, v1 in zip(ss.scene.views, moved.views):
        e0, e1 = np.asarray(v0.extrinsic), np.asarray(v1.extrinsic)
        centre = lambda e: -e[:3, :3].T @ e[:3, 3]  # noqa: E731
        np.testing.assert_allclose(centre(e1), centre(e0), atol=1e-9)
        q = e1[:3, :3] @ e0[:3, :3].T
        angle = np.degrees(np.arccos(np.clip((np.trace(q) - 1) / 2, -1, 1)))
        assert abs(angle - 2.0) < 1e-6
    with pytest.raises(ValueError, match="degrees"):
        synthetic.perturb_poses(ss.scene, float("nan"))


def test_colour_inliers_drops_wrong_correspondences(rng):
    from o3d_seqcc.correction.cmf import fit_cmf
    from o3d_seqcc.correction.methods.seqcc import colour_inliers

    n = 4000
    ct = rng.uniform(0.05, 0.9, (n, 3))
    cs = np.clip(ct ** np.array([0.8, 1.0, 1.25]) + rng.normal(0, 0.01, (n, 3)), 0, 1)
    wrong = rng.random(n) < 0.05
    cs[wrong] = rng.uniform(0, 1, (wrong.sum(), 3))  # another surface's colour
    lut = np.stack([fit_cmf(ct[:, c], cs[:, c]) for c in range(3)])
    keep = colour_inliers(ct, cs, lut, k=3.0)
    assert keep[~wrong].mean() > 0.98
    assert (~keep[wrong]).mean() > 0.85
    assert colour_inliers(ct[:5], cs[:5], lut).all()  # too few to judge: all kept


def test_quantile_luts_recover_a_known_tone_curve(rng):
    from o3d_seqcc.correction.cmf import quantile_samples
    from o3d_seqcc.correction.methods.seqcc import quantile_luts

    ct = rng.uniform(0.0, 1.0, (20000, 3))
    gammas = np.array([0.7, 1.0, 1.6])
    lut = quantile_luts(ct, ct**gammas, n_out=256)
    grid = np.linspace(0, 1, 256)
    inner = (grid > 0.05) & (grid < 0.95)
    for c in range(3):
        np.testing.assert_allclose(lut[c, inner], grid[inner] ** gammas[c], atol=0.02)
        assert np.all(np.diff(lut[c]) >= 0)
        # the same curve as the weighted quantile pairing of cmf (unit weights)
        xq, yq, _ = quantile_samples(ct[:, c], ct[:, c] ** gammas[c], np.ones(len(ct)))
        np.testing.assert_allclose(lut[c], np.interp(grid, xq, yq), atol=1e-6)
