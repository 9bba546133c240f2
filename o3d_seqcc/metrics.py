"""Image-based colour-similarity metrics over pairwise mappings (paper section 4, Table 2).

For every view pair ``(a, b)`` the two images are sampled at the pair's filtered mappings
(:func:`o3d_seqcc.imageops.sample_colors`) and compared:

- **PSNR** ``20 log10(L / RMS)`` over all mapped channel values, computed on colours scaled
  to [0, 1] (``L = 1``; identical to ``L = 255`` on 8-bit values and ``L = 65535`` on 16-bit
  values, so 8- and 16-bit images agree). Higher is more similar. Identical colours give
  ``inf``; summaries cap every pair at :data:`PSNR_CAP_DB` (100 dB) so a single perfect pair
  cannot make a mean infinite (the per-pair record keeps ``inf``).
- **CIEDE2000** (:func:`o3d_seqcc.imageops.delta_e_2000`, scikit-image) between the CIE Lab
  values of the two colours (sRGB with its transfer function -> XYZ -> Lab, D65), averaged
  over the pair's mappings. Lower is more similar.

The summaries are the paper's Table 2: simple mean over pairs, mean weighted by the number
of mappings ``n`` of each pair, and the (population, ``ddof=0``) standard deviation over pairs.

This module only scores; :mod:`o3d_seqcc.evaluation` fits a correction method and scores it
(the paper's in-sample protocol and a held-out one).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np

from .errors import InputError
from .imageops import INTERPOLATIONS, delta_e_2000, dtype_scale, img_as_float, sample_colors

__all__ = [
    "PSNR_CAP_DB",
    "Evaluation",
    "MetricSummary",
    "PairScore",
    "blur_images",
    "evaluate",
    "image_delta_e",
    "psnr",
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
        Number of mappings scored.
    psnr : float
        dB over all 3 n channel values in [0, 1] (``inf`` for identical colours).
    ciede2000 : float
        Mean Delta E 2000 over the n mappings.
    """

    a: int
    b: int
    n: int
    psnr: float
    ciede2000: float


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
    """

    pairs: tuple[PairScore, ...]
    psnr: MetricSummary
    ciede2000: MetricSummary
    psnr_cap: float = PSNR_CAP_DB
    view_names: tuple[str, ...] = ()
    skipped: tuple[tuple[int, int], ...] = ()

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
def _check_images(images: Sequence[np.ndarray], n_views: int) -> list[np.ndarray]:
    images = [np.asarray(im) for im in images]
    if len(images) != n_views:
        raise InputError(f"evaluate: got {len(images)} images for mappings over {n_views} views; pass one image per view")
    for i, im in enumerate(images):
        if im.ndim != 3 or im.shape[2] != 3:
            raise InputError(f"evaluate: image {i} has shape {im.shape}; expected (H, W, 3) RGB")
        dtype_scale(im.dtype)
    return images


def evaluate(
    images: Sequence[np.ndarray],
    mappings,
    *,
    pairs: Iterable[tuple[int, int]] | None = None,
    interpolation: str = "bilinear",
    min_n: int = 1,
    psnr_cap: float = PSNR_CAP_DB,
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

    Returns
    -------
    Evaluation
        Per-pair scores and the Table 2 summaries.

    Raises
    ------
    InputError
        Wrong number of images, non-RGB images, unknown pairs.
    ValueError
        Unknown ``interpolation``.
    """
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"unknown interpolation {interpolation!r}; valid: {', '.join(INTERPOLATIONS)}")
    images = _check_images(images, int(mappings.n_views))
    scales = [dtype_scale(im.dtype) for im in images]
    if pairs is None:
        keys = sorted(mappings.pairs)
    else:
        keys = []
        for a, b in pairs:
            key = (min(int(a), int(b)), max(int(a), int(b)))
            if key not in mappings.pairs:
                raise InputError(f"evaluate: pair {key} has no mappings; valid pairs are the keys of mappings.pairs")
            keys.append(key)
        keys = sorted(set(keys))

    scored: list[tuple[int, int, int]] = []
    skipped: list[tuple[int, int]] = []
    sse_parts: list[np.ndarray] = []
    de_parts: list[np.ndarray] = []
    batch_a: list[np.ndarray] = []
    batch_b: list[np.ndarray] = []
    batch_n: list[int] = []

    def flush() -> None:
        # per-pair sums of squared errors and of Delta E 2000 over a batch of pairs (vectorised)
        if not batch_n:
            return
        ca, cb = np.concatenate(batch_a), np.concatenate(batch_b)
        starts = np.concatenate([[0], np.cumsum(batch_n)[:-1]])
        sse_parts.append(np.add.reduceat(((ca - cb) ** 2).sum(axis=1), starts))
        de_parts.append(np.add.reduceat(delta_e_2000(ca, cb), starts))
        batch_a.clear()
        batch_b.clear()
        batch_n.clear()

    for a, b in keys:
        pm = mappings.pairs[(a, b)]
        n = int(len(pm.uv_a))
        if n < max(int(min_n), 1):
            skipped.append((a, b))
            continue
        batch_a.append(sample_colors(images[a], pm.uv_a, interpolation=interpolation) / scales[a])
        batch_b.append(sample_colors(images[b], pm.uv_b, interpolation=interpolation) / scales[b])
        batch_n.append(n)
        scored.append((a, b, n))
        if sum(batch_n) >= _BATCH:
            flush()
    flush()

    names = tuple(getattr(mappings, "view_names", ()) or ())
    if not scored:
        logger.warning("evaluate: no pair with >= %d mappings to score", min_n)
        nan = MetricSummary(float("nan"), float("nan"), float("nan"))
        return Evaluation((), nan, nan, float(psnr_cap), names, tuple(skipped))

    counts = np.array([s[2] for s in scored], dtype=np.int64)
    mse = np.concatenate(sse_parts) / (3.0 * counts)  # over all channel values
    de_mean = np.concatenate(de_parts) / counts
    with np.errstate(divide="ignore"):
        psnr_vals = np.where(mse > 0, 20.0 * np.log10(1.0 / np.sqrt(np.maximum(mse, 1e-300))), np.inf)

    records = tuple(
        PairScore(a=a, b=b, n=n, psnr=float(p), ciede2000=float(d)) for (a, b, n), p, d in zip(scored, psnr_vals, de_mean)
    )
    capped = np.minimum(psnr_vals, float(psnr_cap))
    return Evaluation(
        pairs=records,
        psnr=MetricSummary.from_values(capped, counts),
        ciede2000=MetricSummary.from_values(de_mean, counts),
        psnr_cap=float(psnr_cap),
        view_names=names,
        skipped=tuple(skipped),
    )
