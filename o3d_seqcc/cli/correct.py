"""``o3d-seqcc correct SCENE --reference NAME|auto --out OUT``: colour-correct every view.

Writes, atomically as a whole (everything goes to a temporary sibling folder that is renamed to
OUT at the end, so OUT is never half-written)::

    OUT/images/<view name>.png   corrected images (16-bit PNG when the input was 16-bit)
    OUT/scene.json               the same scene pointing at the corrected images (depth maps and
                                 point clouds still point at the originals), so commands chain:
                                 ``o3d-seqcc correct S --out C && o3d-seqcc evaluate C/scene.json``
    OUT/report.json              graph edges (counts, weights), each view's path (names),
                                 unreachable views, per-pair metrics before / after, per-view
                                 lookup tables (LUT methods), stage timings

An existing non-empty OUT is refused unless ``--overwrite``.
"""

from __future__ import annotations

import argparse
import logging
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from .._io import write_image, write_json
from ..errors import InputError
from ..scene import save_scene
from .info import add_scene_arguments, load_scene_from_args

logger = logging.getLogger(__name__)


def _metrics(images, mappings) -> dict | None:
    try:
        from ..metrics import evaluate
    except ImportError:
        logger.info("o3d_seqcc.metrics is not available: report.json has no metrics")
        return None
    return evaluate(images, mappings).to_dict(per_pair=True)


def build_report(
    scene, result, mappings, *, original_images, t_npm: int, mappings_mode: str, metrics: bool = True
) -> dict:
    """The report.json content of a :class:`~o3d_seqcc.correction.CorrectionResult`.

    ``metrics=False`` skips the per-pair PSNR / CIEDE2000 before and after (the slowest part).
    """
    from ..correction import IdentityTransform, LutTransform

    names = scene.names
    report: dict = {
        "method": result.method,
        "reference": names[result.reference],
        "reference_index": result.reference,
        "t_npm": t_npm,
        "t_npm_effective": result.t_npm,
        "mappings": mappings_mode,
        "views": names,
        "graph_edges": [
            {**e, "a_name": names[e["a"]], "b_name": names[e["b"]]} for e in result.graph_edges
        ],
        "paths": {names[v]: [names[x] for x in p] for v, p in sorted(result.paths.items())},
        "unreachable": [names[v] for v in result.unreachable],
    }
    t0 = time.perf_counter()
    before = _metrics(original_images, mappings) if metrics else None
    if before is not None:
        report["metrics"] = {"before": before, "after": _metrics(result.images, mappings)}
    metrics_time = time.perf_counter() - t0
    if any(isinstance(tr, LutTransform) for tr in result.transforms):
        luts: dict = {}
        for v, tr in enumerate(result.transforms):
            if isinstance(tr, LutTransform):
                luts[names[v]] = np.round(tr.lut, 6).tolist()
            elif isinstance(tr, IdentityTransform):
                luts[names[v]] = "identity"
        report["lookup_tables"] = {
            "note": "per view: 3 rows (R, G, B) of L values in [0, 1] over L evenly spaced inputs in [0, 1], "
            "or 'identity' (reference, unreachable views)",
            "tables": luts,
        }
    report["timings"] = {**{k: round(float(v), 4) for k, v in result.timings.items()}, "metrics": round(metrics_time, 4)}
    return report


def _prepare_out(out: Path, overwrite: bool) -> None:
    if out.exists():
        if not out.is_dir():
            raise InputError(f"--out {out} exists and is not a folder; choose another path")
        if any(out.iterdir()) and not overwrite:
            raise InputError(f"--out {out} exists and is not empty; pass --overwrite to replace it or choose another folder")


def _commit(tmp: Path, out: Path) -> None:
    """Move the finished temporary folder to ``out`` (replacing an existing one)."""
    old = None
    if out.exists():
        old = out.parent / f".{out.name}.old-{os.getpid()}"
        os.replace(out, old)
    try:
        os.replace(tmp, out)
    except BaseException:
        if old is not None:
            os.replace(old, out)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def run(args: argparse.Namespace) -> int:
    from ..correction import correct

    out = Path(args.out)
    _prepare_out(out, args.overwrite)
    scene = load_scene_from_args(args)
    t0 = time.perf_counter()
    from ..mappings import compute_mappings

    mappings = compute_mappings(scene, mode=args.mappings)
    t_map = time.perf_counter() - t0
    originals = [v.load_image() for v in scene.views]
    reference: str | int = args.reference
    result = correct(
        scene,
        reference=reference,
        method=args.method,
        t_npm=args.t_npm,
        mappings=mappings,
        mappings_mode=args.mappings,
        images=originals,
        seed=args.seed,
        graph_weight=args.graph_weight,
    )
    result.timings["mappings"] = t_map

    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)  # mkdtemp creates 0700
    try:
        t0 = time.perf_counter()
        paths = []
        for v, img in zip(scene.views, result.images):
            p = tmp / "images" / f"{v.name}.png"
            write_image(p, img)
            paths.append(p)
        t_write = time.perf_counter() - t0
        # save_scene stores paths relative to the manifest's folder: images/<name>.png inside tmp,
        # and mesh / depth paths relative to tmp, a sibling of OUT, so all stay right after the rename
        new_scene = scene.replace_images(paths)
        report = build_report(
            scene,
            result,
            mappings,
            original_images=originals,
            t_npm=args.t_npm,
            mappings_mode=args.mappings,
            metrics=not args.no_metrics,
        )
        report["timings"]["write_images"] = round(t_write, 4)
        report["graph_weight"] = args.graph_weight
        save_scene(new_scene, tmp / "scene.json")
        write_json(tmp / "report.json", report)
        _commit(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    names = scene.names
    msg = (
        f"corrected {len(names)} views with {result.method} toward {names[result.reference]} "
        f"({len(result.graph_edges)} graph edges, {len(result.unreachable)} unreachable) -> {out}"
    )
    if "metrics" in report:
        b, a = report["metrics"]["before"], report["metrics"]["after"]
        msg += (
            f"\nmean PSNR {b['psnr']['mean']:.2f} -> {a['psnr']['mean']:.2f} dB, "
            f"mean CIEDE2000 {b['ciede2000']['mean']:.2f} -> {a['ciede2000']['mean']:.2f}"
        )
    print(msg)
    return 0


def register(sub) -> argparse.ArgumentParser:
    from ..correction import available_methods

    p = sub.add_parser(
        "correct",
        help="colour-correct every view toward a reference (sequential pairwise correction by default)",
        description="Sequential pairwise colour correction (Dal'Col et al. 2023) or one of the Table 1 baselines. "
        "Writes OUT/images/<view>.png, OUT/scene.json (pointing at the corrected images) and OUT/report.json.",
    )
    add_scene_arguments(p)
    p.add_argument("--reference", default="auto", help="reference view name (or index), or 'auto' (default)")
    p.add_argument("--method", default="seqcc", choices=available_methods(), help="correction method (default seqcc)")
    p.add_argument("--t-npm", type=int, default=400, help="minimum mappings for a graph edge, vertex units (default 400)")
    p.add_argument(
        "--graph-weight", choices=("paper", "log"), default="paper",
        help="edge weight: paper = 1 - n/total (default), log = log(total/n) (prefers strong edges)",
    )
    p.add_argument("--mappings", choices=("vertices", "dense"), default="vertices", help="pairwise mappings (default vertices)")
    p.add_argument("--no-metrics", action="store_true", help="skip the before/after metrics in report.json (faster)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace a non-empty OUT")
    p.set_defaults(func=run)
    return p
