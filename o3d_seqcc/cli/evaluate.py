"""``o3d-seqcc evaluate SCENE``: image-based colour-similarity metrics (paper Table 2).

Scores the scene's images as they are -- for the output of ``o3d-seqcc correct`` (its
``scene.json`` points at the corrected images) that is the corrected set::

    o3d-seqcc correct SCENE --reference auto --out OUT && o3d-seqcc evaluate OUT/scene.json

Mappings are computed from the scene's geometry (``compute_mappings``, filtered as in the paper).
For every view pair: PSNR and CIEDE2000 between the two images at the pair's mappings; printed:
mean, weighted mean (by number of mappings) and standard deviation over pairs.

``--holdout F`` scores only the mappings of a random fraction F of the mesh faces (the ``test``
part of ``Mappings.split(F, seed=--seed)``). On already-corrected images this is a subset
score, not a refit: ``correct`` saw every face. For a true held-out score give ``--method``:
the method is then fitted here on the other faces (and, for the in-sample figures, on all of
them) and scored on the held-out faces, next to the uncorrected images (``none``).
"""

from __future__ import annotations

import argparse
import logging

from .._io import write_json
from .info import add_scene_arguments, load_scene_from_args

logger = logging.getLogger(__name__)


def _row(label: str, ev) -> str:
    p, c = ev.psnr, ev.ciede2000
    return (
        f"{label:<32} {p.mean:7.2f} {p.weighted_mean:7.2f} {p.std:6.2f}   "
        f"{c.mean:7.2f} {c.weighted_mean:7.2f} {c.std:6.2f}   {ev.n_pairs:5d}"
    )


def _header() -> str:
    return (
        f"{'':<32} {'PSNR (dB)':^22}   {'CIEDE2000':^22}   {'pairs':>5}\n"
        f"{'':<32} {'mean':>7} {'w.mean':>7} {'std':>6}   {'mean':>7} {'w.mean':>7} {'std':>6}"
    )


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..mappings import compute_mappings
    from ..metrics import blur_images, evaluate, evaluate_method

    if not 0.0 <= args.holdout < 1.0:
        raise InputError(f"--holdout must be in [0, 1), got {args.holdout}")
    scene = load_scene_from_args(args)
    mappings = compute_mappings(scene, mode=args.mappings)
    out: dict = {
        "scene": str(args.scene),
        "mappings": args.mappings,
        "holdout": args.holdout,
        "seed": args.seed,
        "blur": args.blur,
        "min_n": args.min_n,
        "psnr_cap_db": None,
    }
    lines = [_header()]
    if args.method is None:
        images = blur_images([v.load_image() for v in scene.views], args.blur)
        scored = mappings
        if args.holdout > 0:
            _, scored = mappings.split(args.holdout, seed=args.seed)
        ev = evaluate(images, scored, min_n=args.min_n)
        out["psnr_cap_db"] = ev.psnr_cap
        out["evaluation"] = ev.to_dict()
        label = "images" if args.holdout == 0 else f"images, held-out {args.holdout:g}"
        lines.append(_row(label, ev))
    else:
        from ..correction import available_methods

        valid = available_methods()
        if args.method not in valid:
            raise InputError(f"unknown method {args.method!r}; valid: {', '.join(valid)}")
        holdout = args.holdout if args.holdout > 0 else 0.0
        images = [v.load_image() for v in scene.views]
        runs = {}
        ref = args.reference
        for m in dict.fromkeys(["none", args.method]):
            runs[m] = evaluate_method(
                images,
                mappings,
                scene=scene,
                method=m,
                reference=ref,
                holdout=holdout,
                seed=args.seed,
                t_npm=args.t_npm,
                blur=args.blur,
                min_n=args.min_n,
            )
            ref = runs[m].reference  # "auto" resolved once, then reused
        out["reference"] = scene.names[runs[args.method].reference]
        out["methods"] = {}
        for m, r in runs.items():
            out["psnr_cap_db"] = r.in_sample.psnr_cap
            out["methods"][m] = r.to_dict(per_pair=True)
            lines.append(_row(f"{m} in-sample", r.in_sample))
            if r.held_out is not None:
                lines.append(_row(f"{m} held-out {holdout:g}", r.held_out))
    print(f"scene {args.scene}: {len(scene.views)} views, {len(mappings.pairs)} overlapping pairs ({args.mappings} mappings)")
    print("\n".join(lines))
    if args.json:
        write_json(args.json, out)
        logger.info("wrote %s", args.json)
    return 0


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "evaluate",
        help="PSNR / CIEDE2000 between overlapping views at their mappings (paper Table 2)",
        description=__doc__.split("\n\n", 1)[1] if __doc__ else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_scene_arguments(p)
    p.add_argument("--mappings", choices=("vertices", "dense"), default="vertices", help="mapping mode (default vertices)")
    p.add_argument(
        "--holdout",
        type=float,
        default=0.0,
        metavar="F",
        help="score only the mappings of a random fraction F of the faces (with --method: fit on the rest)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the --holdout face split (default 0)")
    p.add_argument("--method", default=None, help="fit this correction method here and score it (in-sample and held-out)")
    p.add_argument("--reference", default="auto", help="reference view for --method: name, index or auto (default)")
    p.add_argument("--t-npm", type=int, default=400, help="minimum mappings per graph edge for --method (default 400)")
    p.add_argument("--blur", type=float, default=0.0, help="Gaussian sigma (px) applied to the images for scoring only (default 0)")
    p.add_argument("--min-n", type=int, default=1, help="skip pairs with fewer mappings (default 1: all pairs)")
    p.add_argument("--json", metavar="FILE", help="also write the numbers (with per-pair records) to this JSON file")
    p.set_defaults(func=run)
    return p
