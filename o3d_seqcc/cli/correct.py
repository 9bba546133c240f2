"""Colour-correct every view toward a reference (joint refinement over all graph edges by default).

Sequential pairwise colour correction (Dal'Col et al. 2023) refined jointly over every graph edge
(seqcc-global, the default), the paper's sequential method (seqcc) or one of the Table 1 baselines.
Writes, as a whole (staged, then swapped in: OUT is never half-written):

  OUT/images/<view>.png   corrected images (16-bit PNG when the input was 16-bit)
  OUT/scene.json          the scene pointing at the corrected images, so commands chain:
                          o3d-seqcc correct S --out C && o3d-seqcc evaluate C/scene.json
  OUT/report.json         graph edges, paths, unreachable views, metrics before / after,
                          per-view lookup tables, stage timings
"""

from __future__ import annotations

import argparse

from ..correction.graph import WEIGHTS
from ..pipeline import correct_scene
from ..settings import CorrectionSettings, RunSettings
from .console import add_progress_argument
from .correction_flags import add_correction_arguments, add_split_argument
from .scene_flags import add_scene_arguments, prepare_out_dir, print_report_path, scene_from_args
from .texture_flags import run_options_from_args


def run(args: argparse.Namespace) -> int:
    scene = scene_from_args(args)
    out = prepare_out_dir(args, scene)
    job = correct_scene(scene, settings=run_options_from_args(args, texture=False))
    job.save(out, overwrite=args.overwrite)
    r, names = job.result, job.scene.names
    print(f"corrected {len(names)} views with {r.method} toward {names[r.reference]} "
          f"({len(r.graph_edges)} graph edges, {len(r.unreachable)} unreachable) -> {out}")
    if job.report.get("metrics"):
        b, a = job.report["metrics"]["before"], job.report["metrics"]["after"]
        print(f"mean PSNR {b['psnr']['mean']:.2f} -> {a['psnr']['mean']:.2f} dB, "
              f"mean CIEDE2000 {b['ciede2000']['mean']:.2f} -> {a['ciede2000']['mean']:.2f}")
    print_report_path(out)
    return 0




def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    add_correction_arguments(p)
    add_split_argument(p)
    d = CorrectionSettings()
    p.add_argument("--graph-weight", choices=WEIGHTS, default=d.graph_weight,
                   help=f"edge weight: paper = 1 - n/total, log = log(total/n) (prefers strong edges); default "
                   f"{d.graph_weight}")
    p.add_argument("--no-metrics", dest="metrics", action="store_false", default=RunSettings().metrics,
                   help="skip the before/after metrics in report.json (faster)")
    p.add_argument("--seed", type=int, default=d.seed, help=f"random seed of the correction (default {d.seed})")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace a non-empty OUT")
    add_progress_argument(p)
