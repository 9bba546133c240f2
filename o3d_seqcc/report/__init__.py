"""The HTML report of a run, ``OUT/report.html``: the paper's figures for this run, in one file.

One self-contained page (images embedded as base64 PNG / JPEG, CSS inline, no external URL,
works offline) that ``run``, ``correct`` and ``texture`` (and so ``demo``) write into their
output folder, and that :func:`regenerate_report` (``o3d-seqcc report RUN_DIR``) writes again
from an output folder. Sections, each only when the command produced its data:

- the colour-correction graph with edge weights and the Dijkstra paths, reference marked
  (paper Figures 4-5), and the path edges as a table;
- the joint image histograms (JIH) and fitted colour mapping functions (CMF) of every path edge
  and channel (Figures 6-7): every edge of one path in full, all edges as thumbnails;
- the sequential steps of that path (Figure 8): the source view corrected step by step;
- a before / after grid of all views, reference marked (Figure 10);
- Table 2: PSNR / CIEDE2000 mean, weighted mean and std over the view pairs, before and after,
  with the contrast ratio (:func:`o3d_seqcc.metrics.before_after`);
- the per-face image selection with a legend (Figure 9);
- renders of the textured mesh from two views beside the photos (Figures 12-13);
- seam metric, timings and the run's settings.

At run time everything comes from memory. On fountain (33 views, 16k faces) the report costs
about 1.3 s of CPU on one core: importing matplotlib's Figure 0.2 s, Table 2 on at most
:data:`METRICS_MAX_PER_PAIR` mappings per pair 0.5 s (all 3.9 M mappings: 11 s), the page 0.6 s
(figures, thumbnails, two small ray-cast renders; selection.png is reused);
:meth:`~o3d_seqcc.pipeline.RunResult.save` runs the first two in a thread beside the export.
:func:`regenerate_report` reloads the scene, recomputes the visibility, mappings and correction
with the settings ``report.json`` recorded (the per-edge CMFs are not saved) and reads the
selection, the textured mesh and the numbers from the folder.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..io.files import atomic_write_bytes
from .page import PageInputs, facts, render_page

__all__ = ["METRICS_MAX_PER_PAIR", "REPORT_FILE", "html_report", "regenerate_report", "write_report"]

logger = logging.getLogger(__name__)

#: file name of the report in an output folder
REPORT_FILE = "report.html"
#: mappings scored per pair for the Table 2 of ``run`` (evenly spaced; ``correct`` scores them all)
METRICS_MAX_PER_PAIR = 200


def _selection_png(folder: Path | None) -> bytes | None:
    """The folder's selection.png (the report embeds it instead of rendering the same picture again)."""
    p = None if folder is None else folder / "selection.png"
    return p.read_bytes() if p is not None and p.is_file() else None


def _inputs_from_result(result: Any, report: dict | None, folder: Path | None = None) -> PageInputs:
    if hasattr(result, "textured"):  # pipeline.RunResult
        vis = result.visibility
        corrected = result.images if result.correction is not None else None
        photos = result.originals if result.correction is not None else result.images
        return PageInputs(
            rep=result.report() if report is None else report, scene=result.scene, photos=photos, corrected=corrected,
            correction=result.correction, mappings=result.mappings, selection=np.asarray(result.selection),
            mesh=(vis.mesh.vertices, vis.mesh.faces), textured=result.textured,
            usable=vis.usable_counts(), selection_png=_selection_png(folder))
    if hasattr(result, "result") and hasattr(result, "originals"):  # pipeline.CorrectionRun
        vis = getattr(result.mappings, "visibility", None)
        return PageInputs(
            rep=result.report if report is None else report, scene=result.scene, photos=result.originals,
            corrected=result.result.images, correction=result.result, mappings=result.mappings,
            usable=None if vis is None else vis.usable_counts())
    raise TypeError(f"html_report needs a pipeline.RunResult or pipeline.CorrectionRun, got {type(result).__name__}")


def html_report(result: Any, *, report: dict | None = None, thumb_width: int = 160) -> str:
    """The HTML report of a result of :mod:`o3d_seqcc.pipeline`, as one self-contained page.

    Parameters
    ----------
    result : pipeline.RunResult or pipeline.CorrectionRun
        What :func:`~o3d_seqcc.pipeline.run`, :func:`~o3d_seqcc.pipeline.texture` or
        :func:`~o3d_seqcc.pipeline.correct_scene` returned.
    report : dict, optional
        The ``report.json`` content to show (numbers, settings, timings, Table 2 under
        ``"metrics"``); default the result's own report (without Table 2 for ``run``: see
        :func:`o3d_seqcc.metrics.before_after`).
    thumb_width : int, default 160
        Width in pixels of the views' thumbnails (photos beside renders: twice that).

    Returns
    -------
    str
        The HTML document; images embedded as base64 PNG / JPEG, no external resource.
    """
    return render_page(_inputs_from_result(result, report), width=int(thumb_width))


def write_report(result: Any, path: str | os.PathLike, *, report: dict | None = None, thumb_width: int = 160) -> Path:
    """Write :func:`html_report` of ``result`` to ``path`` atomically; returns the path.

    A ``selection.png`` beside ``path`` rendered from the view the report names
    (``report["selection"]["picture_view"]``, as :meth:`~o3d_seqcc.pipeline.RunResult.save`
    writes it) is embedded as Figure 9 instead of being rendered again.
    """
    path = Path(path)
    inp = _inputs_from_result(result, report, folder=path.parent)
    return atomic_write_bytes(path, render_page(inp, width=int(thumb_width)).encode("utf-8"))


def _read_report(run_dir: Path) -> dict:
    if not run_dir.is_dir():
        raise InputError(f"{run_dir} is not a folder; give the output folder (--out) of o3d-seqcc run, correct or "
                         "texture")
    rj = run_dir / "report.json"
    if not rj.is_file():
        raise InputError(f"{run_dir} is not an o3d-seqcc output folder (no report.json); give the --out folder of "
                         "o3d-seqcc run, correct or texture")
    try:
        rep = json.loads(rj.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        raise InputError(f"{rj} is not readable JSON ({e}); run the command again to rewrite the folder") from None
    if not isinstance(rep, dict):
        raise InputError(f"{rj} is not an o3d-seqcc report (not a JSON object); run the command again")
    return rep


def _scene_frame(tm, rep: dict, fmt: str):
    """``tm`` back in the scene's frame: the exporters baked the report's up-axis rotation into ``fmt``'s file."""
    o = (rep.get("export") or {}).get("orientation") or {}
    if fmt not in o.get("applies_to", ()) or o.get("rotation") is None:
        return tm
    R = np.asarray(o["rotation"], dtype=np.float64)
    if np.allclose(R, np.eye(3)):
        return tm
    return replace(tm, vertices=tm.vertices @ R, normals=None if tm.normals is None else tm.normals @ R)


def _inputs_from_folder(run_dir: Path, rep: dict, *, scene, mesh) -> PageInputs:
    from ..correction import correct
    from ..io.load import load_scene
    from ..mappings import compute_mappings
    from ..metrics import before_after
    from ..texturing import load_textured_mesh
    from ..visibility import compute_visibility

    f = facts(rep)
    src = scene if scene is not None else (rep.get("scene_path") or rep.get("scene"))
    if not src:
        raise InputError(f"{run_dir / 'report.json'} does not say where the scene is (a scene in memory, or an older "
                         "o3d-seqcc); pass --scene (and --mesh)")
    try:
        sc = load_scene(src, mesh=mesh if mesh is not None else (rep.get("mesh") or None))
    except InputError as e:
        raise InputError(f"cannot reload the scene {src} named in {run_dir / 'report.json'}: {e}; pass --scene "
                         "(and --mesh) to say where it is now") from None
    split = ((rep.get("visibility_stats") or {}).get("split") or {}).get("enabled", False)  # older runs: not split
    vis = compute_visibility(sc, split_faces=bool(split))
    photos = [v.load_image() for v in sc.views]
    correction = maps = corrected = None
    if f["method"]:
        s = f["settings"]
        ref = rep.get("reference") or rep["correction"]["reference"]
        maps = compute_mappings(sc, visibility=vis, mode=f["mappings"] or "vertices")  # older reports: the paper's
        seed = s.get("seed", (rep.get("selection") or {}).get("seed", 0))
        t_npm = s.get("t_npm", f["t_npm"])
        correction = correct(sc, reference=ref, method=f["method"], t_npm=t_npm if t_npm == "auto" else int(t_npm),
                             mappings=maps,
                             images=photos, seed=int(seed), interpolation=s.get("interpolation", "bilinear"),
                             graph_weight=s.get("graph_weight", "paper"), **s.get("options", {}))
        corrected = correction.images
        if f["metrics"] is None and f["command"] == "run":
            logger.info("report.json has no metrics (older o3d-seqcc): computing Table 2")
            rep = {**rep, "metrics": before_after(photos, corrected, maps, correction.paths,
                                                  max_per_pair=METRICS_MAX_PER_PAIR)}
    selection = textured = None
    faces = vis.mesh.faces
    if (run_dir / "selection.npy").is_file():
        selection = np.load(run_dir / "selection.npy", allow_pickle=False)
        if selection.shape != (len(faces),):
            logger.warning("selection.npy has %s entries for %d faces: the selection is left out", selection.shape,
                           len(faces))
            selection = None
    tm_path = next((run_dir / n for n in ("mesh.glb", "mesh.obj", "mesh.ply") if (run_dir / n).is_file()), None)
    if tm_path is not None and selection is not None:
        textured = _scene_frame(load_textured_mesh(tm_path), rep, tm_path.suffix.lstrip("."))
    return PageInputs(rep=rep, scene=sc, photos=photos, corrected=corrected, correction=correction, mappings=maps,
                   selection=selection, mesh=(vis.mesh.vertices, faces), textured=textured,
                   usable=vis.usable_counts(), selection_png=_selection_png(run_dir))


def regenerate_report(
    run_dir: str | os.PathLike,
    *,
    scene: str | os.PathLike | None = None,
    mesh: str | os.PathLike | None = None,
    output: str | os.PathLike | None = None,
    thumb_width: int = 160,
) -> Path:
    """Write the HTML report of an output folder of ``run``, ``correct`` or ``texture`` again.

    Reads ``report.json`` (numbers, settings, the scene's path), ``selection.npy`` and the
    textured mesh (``mesh.glb`` / ``.obj`` / ``.ply``) from the folder, reloads the scene and
    recomputes with the library what the folder does not hold: visibility, mappings and the
    correction (with the recorded method, reference and settings; deterministic, so the same
    as the run's with the same o3d_seqcc). Fountain (33 views, 16k faces): about 6 s of CPU.

    Parameters
    ----------
    run_dir : path-like
        The output folder.
    scene, mesh : path-like, optional
        Where the scene (and its mesh) are now, when not where ``report.json`` says.
    output : path-like, optional
        Write the page there instead of ``run_dir/report.html`` (which is then also listed in
        the folder's manifest).
    thumb_width : int, default 160

    Returns
    -------
    pathlib.Path
        The page written.

    Raises
    ------
    InputError
        ``run_dir`` is not an output folder of o3d-seqcc (no ``report.json``), or its scene cannot
        be found (the message says to pass ``scene``).
    """
    run_dir = Path(run_dir)
    rep = _read_report(run_dir)
    inp = _inputs_from_folder(run_dir, rep, scene=scene, mesh=mesh)
    data = render_page(inp, width=int(thumb_width)).encode("utf-8")
    if output is not None:
        return atomic_write_bytes(output, data)
    from ..io.output import add_output_file

    return add_output_file(run_dir, REPORT_FILE, data)
