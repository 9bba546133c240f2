"""Image-based colour-similarity metrics over pairwise mappings (paper section 4, Table 2).

For every view pair ``(a, b)`` the two images are sampled at the pair's filtered mappings
(:func:`o3d_seqcc.imaging.arrays.sample_colors`) and compared:

- **PSNR** ``20 log10(L / RMS)`` over all mapped channel values, computed on colours scaled
  to [0, 1] (``L = 1``; identical to ``L = 255`` on 8-bit values and ``L = 65535`` on 16-bit
  values, so 8- and 16-bit images agree). Higher is more similar. Identical colours give
  ``inf``; summaries cap every pair at :data:`PSNR_CAP_DB` (100 dB) so a single perfect pair
  cannot make a mean infinite (the per-pair record keeps ``inf``).
- **CIEDE2000** (:func:`o3d_seqcc.imaging.arrays.delta_e_2000`, scikit-image) between the CIE Lab
  values of the two colours (sRGB with its transfer function -> XYZ -> Lab, D65), averaged
  over the pair's mappings. Lower is more similar.

The summaries are the paper's Table 2: simple mean over pairs, mean weighted by the number
of mappings ``n`` of each pair, and the (population, ``ddof=0``) standard deviation over pairs.
``max_per_pair`` scores at most that many evenly spaced mappings of each pair (deterministic;
the weights stay the pairs' full counts): fountain, 524 pairs, 3.9 M mappings, 5 s per scoring
in full, 0.2 s with 250 per pair.

:func:`contrast_ratios` is the column that keeps the scores honest: a correction that washes
the images out (shrinks colours toward the mean) scores well at misregistered mappings, and
shows a contrast ratio below 1. :func:`o3d_seqcc.evaluation.table2.before_after` gives both, before
and after a correction.

This module only scores; :mod:`o3d_seqcc.evaluation` fits a correction method and scores it
(the paper's in-sample protocol and a held-out one).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np

from ..errors import InputError
from ..imaging.arrays import INTERPOLATIONS, delta_e_2000, dtype_scale, img_as_float, sample_colors
from ..imaging.sequences import ImageSequence, image_dtypes
from ..mappings.pairs import thinned_many

__all__ = [
    "PSNR_CAP_DB",
    "Evaluation",
    "MetricSummary",
    "PairScore",
    "blur_images",
    "contrast_ratios",
    "evaluate",
    "image_delta_e",
    "psnr",
    "thin_indices",
]

logger = logging.getLogger(__name__)

#: Cap (dB) applied to per-pair PSNR values in summaries (identical colours give inf).
PSNR_CAP_DB = 100.0

#: mappings converted to Lab per batch in :func:`evaluate` (bounds the memory to ~0.5 GB)
_BATCH = 1_000_000


# ----------------------------------------------------------------------------- primitives
def psnr(colors_a: np.ndarray, colors_b: np.ndarray, *, peak: float = 1.0) -> float:
    """Peak signal-to-noise ratio ``20 log10(peak / RMS)`` over all values.

    Parameters
    ----------
    colors_a, colors_b : array_like of the same shape
        Colours (e.g. (n, 3) in [0, 1]).
    peak : float, default 1.0
        Largest possible value (1 for [0, 1] colours, 255 for 8-bit values).

    Returns
    -------
    float
        PSNR in dB; ``inf`` when the colours are identical, ``nan`` when empty.
    """
    a = np.asarray(colors_a, dtype=np.float64)
    b = np.asarray(colors_b, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"psnr: shapes differ, {a.shape} vs {b.shape}")
    if a.size == 0:
        return float("nan")
    mse = float(np.mean((a - b) ** 2))
    if mse == 0.0:
        return float("inf")
    return float(20.0 * math.log10(peak / math.sqrt(mse)))


def blur_images(images: Sequence[np.ndarray], sigma: float) -> list[np.ndarray]:
    """Gaussian-blur images (for scoring only, to soften a few pixels of pose error).

    Parameters
    ----------
    images : sequence of (H, W, 3) arrays
        Any dtype OpenCV's ``GaussianBlur`` accepts (uint8, uint16, float32/64).
    sigma : float
        Standard deviation in pixels; ``<= 0`` returns the images unchanged (not copied).

    Returns
    -------
    list of numpy.ndarray
        Blurred images, same dtype and shape (new arrays).
    """
    if sigma <= 0:
        return list(images)
    import cv2

    out = []
    for im in images:
        im = np.asarray(im)
        out.append(cv2.GaussianBlur(im, (0, 0), sigmaX=float(sigma), sigmaY=float(sigma), borderType=cv2.BORDER_REFLECT))
    return out


def image_delta_e(image: np.ndarray, truth: np.ndarray, *, mask: np.ndarray | None = None) -> float:
    """Mean CIEDE2000 between an image and its ground truth over a pixel mask.

    Parameters
    ----------
    image, truth : (H, W, 3) uint8 / uint16 / float [0, 1] arrays
        Each scaled to [0, 1] by its own dtype.
    mask : (H, W) bool array, optional
        Pixels to include (e.g. the pixels the mesh covers); default all.

    Returns
    -------
    float
        Mean Delta E 2000 (``nan`` if the mask is empty).
    """
    image = np.asarray(image)
    truth = np.asarray(truth)
    if image.shape != truth.shape or image.ndim != 3 or image.shape[2] != 3:
        raise InputError(f"image_delta_e: need two (H, W, 3) images of the same shape, got {image.shape} and {truth.shape}")
    if mask is None:
        a, b = image.reshape(-1, 3), truth.reshape(-1, 3)
    else:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != image.shape[:2]:
            raise InputError(f"image_delta_e: mask shape {mask.shape} != image shape {image.shape[:2]}")
        a, b = image[mask], truth[mask]
    if len(a) == 0:
        return float("nan")
    return float(np.mean(delta_e_2000(img_as_float(a), img_as_float(b))))


# ----------------------------------------------------------------------------- results
@dataclass(frozen=True)
class PairScore:
    """Metrics of one view pair.

    Attributes
    ----------
    a, b : int
        View indices (a < b).
    n : int
        Number of mappings of the pair (its weight in the weighted means).
    psnr : float
        dB over all channel values in [0, 1] of the scored mappings (``inf`` for identical colours).
    ciede2000 : float
        Mean Delta E 2000 over the scored mappings.
    n_scored : int or None
        Number of mappings scored when fewer than ``n`` (``max_per_pair``); None = all n.
    """

    a: int
    b: int
    n: int
    psnr: float
    ciede2000: float
    n_scored: int | None = None


@dataclass(frozen=True)
class MetricSummary:
    """Summary of one metric over pairs (paper Table 2): mean, mean weighted by n, std (ddof=0)."""

    mean: float
    weighted_mean: float
    std: float

    @staticmethod
    def from_values(values: np.ndarray, weights: np.ndarray) -> "MetricSummary":
        values = np.asarray(values, dtype=np.float64)
        weights = np.asarray(weights, dtype=np.float64)
        if len(values) == 0:
            nan = float("nan")
            return MetricSummary(nan, nan, nan)
        return MetricSummary(
            mean=float(values.mean()),
            weighted_mean=float(np.average(values, weights=weights)) if weights.sum() > 0 else float("nan"),
            std=float(values.std()),
        )

    def to_dict(self) -> dict[str, float | None]:
        return {k: _json_float(v) for k, v in (("mean", self.mean), ("weighted_mean", self.weighted_mean), ("std", self.std))}


def _json_float(x: float) -> float | None:
    """JSON has no inf/nan: non-finite values are written as None (null)."""
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass(frozen=True)
class Evaluation:
    """Per-pair PSNR / CIEDE2000 and their summaries (paper Table 2).

    Attributes
    ----------
    pairs : tuple of PairScore
        One record per scored pair, sorted by (a, b).
    psnr : MetricSummary
        Over pairs, each pair's PSNR capped at ``psnr_cap`` dB.
    ciede2000 : MetricSummary
        Over pairs.
    psnr_cap : float
        The cap used for the PSNR summaries.
    view_names : tuple of str
        Names of the views (for display), may be empty.
    skipped : tuple of (int, int)
        Pairs left out because they had fewer than ``min_n`` mappings.
    max_per_pair : int or None
        At most this many mappings were scored per pair (None: all).
    """

    pairs: tuple[PairScore, ...]
    psnr: MetricSummary
    ciede2000: MetricSummary
    psnr_cap: float = PSNR_CAP_DB
    view_names: tuple[str, ...] = ()
    skipped: tuple[tuple[int, int], ...] = ()
    max_per_pair: int | None = None

    @property
    def n_pairs(self) -> int:
        return len(self.pairs)

    @property
    def n_mappings(self) -> int:
        return int(sum(p.n for p in self.pairs))

    def to_dict(self, *, per_pair: bool = True) -> dict[str, Any]:
        """JSON-serialisable dict (non-finite per-pair PSNR is written as null)."""
        d: dict[str, Any] = {
            "n_pairs": self.n_pairs,
            "n_mappings": self.n_mappings,
            "psnr_cap_db": self.psnr_cap,
            "psnr": self.psnr.to_dict(),
            "ciede2000": self.ciede2000.to_dict(),
        }
        if self.max_per_pair is not None:
            d["max_per_pair"] = int(self.max_per_pair)
            d["n_scored"] = int(sum(p.n if p.n_scored is None else p.n_scored for p in self.pairs))
        if per_pair:
            names = self.view_names
            d["pairs"] = [
                {
                    "a": p.a,
                    "b": p.b,
                    **({"a_name": names[p.a], "b_name": names[p.b]} if len(names) > max(p.a, p.b) else {}),
                    "n": p.n,
                    "psnr": _json_float(p.psnr),
                    "ciede2000": _json_float(p.ciede2000),
                }
                for p in self.pairs
            ]
            d["skipped_pairs"] = [list(s) for s in self.skipped]
        return d

    def table(self, *, title: str | None = None) -> str:
        """Pretty text table of the summaries (Table 2 layout)."""
        head = f"{'':>10} {'mean':>8} {'w.mean':>8} {'std':>7}"
        lines = [title] if title else []
        lines.append(f"{self.n_pairs} pairs, {self.n_mappings} mappings")
        lines.append(head)
        lines.append(f"{'PSNR dB':>10} {self.psnr.mean:8.2f} {self.psnr.weighted_mean:8.2f} {self.psnr.std:7.2f}")
        lines.append(
            f"{'CIEDE2000':>10} {self.ciede2000.mean:8.2f} {self.ciede2000.weighted_mean:8.2f} {self.ciede2000.std:7.2f}"
        )
        return "\n".join(lines)


# ----------------------------------------------------------------------------- evaluate
def _rgb(im, i: int) -> np.ndarray:
    im = np.asarray(im)
    if im.ndim != 3 or im.shape[2] != 3:
        raise InputError(f"evaluate: image {i} has shape {im.shape}; expected (H, W, 3) RGB")
    return im


class _CheckedImages(ImageSequence):
    """A lazy sequence's images, each checked to be (H, W, 3) when it is read (its dtypes from the headers)."""

    def __init__(self, images: ImageSequence) -> None:
        self.images = images

    def __len__(self) -> int:
        return len(self.images)

    def _load(self, i: int) -> np.ndarray:
        return _rgb(self.images[i], i)

    def dtypes(self) -> list[np.dtype]:
        return self.images.dtypes()


def _check_images(images: Sequence[np.ndarray], n_views: int) -> Sequence[np.ndarray]:
    """The images, one per view, checked: a list of arrays now; a lazy sequence (read when a view is sampled,
    released after) by its dtypes now and each image's shape when it is read."""
    if len(images) != n_views:
        raise InputError(f"evaluate: got {len(images)} images for mappings over {n_views} views; pass one image per view")
    images = _CheckedImages(images) if isinstance(images, ImageSequence) else [_rgb(im, i) for i, im in enumerate(images)]
    for dt in image_dtypes(images):
        dtype_scale(dt)
    return images


def _pair_keys(mappings, pairs: Iterable[tuple[int, int]] | None) -> list[tuple[int, int]]:
    if pairs is None:
        return sorted(mappings.pairs)
    keys = []
    for a, b in pairs:
        key = (min(int(a), int(b)), max(int(a), int(b)))
        if key not in mappings.pairs:
            raise InputError(f"evaluate: pair {key} has no mappings; valid pairs are the keys of mappings.pairs")
        keys.append(key)
    return sorted(set(keys))


def thin_indices(n: int, k: int | None) -> np.ndarray | None:
    """Indices of ``k`` evenly spaced items out of ``n``, first and last included (None when n <= k or k is None).

    Deterministic and strictly increasing (``floor(i (n - 1) / (k - 1) + 0.5)``): how
    ``max_per_pair`` thins each pair's mappings.
    """
    if k is None or n <= k:
        return None
    if k == 1:
        return np.zeros(1, dtype=np.int64)
    return np.floor(np.linspace(0, n - 1, int(k)) + 0.5).astype(np.int64)


def _pair_items(mappings, keys, *, min_n: int, max_per_pair: int | None, skipped: list):
    """Yield ``(a, b, n, uv_a, uv_b)`` per pair with the (thinned) mappings; pairs below min_n go to ``skipped``.

    A generator: lazy pairs are built in batches of thinned pairs (:func:`~o3d_seqcc.mappings.pairs.thinned_many`),
    one at a time when all their mappings are scored (a large scene's are never all held).
    """
    if max_per_pair is not None and int(max_per_pair) < 1:
        raise ValueError(f"max_per_pair must be >= 1 or None, got {max_per_pair!r}")
    lo = max(int(min_n), 1)

    def pick(n: int) -> np.ndarray | None:  # only the mappings scored are built
        return thin_indices(n, max_per_pair) if n >= lo else np.zeros(0, np.int64)

    # pairs built in vectorised batches on local threads (numpy releases the GIL), yielded in order
    keys = list(keys)
    batch = None if max_per_pair is not None else 1
    for (a, b), (n, pm) in zip(keys, thinned_many(mappings.pairs, keys, pick, batch_pairs=batch)):
        if n < lo:
            skipped.append((a, b))
            continue
        yield a, b, n, pm.uv_a, pm.uv_b


def _sample_batch(images: Sequence[np.ndarray], scales: list[float], batch, interpolation: str):
    """Colours of a batch of pairs at their mappings, in [0, 1] (each view read once and sampled once, at all
    its positions in the batch), and where each pair starts."""
    views = np.concatenate([np.full(len(it[3]), it[0]) for it in batch] + [np.full(len(it[4]), it[1]) for it in batch])
    uv = np.concatenate([it[3] for it in batch] + [it[4] for it in batch])
    col = np.empty((len(uv), 3))
    order = np.argsort(views, kind="stable")
    cuts = np.flatnonzero(np.diff(views[order])) + 1
    for rows in np.split(order, cuts) if len(order) else ():
        v = int(views[rows[0]])
        col[rows] = sample_colors(images[v], uv[rows], interpolation=interpolation) / scales[v]
    half = len(uv) // 2
    return col[:half], col[half:], np.concatenate([[0], np.cumsum([len(it[3]) for it in batch])[:-1]]).astype(np.int64)


def _colour_batches(images: Sequence[np.ndarray], items, interpolation: str, meta: list):
    """Yield ``(batch, ca, cb, starts)``: the items in batches of about :data:`_BATCH` mappings, their colours
    in [0, 1] (each view read once per batch) and where each item's start; ``meta`` collects ``(a, b, n,
    n scored)`` per item."""
    scales = [dtype_scale(dt) for dt in image_dtypes(images)]
    batch: list = []
    size = 0
    for it in items:
        batch.append(it)
        meta.append((it[0], it[1], it[2], len(it[3])))
        size += len(it[3])
        if size >= _BATCH:
            yield batch, *_sample_batch(images, scales, batch, interpolation)
            batch, size = [], 0
    if batch:
        yield batch, *_sample_batch(images, scales, batch, interpolation)


def _score(images: Sequence[np.ndarray], items, *, interpolation: str, psnr_cap: float, names, skipped,
           max_per_pair: int | None, colours=None) -> Evaluation:
    """PSNR / CIEDE2000 of the images at the pairs' (thinned) mappings, vectorised in batches of pairs.

    ``colours(item, ca, cb)``, when given, sees every pair's colours (n, 3) in [0, 1] (the contrast ratios
    of :func:`before_after` come from the same samples).
    """
    sse_parts: list[np.ndarray] = []
    de_parts: list[np.ndarray] = []
    meta: list[tuple[int, int, int, int]] = []  # (a, b, n, n scored) per pair
    for batch, ca, cb, starts in _colour_batches(images, items, interpolation, meta):
        # per-pair sums of squared errors and of Delta E 2000 over a batch of pairs (vectorised)
        sse_parts.append(np.add.reduceat(((ca - cb) ** 2).sum(axis=1), starts))
        de_parts.append(np.add.reduceat(delta_e_2000(ca, cb), starts))
        for it, s0 in zip(batch, starts) if colours is not None else ():
            colours(it, ca[s0 : s0 + len(it[3])], cb[s0 : s0 + len(it[3])])
    if not meta:
        logger.warning("evaluate: no pair with enough mappings to score")
        nan = MetricSummary(float("nan"), float("nan"), float("nan"))
        return Evaluation((), nan, nan, float(psnr_cap), names, tuple(skipped), max_per_pair)
    counts = np.array([m[2] for m in meta], dtype=np.int64)
    n_scored = np.array([m[3] for m in meta], dtype=np.int64)
    mse = np.concatenate(sse_parts) / (3.0 * n_scored)  # over all channel values
    de_mean = np.concatenate(de_parts) / n_scored
    with np.errstate(divide="ignore"):
        psnr_vals = np.where(mse > 0, 20.0 * np.log10(1.0 / np.sqrt(np.maximum(mse, 1e-300))), np.inf)
    records = tuple(
        PairScore(a=a, b=b, n=n, psnr=float(p), ciede2000=float(d), n_scored=None if k == n else int(k))
        for (a, b, n, k), p, d in zip(meta, psnr_vals, de_mean)
    )
    capped = np.minimum(psnr_vals, float(psnr_cap))
    return Evaluation(
        pairs=records,
        psnr=MetricSummary.from_values(capped, counts),
        ciede2000=MetricSummary.from_values(de_mean, counts),
        psnr_cap=float(psnr_cap),
        view_names=names,
        skipped=tuple(skipped),
        max_per_pair=max_per_pair,
    )


def evaluate(
    images: Sequence[np.ndarray],
    mappings,
    *,
    pairs: Iterable[tuple[int, int]] | None = None,
    interpolation: str = "bilinear",
    min_n: int = 1,
    psnr_cap: float = PSNR_CAP_DB,
    max_per_pair: int | None = None,
) -> Evaluation:
    """PSNR and CIEDE2000 between the images of every view pair at its mappings.

    Parameters
    ----------
    images : sequence of (H, W, 3) arrays
        One per view of ``mappings`` (uint8, uint16 or float in [0, 1]; each scaled to [0, 1]
        by its dtype, so 8- and 16-bit versions of the same image score the same).
    mappings : o3d_seqcc.mappings.Mappings
        Pairwise mappings; ``mappings.pairs[(a, b)]`` has ``uv_a``, ``uv_b`` (n, 2) pixel
        coordinates (pixel centres at integers).
    pairs : iterable of (int, int), optional
        Subset of pairs to score (each ``(a, b)`` or ``(b, a)``); default all of ``mappings.pairs``.
    interpolation : {"bilinear", "nearest"}, default "bilinear"
        How images are sampled at the (sub-pixel) mappings.
    min_n : int, default 1
        Pairs with fewer mappings are skipped (listed in ``Evaluation.skipped``).
    psnr_cap : float, default :data:`PSNR_CAP_DB` (100 dB)
        Cap applied to per-pair PSNR in the summaries (identical colours give inf).
    max_per_pair : int, optional
        Score at most this many evenly spaced mappings of each pair (deterministic); the
        weighted means still weight each pair by its full count. Default: all mappings.

    Returns
    -------
    Evaluation
        Per-pair scores and the Table 2 summaries.

    Raises
    ------
    InputError
        Wrong number of images, non-RGB images, unknown pairs.
    ValueError
        Unknown ``interpolation``, ``max_per_pair`` below 1.
    """
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"unknown interpolation {interpolation!r}; valid: {', '.join(INTERPOLATIONS)}")
    images = _check_images(images, int(mappings.n_views))
    skipped: list[tuple[int, int]] = []
    items = _pair_items(mappings, _pair_keys(mappings, pairs), min_n=min_n, max_per_pair=max_per_pair, skipped=skipped)
    return _score(images, items, interpolation=interpolation, psnr_cap=psnr_cap, skipped=skipped,
                  names=tuple(getattr(mappings, "view_names", ()) or ()), max_per_pair=max_per_pair)


def _ratio(item, ca: np.ndarray, cb: np.ndarray, hops: dict[int, int]) -> float | None:
    """A pair's contrast ratio from its colours (None when its views are not at different hops)."""
    a, b = item[0], item[1]
    if a not in hops or b not in hops or hops[a] == hops[b]:
        return None
    ct, cs = (ca, cb) if hops[a] > hops[b] else (cb, ca)
    return float(np.mean(ct.std(0) / np.maximum(cs.std(0), 1e-6)))


def _contrast(images: Sequence[np.ndarray], items, hops: dict[int, int]) -> np.ndarray:
    """The contrast ratios of the pairs of ``items`` at different hops, in their order (sampled in batches)."""
    out = [_ratio(it, ca[s0 : s0 + len(it[3])], cb[s0 : s0 + len(it[3])], hops)
           for batch, ca, cb, starts in _colour_batches(images, items, "bilinear", []) for it, s0 in zip(batch, starts)]
    return np.array([r for r in out if r is not None])


def contrast_ratios(
    images: Sequence[np.ndarray],
    mappings,
    paths: dict[int, list[int]],
    *,
    min_n: int = 50,
    max_per_pair: int | None = None,
) -> np.ndarray:
    """Per-pair contrast ratio of (corrected) images: std(target) / std(source) at the mappings.

    For every pair whose views are at different hop distances from the reference along the
    correction ``paths``, the *target* is the view farther from the reference and the *source*
    the nearer one; the ratio is the per-channel standard deviation of the target's colours at
    the pair's mappings over the source's, averaged over the channels. About 1 for an honest
    correction; a method that shrinks colours toward the mean (washes images out, which pairwise
    PSNR / CIEDE2000 at misregistered mappings reward) gives < 1, compounding along the paths.

    Parameters
    ----------
    images : sequence of (H, W, 3) arrays
        One per view.
    mappings : o3d_seqcc.mappings.Mappings
    paths : dict[int, list[int]]
        ``view -> [view, ..., reference]`` (:func:`o3d_seqcc.correction.graph.correction_paths`,
        ``CorrectionResult.paths``); views absent from it are left out.
    min_n : int, default 50
        Pairs with fewer mappings are left out.
    max_per_pair : int, optional
        At most this many evenly spaced mappings per pair (default all).

    Returns
    -------
    numpy.ndarray
        (m,) float64, one ratio per pair used, in the order of the sorted pairs.
    """
    images = _check_images(images, int(mappings.n_views))
    hops = {int(v): len(p) - 1 for v, p in paths.items()}
    keys = [(a, b) for a, b in sorted(mappings.pairs) if a in hops and b in hops and hops[a] != hops[b]]
    return _contrast(images, _pair_items(mappings, keys, min_n=min_n, max_per_pair=max_per_pair, skipped=[]), hops)
