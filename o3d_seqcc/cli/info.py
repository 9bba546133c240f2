"""``o3d-seqcc info SCENE``: load a scene and summarise it."""

from __future__ import annotations

import argparse
import json

import numpy as np

from ..scene import load_scene


def add_scene_arguments(p: argparse.ArgumentParser) -> None:
    """The scene argument and the loader options every command shares."""
    p.add_argument("scene", help="scene.json (or its folder), an Open3D RGB-D folder, or a COLMAP text model folder")
    p.add_argument("--mesh", help="mesh file (required for RGB-D folders and COLMAP models; overrides scene.json's)")


def load_scene_from_args(args: argparse.Namespace):
    return load_scene(args.scene, mesh=getattr(args, "mesh", None))


def summarise(scene) -> dict:
    m = scene.load_mesh()
    centres = np.array([v.center for v in scene.views])
    return {
        "views": len(scene.views),
        "names": scene.names[:3] + (["..."] if len(scene.views) > 3 else []),
        "image_size": sorted({f"{v.width}x{v.height}" for v in scene.views}),
        "with_depth": sum(v.depth is not None for v in scene.views),
        "with_point_cloud": sum(v.point_cloud is not None for v in scene.views),
        "mesh": str(scene.mesh),
        "mesh_vertices": int(len(m.vertices)),
        "mesh_faces": int(len(m.faces)),
        "mesh_bounds": [m.vertices.min(0).round(3).tolist(), m.vertices.max(0).round(3).tolist()],
        "camera_centre_bounds": [centres.min(0).round(3).tolist(), centres.max(0).round(3).tolist()],
    }


def run(args: argparse.Namespace) -> int:
    scene = load_scene_from_args(args)
    print(json.dumps(summarise(scene), indent=1))
    return 0


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("info", help="load a scene, validate it and print a summary")
    add_scene_arguments(p)
    p.set_defaults(func=run)
    return p
