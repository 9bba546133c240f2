"""Load a scene, validate it and print a summary.

Reads any scene o3d-seqcc accepts (scene.json, MeshLab .mlp, Meshroom cameras.sfm, Open3D RGB-D
folder, COLMAP text or binary model), checks every file and image header, and prints the
number of views, image sizes, depth, mesh size and bounds.
"""

from __future__ import annotations

import argparse
import json

from ..scene import summarise
from .common import add_scene_arguments, scene_from_args


def run(args: argparse.Namespace) -> int:
    print(json.dumps(summarise(scene_from_args(args)), indent=1))
    return 0




def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
