"""What is read back from a run's output folder: its report, its selection, and the page written again.

``o3d-seqcc report RUN_DIR`` (:func:`regenerate_report`) and the checks of a folder read through
here; nothing read is trusted: ``report.json`` is validated against the schema
(:func:`~o3d_seqcc.report.validate.validate_report`), ``selection.npy`` is checked from its header
(shape, dtype, size, index range) before it is read, and the manifest's entries by
:mod:`o3d_seqcc.io.manifest`. The names are :mod:`o3d_seqcc.run_folder.layout`'s.
"""

from __future__ import annotations

import logging
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import InputError, warn
from ..io.json_files import read_json
from ..io.regular_files import open_regular
from ..io.output import add_output_file, check_output_file, write_output_file
from ..report import metrics_sample
from ..report.inputs import PageInputs, facts
from ..report.page import render_page
from ..report.schema import upgrade
from ..report.validate import page_bytes, validate_report
from .layout import MESH_FORMATS, REPORT_HTML, REPORT_JSON, SELECTION_NPY, SELECTION_PNG, mesh_file, read_back_files

__all__ = ["read_report_json", "read_selection", "regenerate_report", "selection_png"]

logger = logging.getLogger(__name__)


def read_report_json(run_dir: str | os.PathLike) -> dict:
    """``run_dir/report.json``, read (regular file, UTF-8, no duplicate keys), validated and in the current schema.

    A report of an older o3d_seqcc is checked as written (the messages name its fields) and returned
    through :func:`~o3d_seqcc.report.schema.upgrade` (its keys moved where the schema has them).

    Raises
    ------
    InputError
        ``run_dir`` is not a folder or holds no report.json; the file is not valid JSON (cut
        short, edited) or does not pass :func:`validate_report`.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise InputError(f"{run_dir} is not a folder; give the output folder (--out) of o3d-seqcc run, correct or "
                         "texture")
    rj = run_dir / REPORT_JSON
    if not os.path.lexists(rj):
        raise InputError(f"{run_dir} is not an o3d-seqcc output folder (no report.json); give the --out folder of "
                         "o3d-seqcc run, correct or texture")
    try:
        rep = read_json(rj, REPORT_JSON)
    except InputError as e:
        raise InputError(f"{e}; run the command again to rewrite the folder") from None
    return upgrade(validate_report(rep, rj))


def read_selection(path: str | os.PathLike, n_faces: int, n_views: int) -> np.ndarray | None:
    """``selection.npy``: one view index per face (-1 = seen by no view), checked from its header first.

    Returns None, with a warning, when it holds another number of faces than the mesh (the
    report then leaves the selection out).

    Raises
    ------
    InputError
        Not a regular file, not a ``.npy`` array, not a 1-D integer array, cut short, or indices
        outside -1..``n_views`` - 1.
    """
    path = Path(path)
    with open_regular(path, SELECTION_NPY) as f:
        size = os.fstat(f.fileno()).st_size
        try:
            fmt = np.lib.format
            version = fmt.read_magic(f)
            header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
            shape, fortran, dtype = header(f)
            offset = f.tell()
        except (ValueError, OSError, EOFError, SyntaxError, TypeError) as e:
            raise InputError(f"{path} is not a numpy .npy array ({e}); run the command again") from None
        if dtype.kind not in "iu" or len(shape) != 1:
            raise InputError(f"{path} holds a {dtype} array of shape {shape}; expected one integer view index per "
                             f"face ({n_faces},); run the command again")
        if shape[0] != n_faces:
            warn(f"{path} has {shape[0]} entries for the {n_faces} faces of the mesh (another mesh?): the selection "
                 "is left out of the report; pass the run's --mesh, or run the command again")
            return None
        if size - offset < shape[0] * dtype.itemsize:
            raise InputError(f"{path} is truncated ({size} bytes for {shape[0]} entries); run the command again")
        sel = np.fromfile(f, dtype=dtype, count=shape[0]).astype(np.int64)
    if len(sel) and (sel.min() < -1 or sel.max() >= n_views):
        raise InputError(f"{path} holds view indices {int(sel.min())}..{int(sel.max())} for {n_views} views "
                         f"(-1..{n_views - 1}); run the command again")
    return sel


def selection_png(folder: Path | None) -> bytes | None:
    """The folder's selection.png (the report embeds it instead of rendering the same picture again)."""
    p = None if folder is None else folder / SELECTION_PNG
    return p.read_bytes() if p is not None and p.is_file() else None


def _scene_frame(tm, rep: dict, fmt: str):
    """``tm`` back in the scene's frame: the exporters baked the report's up-axis rotation into ``fmt``'s file."""
    o = (rep.get("export") or {}).get("orientation") or {}
    if fmt not in o.get("applies_to", ()) or o.get("rotation") is None:
        return tm
    R = np.asarray(o["rotation"], dtype=np.float64)
    if np.allclose(R, np.eye(3)):
        return tm
    return replace(tm, vertices=tm.vertices @ R, normals=None if tm.normals is None else tm.normals @ R)


def _inputs_from_folder(run_dir: Path, rep: dict, *, scene, mesh, image_dir=None, output=None) -> PageInputs:
    from ..correction import correct
    from ..io.load import load_scene
    from ..mappings.compute import compute_mappings
    from ..evaluation.table2 import before_after
    from ..texturing import load_textured_mesh
    from ..visibility.compute import compute_visibility

    f = facts(rep)
    src = scene if scene is not None else (rep.get("scene_path") or rep.get("scene"))
    if not src:
        raise InputError(f"{run_dir / REPORT_JSON} does not say where the scene is (a scene in memory, or an older "
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
        raise InputError(f"cannot reload the scene {src} named in {run_dir / REPORT_JSON}: {e}; pass --scene "
                         "(and --mesh) to say where it is now") from None
    if output is not None:  # before any work: the page may not replace a file the report reads
        check_output_file(output, option="--output", inputs=[*sc.input_paths(), *read_back_files(run_dir)])
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
    if os.path.lexists(run_dir / SELECTION_NPY):
        selection = read_selection(run_dir / SELECTION_NPY, len(faces), len(sc.views))
    tm_path = next((run_dir / mesh_file(f) for f in MESH_FORMATS if (run_dir / mesh_file(f)).is_file()), None)
    if tm_path is not None and selection is not None:
        textured = _scene_frame(load_textured_mesh(tm_path), rep, tm_path.suffix.lstrip("."))
        if textured.face_view is None and len(textured.faces) == len(selection) \
                and int((rep.get("atlas") or {}).get("pages", 1)) == 1:  # one page: the file keeps the faces' order
            textured = replace(textured, face_view=np.where(selection >= 0, selection, -1))
    return PageInputs(rep=rep, scene=sc, photos=photos, corrected=corrected, correction=correction, mappings=maps,
                   selection=selection, mesh=(vis.mesh.vertices, faces), textured=textured,
                   usable=vis.usable_counts(), selection_png=selection_png(run_dir))


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
    if output is not None and os.path.realpath(output) == os.path.realpath(run_dir / REPORT_HTML):
        output = None  # the folder's own page: listed in its manifest as before
    if output is not None:  # before any work (again with the scene's files once it is loaded)
        check_output_file(output, option="--output", inputs=[p for p in (rep.get("scene_path"), rep.get("mesh"),
                                                                         scene, mesh) if p] + read_back_files(run_dir))
    inp = _inputs_from_folder(run_dir, rep, scene=scene, mesh=mesh, image_dir=image_dir, output=output)
    data = page_bytes(render_page(inp, width=int(thumb_width)))
    if output is not None:
        return write_output_file(output, data, option="--output",
                                 inputs=[*inp.scene.input_paths(), *read_back_files(run_dir)])
    return add_output_file(run_dir, REPORT_HTML, data)
