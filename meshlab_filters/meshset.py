"""A ``pymeshlab.MeshSet`` as our scene, and the two filters' jobs on it.

pymeshlab gives Python no access to its rasters (no camera, no image, no way to replace or delete
one: ``delete_current_raster`` is only safe while the current raster is not the first). So:

- **in**: ``ms.save_project`` writes the MeshSet's rasters (cameras and image files) to a temporary
  ``.mlp``, read by :func:`o3d_seqcc.io.meshlab.load_mlp`; the mesh is the current layer as MeshLab
  shows it (its placement matrix applied), written to a temporary PLY;
- **out**: the correction writes a complete MeshLab project (every mesh layer saved by MeshLab's
  own writer with its label, placement and visibility, plus the corrected rasters) and the
  MeshSet is re-opened from it (``ms.clear()``, ``ms.load_project``), so it holds exactly what
  the saved project holds; the texturing adds the textured mesh as a new layer
  (``ms.load_new_mesh``).

Caveats of pymeshlab 2025.7 (measured): ``save_project`` and ``load_project`` need an absolute
path (a relative one is resolved twice); a text ``.mlp`` keeps 6 significant digits of the
cameras, as MeshLab's own project files do; mesh ids change when the MeshSet is re-opened (the
current layer stays the current one).
"""

from __future__ import annotations

import logging
import re
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from o3d_seqcc.errors import InputError
from o3d_seqcc.io.meshlab import MeshLayer, load_mlp
from o3d_seqcc.io.output import check_output
from o3d_seqcc.run_folder.layout import IMAGES_DIR
from o3d_seqcc.run_folder.write import save_rasters
from o3d_seqcc.scene import Scene

__all__ = ["color_correct_rasters", "mesh_ids", "meshset_scene", "texture_from_rasters"]

logger = logging.getLogger(__name__)


def mesh_ids(ms: Any) -> list[int]:
    """Ids of the MeshSet's mesh layers, in layer order."""
    ids: list[int] = []
    i = 0
    while len(ids) < ms.mesh_number():
        if ms.mesh_id_exists(i):
            ids.append(i)
        i += 1
    return ids


def meshset_scene(ms: Any, folder: str | Path) -> Scene:
    """The MeshSet as a :class:`~o3d_seqcc.scene.Scene`: its current mesh and every raster.

    Parameters
    ----------
    ms : pymeshlab.MeshSet
        At least one triangle mesh and one raster.
    folder : path-like
        Existing folder for the project and mesh written on the way (``meshset.mlp``,
        ``current_mesh.ply``); they must outlive the scene's use.

    Returns
    -------
    Scene
        Mesh in world coordinates (the layer's placement matrix applied), one view per raster,
        named after the raster labels, images = the rasters' files. A current mesh with deleted
        elements is compacted first (``Mesh.compact``, as MeshLab's filters do).

    Raises
    ------
    InputError
        No raster, no mesh, or a current mesh without faces.
    """
    import trimesh

    if ms.mesh_number() == 0:
        raise InputError("the MeshSet holds no mesh; load a project with ms.load_project('/abs/project.mlp') "
                         "or a mesh with ms.load_new_mesh(...)")
    if ms.raster_number() == 0:
        raise InputError("the MeshSet holds no rasters; load a project with registered rasters "
                         "(ms.load_project('/abs/project.mlp'))")
    m = ms.current_mesh()
    if m.face_number() == 0:
        raise InputError(f"the current mesh {m.label()!r} has no faces (a point cloud?); make a triangle mesh "
                         "current with ms.set_current_mesh(id)")
    if not m.is_compact():
        m.compact()
    folder = Path(folder).resolve()
    project = folder / "meshset.mlp"
    ms.save_project(str(project))
    v, f = m.transformed_vertex_matrix(), m.face_matrix()
    uv = (m.wedge_tex_coord_matrix().reshape(-1, 3, 2) if m.has_wedge_tex_coord() else
          m.vertex_tex_coord_matrix()[f] if m.has_vertex_tex_coord() else None)
    if uv is None:
        mesh_path = folder / "current_mesh.ply"
        trimesh.Trimesh(v, f, process=False).export(mesh_path)
    else:  # its texture coordinates too, for uv="keep": an OBJ with one vt per face corner
        mesh_path = folder / "current_mesh.obj"
        _write_obj_with_corner_uv(mesh_path, v, f, uv)
    return load_mlp(project, mesh=mesh_path)


def _write_obj_with_corner_uv(path: Path, v: np.ndarray, f: np.ndarray, uv: np.ndarray) -> None:
    """An OBJ of ``v`` and ``f`` with ``uv`` (F, 3, 2) as one ``vt`` per face corner."""
    from o3d_seqcc.io.export.obj_text import general_field, int_field, rows

    v, t = np.asarray(v, dtype=np.float64), np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    f = np.asarray(f, dtype=np.int64) + 1
    c = np.arange(1, 3 * len(f) + 1).reshape(-1, 3)
    text = b"# o3d_seqcc: the MeshSet's current mesh with its texture coordinates\n"
    text += rows(["v ", general_field(v[:, 0], 9), " ", general_field(v[:, 1], 9), " ", general_field(v[:, 2], 9),
                  "\n"])
    text += rows(["vt ", general_field(t[:, 0], 9), " ", general_field(t[:, 1], 9), "\n"])
    text += rows(["f ", int_field(f[:, 0]), "/", int_field(c[:, 0]), " ", int_field(f[:, 1]), "/", int_field(c[:, 1]),
                  " ", int_field(f[:, 2]), "/", int_field(c[:, 2]), "\n"])
    path.write_bytes(text)


def _safe(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", Path(label).stem) or "mesh"


def _save_layers(ms: Any, folder: Path) -> list[MeshLayer]:
    """Every mesh layer saved by MeshLab's own PLY writer (textures beside it) under ``folder/layers/``."""
    current = ms.current_mesh_id()
    layers = []
    try:
        for k, i in enumerate(mesh_ids(ms)):
            ms.set_current_mesh(i)
            m = ms.current_mesh()
            path = folder / "layers" / str(k) / f"{_safe(m.label())}.ply"
            path.parent.mkdir(parents=True, exist_ok=True)
            ms.save_current_mesh(str(path.resolve()))
            layers.append(MeshLayer(path, label=m.label(), matrix=m.transform_matrix(), visible=m.is_visible()))
    finally:
        ms.set_current_mesh(current)
    return layers


def _reopen(ms: Any, project: Path, current_index: int) -> None:
    """Replace the MeshSet's content with ``project``; the layer at ``current_index`` becomes current."""
    ms.clear()
    ms.load_project(str(project.resolve()))
    ids = mesh_ids(ms)
    if ids:
        ms.set_current_mesh(ids[min(current_index, len(ids) - 1)])


def color_correct_rasters(
    ms: Any,
    *,
    reference: str | int,
    method: str,
    t_npm: int,
    mappings: str,
    graph_weight: str,
    seed: int,
    metrics: bool,
    savedir: str,
    overwrite: bool,
) -> dict[str, Any]:
    """Colour-correct the MeshSet's rasters (filter ``seqcc_color_correct_rasters``).

    Writes ``savedir`` as a whole: ``images/<raster>.png`` (corrected), ``layers/<k>/<label>.ply``
    (the mesh layers as they were), ``project.mlp`` (the layers + the corrected rasters, same
    cameras), ``report.json`` (what ``o3d-seqcc correct`` reports); then re-opens the MeshSet
    from that project. Options as :func:`o3d_seqcc.pipeline.correct_scene`.

    Returns
    -------
    dict
        ``savedir``, ``project``, ``images`` (raster -> corrected file), ``reference`` (raster
        label), ``unreachable`` (labels of the rasters left as they were).
    """
    from o3d_seqcc.pipeline import correct_scene

    out = Path(savedir).absolute()
    with tempfile.TemporaryDirectory(prefix="seqcc_meshset_") as tmp:
        scene = meshset_scene(ms, tmp)
        check_output(out, overwrite=overwrite, inputs=scene.input_paths())
        job = correct_scene(scene, reference=reference, method=method, t_npm=t_npm, mappings=mappings,
                            graph_weight=graph_weight, seed=seed, metrics=metrics)
        current_index = mesh_ids(ms).index(ms.current_mesh_id())
        project = save_rasters(out, scene, job.result.images, job.report, overwrite=overwrite,
                               command="seqcc_color_correct_rasters", layers=lambda stage: _save_layers(ms, stage))
    _reopen(ms, project, current_index)
    names = scene.names
    logger.info("corrected %d rasters toward %s -> %s", len(names), names[job.result.reference], out)
    return {
        "savedir": str(out),
        "project": str(project),
        "images": {v.name: str(out / IMAGES_DIR / f"{v.name}.png") for v in scene.views},
        "reference": names[job.result.reference],
        "unreachable": [names[i] for i in job.result.unreachable],
    }


def texture_from_rasters(
    ms: Any,
    *,
    colorcorrection: bool,
    reference: str | int,
    method: str,
    t_npm: int,
    mappings: str,
    seams: bool,
    formats: str,
    save_images: bool,
    savedir: str,
    overwrite: bool,
    **texture_settings: Any,
) -> dict[str, Any]:
    """Texture the MeshSet's current mesh from its rasters (filter ``seqcc_texture_from_rasters``).

    Runs :func:`o3d_seqcc.pipeline.run` (``colorcorrection``) or :func:`~o3d_seqcc.pipeline.texture`,
    writes ``savedir`` as they do (``RunResult.save``: ``mesh_meshlab.ply`` + texture, the export
    formats, ``project.mlp``, ``report.json``), then adds ``mesh_meshlab.ply`` to the MeshSet as a
    new layer, which becomes the current mesh. ``**texture_settings``: fields of
    :class:`~o3d_seqcc.texturing.TextureSettings`.

    Returns
    -------
    dict
        ``savedir``, ``project``, ``mesh`` (the layer's file), ``mesh_id`` (its id in the MeshSet),
        ``files`` (kind -> path, as ``report.json``), ``faces``, ``unseen_faces``, ``atlas_size``,
        ``reference`` (raster label, or None without colour correction).
    """
    from o3d_seqcc import pipeline
    from o3d_seqcc.texturing import TextureSettings

    fmts = pipeline.parse_formats(formats)
    settings = TextureSettings(**texture_settings)
    out = Path(savedir).absolute()
    label = ms.current_mesh().label() if ms.mesh_number() else ""
    with tempfile.TemporaryDirectory(prefix="seqcc_meshset_") as tmp:
        scene = meshset_scene(ms, tmp)
        check_output(out, overwrite=overwrite, inputs=scene.input_paths())
        if colorcorrection:
            res = pipeline.run(scene, reference=reference, method=method, t_npm=t_npm, mappings=mappings,
                               settings=settings, seams=seams)
        else:
            res = pipeline.texture(scene, settings=settings, seams=seams)
        files = res.save(out, overwrite=overwrite, formats=fmts, save_images=save_images)
    if "meshlab_mesh" not in files:
        raise InputError(f"{out}: no MeshLab layer was written (see the warning above); the cameras cannot be "
                         "written to a MeshLab project")
    ms.load_new_mesh(files["meshlab_mesh"])
    ms.current_mesh().set_label(f"{_safe(label)}_textured")
    s = res.selection_stats
    logger.info("textured %s (%d faces, %d unseen) -> %s", label, s["faces"], s["unseen_faces"], out)
    return {
        "savedir": str(out),
        "project": files["meshlab_project"],
        "mesh": files["meshlab_mesh"],
        "mesh_id": int(ms.current_mesh_id()),
        "files": files,
        "faces": int(s["faces"]),
        "unseen_faces": int(s["unseen_faces"]),
        "atlas_size": int(res.textured.atlas_size),
        "reference": res.scene.names[res.correction.reference] if res.correction is not None else None,
    }
