"""The paper's Table 2 of a correction: PSNR / CIEDE2000 and contrast ratios, before and after.

:func:`before_after` scores the images before and after a correction over the same (thinned)
mappings of every pair, with :mod:`~o3d_seqcc.evaluation.metrics`' scoring
(:func:`~o3d_seqcc.evaluation.metrics.evaluate`'s numbers) and, from the same samples, the
contrast ratios (:func:`~o3d_seqcc.evaluation.metrics.contrast_ratios`) that keep the scores
honest. It is what a run's report and ``report.json``'s ``metrics`` hold.
"""

from __future__ import annotations

import logging
from typing import Any, Sequence

import numpy as np

from .metrics import PSNR_CAP_DB, _check_images, _json_float, _pair_items, _ratio, _score

__all__ = ["before_after"]

logger = logging.getLogger(__name__)


def _contrast_summary(ratios: np.ndarray) -> dict[str, Any]:
    return {"mean": _json_float(ratios.mean()) if ratios.size else None,
            "min": _json_float(ratios.min()) if ratios.size else None, "n_pairs": int(ratios.size)}


def before_after(
    originals: Sequence[np.ndarray],
    corrected: Sequence[np.ndarray],
    mappings,
    paths: dict[int, list[int]],
    *,
    max_per_pair: int | None = None,
    per_pair: bool = False,
    min_n_contrast: int = 50,
) -> dict[str, Any]:
    """Table 2 of a correction: PSNR / CIEDE2000 summaries and contrast ratios, before and after.

    Every pair is built (and thinned) once for the four scorings; per image set each view is read and
    sampled once (lazy sequences: one image held at a time), the contrast ratios from the same samples.

    Parameters
    ----------
    originals, corrected : sequences of (H, W, 3) arrays
        The images before and after the correction, one per view.
    mappings : o3d_seqcc.mappings.Mappings
    paths : dict[int, list[int]]
        The correction paths (for :func:`contrast_ratios`).
    max_per_pair : int, optional
        At most this many evenly spaced mappings scored per pair (default all).
    per_pair : bool, default False
        Also list every pair's scores.
    min_n_contrast : int, default 50

    Returns
    -------
    dict
        JSON-ready: ``before`` and ``after`` (:meth:`Evaluation.to_dict`), ``contrast``
        (``before`` / ``after``: mean, min and number of pairs of :func:`contrast_ratios`).
    """
    originals = _check_images(originals, int(mappings.n_views))
    corrected = _check_images(corrected, int(mappings.n_views))
    names = tuple(getattr(mappings, "view_names", ()) or ())
    hops = {int(v): len(p) - 1 for v, p in paths.items()}
    keys = sorted(mappings.pairs)
    skipped: list[tuple[int, int]] = []
    # thinned pairs are small: build them once for the four scorings; all mappings are streamed each time
    items = list(_pair_items(mappings, keys, min_n=1, max_per_pair=max_per_pair, skipped=skipped)) \
        if max_per_pair is not None else None
    out: dict[str, Any] = {}
    contrast: dict[str, Any] = {}  # ("contrast" after "before" and "after", as report.json holds them)
    for key, images in (("before", originals), ("after", corrected)):
        ratios: list[float] = []

        def keep(item, ca: np.ndarray, cb: np.ndarray) -> None:  # the contrast ratios from the same samples
            r = _ratio(item, ca, cb, hops) if item[2] >= min_n_contrast else None
            if r is not None:
                ratios.append(r)

        it = items if items is not None else _pair_items(mappings, keys, min_n=1, max_per_pair=None, skipped=[])
        ev = _score(images, it, interpolation="bilinear", psnr_cap=PSNR_CAP_DB, names=names,
                    skipped=skipped if items is not None else [], max_per_pair=max_per_pair, colours=keep)
        out[key] = ev.to_dict(per_pair=per_pair)
        contrast[key] = _contrast_summary(np.array(ratios))
    out["contrast"] = contrast
    return out
