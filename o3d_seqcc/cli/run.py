"""``o3d-seqcc run SCENE --reference NAME|auto --out OUT``: colour correction + texturing in one go.

One visibility computation serves both the pairwise mappings of the correction and the
per-face image selection. Writes the textured mesh (``OUT/mesh.glb``, ``OUT/mesh.obj`` ...),
``OUT/selection.npy``, optionally the corrected images (``--save-images``: ``OUT/images/<view>.png``)
and ``OUT/report.json`` with the correction summary (reference, paths, unreachable views),
the selection statistics (image transitions, unseen faces), the seam metric and the timings of
every stage (also printed). Global seam leveling is on unless ``--no-leveling``, local seam leveling
unless ``--no-local-leveling``; ``OUT/selection.png``
shows the per-face selection. ``--compare-original`` also bakes the uncorrected images (in memory) and reports
their seam metric next to the corrected one.
"""

from __future__ import annotations

import argparse
import logging
import time

from .._io import write_image, write_json
from ..errors import InputError
from .info import add_scene_arguments, load_scene_from_args
from .texture import add_texture_arguments, parse_formats, prepare_out_dir, seam_summary, texture_and_export

logger = logging.getLogger(__name__)


def run(args: argparse.Namespace) -> int:
    from ..correction import available_methods, correct
    from ..mappings import compute_mappings
    from ..texturing import bake_texture
    from ..visibility import compute_visibility

    t_all = time.perf_counter()
    timings: dict[str, float] = {}
    parse_formats(args.format)
    if args.method not in available_methods():
        raise InputError(f"--method {args.method!r} unknown; valid: {', '.join(available_methods())}")
    scene = load_scene_from_args(args)
    reference = args.reference
    if reference != "auto":
        if reference not in scene.names and reference.isdigit():
            reference = int(reference)
        scene.index(reference)  # raises InputError listing the valid names
    out = prepare_out_dir(args.out, args.overwrite)
    t = time.perf_counter()
    vis = compute_visibility(scene)
    timings["visibility"] = time.perf_counter() - t
    t = time.perf_counter()
    mappings = compute_mappings(scene, visibility=vis, mode=args.mappings)
    timings["mappings"] = time.perf_counter() - t
    t = time.perf_counter()
    originals = [v.load_image() for v in scene.views]
    timings["load_images"] = time.perf_counter() - t
    t = time.perf_counter()
    res = correct(scene, reference=reference, method=args.method, t_npm=args.t_npm, mappings=mappings,
                  images=originals, seed=args.seed)
    timings["correction"] = time.perf_counter() - t
    tm, tex_report = texture_and_export(scene, res.images, vis, out, args, timings)
    compare = None
    if args.compare_original:
        t = time.perf_counter()
        import numpy as np

        labels = np.load(out / "selection.npy")
        tm0 = bake_texture(vis.mesh, originals, vis, labels, atlas_size=tm.atlas_size, padding=args.padding,
                           texel_scale=tm.stats["texel_scale"], overflow="scale", leveling=not args.no_leveling,
                           leveling_smoothness=args.leveling_smoothness, fallback=args.fallback,
                           local_leveling=not args.no_local_leveling, local_band=args.local_band)
        compare = {"seams_original_images": seam_summary(tm0)}
        timings["compare_original"] = time.perf_counter() - t
    if args.save_images:
        t = time.perf_counter()
        for v, img in zip(scene.views, res.images):
            write_image(out / "images" / f"{v.name}.png", img)
        timings["save_images"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t_all
    names = scene.names
    report = {
        "command": "run",
        "scene": str(args.scene),
        "correction": {
            "method": res.method,
            "reference": names[res.reference],
            "t_npm": res.t_npm,
            "unreachable": [names[i] for i in res.unreachable],
            "paths": {names[k]: [names[i] for i in p] for k, p in res.paths.items()},
            "n_graph_edges": len(res.graph_edges),
            "timings_s": {k: round(float(v), 4) for k, v in res.timings.items()},
        },
        **tex_report,
        **(compare or {}),
        "visibility_stats": getattr(vis, "stats", {}),
        "timings_s": {k: round(v, 4) for k, v in timings.items()},
    }
    write_json(out / "report.json", report)
    s = report["selection"]
    msg = (f"corrected {len(names)} views toward {names[res.reference]} ({len(res.unreachable)} unreachable), "
           f"textured {s['faces']} faces ({s['transitions']} image transitions) in {timings['total']:.2f} s -> {out}")
    if report.get("seams"):
        msg += f"; seams: mean {report['seams']['mean']:.2f}, >5: {report['seams']['frac_above_5']:.3f}"
    print(msg)
    print("timings (s): " + ", ".join(f"{k} {v:.2f}" for k, v in timings.items()))
    return 0


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "run",
        help="colour-correct the views (seqcc) and texture the mesh with the corrected images, with a report",
        description="Sequential pairwise colour correction followed by per-face image selection, atlas baking and "
        "GLB/OBJ export; report.json holds the correction summary, selection statistics, seam metric and timings.",
    )
    add_scene_arguments(p)
    p.add_argument("--reference", default="auto", help="reference view name (or index), or 'auto' (default)")
    p.add_argument("--method", default="seqcc", help="colour-correction method (default seqcc)")
    p.add_argument("--t-npm", type=int, default=400, help="minimum pairwise mappings for a graph edge (default 400)")
    p.add_argument("--mappings", choices=("vertices", "dense"), default="vertices",
                   help="pairwise mappings mode (default vertices, the paper's)")
    p.add_argument("--save-images", action="store_true", help="also write the corrected images to OUT/images/")
    p.add_argument("--compare-original", action="store_true",
                   help="also report the seam metric of the same texturing with the uncorrected images")
    add_texture_arguments(p, with_images=False)
    p.set_defaults(func=run)
    return p


__all__ = ["register", "run"]
