"""Compute the filtered pairwise mappings of all view pairs and save them (.npz).

Projects the mesh into every view, applies the z-buffering, depth-consistency and
camera-viewpoint filters and saves the pairwise mappings of every pair of views (read them back
with o3d_seqcc.io.mappings_npz.load_mappings); --plot draws the paper's Figure 3 for a pair.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..errors import InputError
from ..io.mappings_npz import save_mappings
from ..io.output import check_output_file, output_file
from ..correction.graph import mappings_summary
from ..mappings.compute import MODES, compute_mappings
from ..evaluation.render import plot_pair
from ..settings import CorrectionSettings, VisibilitySettings
from ..visibility.settings import FILTERS, OBLIQUE_REFERENCES
from .scene_flags import add_scene_arguments, scene_from_args

_D = VisibilitySettings.defaults()


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix.lower() != ".npz":
        raise InputError(f"--out {out}: give a file name ending in .npz")
    if out.is_dir():
        raise InputError(f"--out {out} is a folder; give a file name ending in .npz")
    if out.exists() and not args.overwrite:
        raise InputError(f"--out {out} exists; choose another file or pass --overwrite")
    scene = scene_from_args(args)
    inputs = scene.input_paths()
    check_output_file(out, option="--out", inputs=inputs, overwrite=bool(args.overwrite))
    pair = None
    if args.plot and "," in args.plot:
        parts = [p.strip() for p in args.plot.split(",")]
        if len(parts) != 2:
            raise InputError(f"--plot {args.plot!r}: give two views 'A,B' (names or indices) or a folder")
        pair = (scene.index(parts[0]), scene.index(parts[1]))
        if pair[0] == pair[1]:
            raise InputError(f"--plot {args.plot!r}: the two views must differ")
        names = scene.names
        check_output_file(out.with_name(f"{out.stem}_{names[pair[0]]}_{names[pair[1]]}.png"), option="--plot",
                          inputs=inputs)
    elif args.plot and Path(args.plot).suffix.lower() == ".png":
        raise InputError(f"--plot {args.plot}: give a pair 'A,B' (view names or indices) or a folder")
    filters = tuple(f for f in FILTERS if f not in set(args.disable or ()))
    vs = VisibilitySettings.from_options(**{n: getattr(args, n) for n in VisibilitySettings.field_names()
                                            if hasattr(args, n)}, filters=filters)
    M = compute_mappings(scene, mappings=args.mappings, settings=vs)
    with output_file(out, option="--out", inputs=inputs, overwrite=bool(args.overwrite)) as tmp:
        save_mappings(M, tmp, format="arrays" if args.arrays else "auto")
    summary = {"out": str(out), **mappings_summary(M, t_npm=CorrectionSettings().t_npm)}
    if args.plot:
        if pair is None:
            a, b = max(M.counts, key=M.counts.get)
            path = Path(args.plot) / f"mappings_{scene.views[a].name}_{scene.views[b].name}.png"
        else:
            a, b = pair
            path = out.with_name(f"{out.stem}_{scene.views[a].name}_{scene.views[b].name}.png")
        with output_file(path, option="--plot", inputs=inputs) as tmp:
            plot_pair(scene, M, a, b, tmp, stages=not args.no_stages)
        summary["plot"] = str(path)
    print(json.dumps(summary, indent=1))
    return 0




def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("--out", required=True, help="output .npz (read it with o3d_seqcc.io.mappings_npz.load_mappings)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    p.add_argument("--mode", dest="mappings", choices=MODES, default=CorrectionSettings().mappings,
                   help="surface (default): the shared faces' vertices and points inside the large ones at the photos' "
                   "resolution, pairs counted in "
                   "pixels; vertices: the 3 vertices of each shared face (paper); dense: the vertices plus interior "
                   "points of each face, adaptive to its size")
    p.add_argument("--plot", metavar="PAIR_OR_DIR",
                   help="'A,B' (view names or indices): write OUT_A_B.png next to --out; a folder: figure of the "
                   "pair with the most mappings in it")
    p.add_argument("--no-stages", action="store_true",
                   help="plot only the final mappings instead of the four filter stages (paper Fig. 3)")
    p.add_argument("--max-angle", type=float, default=_D["max_angle"],
                   help=f"oblique filter threshold in degrees (default {_D['max_angle']:g})")
    p.add_argument("--oblique-reference", choices=OBLIQUE_REFERENCES, default=_D["oblique_reference"],
                   help="viewing direction of the oblique filter: ray to the camera (default) or focal axis (paper)")
    p.add_argument("--depth-tol", type=float, default=_D["depth_tol"],
                   help=f"relative depth-consistency threshold (default {_D['depth_tol']:g})")
    p.add_argument("--depth-atol", type=float, default=_D["depth_atol"],
                   help=f"absolute depth threshold floor, scene units (default {_D['depth_atol']:g})")
    p.add_argument("--depth-edge-margin", type=int, default=_D["depth_edge_margin"], metavar="PX",
                   help="also drop faces within PX pixels of a depth discontinuity (colour/depth misregistration); "
                   f"default {_D['depth_edge_margin']}")
    p.add_argument("--occlusion-tol", type=float, default=_D["occlusion_tol"],
                   help=f"relative z-buffer tolerance (default {_D['occlusion_tol']:g})")
    p.add_argument("--two-sided", action="store_true", default=_D["two_sided"],
                   help="no back-face removal (meshes with unreliable normals)")
    p.add_argument("--disable", action="append", choices=FILTERS, help="disable a filter (repeatable)")
    p.add_argument("--arrays", action="store_true",
                   help="store every pair's arrays explicitly instead of the compact per-vertex layout")
