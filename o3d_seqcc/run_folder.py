"""What :meth:`o3d_seqcc.pipeline.RunResult.save` writes into its staging folder, the independent parts at once.

The parts of a run's folder do not wait for each other: the textured mesh's files (texture
pages encoded by OpenCV, GLB / OBJ / PLY written, the MeshLab project), ``selection.png`` (a
ray-cast render), the report's Table 2 and selection seams (ready from :func:`~o3d_seqcc.pipeline.run`'s
background thread, else computed here), and the report page (figures, the viewer's textures,
renders; its Figure 9 is ``selection.png``, taken when written) run side by side on threads
(OpenCV, Open3D and numpy release the GIL), so the export and the report share the machine's
cores instead of following each other.
Only the page's timings table waits for the export (it shows the export's seconds): the page
is built with the timings known then, and that one table is filled in at the end. Every file
is written into the staging folder of :func:`o3d_seqcc.io.output.output_folder`, which is
swapped in only when all of them are complete; an error in any part cancels the parts not
started, waits for the running ones, and leaves the folder unswapped.
"""

from __future__ import annotations

import io
import logging
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from .io.export import export_meshlab_ply, export_textured_mesh, float32_offset, texture_file_names
from .io.atomic import atomic_write_bytes
from .io.json_files import write_json
from .io.result_files import meshlab_project, write_images
from ._shared.interrupts import held
from ._shared.parallel import carried
from .evaluation.render import Casters, picture_view, write_selection_picture
from .report import REPORT_FILE, cached_images
from .report.validate import page_bytes

__all__ = ["write_run_folder"]

logger = logging.getLogger(__name__)


def _mesh_files(res: Any, stage: Path, *, fmts: list[str], tfmt: str, quality: int, unlit: bool, rotation: Any,
                save_images: bool) -> tuple[dict[str, Path], dict[str, Path], float]:
    """The textured mesh's files, selection.npy, the images, the MeshLab project: (files before the selection
    picture, files after it, seconds)."""
    t = time.perf_counter()
    written = {k: Path(v) for k, v in export_textured_mesh(
        res.textured, stage, formats=fmts, unlit=unlit, texture_format=tfmt, quality=int(quality),
        transform=rotation).items()}
    buf = io.BytesIO()
    np.save(buf, res.selection)
    atomic_write_bytes(stage / "selection.npy", buf.getvalue())
    after: dict[str, Path] = {}
    rasters = None
    if save_images:
        rasters = write_images(stage / "images", res.scene.views, res.images)
        after["images"] = stage / "images"
    # the layer is MeshLab's own textured PLY: MeshLab 2020.09 (Debian 12) aborts on any OBJ
    layer = stage / "mesh_meshlab.ply"
    shift = float32_offset(res.textured.vertices)  # MeshLab holds float32: the layer matrix adds it back
    project = meshlab_project(res.scene, stage, mesh=layer, images=rasters, offset=shift)
    if project is not None:
        after["meshlab_project"] = project
        reuse = "obj" in written and tfmt in ("png", "jpg")  # MeshLab reads the OBJ's PNG / JPEG files
        after["meshlab_mesh"] = export_meshlab_ply(
            res.textured, layer, texture=[stage / n for n in texture_file_names("mesh", tfmt, res.textured.pages)]
            if reuse else None, offset=shift)
    return written, after, time.perf_counter() - t


def _selection_picture(res: Any, path: Path, view: Any, casters: Casters, mesh: tuple) -> tuple[Path, str]:
    return write_selection_picture(res.scene, res.visibility, res.selection, path, view, caster=casters.get(mesh))


def write_run_folder(res: Any, stage: Path, out: Path, *, fmts: list[str], tfmt: str, quality: int, unlit: bool,
                     rotation: Any, orientation: dict, picture: bool, view: Any, save_images: bool,
                     report: bool) -> dict[str, str]:
    """Write ``res``'s folder into ``stage`` (later swapped in as ``out``); returns kind -> final path.

    Parameters
    ----------
    res : pipeline.RunResult
    stage, out : pathlib.Path
        The staging folder, and the folder it becomes (the paths the report names).
    fmts, tfmt, quality, unlit
        Export formats, texture format, JPEG / WebP quality, unlit GLB material.
    rotation : (3, 3) float or None
        The export's up-axis rotation (None: the scene's frame); ``orientation`` its record.
    picture : bool
        Write ``selection.png`` (from ``view``; None: the view seeing the most faces).
    save_images : bool
        Also write the images used to ``images/``.
    report : bool
        Also write ``report.html`` and Table 2.
    """
    from .report import write_report
    from .report.page import timings_block

    table2 = report and res.correction is not None and res.mappings is not None and res.originals is not None
    images = cached_images(*((res.originals, res.images) if res.originals else (res.images, None)))
    export = {"formats": fmts, "texture_format": tfmt, "jpeg_quality": int(quality), "unlit": bool(unlit),
              "orientation": {**orientation, "applies_to": [f for f in fmts]}}
    casters = Casters()  # the ray-casting scenes of the mesh and the textured mesh: built once for the picture and the page
    mesh = (res.visibility.mesh.vertices, res.visibility.mesh.faces)
    pool = ThreadPoolExecutor(max_workers=3, thread_name_prefix="o3d_seqcc-save")
    try:
        with held():  # a signal inside submit's Thread.start would leave a writer that shutdown does not join
            files = pool.submit(carried(_mesh_files, "save: mesh files"), res, stage, fmts=fmts, tfmt=tfmt,
                                quality=quality, unlit=unlit, rotation=rotation, save_images=save_images)
            pic = pool.submit(carried(_selection_picture, "save: selection picture"), res, stage / "selection.png",
                              view, casters, mesh) if picture else None
            prelude = pool.submit(carried(res._report_prelude, "save: table 2 and seam steps"), table2,
                                  images) if report else None
        rep = page = None
        t = time.perf_counter()
        if report:  # the page, while the files are written: everything but the export's seconds is known
            metrics, steps, parts = prelude.result()
            name = None if pic is None else res.scene.names[picture_view(res.scene, res.visibility, view)]
            rep = res.report({}, picture_view=name, export=export, metrics=metrics, selection_seams=steps)
            page = write_report(res, stage / REPORT_FILE, report=rep, selection_seams=steps, images=images,
                                write=False, casters=casters, parts=parts,
                                selection_png=None if pic is None else lambda: pic.result()[0].read_bytes())
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
        written_out["report_html"] = str(Path(out) / REPORT_FILE)
    final = res.report(written_out, picture_view=None if picture_path is None else picture_path[1], export=export,
                       metrics=None if rep is None else rep.get("metrics"),
                       selection_seams=None if rep is None else prelude.result()[1])
    if report:
        head, rest = page.split("<!-- timings -->", 1)
        tail = rest.split("<!-- /timings -->", 1)[1]
        atomic_write_bytes(stage / REPORT_FILE, page_bytes(head + timings_block(final) + tail))
        res.timings["report"] = t_report
        final["timings_s"]["report"] = round(t_report, 4)
    write_json(stage / "report.json", final)
    return written_out
