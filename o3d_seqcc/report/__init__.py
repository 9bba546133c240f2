"""The HTML report of a run, ``OUT/report.html``: the paper's figures for this run, in one file.

One self-contained page (images embedded as base64 PNG / JPEG, CSS inline, no external URL,
works offline) that ``run``, ``correct`` and ``texture`` (and so ``demo``) write into their
output folder, and that :func:`regenerate_report` (``o3d-seqcc report RUN_DIR``) writes again
from an output folder. Sections, each only when the command produced its data:

- the textured model in an interactive 3D viewer (:mod:`o3d_seqcc.report.viewer`: the GLB
  inline, three.js bundled into the page; orbit, zoom, the texture corrected / as taken / the
  selection colours);
- what the correction changes (:mod:`o3d_seqcc.report.comparison`): one close-up of the model
  as written, with each face its photo corrected and as taken, and the selection seams on a
  colour scale of their step;
- the colour-correction graph with edge weights and the Dijkstra paths, reference marked
  (paper Figures 4-5), and the path edges as a table;
- the joint image histograms (JIH) and fitted colour mapping functions (CMF) of every path edge
  and channel (Figures 6-7): every edge of one path in full, all edges as thumbnails;
- the sequential steps of that path (Figure 8): the source view corrected step by step;
- a before / after grid of all views, reference marked (Figure 10);
- Table 2: PSNR / CIEDE2000 mean, weighted mean and std over the view pairs, before and after,
  with the contrast ratio (:func:`o3d_seqcc.evaluation.metrics.before_after`);
- the per-face image selection with a legend (Figure 9);
- renders of the textured mesh from two views beside the photos (Figures 12-13);
- seam metric, timings and the run's settings.

At run time everything comes from memory: the page is drawn from the result objects the command
returns (:class:`~o3d_seqcc.report.page.PageInputs`: the images, the correction with its per-edge
lookup tables, the mappings, the selection, the textured mesh, the visibility's usable counts),
and no stage runs again (``tests/test_report_schema.py`` makes every stage raise while a run is
saved). :meth:`~o3d_seqcc.pipeline.RunResult.save` scores Table 2 on at most
:data:`METRICS_MAX_PER_PAIR` mappings per pair (all of them up to :data:`METRICS_ALL_UP_TO`; :func:`~o3d_seqcc.pipeline.run`
starts it in the background) and measures the selection seams' steps in a thread beside the export; the page then
draws the figures (the joint histograms with numpy and OpenCV, the graph as SVG text), the viewer's textures,
the close-ups and two ray-cast renders (selection.png is reused), reading each photo once.
:func:`regenerate_report` (a folder, not a result) reloads the scene, recomputes only what the
folder does not hold (visibility, mappings and correction, with the settings ``report.json``
recorded: the per-edge CMFs are not saved) and reads the selection, the textured mesh and the
numbers from the folder.
"""

from __future__ import annotations

import logging
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_write_bytes
from ..io.output import add_output_file, check_output_file, write_output_file
from .page import PageInputs, facts, render_page
from .validate import page_bytes, read_report_json, read_selection

__all__ = ["IMAGE_CACHE_BYTES", "METRICS_ALL_UP_TO", "METRICS_MAX_PER_PAIR", "REPORT_FILE", "cached_images",
           "metrics_sample", "html_report", "regenerate_report", "write_report"]

logger = logging.getLogger(__name__)

#: file name of the report in an output folder
REPORT_FILE = "report.html"
#: mappings scored per pair for the Table 2 of ``run`` beyond :data:`METRICS_ALL_UP_TO` (evenly spaced)
METRICS_MAX_PER_PAIR = 200
#: ``run`` scores every mapping (its Table 2 is then ``correct``'s, number for number) up to this many in all
METRICS_ALL_UP_TO = 100_000


#: bytes of images a report keeps while it is made (each photo read, and corrected, once while they fit):
#: at least this, up to :data:`IMAGE_CACHE_MAX_BYTES` when the photos and their corrections need more
IMAGE_CACHE_BYTES = 256 << 20
#: the most a report's image cache grows to (10 photos of 6 MP and their corrections: 360 MB)
IMAGE_CACHE_MAX_BYTES = 768 << 20
#: bytes of corrected images a run's report keeps while it is made (its photos are the run's cached ones)
CORRECTED_CACHE_BYTES = 64 << 20


def _bytes(images: Any) -> int:
    """Bytes of a sequence's images (views' sizes and header dtypes for a lazy one, 0 for None)."""
    from ..imaging.sequences import image_dtypes

    if images is None:
        return 0
    views = getattr(images, "views", None) or getattr(getattr(images, "originals", None), "views", None)
    if views is not None and len(views) == len(images):
        return sum(v.width * v.height * 3 * np.dtype(d).itemsize for v, d in zip(views, image_dtypes(images)))
    return sum(int(np.asarray(im).nbytes) for im in images) if isinstance(images, (list, tuple)) else 0


def cached_images(photos: Any, corrected: Any) -> tuple[Any, Any]:
    """``photos`` and ``corrected`` read through one shared cache; lazily corrected images from the cached photos.

    What :meth:`~o3d_seqcc.pipeline.RunResult.save` hands to Table 2, the seam steps and the page,
    so that together they read each photo once (``None`` stays ``None``). A run's photos keep their
    own cache, and its corrected images get one of :data:`CORRECTED_CACHE_BYTES`.
    """
    from ..correction.base import CorrectedImages
    from ..imaging.sequences import CachedImages, LRUCache

    if isinstance(photos, CachedImages):  # a run's photos (images.scene_photos), cached already
        if corrected is None or isinstance(corrected, CachedImages):
            return photos, corrected
        # the corrections (a lookup table applied to a cached photo: cheap) in a small cache of their own: the page
        # reads most views' twice at most, and keeping them all would add their size to the run's memory
        return photos, CachedImages(corrected, LRUCache(CORRECTED_CACHE_BYTES), "corrected")
    cache = LRUCache(max(IMAGE_CACHE_BYTES, min(IMAGE_CACHE_MAX_BYTES, _bytes(photos) + _bytes(corrected))))
    p = None if photos is None else CachedImages(photos, cache, "photos")
    if isinstance(corrected, CorrectedImages) and p is not None and corrected.originals is photos:
        corrected = CorrectedImages(p, corrected.transforms)  # the LUTs applied to the cached photos
    return p, None if corrected is None else CachedImages(corrected, cache, "corrected")


def metrics_sample(mappings) -> int | None:
    """``max_per_pair`` of ``run``'s Table 2: None (all) up to :data:`METRICS_ALL_UP_TO` mappings, else the cap."""
    return None if mappings.total <= METRICS_ALL_UP_TO else METRICS_MAX_PER_PAIR


def _selection_png(folder: Path | None) -> bytes | None:
    """The folder's selection.png (the report embeds it instead of rendering the same picture again)."""
    p = None if folder is None else folder / "selection.png"
    return p.read_bytes() if p is not None and p.is_file() else None


def _inputs_from_result(result: Any, report: dict | None, folder: Path | None = None,
                        selection_seams: dict | None = None, images: tuple | None = None,
                        casters: Any = None, parts: Any = None, selection_png: Any = None) -> PageInputs:
    if hasattr(result, "textured"):  # pipeline.RunResult
        vis = result.visibility
        corrected = result.images if result.correction is not None else None
        photos = result.originals if result.correction is not None else result.images
        if images is not None:
            photos, corrected = images
        return PageInputs(
            rep=result.report() if report is None else report, scene=result.scene, photos=photos, corrected=corrected,
            correction=result.correction, mappings=result.mappings, selection=np.asarray(result.selection),
            mesh=(vis.mesh.vertices, vis.mesh.faces), textured=result.textured,
            usable=vis.usable_counts(), selection_seams=selection_seams, casters=casters, parts=parts,
            selection_png=_selection_png(folder) if selection_png is None else selection_png)
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
        :func:`o3d_seqcc.evaluation.metrics.before_after`).
    thumb_width : int, default 160
        Width in pixels of the views' thumbnails (photos beside renders: twice that).

    Returns
    -------
    str
        The HTML document; images embedded as base64 PNG / JPEG, no external resource.
    """
    return render_page(_inputs_from_result(result, report), width=int(thumb_width))


def write_report(result: Any, path: str | os.PathLike, *, report: dict | None = None, thumb_width: int = 160,
                 selection_seams: dict | None = None, images: tuple | None = None, write: bool = True,
                 casters: Any = None, parts: Any = None, selection_png: Any = None) -> Path | str:
    """Write :func:`html_report` of ``result`` to ``path`` atomically; returns the path.

    A ``selection.png`` beside ``path`` rendered from the view the report names
    (``report["selection"]["picture_view"]``, as :meth:`~o3d_seqcc.pipeline.RunResult.save`
    writes it) is embedded as Figure 9 instead of being rendered again; ``selection_seams``
    (``{"photos", "corrected"}`` -> :class:`~o3d_seqcc.evaluation.seams.SelectionSeams`, computed when
    not given) are the colour steps the page shows; ``images`` (photos, corrected) replace the
    result's (e.g. :func:`cached_images` shared with whoever read them before); ``casters``
    (:class:`~o3d_seqcc.evaluation.render.Casters`) the meshes' ray-casting scenes built before; ``parts``
    (:class:`~o3d_seqcc.report.parts.CorrectionParts`) the correction's figures computed before;
    ``selection_png`` a callable returning that picture's bytes (while it is being written). ``write=False``
    returns the page (str) without writing it (the caller writes :func:`page_bytes` of it).
    """
    path = Path(path)
    inp = _inputs_from_result(result, report, folder=path.parent, selection_seams=selection_seams, images=images,
                              casters=casters, parts=parts, selection_png=selection_png)
    page = render_page(inp, width=int(thumb_width))
    return atomic_write_bytes(path, page_bytes(page)) if write else page


def _scene_frame(tm, rep: dict, fmt: str):
    """``tm`` back in the scene's frame: the exporters baked the report's up-axis rotation into ``fmt``'s file."""
    o = (rep.get("export") or {}).get("orientation") or {}
    if fmt not in o.get("applies_to", ()) or o.get("rotation") is None:
        return tm
    R = np.asarray(o["rotation"], dtype=np.float64)
    if np.allclose(R, np.eye(3)):
        return tm
    return replace(tm, vertices=tm.vertices @ R, normals=None if tm.normals is None else tm.normals @ R)


def _run_files(run_dir: Path) -> list[Path]:
    """The files of an output folder the report reads."""
    return [run_dir / n for n in ("report.json", "selection.npy", "selection.png", "mesh.glb", "mesh.obj", "mesh.ply")]


def _inputs_from_folder(run_dir: Path, rep: dict, *, scene, mesh, image_dir=None, output=None) -> PageInputs:
    from ..correction import correct
    from ..io.load import load_scene
    from ..mappings.compute import compute_mappings
    from ..evaluation.metrics import before_after
    from ..texturing import load_textured_mesh
    from ..visibility.compute import compute_visibility

    f = facts(rep)
    src = scene if scene is not None else (rep.get("scene_path") or rep.get("scene"))
    if not src:
        raise InputError(f"{run_dir / 'report.json'} does not say where the scene is (a scene in memory, or an older "
                         "o3d-seqcc); pass --scene (and --mesh)")
    try:
        opts = dict(rep.get("scene_options") or {})  # as the run loaded it (a moved scene: its conventions only)
        opts.pop("skipped_images", None)  # what skip_missing left out: found again, not an option
        if scene is not None:
            opts = {k: v for k, v in opts.items() if k not in ("image_dir", "depth_dir", "depth_scale")}
        if image_dir is not None:
            opts["image_dir"] = image_dir
        sc = load_scene(src, mesh=mesh if mesh is not None else (rep.get("mesh") or None), **opts)
    except InputError as e:
        raise InputError(f"cannot reload the scene {src} named in {run_dir / 'report.json'}: {e}; pass --scene "
                         "(and --mesh) to say where it is now") from None
    if output is not None:  # before any work: the page may not replace a file the report reads
        check_output_file(output, option="--output", inputs=[*sc.input_paths(), *_run_files(run_dir)])
    split = ((rep.get("visibility_stats") or {}).get("split") or {}).get("enabled", False)  # older runs: not split
    vis = compute_visibility(sc, split_faces=bool(split))
    photos = [v.load_image() for v in sc.views]
    correction = maps = corrected = None
    if f["method"]:
        s = f["settings"]
        ref = rep["correction"]["reference"]
        maps = compute_mappings(sc, visibility=vis, mappings=f["mappings"] or "vertices")  # older reports: the paper's
        seed = s.get("seed", (rep.get("selection") or {}).get("seed", 0))
        t_npm = s.get("t_npm", f["t_npm"])
        correction = correct(sc, reference=ref, method=f["method"], t_npm=t_npm if t_npm == "auto" else int(t_npm),
                             mappings=maps,
                             images=photos, seed=int(seed), interpolation=s.get("interpolation"),  # None: the default
                             graph_weight=s.get("graph_weight"), **s.get("options", {}))
        corrected = correction.images
        if f["metrics"] is None and f["command"] == "run":
            logger.info("report.json has no metrics (older o3d-seqcc): computing Table 2")
            rep = {**rep, "metrics": before_after(photos, corrected, maps, correction.paths,
                                                  max_per_pair=metrics_sample(maps))}
    selection = textured = None
    faces = vis.mesh.faces
    if os.path.lexists(run_dir / "selection.npy"):
        selection = read_selection(run_dir / "selection.npy", len(faces), len(sc.views))
    tm_path = next((run_dir / n for n in ("mesh.glb", "mesh.obj", "mesh.ply") if (run_dir / n).is_file()), None)
    if tm_path is not None and selection is not None:
        textured = _scene_frame(load_textured_mesh(tm_path), rep, tm_path.suffix.lstrip("."))
        if textured.face_view is None and len(textured.faces) == len(selection) \
                and int((rep.get("atlas") or {}).get("pages", 1)) == 1:  # one page: the file keeps the faces' order
            textured = replace(textured, face_view=np.where(selection >= 0, selection, -1))
    return PageInputs(rep=rep, scene=sc, photos=photos, corrected=corrected, correction=correction, mappings=maps,
                   selection=selection, mesh=(vis.mesh.vertices, faces), textured=textured,
                   usable=vis.usable_counts(), selection_png=_selection_png(run_dir))


def regenerate_report(
    run_dir: str | os.PathLike,
    *,
    scene: str | os.PathLike | None = None,
    mesh: str | os.PathLike | None = None,
    output: str | os.PathLike | None = None,
    image_dir: str | os.PathLike | None = None,
    thumb_width: int = 160,
) -> Path:
    """Write the HTML report of an output folder of ``run``, ``correct`` or ``texture`` again.

    Reads ``report.json`` (numbers, settings, the scene's path; any schema of
    :mod:`o3d_seqcc.report.schema`, older folders included), ``selection.npy`` and the textured
    mesh (``mesh.glb`` / ``.obj`` / ``.ply``) from the folder, reloads the scene and recomputes
    with the library only what the folder does not hold: the visibility (the split mesh the
    selection refers to, the usable faces per view), the mappings and the correction (the
    per-edge curves and colours the figures draw are not saved; recomputed with the recorded
    method, reference and settings: deterministic, so the same as the run's with the same
    o3d_seqcc), and Table 2 only for an older ``run`` folder without it. A report written by
    ``run`` / ``correct`` / ``texture`` itself recomputes nothing (it draws from the result in
    memory). Fountain (33 views, 16k faces): about 6 s of CPU.

    Parameters
    ----------
    run_dir : path-like
        The output folder.
    scene, mesh : path-like, optional
        Where the scene (and its mesh) are now, when not where ``report.json`` says.
    image_dir : path-like, optional
        Where the images of a COLMAP, Meshroom or OpenMVS scene are now (``load_scene``'s).
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
    rep = read_report_json(run_dir)
    if output is not None and os.path.realpath(output) == os.path.realpath(run_dir / REPORT_FILE):
        output = None  # the folder's own page: listed in its manifest as before
    if output is not None:  # before any work (again with the scene's files once it is loaded)
        check_output_file(output, option="--output", inputs=[p for p in (rep.get("scene_path"), rep.get("mesh"),
                                                                         scene, mesh) if p] + _run_files(run_dir))
    inp = _inputs_from_folder(run_dir, rep, scene=scene, mesh=mesh, image_dir=image_dir, output=output)
    data = page_bytes(render_page(inp, width=int(thumb_width)))
    if output is not None:
        return write_output_file(output, data, option="--output",
                                 inputs=[*inp.scene.input_paths(), *_run_files(run_dir)])
    return add_output_file(run_dir, REPORT_FILE, data)
