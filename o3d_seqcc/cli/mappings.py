"""``o3d-seqcc mappings SCENE --out FILE.npz``: compute, filter and save the pairwise mappings."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from .info import add_scene_arguments, load_scene_from_args


def _parse_pair(text: str, scene) -> tuple[int, int] | None:
    """'A,B' (view names or indices) -> indices; None when ``text`` has no comma (a folder)."""
    from ..errors import InputError

    if "," not in text:
        return None
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 2:
        raise InputError(f"--plot {text!r}: give two views 'A,B' (names or indices) or a folder")
    out = []
    for p in parts:
        key = int(p) if p.isdigit() and p not in scene.names else p
        out.append(scene.index(key))  # InputError listing the valid names
    if out[0] == out[1]:
        raise InputError(f"--plot {text!r}: the two views must differ")
    return out[0], out[1]


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..mappings import compute_mappings, plot_pair
    from ..visibility import FILTERS

    scene = load_scene_from_args(args)
    filters = tuple(f for f in FILTERS if f not in set(args.disable or ()))
    M = compute_mappings(
        scene,
        mode=args.mode,
        occlusion_tol=args.occlusion_tol,
        depth_tol=args.depth_tol,
        depth_atol=args.depth_atol,
        depth_edge_margin=args.depth_edge_margin,
        max_angle=args.max_angle,
        oblique_reference=args.oblique_reference,
        two_sided=args.two_sided,
        filters=filters,
        n_jobs=args.n_jobs,
    )
    out = Path(args.out)
    M.save(out, format="arrays" if args.arrays else "auto")
    st = M.filter_stats
    counts = sorted(M.counts.values())
    summary = {
        "out": str(out),
        "mode": M.mode,
        "views": M.n_views,
        "pairs_with_mappings": len(M.counts),
        "pairs_at_least_400": sum(c >= 400 for c in counts),
        "mappings_total": M.total,
        "mappings_per_pair_median": counts[len(counts) // 2] if counts else 0,
        "filters (face-view incidences)": {
            k: st.get(k) for k in ("valid", "occluded", "depth_inconsistent", "oblique", "usable")
        },
        "views_seeing_nothing": st.get("views_seeing_nothing", []),
        "seconds": {k: round(v, 3) for k, v in st.get("timings", {}).items()},
    }
    if args.plot:
        pair = _parse_pair(args.plot, scene)
        if pair is None:
            target = Path(args.plot)
            if target.suffix.lower() == ".png":
                raise InputError(f"--plot {args.plot}: give a pair 'A,B' (view names or indices) or a folder")
            a, b = max(M.counts, key=M.counts.get)
            path = target / f"mappings_{scene.views[a].name}_{scene.views[b].name}.png"
        else:
            a, b = pair
            path = out.with_name(f"{out.stem}_{scene.views[a].name}_{scene.views[b].name}.png")
        plot_pair(scene, M, a, b, path, stages=not args.no_stages)
        summary["plot"] = str(path)
    print(json.dumps(summary, indent=1))
    return 0


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "mappings",
        help="compute the filtered pairwise mappings of all view pairs and save them (.npz)",
        description="Project the mesh into every view, apply the z-buffering, depth-consistency and "
        "camera-viewpoint filters and save the pairwise mappings of every pair of views.",
    )
    add_scene_arguments(p)
    p.add_argument("--out", required=True, help="output .npz (load it with o3d_seqcc.mappings.load_mappings)")
    p.add_argument("--mode", choices=("vertices", "dense"), default="vertices",
                   help="vertices: the 3 vertices of each shared face (paper); dense: the vertices plus interior points of each face, adaptive to its size")
    p.add_argument("--plot", metavar="PAIR_OR_DIR",
                   help="'A,B' (view names or indices): write OUT_A_B.png next to --out; a folder: figure of the "
                   "pair with the most mappings in it")
    p.add_argument("--no-stages", action="store_true",
                   help="plot only the final mappings instead of the four filter stages (paper Fig. 3)")
    p.add_argument("--max-angle", type=float, default=75.0, help="oblique filter threshold in degrees (75)")
    p.add_argument("--oblique-reference", choices=("ray", "axis"), default="ray",
                   help="viewing direction of the oblique filter: ray to the camera (default) or focal axis (paper)")
    p.add_argument("--depth-tol", type=float, default=0.03, help="relative depth-consistency threshold (0.03)")
    p.add_argument("--depth-atol", type=float, default=0.05, help="absolute depth threshold floor, scene units (0.05)")
    p.add_argument("--depth-edge-margin", type=int, default=0, metavar="PX",
                   help="also drop faces within PX pixels of a depth discontinuity (colour/depth misregistration); 0")
    p.add_argument("--occlusion-tol", type=float, default=0.01, help="relative z-buffer tolerance (0.01)")
    p.add_argument("--two-sided", action="store_true", help="no back-face removal (meshes with unreliable normals)")
    p.add_argument("--disable", action="append", choices=("occlusion", "depth", "oblique"),
                   help="disable a filter (repeatable)")
    p.add_argument("--arrays", action="store_true",
                   help="store every pair's arrays explicitly instead of the compact per-vertex layout")
    p.add_argument("--n-jobs", type=int, default=None, help="parallel workers for per-view work (joblib)")
    p.set_defaults(func=run)
    return p
