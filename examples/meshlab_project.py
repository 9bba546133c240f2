"""MeshLab project in, colour-corrected (and textured) MeshLab project out, through pymeshlab.

What it shows: a MeshLab project (.mlp: a mesh + registered rasters) loaded into a
pymeshlab.MeshSet; our two jobs applied pymeshlab style, meshlab_filters.apply(ms, name, ...)
as ms.apply_filter(name, ...) would be called, with the command line's defaults
(print_filter_parameter_list shows them); the MeshSet saved as a project MeshLab opens. Without
a project it builds a small synthetic room (4 photos with different exposure, white balance and
gamma) and writes its project first.

How to run (from any folder; a few seconds on the synthetic room; needs the meshlab extra,
pip install "o3d-seqcc[meshlab]", which ./dev.sh setup installs):

    python examples/meshlab_project.py                          # the synthetic room
    python examples/meshlab_project.py /abs/path/project.mlp --texture --out DIR

Output: --out (default: TMP/o3d_seqcc_examples/meshlab_project)/corrected.mlp; open it in MeshLab.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import pymeshlab

import meshlab_filters
import o3d_seqcc


def synthetic_project(folder: Path) -> Path:
    """A small synthetic room saved as a MeshLab project (mesh.ply + 4 rasters)."""
    o3d_seqcc.make_synthetic_scene(folder, n_views=4, width=160, height=120, cell_size=0.12, overwrite=True)
    return meshlab_filters.save_mlp(o3d_seqcc.load_scene(folder), folder / "project.mlp")


def run(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("project", nargs="?", type=Path, help="MeshLab project (default: a synthetic room)")
    p.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "o3d_seqcc_examples" / "meshlab_project",
                   help="output folder (default: %(default)s)")
    p.add_argument("--texture", action="store_true", help="also texture the mesh from the corrected rasters")
    args = p.parse_args(argv)
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    project = args.project.resolve() if args.project else synthetic_project(out / "input")

    ms = pymeshlab.MeshSet()
    ms.load_project(str(project))  # pymeshlab wants absolute paths for projects
    print(f"{project}: {ms.mesh_number()} mesh, {ms.raster_number()} rasters")

    meshlab_filters.print_filter_parameter_list("seqcc_color_correct_rasters")
    res = meshlab_filters.apply(ms, "seqcc_color_correct_rasters", reference="auto", metrics=False,
                                savedir=str(out / "corrected"), overwrite=True)
    print(f"corrected {len(res['images'])} rasters toward {res['reference']} -> {res['savedir']}")
    if args.texture:
        tex = meshlab_filters.apply(ms, "seqcc_texture_from_rasters", colorcorrection=False, atlassize=1024,
                                    savedir=str(out / "textured"), overwrite=True)
        print(f"textured {tex['faces']} faces -> layer {tex['mesh_id']} ({tex['mesh']})")

    ms.save_project(str(out / "corrected.mlp"))  # the MeshSet: mesh layer(s) + corrected rasters
    print(f"wrote {out / 'corrected.mlp'} ({ms.mesh_number()} mesh layer(s), {ms.raster_number()} rasters)")
    return 0


if __name__ == "__main__":
    sys.exit(run())
