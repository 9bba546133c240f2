"""The names of everything a run's output folder holds, defined once.

Every writer (:mod:`o3d_seqcc.run_folder.write`, the MeshLab filters, the demo) and every reader
(:mod:`o3d_seqcc.run_folder.read`, the report, ``o3d-seqcc report``) takes the names from here;
``tests/test_layout.py`` checks that no other module spells them. The folder itself is written as
a whole by :func:`o3d_seqcc.io.output.output_folder` (staged, then swapped in), whose manifest
(:data:`o3d_seqcc.io.manifest.MANIFEST`) lists what o3d-seqcc wrote.

Layout of ``o3d-seqcc run`` / ``texture`` (``correct`` writes the images, the scene and the report)::

    OUT/
      mesh.glb, mesh.obj + mesh.mtl + mesh.png   the textured mesh (MESH_STEM; pages mesh_<k>.png)
      mesh_colors.ply                             with --format ply (vertex colours)
      mesh_meshlab.ply                            MeshLab's layer (MESHLAB_LAYER) of project.mlp
      project.mlp                                 the MeshLab project (MESHLAB_PROJECT)
      selection.npy, selection.png                the view per face and its picture
      images/<view>.png                           the images used (correct; run --save-images)
      scene.json (+ mesh.ply)                     correct: the scene of the corrected images
      report.json, report.html                    the numbers and the page
"""

from __future__ import annotations

from pathlib import Path

from ..io.export import FILE_SUFFIXES
from ..io.scene_json import SCENE_JSON

__all__ = ["DEMO_SUMMARY", "IMAGES_DIR", "MESHLAB_LAYER", "MESHLAB_PROJECT", "MESH_FORMATS", "MESH_STEM",
           "REPORT_HTML", "REPORT_JSON", "SCENE_JSON", "SCENE_MESH", "SELECTION_NPY", "SELECTION_PNG", "mesh_file",
           "read_back_files"]

#: the numbers of the run (o3d_seqcc.report.schema)
REPORT_JSON = "report.json"
#: the page (o3d_seqcc.report)
REPORT_HTML = "report.html"
#: (F,) int32: the view of each face of the split mesh, -1 unseen
SELECTION_NPY = "selection.npy"
#: the selection coloured by view, rendered from one view (the report's Figure 9)
SELECTION_PNG = "selection.png"
#: the stem of the textured mesh's files: mesh.glb, mesh.obj, mesh.ply, mesh.mtl, mesh.png / mesh_<page>.png
MESH_STEM = "mesh"
#: the textured mesh formats the report reads back, in this order (the PLY holds vertex colours, no texture)
MESH_FORMATS = ("glb", "obj")
#: MeshLab's textured PLY layer (MeshLab 2020.09 aborts on any OBJ)
MESHLAB_LAYER = "mesh_meshlab.ply"
#: the MeshLab project: the mesh layer and the rasters
MESHLAB_PROJECT = "project.mlp"
#: the images used (corrected for run / correct), one <view>.png each
IMAGES_DIR = "images"
#: correct's scene of the corrected images names this mesh when the scene's was in memory
SCENE_MESH = "mesh.ply"
#: the demo's summary beside its report
DEMO_SUMMARY = "demo_summary.json"


def mesh_file(fmt: str) -> str:
    """The textured mesh's file name for export format ``fmt`` (``"glb"`` -> ``"mesh.glb"``, ``"ply"`` ->
    ``"mesh_colors.ply"``: :data:`o3d_seqcc.io.export.FILE_SUFFIXES`)."""
    return f"{MESH_STEM}{FILE_SUFFIXES[fmt]}"


def read_back_files(run_dir: Path) -> list[Path]:
    """The files of an output folder that ``o3d-seqcc report`` reads back (a page may not replace them)."""
    return [run_dir / n for n in (REPORT_JSON, SELECTION_NPY, SELECTION_PNG, *map(mesh_file, FILE_SUFFIXES))]
