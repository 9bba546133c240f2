"""PSNR / CIEDE2000 between overlapping views at their mappings (paper Table 2).

Scores the scene's images as they are; for the output of correct (its scene.json points at the
corrected images) that is the corrected set:

  o3d-seqcc correct SCENE --out OUT && o3d-seqcc evaluate OUT/scene.json

For every view pair: PSNR and CIEDE2000 between the two images at the pair's mappings; printed:
mean, weighted mean (by number of mappings) and standard deviation over pairs. --holdout F
scores only the mappings of a random fraction F of the mesh faces; with --method the method is
fitted here on the other faces (and, for the in-sample figures, on all of them) and scored on
the held-out ones, next to the uncorrected images (none).
"""

from __future__ import annotations

import argparse

from ..correction import CorrectionSettings, available_methods
from ..errors import InputError
from ..evaluation.fit import evaluate_scene
from ..io.output import write_output_json
from ..mappings.compute import MODES
from .correction_flags import add_t_npm_argument
from ..settings import keyword_defaults
from .scene_flags import add_scene_arguments, refuse_input_overwrite, scene_from_args


def _row(label: str, ev) -> str:
    p, c = ev.psnr, ev.ciede2000
    return (f"{label:<32} {p.mean:7.2f} {p.weighted_mean:7.2f} {p.std:6.2f}   "
            f"{c.mean:7.2f} {c.weighted_mean:7.2f} {c.std:6.2f}   {ev.n_pairs:5d}")


def run(args: argparse.Namespace) -> int:
    if not args.blur >= 0:
        raise InputError(f"--blur must be a Gaussian sigma >= 0 pixels, got {args.blur}")
    scene = scene_from_args(args)
    if args.json:
        refuse_input_overwrite(args.json, scene.input_paths(), "--json")
    out = evaluate_scene(scene, mappings=args.mappings, method=args.method, reference=args.reference,
                         holdout=args.holdout, seed=args.seed, t_npm=args.t_npm, blur=args.blur, min_n=args.min_n)
    rows = out.pop("rows")
    print(f"scene {args.scene}: {len(scene.views)} views, {out['n_pairs']} overlapping pairs ({args.mappings} mappings)")
    print(f"{'':<32} {'PSNR (dB)':^22}   {'CIEDE2000':^22}   {'pairs':>5}\n"
          f"{'':<32} {'mean':>7} {'w.mean':>7} {'std':>6}   {'mean':>7} {'w.mean':>7} {'std':>6}")
    print("\n".join(_row(label, ev) for label, ev in rows))
    if args.json:
        write_output_json(args.json, {"scene": str(args.scene), **out}, inputs=scene.input_paths())
    return 0




def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    d = keyword_defaults(evaluate_scene)
    p.add_argument("--mappings", choices=MODES, default=d["mappings"],
                   help=f"mapping mode (default {d['mappings']}: the paper's Table 2 scores at the face vertices)")
    p.add_argument("--holdout", type=float, default=0.0, metavar="F",
                   help="score only the mappings of a random fraction F of the faces (with --method: fit on the rest)")
    p.add_argument("--seed", type=int, default=0, help="seed of the --holdout face split (default 0)")
    p.add_argument("--method", default=None, choices=available_methods(), metavar="METHOD",
                   help=f"fit this correction method here and score it (in-sample and held-out): "
                   f"{', '.join(available_methods())}")
    c = CorrectionSettings()
    p.add_argument("--reference", default=c.reference,
                   help=f"reference view for --method: name, index or auto (default {c.reference})")
    add_t_npm_argument(p, c.t_npm, extra="; for --method")
    p.add_argument("--blur", type=float, default=0.0,
                   help="Gaussian sigma (px) applied to the images for scoring only (default 0)")
    p.add_argument("--min-n", type=int, default=1, help="skip pairs with fewer mappings (default 1: all pairs)")
    p.add_argument("--json", metavar="FILE", help="also write the numbers (with per-pair records) to this JSON file")
