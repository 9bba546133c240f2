"""Select one image per face, bake a texture atlas, export GLB/OBJ (+ report.json).

Per-face image selection (mrf, largest-area, random) using the visibility filters, a texture
atlas cut from the images at their own resolution, seam leveling, and OBJ+MTL+PNG / GLB export,
on the scene's images (or --images, a folder of images named after the views, e.g. corrected
ones). Writes what run writes, without the correction.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

from .. import pipeline
from ..io.images import read_view_images
from .console import add_progress_argument
from .correction_flags import add_split_argument
from .scene_flags import add_scene_arguments, print_run_summary
from .texture_flags import add_texture_arguments, texture_job_from_args


def run(args: argparse.Namespace) -> int:
    settings, save_options, scene, out = texture_job_from_args(args)
    images = read_view_images(scene, args.images) if args.images else None
    res = pipeline.texture(scene, images=images, settings=settings)
    res = replace(res, source=args.scene, images_from=str(args.images) if args.images else "scene")
    res.save(out, overwrite=args.overwrite, formats=args.format, selection_view=args.selection_view,
             **save_options)
    print_run_summary(res, out)
    return 0




def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    add_split_argument(p)
    add_texture_arguments(p)
    p.add_argument("--images", help="folder of (corrected) images named after the views, used instead of the scene's")
    add_progress_argument(p)
