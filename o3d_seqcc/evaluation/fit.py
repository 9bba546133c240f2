"""Fitting a colour-correction method and scoring it: the paper's protocol and a held-out one.

:func:`evaluate_method` runs :func:`o3d_seqcc.correction.correct` and scores the corrected
images with :func:`o3d_seqcc.evaluation.metrics.evaluate` in two protocols: *in-sample* (the paper's:
fitted on all mappings, scored on all) and *held-out* (fitted on the mappings of part of the
mesh faces, :meth:`o3d_seqcc.mappings.Mappings.split`, scored on the others).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..correction import CorrectionSettings, correct
from ..errors import InputError
from ..correction.graph import PAPER_T_NPM
from .metrics import Evaluation, blur_images, evaluate

__all__ = ["MethodEvaluation", "evaluate_method", "evaluate_scene"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class MethodEvaluation:
    """A colour-correction method scored in-sample and on held-out mappings.

    Attributes
    ----------
    method : str
        Registry name of the method.
    reference : int
        Reference view index used (``"auto"`` is resolved by the in-sample run and reused).
    in_sample : Evaluation
        The paper's protocol: method fitted on all mappings, scored on all mappings.
    held_out : Evaluation or None
        Fitted on the ``fit`` part of ``mappings.split(holdout)``, scored on the ``test`` part
        (mesh faces never seen by the fit); None when ``holdout == 0``.
    fit_seconds : float
        Wall time of the in-sample ``correct`` call.
    holdout_fit_seconds : float or None
        Wall time of the held-out ``correct`` call.
    holdout : float
        Fraction of faces held out.
    seed : int
        Seed of the split.
    corrected : tuple of numpy.ndarray
        The in-sample corrected images (same dtype as the input), e.g. to score against ground truth.
    """

    method: str
    reference: int
    in_sample: Evaluation
    held_out: Evaluation | None
    fit_seconds: float
    holdout_fit_seconds: float | None
    holdout: float
    seed: int
    corrected: tuple[np.ndarray, ...] = field(default=(), repr=False)

    def to_dict(self, *, per_pair: bool = False) -> dict[str, Any]:
        return {
            "method": self.method,
            "reference": self.reference,
            "holdout": self.holdout,
            "seed": self.seed,
            "fit_seconds": self.fit_seconds,
            "holdout_fit_seconds": self.holdout_fit_seconds,
            "in_sample": self.in_sample.to_dict(per_pair=per_pair),
            "held_out": None if self.held_out is None else self.held_out.to_dict(per_pair=per_pair),
        }


def evaluate_method(
    scene_or_images,
    mappings,
    *,
    method: str,
    reference: str | int | None = None,
    holdout: float = 0.5,
    seed: int = 0,
    t_npm: int | str | None = None,
    blur: float = 0.0,
    interpolation: str | None = None,
    min_n: int = 1,
    scene=None,
    **options: Any,
) -> MethodEvaluation:
    """Fit a colour-correction method and score it in-sample and on held-out mappings.

    Parameters
    ----------
    scene_or_images : Scene or sequence of (H, W, 3) arrays
        A :class:`~o3d_seqcc.scene.Scene` (its images are loaded once) or the images
        themselves (then ``scene=`` may give the scene ``correct`` receives; without one the
        views are named by ``mappings.view_names``).
    mappings : Mappings
        All pairwise mappings of the scene.
    method : str
        Name in :data:`o3d_seqcc.correction.METHODS` (e.g. "none", "seqcc", "gain-compensation").
    reference : str or int, optional
        Passed to ``correct`` (default :class:`~o3d_seqcc.correction.settings.CorrectionSettings`'s,
        "auto"); the reference actually used by the in-sample run is reused for the held-out run
        (so both use the same view).
    holdout : float, default 0.5
        Fraction of mesh faces whose mappings are held out for scoring; 0 skips the held-out run.
    seed : int, default 0
        Seed of the face split.
    t_npm : "auto" or int, optional
        Minimum pair count per graph edge (default the settings', "auto"; passed to ``correct``;
        :func:`o3d_seqcc.correction.graph.resolve_t_npm`). With ``holdout`` the fit half has fewer
        mappings per pair; ``t_npm`` (``"auto"`` resolved first) is scaled by ``1 - holdout``
        for the held-out fit so the graph keeps the same edges.
    blur : float, default 0.0
        Gaussian sigma (px) applied to the corrected images before scoring only.
    interpolation, min_n
        Passed to :func:`evaluate` (``interpolation`` default the settings', "bilinear"; ``min_n``
        scaled by ``holdout`` for the held-out part).
    **options
        Extra keyword options of the method, passed to ``correct``.

    Returns
    -------
    MethodEvaluation
    """
    if not 0.0 <= float(holdout) < 1.0:
        raise InputError(f"holdout must be in [0, 1), got {holdout}")
    cs = CorrectionSettings.resolve(None, {"reference": reference, "method": method, "t_npm": t_npm,
                                           "interpolation": interpolation}, where="evaluate_method")
    reference, t_npm, interpolation = cs.reference, cs.t_npm, cs.interpolation
    if isinstance(scene_or_images, (list, tuple, np.ndarray)):
        images = [np.asarray(im) for im in scene_or_images]
    else:
        scene = scene_or_images
        images = [v.load_image() for v in scene.views]

    t0 = time.perf_counter()
    res = correct(scene, reference=reference, method=method, t_npm=t_npm, mappings=mappings, images=images, **options)
    fit_seconds = time.perf_counter() - t0
    ref = int(res.reference)
    in_sample = evaluate(blur_images(res.images, blur), mappings, interpolation=interpolation, min_n=min_n)

    held_out = None
    ho_seconds = None
    if holdout > 0:
        fit, test = mappings.split(float(holdout), seed=seed)
        if t_npm == "auto":  # in the units correct() takes: pixels (surface) or vertex mappings
            t_npm = res.t_npm if getattr(mappings, "mode", "vertices") == "surface" else PAPER_T_NPM
        t_fit = max(1, int(round(t_npm * (1.0 - float(holdout)))))
        t0 = time.perf_counter()
        res_h = correct(scene, reference=ref, method=method, t_npm=t_fit, mappings=fit, images=images, **options)
        ho_seconds = time.perf_counter() - t0
        min_test = max(1, int(round(min_n * float(holdout))))
        held_out = evaluate(blur_images(res_h.images, blur), test, interpolation=interpolation, min_n=min_test)
    logger.info(
        "%s: in-sample PSNR %.2f dB, CIEDE2000 %.2f (%.2f s)", method, in_sample.psnr.mean, in_sample.ciede2000.mean, fit_seconds
    )
    return MethodEvaluation(method=method, reference=ref, in_sample=in_sample, held_out=held_out, fit_seconds=fit_seconds,
                            holdout_fit_seconds=ho_seconds, holdout=float(holdout), seed=int(seed),
                            corrected=tuple(res.images))


def evaluate_scene(
    scene,
    *,
    mappings: str = "vertices",
    method: str | None = None,
    reference: str | int | None = None,
    holdout: float = 0.0,
    seed: int = 0,
    t_npm: int | str | None = None,
    blur: float = 0.0,
    min_n: int = 1,
) -> dict[str, Any]:
    """Table 2 metrics of a scene's images, or of a method fitted on them (the ``evaluate`` command).

    Parameters
    ----------
    scene : Scene
    mappings : {"vertices", "dense"}, default "vertices"
    method : str, optional
        Without one, the scene's images are scored as they are (e.g. the output of ``correct``);
        ``holdout`` then scores a random fraction of the faces only. With one, the method and
        ``"none"`` are fitted here and scored in-sample and (``holdout > 0``) held out.
    reference, t_npm
        Passed to the method (default :class:`~o3d_seqcc.correction.settings.CorrectionSettings`'s).
    holdout : float in [0, 1), default 0
    seed : int, default 0
        Seed of the face split.
    blur : float, default 0
        Gaussian sigma (px) applied to the images for scoring only.
    min_n : int, default 1
        Pairs with fewer mappings are skipped.

    Returns
    -------
    dict
        ``mappings``, ``holdout``, ``seed``, ``blur``, ``min_n``, ``n_pairs``, and either
        ``evaluation`` (an :meth:`Evaluation.to_dict`) or ``reference`` and ``methods``
        (name -> :meth:`MethodEvaluation.to_dict`); ``rows``: ``(label, Evaluation)`` pairs for
        printing.
    """
    from ..correction import check_method
    from ..mappings.compute import compute_mappings

    if not 0.0 <= float(holdout) < 1.0:
        raise InputError(f"holdout must be in [0, 1), got {holdout}")
    if method is not None:
        check_method(method)
    maps = compute_mappings(scene, mappings=mappings)
    out: dict[str, Any] = {"mappings": mappings, "holdout": holdout, "seed": seed, "blur": blur, "min_n": min_n,
                           "n_pairs": len(maps.pairs)}
    rows = []
    if method is None:
        images = blur_images([v.load_image() for v in scene.views], blur)
        scored = maps if holdout == 0 else maps.split(holdout, seed=seed)[1]
        ev = evaluate(images, scored, min_n=min_n)
        out["evaluation"] = ev.to_dict()
        rows.append(("images" if holdout == 0 else f"images, held-out {holdout:g}", ev))
    else:
        images = [v.load_image() for v in scene.views]
        runs = {}
        ref = reference
        for m in dict.fromkeys(["none", method]):
            runs[m] = evaluate_method(images, maps, scene=scene, method=m, reference=ref, holdout=holdout, seed=seed,
                                      t_npm=t_npm, blur=blur, min_n=min_n)
            ref = runs[m].reference  # "auto" resolved once, then reused
        out["reference"] = scene.names[runs[method].reference]
        out["methods"] = {m: r.to_dict(per_pair=True) for m, r in runs.items()}
        for m, r in runs.items():
            rows.append((f"{m} in-sample", r.in_sample))
            if r.held_out is not None:
                rows.append((f"{m} held-out {holdout:g}", r.held_out))
    out["rows"] = rows
    return out
