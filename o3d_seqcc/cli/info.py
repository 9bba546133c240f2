"""Load a scene, validate it, check its cameras against its mesh and print what was found.

Reads any scene o3d-seqcc accepts (scene.json, MeshLab .mlp, Meshroom cameras.sfm, Open3D RGB-D
folder, COLMAP text or binary model, OpenMVS scene.mvs), checks every file and image header,
checks the cameras against the mesh (camera-to-world matrices given as world-to-camera, OpenGL
axes, mesh units, intrinsics of another image size) and prints the format, the views (sizes,
depth, lens distortion), the mesh, how much of it the cameras see and the warnings; --json
prints the same as JSON. A likely camera mistake, or a mesh the photos do not show (less than 10 %
of it seen, without --allow-unseen), is printed, then reported as the error (exit 2).
"""

from __future__ import annotations

import argparse
import json
import warnings

from ..visibility.camera_checks import MIN_AREA_SEEN, check_cameras
from ..errors import InputError
from ..io.load import camera_fixes, detect_format
from ..scene import summarise
from .scene_flags import add_scene_arguments, scene_from_args, scene_options_from_args


def run(args: argparse.Namespace) -> int:
    fmt, target = detect_format(args.scene)
    check = args.camera_check
    args.camera_check = False  # checked below, so that the findings are printed before any error
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = scene_from_args(args)
    load_warnings = [str(w.message) for w in caught]
    summary = {**summarise(scene), "format": fmt.name, "source": str(target)}
    rep = None
    if check:
        opts = scene_options_from_args(args)
        skip = tuple(n for n, stated in (("inverse", opts["extrinsic"]), ("opengl", opts["axes"])) if stated)
        rep = check_cameras(scene, skip=skip, raise_on_mistake=False, max_views=256)
        summary["camera_check"] = rep.to_dict()
    summary["warnings"] = load_warnings + (rep.warnings if rep is not None else [])
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(_text(summary, rep))
    if rep is not None and rep.mistake is not None:
        raise InputError(rep.error_message(str(target), camera_fixes(fmt)))
    if rep is not None and rep.hardly_seen(MIN_AREA_SEEN) and not args.allow_unseen:
        raise InputError(rep.unseen_message(str(target), camera_fixes(fmt)))
    return 0


def _text(s: dict, rep) -> str:
    lines = [f"scene: {s['source']} ({s['format']})",
             f"views: {s['views']} ({', '.join(s['image_size'])}), {s['with_depth']} with depth maps, "
             f"{s['with_point_cloud']} with point clouds" + (f", {s['distorted']} with lens distortion (undistorted "
                                                             "when read)" if s.get("distorted") else "")
             + (f", {s['with_mask']} with masks" if s.get("with_mask") else ""),
             f"mesh: {s['mesh']}: {s['mesh_faces']} faces, {s['mesh_vertices']} vertices, bounds "
             f"{s['mesh_bounds'][0]} .. {s['mesh_bounds'][1]}",
             f"camera centres: {s['camera_centre_bounds'][0]} .. {s['camera_centre_bounds'][1]}"]
    if rep is not None:
        lines.append(f"cameras: {rep.front_fraction:.0%} of the pixels of {rep.views_checked} views show the mesh from "
                     f"the front; {rep.area_seen:.0%} of the mesh faces a camera ({rep.faces_sampled} faces sampled, "
                     f"{rep.seconds:.2f} s)")
        if rep.views_seeing_nothing:
            names = rep.views_seeing_nothing
            lines.append(f"views that see no part of the mesh: {len(names)} ({', '.join(names[:8])}"
                         f"{' ...' if len(names) > 8 else ''})")
        if rep.mistake is not None:
            lines.append(f"likely camera mistake: {rep.describe_mistake()}")
    else:
        lines.append("cameras: not checked (--no-camera-check)")
    lines += [f"warning: {w}" for w in s["warnings"]]
    return "\n".join(lines)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("--json", action="store_true", help="print the summary as JSON (the keys of earlier versions, plus "
                   "format, source, camera_check and warnings)")
