"""The scene argument and the loader's flags every command shares, and a command's outputs: ``--out``
and output files checked against the inputs before any work, the summary a run prints."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..io.load import load_scene
from ..io.output import check_output, check_output_file
from ..scene import DEPTH_SCALE_RANGE
from ..run_folder.layout import REPORT_HTML
from ..settings import keyword_defaults


def add_scene_arguments(p: argparse.ArgumentParser) -> None:
    """The scene argument and the loader options every command shares."""
    from ..io.load import AXES, EXTRINSIC_CONVENTIONS
    from ..visibility.camera_checks import MIN_AREA_SEEN

    p.add_argument("scene", help="scene.json (or its folder), a MeshLab .mlp, Meshroom cameras.sfm, an Open3D RGB-D "
                   "folder, a COLMAP model folder (text or binary), or an OpenMVS scene.mvs")
    p.add_argument("--mesh", help="mesh file (required for RGB-D folders, COLMAP and Meshroom; overrides the others')")
    p.add_argument("--image-dir", help="folder of the images (COLMAP, Meshroom, OpenMVS), instead of where the scene "
                   "file says")
    p.add_argument("--depth-dir", help="folder of depth maps named after the views, for scenes without depth (MeshLab "
                   "projects, COLMAP, Meshroom): turns the depth-consistency filter on")
    depth_scale = keyword_defaults(load_scene)["depth_scale"]
    p.add_argument("--depth-scale", type=float, default=depth_scale,
                   help=f"depth units per metre of the --depth-dir maps (default {depth_scale:g}: millimetres)")
    p.add_argument("--extrinsic", choices=EXTRINSIC_CONVENTIONS, default=None,
                   help="what the scene's pose matrices map (scene.json, COLMAP, RGB-D folders), when not the format's "
                   "own (scene.json and COLMAP world-to-camera, key.log camera-to-world); default: the format's, "
                   "checked against the mesh")
    p.add_argument("--axes", choices=AXES, default=None,
                   help="the scene's camera axes: opencv (y down, looking down +z; every format's own) or opengl (y up, "
                   "looking down -z); default opencv, checked against the mesh")
    p.add_argument("--intrinsic", metavar="FILE",
                   help="RGB-D folders: the colour camera's intrinsic, Open3D's PinholeCameraIntrinsic JSON (default "
                   "PrimeSense, for 640x480 images only)")
    p.add_argument("--masks", metavar="DIR",
                   help="folder of per-photo masks (PNG/JPG/TIF of the photo's size, named after the image or the view: "
                   "<stem>.png, ...; Meshroom's <viewId>.png, OpenMVS's <stem>.mask.png): nonzero = keep, 0 = masked "
                   "out; masked pixels colour nothing (visibility, mappings, view selection, bake)")
    p.add_argument("--mask-invert", action="store_true",
                   help="the masks' other convention: nonzero = masked out (for --masks and the masks the scene names)")
    p.add_argument("--no-camera-check", dest="camera_check", action="store_false",
                   help="skip the check of the cameras against the mesh (camera-to-world, OpenGL axes, other units)")
    p.add_argument("--skip-missing-images", dest="skip_missing", action="store_true",
                   help="go on without the photos that are missing or unreadable (one warning names them; report.json "
                   "lists them under scene_options.skipped_images); by default they are an error listing them all")
    p.add_argument("--allow-unseen", dest="allow_unseen", action="store_true",
                   help=f"go on (with a warning) when the cameras see less than {100 * MIN_AREA_SEEN:g}%% of the mesh; "
                   "by default an error (a mesh from another scene, other units or camera conventions)")


def scene_options_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword options of :func:`~o3d_seqcc.load_scene` given on the command line (validated)."""
    lo, hi = DEPTH_SCALE_RANGE
    if not lo <= args.depth_scale <= hi:  # NaN, inf and denormals too
        raise InputError(f"--depth-scale must be between {lo:g} and {hi:g} depth units per metre (1000: millimetres, "
                         f"1: metres), got {args.depth_scale!r}")
    return {"mesh": args.mesh, "image_dir": args.image_dir, "depth_dir": args.depth_dir,
            "depth_scale": args.depth_scale, "extrinsic": args.extrinsic, "axes": args.axes,
            "intrinsic": args.intrinsic, "check_cameras": args.camera_check, "masks": args.masks,
            "mask_invert": args.mask_invert, "skip_missing": args.skip_missing,
            "allow_unseen": args.allow_unseen}


def scene_from_args(args: argparse.Namespace):
    """The scene named on the command line (validated, cameras checked)."""
    return load_scene(args.scene, **scene_options_from_args(args))


def prepare_out_dir(args: argparse.Namespace, scene) -> Path:
    """Check ``--out`` against the scene's inputs before any work (:func:`o3d_seqcc.io.output.check_output`)."""
    check_output(args.out, overwrite=args.overwrite, inputs=scene.input_paths())
    return Path(args.out)


def refuse_input_overwrite(path: str | Path, inputs: Any, option: str) -> None:
    """Check an output file path before any work (:func:`o3d_seqcc.io.output.check_output_file`): never one
    of the inputs (links resolved), a folder, a FIFO or device, or a file of an o3d-seqcc output folder.

    Raises
    ------
    InputError
        The message names ``option`` and what ``path`` is.
    """
    check_output_file(path, option=option, inputs=inputs)


def print_run_summary(res, out: Path) -> None:
    """Print what a :class:`~o3d_seqcc.pipeline.RunResult` did (correction, texturing, seams, timings)."""
    names, s, tm = res.scene.names, res.selection_stats, res.textured
    if res.correction is not None:
        c = res.correction
        print(f"corrected {len(names)} views with {c.method} toward {names[c.reference]} ({len(c.unreachable)} unreachable)")
    st = tm.stats
    pages = f"{tm.pages} pages of " if tm.pages > 1 else ""
    mem = st.get("texture_memory") or {}
    if s.get("split_input_faces"):
        split = (f"textured {s['input_faces']} faces ({s['split_input_faces']} split into parts: {s['faces']} out; "
                 f"{s['unseen_input_faces']} unseen, {s['partly_seen_input_faces']} partly: "
                 f"{100 * s['unseen_area']:.1f}% of the surface, ")
    else:
        split = (f"textured {s['faces']} faces ({s['unseen_faces']} unseen: {100 * s.get('unseen_area', 0.0):.1f}% of "
                 "the surface, ")
    print(split + f"{s['transitions']} image transitions, "
          f"{st['charts']} charts, atlas {pages}{tm.page_shape[1]}x{tm.page_shape[0]} at "
          f"{st.get('texels_per_pixel', 1.0):.2f} texels/pixel, {100 * st.get('coverage', 0.0):.0f}% covered) in "
          f"{res.timings['total']:.2f} s -> {out}")
    if mem:
        print(f"texture memory: {mem['gpu_bytes'] / 2**20:.1f} MiB on the GPU (RGBA8 with mipmaps, "
              f"{len(mem['pages'])} page(s))")
    if res.seams is not None:
        print(f"seams: mean {res.seams.mean:.2f}, p99 {res.seams.p99:.2f}, >5: {res.seams.frac_above_5:.3f}")
    print("timings (s): " + ", ".join(f"{k} {v:.2f}" for k, v in res.timings.items()))
    print_report_path(out)


def print_report_path(out: Path) -> None:
    """Print the path of the HTML report of an output folder (the last line of run, texture, correct)."""
    report = Path(out) / REPORT_HTML
    if report.is_file():
        print(f"report: {report}")
