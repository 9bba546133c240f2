"""Semi-real ground truth: real photos with a hidden camera-like change and a known answer.

Pairwise scores at the correspondences of real photos (paper Table 2) cannot tell a faithful
correction from one that flattens the images: the correspondences are misregistered by a few
pixels, and shrinking every image toward its mean raises PSNR there. This protocol keeps the
real scene (its geometry, its registration error, its textures) and adds a known answer:

1. :func:`make_semireal`: every view except the reference gets a hidden, random camera-like
   change (:func:`apply_camera_change`: exposure, white balance, per-channel gamma, S-curve, in
   linear light, then 8-bit quantised; ranges :data:`o3d_seqcc.evaluation.photometric.CAMERA_CHANGE_RANGES`).
   The original photos are the truth: they were consistent enough to texture the mesh, and the
   reference stays as it was.
2. The changed photos are corrected with any method (:func:`o3d_seqcc.correction.correct`).
3. :func:`view_errors`: mean CIEDE2000 between each corrected photo and its original over the
   pixels the mesh covers (:func:`coverage_masks`, ray cast from each view's camera): a method
   that flattens the images is now far from the answer.

Running the same method on the unchanged photos (:func:`evaluate_semireal` does both) measures
how much it moves photos that were already consistent -- its floor on real data.
"""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..errors import InputError
from ..imaging.arrays import img_as_dtype, img_as_float, linear_to_srgb, srgb_to_linear
from .photometric import CAMERA_CHANGE_RANGES, apply_photometric, identity_photometric, sample_camera_change

__all__ = [
    "SemiRealCase",
    "SemiRealResult",
    "apply_camera_change",
    "camera_change_lut",
    "coverage_masks",
    "evaluate_semireal",
    "linear_to_srgb",
    "make_semireal",
    "srgb_to_linear",
    "view_errors",
]

logger = logging.getLogger(__name__)


def apply_camera_change(image: np.ndarray, params: dict[str, Any]) -> np.ndarray:
    """Apply a camera-like change to an sRGB photo in linear light.

    The photo is decoded to linear light, changed by :func:`o3d_seqcc.evaluation.photometric.apply_photometric`
    (``clip(x * gain * wb[c]) ** gamma[c]``, then the S-curve) and encoded back to sRGB.

    Parameters
    ----------
    image : (H, W, 3) uint8, uint16 or float array in [0, 1]
        sRGB photo.
    params : dict
        ``gain``, ``white_balance`` (3), ``gamma`` (3), ``s_curve``, e.g. from
        :func:`o3d_seqcc.evaluation.photometric.sample_camera_change`.

    Returns
    -------
    numpy.ndarray
        Same shape and dtype as ``image`` (integers rounded: uint8 is 8-bit quantised).
    """
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3:
        raise InputError(f"apply_camera_change: image must be (H, W, 3) RGB, got shape {img.shape}")
    out = linear_to_srgb(apply_photometric(srgb_to_linear(img_as_float(img)), params))
    return img_as_dtype(out, img.dtype)


def camera_change_lut(params: dict[str, Any], *, size: int = 256, inverse: bool = False) -> np.ndarray:
    """The camera-like change of :func:`apply_camera_change` as per-channel lookup tables.

    Parameters
    ----------
    params : dict
        As for :func:`apply_camera_change`.
    size : int, default 256
        Table length (inputs ``linspace(0, 1, size)``, sRGB-encoded).
    inverse : bool, default False
        The inverse change instead (what a perfect correction applies): where the change
        clipped, the inverse is the lowest input that reaches the clipped value.

    Returns
    -------
    numpy.ndarray
        (3, size) float64 in [0, 1], monotone non-decreasing.
    """
    fine = np.linspace(0.0, 1.0, 8 * int(size) + 1)
    fwd = linear_to_srgb(apply_photometric(np.repeat(srgb_to_linear(fine)[:, None], 3, axis=1), params)).T  # (3, F)
    grid = np.linspace(0.0, 1.0, int(size))
    if not inverse:
        return np.stack([np.interp(grid, fine, fwd[c]) for c in range(3)])
    out = np.empty((3, grid.size))
    for c in range(3):
        y = np.maximum.accumulate(fwd[c])
        keep = np.concatenate([[True], np.diff(y) > 0])  # first input of each output value
        out[c] = np.interp(grid, y[keep], fine[keep])
    return out


@dataclass(frozen=True, eq=False)
class SemiRealCase:
    """Photos with a hidden change per view, and the truth.

    Attributes
    ----------
    images : tuple of (H, W, 3) arrays
        The changed photos (the reference's is the original), input dtype.
    originals : tuple of (H, W, 3) arrays
        The unchanged photos: the answer.
    params : tuple of dict
        The change applied to each view (identity for the reference).
    reference : int
        The view left unchanged.
    seed : int
        Seed of the draws.
    """

    images: tuple
    originals: tuple
    params: tuple
    reference: int
    seed: int


def make_semireal(
    images: Sequence[np.ndarray],
    *,
    reference: int,
    seed: int = 0,
    ranges: dict[str, Any] | None = None,
) -> SemiRealCase:
    """Hide a random camera-like change in every photo except the reference's.

    Parameters
    ----------
    images : sequence of (H, W, 3) uint8 / uint16 / float arrays
        The real photos (not modified).
    reference : int
        Index of the view left unchanged.
    seed : int, default 0
        Seed of ``numpy.random.default_rng``; the draws depend only on it and the number of views.
    ranges : dict, optional
        Keyword ranges of :func:`o3d_seqcc.evaluation.photometric.sample_camera_change` (default
        :data:`o3d_seqcc.evaluation.photometric.CAMERA_CHANGE_RANGES`: exposure 0.6-1.6, white balance
        +-20 %, gamma 0.64-1.51 per channel, S-curve 0-0.6).

    Returns
    -------
    SemiRealCase
    """
    originals = tuple(np.asarray(im) for im in images)
    n = len(originals)
    if not (isinstance(reference, (int, np.integer)) and 0 <= int(reference) < n):
        raise InputError(f"make_semireal: reference must be a view index in 0..{n - 1}, got {reference!r}")
    ranges = dict(CAMERA_CHANGE_RANGES if ranges is None else ranges)
    rng = np.random.default_rng(seed)
    params, changed = [], []
    for v, img in enumerate(originals):
        p = sample_camera_change(rng, **ranges)  # drawn for every view: the draws do not depend on the reference
        if v == int(reference):
            p = identity_photometric()
        params.append(p)
        changed.append(np.array(img, copy=True) if v == int(reference) else apply_camera_change(img, p))
    return SemiRealCase(images=tuple(changed), originals=originals, params=tuple(params), reference=int(reference), seed=int(seed))


def coverage_masks(scene, *, mesh: Any = None) -> list[np.ndarray]:
    """Pixels of each view that see the mesh (one ray per pixel centre, Open3D ray casting).

    Parameters
    ----------
    scene : o3d_seqcc.Scene
    mesh : optional
        Anything :func:`o3d_seqcc.evaluation.render.raycast` takes (default: ``scene.load_mesh()``).

    Returns
    -------
    list of (H, W) bool arrays
    """
    from .render import raycast

    mesh = scene.load_mesh() if mesh is None else mesh
    return [raycast(mesh, v).mask for v in scene.views]


def view_errors(
    corrected: Sequence[np.ndarray],
    truth: Sequence[np.ndarray],
    masks: Sequence[np.ndarray],
    *,
    skip: Sequence[int] = (),
    stride: int = 1,
) -> np.ndarray:
    """Mean CIEDE2000 between each corrected photo and its truth over its mask.

    Parameters
    ----------
    corrected, truth : sequences of (H, W, 3) uint8 / uint16 / float arrays
        One per view, same shapes pairwise.
    masks : sequence of (H, W) bool arrays
        Pixels scored per view (e.g. :func:`coverage_masks`).
    skip : sequence of int, default ()
        Views not scored (NaN), e.g. the reference.
    stride : int, default 1
        Score every ``stride``-th pixel in both directions (2 is 4x faster; the mean over a
        regular sub-grid of a whole view differs from the full mean by far less than 0.01).

    Returns
    -------
    numpy.ndarray
        (n_views,) float64, NaN for skipped views and empty masks.
    """
    from .metrics import image_delta_e

    if not (len(corrected) == len(truth) == len(masks)):
        raise InputError(f"view_errors: {len(corrected)} corrected, {len(truth)} truth images and {len(masks)} masks; give one each per view")
    stride = int(stride)
    if stride < 1:
        raise InputError(f"view_errors: stride must be an integer >= 1, got {stride}")
    out = np.full(len(corrected), np.nan)
    sk = {int(v) for v in skip}
    for v, (a, b, m) in enumerate(zip(corrected, truth, masks)):
        if v in sk:
            continue
        a, b, m = np.asarray(a), np.asarray(b), np.asarray(m, dtype=bool)
        if a.shape != b.shape or m.shape != a.shape[:2]:
            raise InputError(f"view_errors: view {v} has image {a.shape}, truth {b.shape}, mask {m.shape}; they must match")
        sl = (slice(None, None, stride), slice(None, None, stride))
        out[v] = image_delta_e(a[sl], b[sl], mask=m[sl])  # NaN for an empty mask
    return out


@dataclass(frozen=True, eq=False)
class SemiRealResult:
    """Scores of several methods on semi-real cases.

    Attributes
    ----------
    methods : tuple of str
        Labels of the methods, in order.
    seeds : tuple of int
    reference : int
    errors : dict of str to (n_seeds, n_views) float arrays
        Per method, each view's mean CIEDE2000 to the original photo (NaN for the reference).
    unchanged : dict of str to (n_views,) float arrays
        Per method, the same score when the method corrects the unchanged photos: how much it
        moves photos that were consistent already -- or, on real photos, how much of their own
        inconsistency (auto exposure, white balance, view-dependent light) it removes.
    seconds : dict of str to float
        Per method, mean wall time of one ``correct`` call.
    params : tuple of tuple of dict
        Per seed, the hidden change of each view.
    invariance : dict of str to (n_seeds, n_views) float arrays
        Per method, mean CIEDE2000 between its correction of the changed photos and its
        correction of the unchanged ones: how completely it undoes the hidden change, whatever
        it does to the originals (empty when ``unchanged`` was not run).
    oracle : (n_seeds, n_views) float array
        The score of undoing exactly the hidden change (:func:`camera_change_lut` with
        ``inverse=True``): what quantisation and clipping leave of the answer.
    """

    methods: tuple
    seeds: tuple
    reference: int
    errors: dict
    unchanged: dict
    seconds: dict
    params: tuple = field(default=(), repr=False)
    invariance: dict = field(default_factory=dict)
    oracle: np.ndarray | None = None

    def summary(self) -> dict[str, dict[str, Any]]:
        """Per method: ``mean`` / ``worst`` per seed (lists), their averages, ``unchanged`` mean and
        worst, ``invariance_mean``, ``seconds``."""
        out = {}
        for m in self.methods:
            e = self.errors[m]
            means, worst = np.nanmean(e, axis=1), np.nanmax(e, axis=1)
            u = self.unchanged.get(m)
            inv = self.invariance.get(m)
            out[m] = {
                "mean": means.tolist(),
                "worst": worst.tolist(),
                "mean_avg": float(means.mean()),
                "worst_avg": float(worst.mean()),
                "worst_max": float(worst.max()),
                "unchanged_mean": None if u is None else float(np.nanmean(u)),
                "unchanged_worst": None if u is None else float(np.nanmax(u)),
                "invariance_mean": None if inv is None else float(np.nanmean(inv)),
                "seconds": self.seconds.get(m),
            }
        return out


def evaluate_semireal(
    scene,
    *,
    methods: Sequence[str | tuple[str, str, dict]],
    seeds: Sequence[int] = (0, 1, 2),
    reference: str | int = 0,
    mappings=None,
    images: Sequence[np.ndarray] | None = None,
    masks: Sequence[np.ndarray] | None = None,
    t_npm: int | str | None = None,
    ranges: dict[str, Any] | None = None,
    stride: int = 2,
    unchanged: bool = True,
) -> SemiRealResult:
    """Score correction methods on a real scene with hidden camera-like changes (module docstring).

    Parameters
    ----------
    scene : o3d_seqcc.Scene
    methods : sequence
        Registry names of :func:`o3d_seqcc.correction.correct`, or ``(label, name, options)``.
    seeds : sequence of int, default (0, 1, 2)
        One hidden change per view per seed (:func:`make_semireal`).
    reference : str or int, default 0
        View name or index left unchanged and used as the correction reference.
    mappings : o3d_seqcc.mappings.Mappings, optional
        Default ``compute_mappings(scene)`` (geometry only: shared by all seeds and methods).
    images : sequence of (H, W, 3) arrays, optional
        The photos (default: the scene's).
    masks : sequence of (H, W) bool arrays, optional
        Scored pixels (default :func:`coverage_masks`).
    t_npm : "auto" or int, optional
        Graph threshold (:func:`o3d_seqcc.correction.graph.resolve_t_npm`); default
        :attr:`CorrectionSettings.t_npm <o3d_seqcc.correction.settings.CorrectionSettings.t_npm>`.
    ranges : dict, optional
        Ranges of the hidden change (:func:`make_semireal`).
    stride : int, default 2
        Pixel stride of the scoring (:func:`view_errors`).
    unchanged : bool, default True
        Also run every method on the unchanged photos (and score the invariance).

    Returns
    -------
    SemiRealResult
    """
    from ..correction import CorrectionSettings, LutTransform, correct
    from ..correction.graph import build_graph, choose_reference, resolve_t_npm
    from ..mappings.compute import compute_mappings
    from ..scene import resolve_view

    if mappings is None:
        mappings = compute_mappings(scene)
    originals = [v.load_image() for v in scene.views] if images is None else [np.asarray(im) for im in images]
    t_npm = CorrectionSettings.resolve(None, {"t_npm": t_npm}, where="evaluate_semireal").t_npm
    masks = coverage_masks(scene) if masks is None else list(masks)
    t_eff = resolve_t_npm(t_npm, mappings, image_sizes=[(v.width, v.height) for v in scene.views])[0]
    graph = build_graph(dict(mappings.counts), len(originals), t_npm=t_eff)
    ref = choose_reference(graph) if isinstance(reference, str) and reference == "auto" else resolve_view(scene.names, reference)
    specs = [(m, m, {}) if isinstance(m, str) else (str(m[0]), str(m[1]), dict(m[2])) for m in methods]
    if not specs:
        raise InputError("evaluate_semireal: give at least one method")
    cases = [make_semireal(originals, reference=ref, seed=int(s), ranges=ranges) for s in seeds]
    errors: dict[str, np.ndarray] = {}
    plain: dict[str, np.ndarray] = {}
    seconds: dict[str, float] = {}

    def run(name: str, opts: dict, imgs) -> tuple[list, float]:
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            res = correct(scene, reference=ref, method=name, t_npm=t_npm, mappings=mappings, images=imgs, **opts)
        return res.images, time.perf_counter() - t0

    invariance: dict[str, np.ndarray] = {}
    for label, name, opts in specs:
        rows, inv, secs = [], [], []
        base = None
        if unchanged:
            base, dt = run(name, opts, originals)
            secs.append(dt)
            plain[label] = view_errors(base, originals, masks, skip=(ref,), stride=stride)
        for case in cases:
            out, dt = run(name, opts, list(case.images))
            secs.append(dt)
            rows.append(view_errors(out, case.originals, masks, skip=(ref,), stride=stride))
            if base is not None:
                inv.append(view_errors(out, base, masks, skip=(ref,), stride=stride))
        errors[label] = np.stack(rows)
        if inv:
            invariance[label] = np.stack(inv)
        seconds[label] = float(np.mean(secs))
        logger.info("semireal %s: mean %.2f (seeds %s)", label, float(np.nanmean(errors[label])), list(seeds))
    oracle = []
    for case in cases:
        undone = [
            np.array(im, copy=True) if v == ref else LutTransform(camera_change_lut(p, size=4096, inverse=True)).apply_levels(im)
            for v, (im, p) in enumerate(zip(case.images, case.params))
        ]
        oracle.append(view_errors(undone, case.originals, masks, skip=(ref,), stride=stride))
    return SemiRealResult(methods=tuple(lbl for lbl, _, _ in specs), seeds=tuple(int(s) for s in seeds), reference=ref,
                          errors=errors, unchanged=plain, seconds=seconds, params=tuple(c.params for c in cases),
                          invariance=invariance, oracle=np.stack(oracle))
