"""The whole job on a built-in scene (``o3d-seqcc demo``).

:func:`run_demo` generates the synthetic room (:func:`o3d_seqcc.synthetic.make_synthetic_scene`
with :data:`DEMO_SCENE`: cameras looking up and down, a mesh of what they see; reused when an
identical one is already there), runs :func:`o3d_seqcc.pipeline.run` on it toward the unchanged
view ``v00`` (dense mappings; the colour steps at the seams between photos measured as taken and
corrected) and measures the
mean CIEDE2000 between each view and its ground-truth render over the pixels the mesh covers,
before and after correction. ``dataset="fountain"`` runs the real Fountain set instead.
"""

from __future__ import annotations

import inspect
import json
import logging
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError
from .io.output import check_output, check_output_file, write_output_file, write_output_json
from .evaluation.metrics import image_delta_e
from .pipeline import RunResult, run
from .run_folder.layout import DEMO_SUMMARY, REPORT_HTML, REPORT_JSON
from .datasets import DatasetUnavailable, fountain
from .synthetic import SyntheticScene, load_synthetic, make_synthetic_scene
from .texturing import TextureSettings

__all__ = ["DemoResult", "run_demo", "texture_ground_truth"]

logger = logging.getLogger(__name__)

#: options of make_synthetic_scene the demo passes through, and their defaults
_SCENE_KEYS = ("n_views", "width", "height", "seed", "photometric", "cell_size", "layout", "seen_only")
#: the demo's synthetic room: cameras looking up and down, a mesh of what they see (as a scan's)
DEMO_SCENE = {"n_views": 16, "layout": "two-rings", "seen_only": True}
#: datasets of the demo
DATASETS = ("synthetic", "fountain")
_SCENE_DEFAULTS = {n: p.default for n, p in inspect.signature(make_synthetic_scene).parameters.items()}


@dataclass(frozen=True, eq=False)
class DemoResult:
    """What :func:`run_demo` produces.

    Attributes
    ----------
    out : pathlib.Path
        The demo folder: ``scene/`` (the synthetic scene), ``run/`` (the outputs of the run),
        ``demo_summary.json``.
    synthetic : SyntheticScene or None
        The synthetic scene (None for the fountain).
    result : RunResult
    summary : dict
        ``synthetic``, ``load``, ``summary`` (per-view photometric changes), ``run`` and
        ``ground_truth`` (per-view CIEDE2000 before / after and their means).
    timings : dict
    """

    out: Path
    synthetic: SyntheticScene | None
    result: RunResult
    summary: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)


def _generate(out: Path, params: dict[str, Any], overwrite: bool) -> tuple[SyntheticScene, bool]:
    """The synthetic scene in ``out``: reused when it holds one with the same parameters."""
    if not overwrite and (out / "synthetic.json").is_file():
        try:
            syn = load_synthetic(out)
        except InputError as e:
            logger.info("cannot reuse %s (%s): regenerating needs overwrite", out, e)
        else:
            if all(syn.metadata.get(k) == (float(v) if k == "cell_size" else v) for k, v in params.items()):
                return syn, True
    return make_synthetic_scene(out, overwrite=overwrite, **params), False


def run_demo(
    out: str | os.PathLike = "out/demo",
    *,
    dataset: str = "synthetic", data_root: str | os.PathLike | None = None,
    t_npm: int | str | None = None,
    overwrite: bool = False,
    settings: TextureSettings | None = None,
    save_options: dict[str, Any] | None = None,
    **scene_options: Any,
) -> DemoResult:
    """The whole job on a built-in scene, with what it did (and, on the synthetic room, its error to the truth).

    Parameters
    ----------
    out : path-like, default "out/demo"
        Demo folder: ``scene/`` (the synthetic scene), ``run/`` (the job's outputs), ``report.html``
        (a copy of ``run/report.html``: one offline file, the result to open),
        ``demo_summary.json``.
    dataset : {"synthetic", "fountain"}, default "synthetic"
        The synthetic room (generated, or reused when identical; scored against its ground-truth
        renders), or the real Fountain set (:func:`o3d_seqcc.datasets.fountain`: ``data_root``,
        else Open3D's download).
    data_root : path-like, optional
        Fountain only: a local copy of the set.
    t_npm : "auto" or int, optional
        Minimum pair count for a graph edge; default :attr:`CorrectionSettings.t_npm
        <o3d_seqcc.correction.settings.CorrectionSettings.t_npm>` ("auto").
    overwrite : bool, default False
        Regenerate the synthetic scene.
    settings : TextureSettings, optional
        Texturing options (default: :class:`~o3d_seqcc.texturing.TextureSettings`).
    save_options : dict, optional
        Export options of :meth:`~o3d_seqcc.pipeline.RunResult.save` (``up_axis``,
        ``texture_format``, ``jpeg_quality``, ``unlit``).
    **scene_options
        Synthetic only: options of :func:`~o3d_seqcc.synthetic.make_synthetic_scene` (``n_views``,
        ``width``, ``height``, ``seed``, ``photometric``, ``cell_size``, ``layout``,
        ``seen_only``); default :data:`DEMO_SCENE`, else the generator's defaults.

    Returns
    -------
    DemoResult
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out} is a file; give a folder")
    if dataset not in DATASETS:
        raise InputError(f"unknown demo dataset {dataset!r}; valid: {', '.join(DATASETS)}")
    if (out / REPORT_HTML).exists() and not (out / DEMO_SUMMARY).is_file():
        # the demo replaces its own page only (a folder it wrote has its summary beside the page)
        raise InputError(f"--out {out} holds a report.html that no demo wrote (no demo_summary.json beside it); "
                         "choose another folder")
    unknown = sorted(set(scene_options) - set(_SCENE_KEYS))
    if unknown:
        raise TypeError(f"run_demo got unknown option(s) {unknown}; valid: {sorted(_SCENE_KEYS)}")
    check_output(out / "run", overwrite=True)  # what the demo writes, checked before any work
    for name in (REPORT_HTML, DEMO_SUMMARY):
        check_output_file(out / name, option="--out")
    if dataset == "fountain" and scene_options:
        raise TypeError(f"scene options {sorted(scene_options)} apply to the synthetic dataset only")
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    syn = None
    if dataset == "synthetic":
        params = {**{k: v for k, v in _SCENE_DEFAULTS.items() if k in _SCENE_KEYS}, **DEMO_SCENE, **scene_options}
        syn, reused = _generate(out / "scene", params, overwrite)
        scene, source = syn.scene, out / "scene" / "scene.json"
        summary: dict[str, Any] = {"synthetic": {"folder": str(out / "scene"), "reused": reused}}
        run_options = {"reference": scene.names[0], "mappings": "dense"}
    else:
        try:
            scene = fountain(data_root)
        except DatasetUnavailable as e:
            raise e.for_python("run_demo(..., data_root=DIR)") from None
        source = scene.source or scene.mesh
        summary = {"dataset": {"name": "fountain", "folder": str(Path(scene.views[0].image).parents[1])}}
        run_options = {"reference": "auto"}
    timings["scene"] = time.perf_counter() - t0
    mesh = scene.load_mesh()
    summary["load"] = {"scene": str(source), "views": len(scene.views),
                       "image_size": f"{scene.views[0].width}x{scene.views[0].height}",
                       "mesh_vertices": int(len(mesh.vertices)), "mesh_faces": int(len(mesh.faces))}
    t = time.perf_counter()
    res = run(scene, t_npm=t_npm, settings=settings, **run_options)
    res = replace(res, source=str(Path(source).resolve()))  # the report names the scene it ran on
    run_dir = out / "run"
    res.save(run_dir, overwrite=True, save_images=True, **(save_options or {}))
    timings["run"] = time.perf_counter() - t
    c = res.correction
    summary["run"] = {
        "reference": scene.names[c.reference], "unreachable": [scene.names[i] for i in c.unreachable],
        "selection": res.settings.selection, "transitions": res.selection_stats["transitions"],
        "faces": res.selection_stats["faces"], "unseen_faces": res.selection_stats["unseen_faces"],
        **{k: res.selection_stats[k] for k in ("input_faces", "unseen_input_faces", "unseen_area")},
        "atlas": {k: res.textured.stats[k] for k in ("atlas_size", "page_width", "page_height", "pages",
                                                      "texels_per_pixel", "charts", "coverage", "utilization")},
        "texture_memory_bytes": res.textured.stats["texture_memory"]["gpu_bytes"],
        "seams": None if res.seams is None else res.seams.to_dict(),
        # what the correction bought at the seams: the colour steps in the photos as taken and corrected (the
        # report measured them; the seam metric of the levelled texture is about the same either way)
        "selection_seams": json.loads((run_dir / REPORT_JSON).read_text(encoding="utf-8")).get("selection_seams"),
        "timings": {k: round(v, 4) for k, v in res.timings.items()},
        "outputs": sorted(p.name for p in run_dir.iterdir() if not p.name.startswith(".")),
    }
    if syn is not None:
        t = time.perf_counter()
        summary.update(_ground_truth(syn, res))
        timings["ground_truth"] = time.perf_counter() - t
    page = run_dir / REPORT_HTML
    if page.is_file():  # one offline file (figures and model inline): the result to open, at the top of OUT
        write_output_file(out / REPORT_HTML, page.read_bytes(), option="--out", inputs=scene.input_paths())
    timings["total"] = time.perf_counter() - t0
    write_output_json(out / DEMO_SUMMARY, {"summary": summary, "timings": timings}, option="--out",
                      inputs=scene.input_paths())
    return DemoResult(out=out, synthetic=syn, result=res, summary=summary, timings=timings)


def texture_ground_truth(syn: SyntheticScene, textured, *, views=None) -> dict[str, Any]:
    """A textured mesh of a synthetic scene against the true albedo: rendered from each view, scored like the photos.

    Each view's camera renders ``textured`` (:func:`o3d_seqcc.evaluation.render.render_textured`, one ray per
    pixel) and the render is compared with the view's ground-truth render over the pixels the
    mesh covers (:func:`o3d_seqcc.evaluation.metrics.image_delta_e`, as the corrected photos are in
    :func:`run_demo`); *holes* are the covered pixels whose ray hits a face textured by no photo
    (the fallback colour; ``TexturedMesh.face_view`` -1).

    Parameters
    ----------
    syn : SyntheticScene
    textured : TexturedMesh or path
        E.g. ``RunResult.textured``, or an exported GLB / OBJ.
    views : sequence of int, optional
        Default all.

    Returns
    -------
    dict
        ``views`` (per view ``name``, ``ciede2000``, ``holes``), ``mean`` (CIEDE2000 over the
        views), ``holes`` (share of the covered pixels, all views together).
    """
    from .evaluation.render import raycast, render_textured
    from .texturing import load_textured_mesh

    tm = load_textured_mesh(textured)
    rows, hole_px, px = [], 0, 0
    for i in range(len(syn.scene.views)) if views is None else views:
        v = syn.scene.views[i]
        mask = syn.load_face_ids(i) >= 0
        hits = raycast(tm, v)
        de = image_delta_e(render_textured(tm, v, hits=hits), syn.load_gt(i), mask=mask)
        on = mask & hits.mask
        holes = int(np.count_nonzero(tm.face_view[hits.face_ids[on]] < 0)) if tm.face_view is not None else 0
        rows.append({"name": v.name, "ciede2000": round(de, 3), "holes": round(holes / max(int(mask.sum()), 1), 5)})
        hole_px += holes
        px += int(mask.sum())
    return {"views": rows, "mean": round(float(np.mean([r["ciede2000"] for r in rows])), 3),
            "holes": round(hole_px / max(px, 1), 5)}


def _ground_truth(syn: SyntheticScene, res: RunResult) -> dict[str, Any]:
    """Per-view photometric changes and CIEDE2000 to the ground-truth renders, before and after."""
    rows, per_view = [], []
    for v, img in zip(syn.scene.views, res.images):
        original = v.load_image()
        gt = syn.load_gt(v.name)
        p = syn.transforms[v.name]
        per_view.append({"name": v.name, "gain": round(float(p["gain"]), 3),
                         "white_balance": [round(float(x), 3) for x in p["white_balance"]],
                         "gamma": [round(float(x), 3) for x in p["gamma"]], "s_curve": round(float(p["s_curve"]), 3),
                         "mean_abs_diff": round(float(np.abs(original.astype(np.float64) - gt).mean()), 2)})
        mask = syn.load_face_ids(v.name) >= 0
        rows.append({"name": v.name, "before": round(image_delta_e(original, gt, mask=mask), 2),
                     "after": round(image_delta_e(img, gt, mask=mask), 2)})
    return {
        "summary": {"photometric": syn.metadata.get("photometric"), "seed": syn.metadata.get("seed"),
                    "face_groups": {k: list(g) for k, g in syn.face_groups.items()}, "views": per_view,
                    "mean_abs_diff_mean": round(float(np.mean([r["mean_abs_diff"] for r in per_view])), 2)},
        "ground_truth": {"views": rows, "mean_before": round(float(np.mean([r["before"] for r in rows])), 2),
                         "mean_after": round(float(np.mean([r["after"] for r in rows])), 2),
                         "texture": {k: v for k, v in texture_ground_truth(syn, res.textured).items() if k != "views"}},
    }
