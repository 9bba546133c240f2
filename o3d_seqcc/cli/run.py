"""Colour-correct the views, then texture the mesh with the corrected images (the main job).

Sequential pairwise colour correction refined jointly over every graph edge (seqcc-global, the
default; --method seqcc is the paper's) followed by per-face image selection, atlas baking, seam
leveling and GLB/OBJ export. Writes OUT/mesh.glb, OUT/mesh.obj (+ .mtl, .png), OUT/selection.npy,
OUT/selection.png (the selection coloured by image), optionally the corrected images
(--save-images), OUT/report.json (correction summary, selection statistics, seam metric,
timings) and OUT/project.mlp, which MeshLab opens: OUT/mesh_meshlab.ply (the textured mesh as
MeshLab's own textured PLY) as a layer and the rasters (the corrected ones with --save-images).
"""

from __future__ import annotations

import argparse
from dataclasses import replace

from .. import pipeline
from ..settings import RunSettings
from .console import add_progress_argument
from .correction_flags import add_correction_arguments, add_split_argument
from .scene_flags import add_scene_arguments, print_run_summary
from .texture_flags import add_texture_arguments, texture_job_from_args


def run(args: argparse.Namespace) -> int:
    settings, save_options, scene, out = texture_job_from_args(args)
    res = pipeline.run(scene, settings=settings)
    res = replace(res, source=args.scene)
    res.save(out, overwrite=args.overwrite, formats=args.format, save_images=args.save_images,
             selection_view=args.selection_view, **save_options)
    print_run_summary(res, out)
    return 0




def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    add_correction_arguments(p)
    add_split_argument(p)
    add_texture_arguments(p)
    p.add_argument("--save-images", action="store_true", help="also write the corrected images to OUT/images/")
    p.add_argument("--compare-original", action="store_true", default=RunSettings().compare_original,
                   help="also report the seam metric of the same texturing with the uncorrected images")
    add_progress_argument(p)
