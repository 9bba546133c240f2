"""What :meth:`~o3d_seqcc.pipeline.RunResult.save` and :meth:`~o3d_seqcc.pipeline.CorrectionRun.save` write.

A run's folder (:func:`save_run`) is written with its independent parts at once:

The parts of a run's folder do not wait for each other: the textured mesh's files (texture
pages encoded by OpenCV, GLB / OBJ / PLY written, the MeshLab project), ``selection.png`` (a
ray-cast render), the report's Table 2 and selection seams (ready from :func:`~o3d_seqcc.pipeline.run`'s
background thread, else computed here), and the report page (figures, the viewer's textures,
renders; its Figure 9 is ``selection.png``, taken when written) run side by side on threads
(OpenCV, Open3D and numpy release the GIL), so the export and the report share the machine's
cores instead of following each other.
Only the page's timings table waits for the export (it shows the export's seconds): the page's
sections are drawn meanwhile (:func:`~o3d_seqcc.report.page.build_page`), and the page is written
with the final timings once the files are (:meth:`~o3d_seqcc.report.page.Page.html`).
The folder of ``correct`` (:func:`save_correction`) holds the corrected images, a ``scene.json``
of them and the report. The file names are :mod:`o3d_seqcc.run_folder.layout`'s. Every file
is written into the staging folder of :func:`o3d_seqcc.io.output.output_folder`, which is
swapped in only when all of them are complete; an error in any part cancels the parts not
started, waits for the running ones, and leaves the folder unswapped.
"""

from __future__ import annotations

import io
import logging
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

from ..evaluation.render import Casters, picture_view, write_selection_picture
from ..evaluation.seams import selection_seams_of
from ..geometry.orientation import up_axis_transform
from ..io.export import (DEFAULT_FORMATS, check_export_options, export_meshlab_ply, export_textured_mesh,
                         float32_offset, parse_formats, texture_file_names)
from ..io.atomic import atomic_write_bytes
from ..io.images import write_image
from ..io.json_files import write_json
from ..io.meshlab import save_mlp
from ..io.load import save_scene
from ..io.output import output_folder
from .._shared.interrupts import held
from .._shared.parallel import carried
from .._shared.progress import stage as _stage
from ..report import cached_images, html_report
from ..report.background import table2_metrics
from ..report.inputs import PageInputs
from ..report.page import build_page
from ..report.validate import page_bytes
from .layout import (IMAGES_DIR, MESH_STEM, MESHLAB_LAYER, MESHLAB_PROJECT, REPORT_HTML, REPORT_JSON, SCENE_JSON,
                     SCENE_MESH, SELECTION_NPY, SELECTION_PNG)
from .parts import meshlab_project, with_mesh_file, write_images
from .read import selection_png as _folder_selection_png

__all__ = ["FolderPlan", "correction_page_inputs", "report_prelude", "run_page_inputs", "save_correction", "save_rasters", "save_run",
           "write_run_folder"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class FolderPlan:
    """What :func:`write_run_folder` writes, checked and resolved by :func:`save_run` before anything is.

    Attributes
    ----------
    formats : list of str
        Export formats (``glb``, ``obj``, ``ply``).
    texture_format : str
        ``png``, ``jpg`` or ``webp``; ``quality`` its JPEG / WebP quality (1-100).
    unlit : bool
        GLB material with ``KHR_materials_unlit``.
    rotation : (3, 3) float or None
        The export's up-axis rotation (None: the scene's frame); ``orientation`` its record for the report.
    picture : bool
        Write ``selection.png`` (from ``view``; None: the view seeing the most faces).
    save_images : bool
        Also write the images used to ``images/``.
    report : bool
        Also write ``report.html`` and Table 2.
    """

    formats: list
    texture_format: str
    quality: int
    unlit: bool
    rotation: Any
    orientation: dict
    picture: bool
    view: Any
    save_images: bool
    report: bool


def _mesh_files(res: Any, stage: Path, plan: FolderPlan) -> tuple[dict[str, Path], dict[str, Path], float]:
    """The textured mesh's files, selection.npy, the images, the MeshLab project: (files before the selection
    picture, files after it, seconds)."""
    fmts, tfmt, quality, unlit, rotation = plan.formats, plan.texture_format, plan.quality, plan.unlit, plan.rotation
    save_images = plan.save_images
    t = time.perf_counter()
    written = {k: Path(v) for k, v in export_textured_mesh(
        res.textured, stage, formats=fmts, unlit=unlit, texture_format=tfmt, quality=int(quality),
        transform=rotation, stem=MESH_STEM).items()}
    buf = io.BytesIO()
    np.save(buf, res.selection)
    atomic_write_bytes(stage / SELECTION_NPY, buf.getvalue())
    after: dict[str, Path] = {}
    rasters = None
    if save_images:
        rasters = write_images(stage / IMAGES_DIR, res.scene.views, res.images)
        after["images"] = stage / IMAGES_DIR
    # the layer is MeshLab's own textured PLY: MeshLab 2020.09 (Debian 12) aborts on any OBJ
    layer = stage / MESHLAB_LAYER
    shift = float32_offset(res.textured.vertices)  # MeshLab holds float32: the layer matrix adds it back
    project = meshlab_project(res.scene, stage, mesh=layer, images=rasters, offset=shift)
    if project is not None:
        after["meshlab_project"] = project
        reuse = "obj" in written and tfmt in ("png", "jpg")  # MeshLab reads the OBJ's PNG / JPEG files
        after["meshlab_mesh"] = export_meshlab_ply(
            res.textured, layer, texture=[stage / n for n in texture_file_names(MESH_STEM, tfmt, res.textured.pages)]
            if reuse else None, offset=shift)
    return written, after, time.perf_counter() - t


def _selection_picture(res: Any, path: Path, view: Any, casters: Casters, mesh: tuple) -> tuple[Path, str]:
    return write_selection_picture(res.scene, res.visibility, res.selection, path, view, caster=casters.get(mesh))


def write_run_folder(res: Any, stage: Path, out: Path, plan: FolderPlan) -> dict[str, str]:
    """Write ``res``'s folder into ``stage`` (later swapped in as ``out``); returns kind -> final path.

    Parameters
    ----------
    res : pipeline.RunResult
    stage, out : pathlib.Path
        The staging folder, and the folder it becomes (the paths the report names).
    plan : FolderPlan
        What to write.
    """
    fmts, tfmt, quality, unlit, orientation = plan.formats, plan.texture_format, plan.quality, plan.unlit, plan.orientation
    picture, view, report = plan.picture, plan.view, plan.report
    table2 = report and res.correction is not None and res.mappings is not None and res.originals is not None
    images = cached_images(*((res.originals, res.images) if res.originals else (res.images, None)))
    export = {"formats": fmts, "texture_format": tfmt, "jpeg_quality": int(quality), "unlit": bool(unlit),
              "orientation": {**orientation, "applies_to": [f for f in fmts]}}
    casters = Casters()  # the ray-casting scenes of the mesh and the textured mesh: built once for the picture and the page
    mesh = (res.visibility.mesh.vertices, res.visibility.mesh.faces)
    pool = ThreadPoolExecutor(max_workers=3, thread_name_prefix="o3d_seqcc-save")
    try:
        with held():  # a signal inside submit's Thread.start would leave a writer that shutdown does not join
            files = pool.submit(carried(_mesh_files, "save: mesh files"), res, stage, plan)
            pic = pool.submit(carried(_selection_picture, "save: selection picture"), res, stage / SELECTION_PNG,
                              view, casters, mesh) if picture else None
            prelude = pool.submit(carried(report_prelude, "save: table 2 and seam steps"), res, table2,
                                  images) if report else None
        rep = page = None
        t = time.perf_counter()
        if report:  # the page, while the files are written: everything but the export's seconds is known
            metrics, steps, parts = prelude.result()
            name = None if pic is None else res.scene.names[picture_view(res.scene, res.visibility, view)]
            rep = res.report({}, picture_view=name, export=export, metrics=metrics, selection_seams=steps)
            page = build_page(run_page_inputs(res, rep, selection_seams=steps, images=images, casters=casters,
                                              parts=parts, selection_png=None if pic is None else
                                              lambda: pic.result()[0].read_bytes()))
        t_report = time.perf_counter() - t
        written, after, t_export = files.result()
        picture_path = None if pic is None else pic.result()
        pool.shutdown(wait=True)
    except BaseException:
        # a SIGTERM / Ctrl-C here (pool.shutdown's join included) must not leave the tasks writing into the
        # stage while the output guard removes it: they finish first (the ones not started are dropped)
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    if picture_path is not None:
        written["selection_png"] = picture_path[0]
    written.update(after)
    written_out = {k: str(Path(out) / p.relative_to(stage)) for k, p in written.items()}
    res.timings["export"] = t_export
    if report:
        written_out["report_html"] = str(Path(out) / REPORT_HTML)
    final = res.report(written_out, picture_view=None if picture_path is None else picture_path[1], export=export,
                       metrics=None if rep is None else rep.get("metrics"),
                       selection_seams=None if rep is None else prelude.result()[1])
    if report:
        atomic_write_bytes(stage / REPORT_HTML, page_bytes(page.html(final)))  # with the export's seconds
        res.timings["report"] = t_report
        final["timings_s"]["report"] = round(t_report, 4)
    write_json(stage / REPORT_JSON, final)
    return written_out


def save_run(res: Any, out: str | os.PathLike, *, overwrite: bool = False,
             formats: str | Iterable[str] = DEFAULT_FORMATS, save_images: bool = False,
             selection_view: str | int | None = None, unlit: bool = False, up_axis: str = "auto",
             texture_format: str = "png", jpeg_quality: int = 90, report: bool = True) -> dict[str, str]:
    """:meth:`~o3d_seqcc.pipeline.RunResult.save`: the options checked before anything is written, then the folder
    ``out`` staged (:func:`write_run_folder`) and swapped in; returns kind -> written path (documented there)."""
    fmts = parse_formats(formats)
    tfmt = check_export_options(up_axis=up_axis, texture_format=texture_format, jpeg_quality=jpeg_quality)
    if str(up_axis).lower() == "auto":
        up_axis = "none" if res.textured.stats.get("uv") == "keep" else "y"
    rotation, orientation = up_axis_transform(res.scene, up_axis)
    view = None if selection_view is None or str(selection_view).lower() == "none" else selection_view
    if view is not None:
        res.scene.index(view)
    with output_folder(out, overwrite=overwrite, inputs=res.scene.input_paths(), command=res.command) as stage, \
            _stage("export"):
        return write_run_folder(res, stage, Path(out), FolderPlan(
            formats=fmts, texture_format=tfmt, quality=int(jpeg_quality), unlit=bool(unlit),
            rotation=None if up_axis == "none" else rotation, orientation=orientation,
            picture=selection_view is None or view is not None, view=view, save_images=bool(save_images),
            report=bool(report)))


def save_correction(run: Any, out: str | os.PathLike, *, overwrite: bool = False, report: bool = True) -> Path:
    """:meth:`~o3d_seqcc.pipeline.CorrectionRun.save`: ``out/images/<view>.png``, ``out/scene.json`` (pointing at
    them), the MeshLab project, ``out/report.json`` and ``out/report.html``, staged then swapped in; returns ``out``."""
    t = time.perf_counter()
    with output_folder(out, overwrite=overwrite, inputs=run.scene.input_paths(), command="correct") as stage, \
            _stage("export"):
        paths = write_images(stage / IMAGES_DIR, run.scene.views, run.result.images)
        rep = dict(run.report)
        rep["timings_s"] = {**rep["timings_s"], "write_images": round(time.perf_counter() - t, 4)}
        rep["files"] = {"images": str(Path(out) / IMAGES_DIR), "scene_json": str(Path(out) / SCENE_JSON)}
        scene = with_mesh_file(run.scene, stage / SCENE_MESH)  # a mesh in memory is written beside them
        # paths relative to the manifest: the staging folder sits beside OUT, so they stay right after the swap
        save_scene(scene.replace_images(paths), stage / SCENE_JSON)
        if meshlab_project(scene, stage, mesh=None, images=paths) is not None:
            rep["files"]["meshlab_project"] = str(Path(out) / MESHLAB_PROJECT)
        if report:
            t = time.perf_counter()
            rep["files"]["report_html"] = str(Path(out) / REPORT_HTML)
            atomic_write_bytes(stage / REPORT_HTML, page_bytes(html_report(correction_page_inputs(run, rep))))
            rep["timings_s"]["report"] = round(time.perf_counter() - t, 4)
        write_json(stage / REPORT_JSON, rep)
    return Path(out)


def report_prelude(res: Any, table2: bool, images: tuple) -> tuple[dict | None, dict | None, Any]:
    """What a run's report needs beside the files: Table 2, the selection seams' steps, the correction's figures
    (:class:`~o3d_seqcc.report.parts.CorrectionParts`, None: the page draws them); from :func:`~o3d_seqcc.pipeline.run`'s
    background thread when it computed them for this result."""
    if not table2:
        return None, None, None
    bg = res._background if res._background is not None and res._background.matches(res) else None
    metrics = bg.result() if bg is not None else table2_metrics(images, res.mappings, res.correction.paths)
    steps = bg.seams(res.selection) if bg is not None else None
    if steps is None:
        photos, corrected = images
        mesh = res.visibility.mesh
        steps = selection_seams_of(mesh.vertices, mesh.faces, res.selection, res.scene.views,
                                   {"photos": photos, "corrected": corrected})
    return metrics, steps, None if bg is None else bg.parts()


def run_page_inputs(res: Any, report: dict | None = None, *, folder: Path | None = None,
                    selection_seams: dict | None = None, images: tuple | None = None, casters: Any = None,
                    parts: Any = None, selection_png: Any = None) -> PageInputs:
    """What the page of a :class:`~o3d_seqcc.pipeline.RunResult` is drawn from.

    ``report``: the report.json content (default the result's own); ``folder``: where a ``selection.png``
    of the same view may be read (``selection_png``: its bytes, or a callable returning them, instead);
    ``images``: (photos, corrected) replacing the result's (e.g. :func:`~o3d_seqcc.report.cached_images`);
    ``casters``, ``parts``, ``selection_seams``: what was computed before (computed when absent).
    """
    vis = res.visibility
    corrected = res.images if res.correction is not None else None
    photos = res.originals if res.correction is not None else res.images
    if images is not None:
        photos, corrected = images
    return PageInputs(
        rep=res.report() if report is None else report, scene=res.scene, photos=photos, corrected=corrected,
        correction=res.correction, mappings=res.mappings, selection=np.asarray(res.selection),
        mesh=(vis.mesh.vertices, vis.mesh.faces), textured=res.textured, usable=vis.usable_counts(),
        selection_seams=selection_seams, casters=casters, parts=parts,
        selection_png=selection_png if selection_png is not None else _folder_selection_png(folder))


def correction_page_inputs(run: Any, report: dict | None = None) -> PageInputs:
    """What the page of a :class:`~o3d_seqcc.pipeline.CorrectionRun` is drawn from (``report``: default its own)."""
    vis = getattr(run.mappings, "visibility", None)
    return PageInputs(rep=run.report if report is None else report, scene=run.scene, photos=run.originals,
                      corrected=run.result.images, correction=run.result, mappings=run.mappings,
                      usable=None if vis is None else vis.usable_counts())


def save_rasters(out: str | os.PathLike, scene: Any, images: Any, report: dict, *, overwrite: bool = False,
                 command: str, layers: Callable[[Path], list] | None = None) -> Path:
    """The folder of the MeshLab filters' colour correction: ``images/<view>.png``, ``project.mlp`` and ``report.json``.

    Parameters
    ----------
    out : path-like
        The folder, staged then swapped in (:func:`o3d_seqcc.io.output.output_folder`).
    scene : Scene
        The rasters' scene (its views name the images; its inputs may not be replaced).
    images : sequence of (H, W, 3) arrays
        The corrected rasters, one per view.
    report : dict
        The report.json content.
    command : str
        The manifest's command.
    layers : callable, optional
        ``layers(stage)`` writes the project's mesh layers into the staging folder and returns their
        :class:`~o3d_seqcc.io.meshlab.MeshLayer` list (None: the scene's mesh).

    Returns
    -------
    pathlib.Path
        ``out/project.mlp``.
    """
    out = Path(out)
    with output_folder(out, overwrite=overwrite, inputs=scene.input_paths(), command=command) as stage:
        paths = [write_image(stage / IMAGES_DIR / f"{v.name}.png", img) for v, img in zip(scene.views, images)]
        save_mlp(scene, stage / MESHLAB_PROJECT, images=paths, layers=None if layers is None else layers(stage))
        write_json(stage / REPORT_JSON, report)
    return out / MESHLAB_PROJECT
