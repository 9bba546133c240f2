"""``o3d-seqcc demo [--out out/demo]``: the whole job on the built-in synthetic scene.

Runs a list of stages (:data:`STAGES`) over a shared :class:`DemoState`; each stage is a
function ``stage(state) -> None`` that reads what earlier stages left in the state, adds its
results, and puts what it wants reported into ``state.summary[<stage name>]``. The stages now:

1. ``synthetic``: generate the synthetic room scene into ``OUT/scene`` (reused when it
   already holds a scene generated with the same parameters);
2. ``load``: load it back with :func:`o3d_seqcc.load_scene` (validates every file);
3. ``summary``: views, faces, the per-view photometric parameters and the mean absolute
   difference between the images and the ground-truth renders;
4. ``run``: the main job, ``o3d-seqcc run`` (mappings, graph, sequential correction toward the
   unchanged view ``v00``, MRF view selection, atlas, GLB + OBJ, seam metric with and without
   correction) into ``OUT/run``;
5. ``ground_truth``: mean CIEDE2000 between each view and its ground-truth render, over the
   pixels the mesh covers, before and after correction.

Writes ``OUT/demo_summary.json`` (summary + timings) and prints a readable summary.
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .._io import write_json
from ..errors import InputError
from .synthetic import add_synthetic_arguments, generate_from_args

logger = logging.getLogger(__name__)


@dataclass
class DemoState:
    """What the demo stages share (mutable on purpose: each stage adds its results)."""

    args: argparse.Namespace
    out: Path
    synthetic: Any = None  # o3d_seqcc.synthetic.SyntheticScene
    scene: Any = None  # o3d_seqcc.scene.Scene
    summary: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)  # free space for later stages

    @property
    def scene_dir(self) -> Path:
        return self.out / "scene"


def _same_parameters(meta: dict, args: argparse.Namespace) -> bool:
    want = {
        "n_views": args.views,
        "width": args.width,
        "height": args.height,
        "seed": args.seed,
        "photometric": args.photometric,
        "cell_size": float(args.cell_size),
    }
    return all(meta.get(k) == v for k, v in want.items())


def stage_synthetic(state: DemoState) -> None:
    """Generate the synthetic scene (or reuse an identical earlier one)."""
    from ..synthetic import load_synthetic

    d = state.scene_dir
    reused = False
    if not state.args.overwrite and (d / "synthetic.json").is_file():
        try:
            syn = load_synthetic(d)
        except InputError as e:
            logger.info("cannot reuse %s (%s): regenerating needs --overwrite", d, e)
            syn = None
        if syn is not None and _same_parameters(syn.metadata, state.args):
            state.synthetic, reused = syn, True
    if not reused:
        state.synthetic = generate_from_args(state.args, d)
    state.summary["synthetic"] = {"folder": str(d), "reused": reused}


def stage_load(state: DemoState) -> None:
    """Load the generated scene with the public loader (validates files and image sizes)."""
    from ..scene import load_scene

    state.scene = load_scene(state.scene_dir / "scene.json")
    mesh = state.scene.load_mesh()
    state.summary["load"] = {
        "scene": str(state.scene_dir / "scene.json"),
        "views": len(state.scene.views),
        "image_size": f"{state.scene.views[0].width}x{state.scene.views[0].height}",
        "mesh_vertices": int(len(mesh.vertices)),
        "mesh_faces": int(len(mesh.faces)),
    }


def stage_summary(state: DemoState) -> None:
    """Per-view photometric parameters and |image - ground truth|."""
    syn, scene = state.synthetic, state.scene
    per_view = []
    for v in scene.views:
        img = v.load_image().astype(np.float64)
        gt = syn.load_gt(v.name).astype(np.float64)
        p = syn.transforms[v.name]
        per_view.append(
            {
                "name": v.name,
                "gain": round(float(p["gain"]), 3),
                "white_balance": [round(float(x), 3) for x in p["white_balance"]],
                "gamma": [round(float(x), 3) for x in p["gamma"]],
                "s_curve": round(float(p["s_curve"]), 3),
                "mean_abs_diff": round(float(np.abs(img - gt).mean()), 2),
            }
        )
    mad = [r["mean_abs_diff"] for r in per_view]
    state.summary["summary"] = {
        "photometric": syn.metadata.get("photometric"),
        "seed": syn.metadata.get("seed"),
        "face_groups": {k: list(v) for k, v in syn.face_groups.items()},
        "views": per_view,
        "mean_abs_diff_mean": round(float(np.mean(mad)), 2),
    }


def stage_run(state: DemoState) -> None:
    """The main job: correct + texture through ``o3d-seqcc run``, into ``OUT/run``."""
    from . import main

    out = state.out / "run"
    argv = ["run", str(state.scene_dir / "scene.json"), "--reference", state.scene.names[0], "--out", str(out),
            "--mappings", "dense", "--t-npm", str(state.args.t_npm), "--save-images", "--compare-original", "--overwrite"]
    code = main(["-q", *argv]) if not state.args.verbose else main(argv)
    if code != 0:
        raise InputError(f"o3d-seqcc {' '.join(argv)} failed with exit code {code}")
    report = json.loads((out / "report.json").read_text())
    state.extra["run_dir"] = out
    corr, sel = report.get("correction", {}), report.get("selection", {})
    state.summary["run"] = {
        "reference": corr.get("reference"),
        "unreachable": corr.get("unreachable"),
        "selection": sel.get("method"),
        "transitions": sel.get("transitions"),
        "unseen_faces": sel.get("unseen_faces"),
        "seams": report.get("seams"),
        "seams_original": report.get("seams_original_images"),
        "timings": report.get("timings_s"),
        "outputs": sorted(p.name for p in out.iterdir() if p.is_file()),
    }


def stage_ground_truth(state: DemoState) -> None:
    """Mean CIEDE2000 to the ground-truth renders, before and after correction."""
    from .._io import read_image
    from ..metrics import image_delta_e

    syn, out = state.synthetic, state.extra["run_dir"]
    rows = []
    for v in state.scene.views:
        gt = syn.load_gt(v.name)
        mask = syn.load_face_ids(v.name) >= 0
        before = image_delta_e(v.load_image(), gt, mask=mask)
        after = image_delta_e(read_image(out / "images" / f"{v.name}.png"), gt, mask=mask)
        rows.append({"name": v.name, "before": round(before, 2), "after": round(after, 2)})
    state.summary["ground_truth"] = {
        "views": rows,
        "mean_before": round(float(np.mean([r["before"] for r in rows])), 2),
        "mean_after": round(float(np.mean([r["after"] for r in rows])), 2),
    }


#: The demo pipeline, in order: (name, stage function).
STAGES: list[tuple[str, Callable[[DemoState], None]]] = [
    ("synthetic", stage_synthetic),
    ("load", stage_load),
    ("summary", stage_summary),
    ("run", stage_run),
    ("ground_truth", stage_ground_truth),
]


def _print_summary(state: DemoState) -> None:
    s = state.summary
    ld = s.get("load", {})
    syn = s.get("synthetic", {})
    print(
        f"scene: {ld.get('scene')} ({'reused' if syn.get('reused') else 'generated'}), {ld.get('views')} views "
        f"{ld.get('image_size')}, mesh {ld.get('mesh_vertices')} vertices / {ld.get('mesh_faces')} faces"
    )
    summ = s.get("summary")
    if summ:
        print(f"photometric changes ({summ['photometric']}, seed {summ['seed']}); |image - ground truth| in DN:")
        print(f"  {'view':<6}{'gain':>7}  {'white balance':<21}{'gamma':<21}{'S':>6}{'|diff|':>9}")
        for r in summ["views"]:
            wb = " ".join(f"{x:.2f}" for x in r["white_balance"])
            ga = " ".join(f"{x:.2f}" for x in r["gamma"])
            print(f"  {r['name']:<6}{r['gain']:>7.2f}  {wb:<21}{ga:<21}{r['s_curve']:>6.2f}{r['mean_abs_diff']:>9.2f}")
        print(f"  mean |diff| over views: {summ['mean_abs_diff_mean']:.2f} DN")
    run_ = s.get("run")
    if run_:
        seams, seams0 = run_.get("seams") or {}, run_.get("seams_original") or {}
        print(f"run: reference {run_.get('reference')}, outputs in {state.extra.get('run_dir')}: {', '.join(run_['outputs'])}")
        if seams:
            print(
                "  seam CIEDE2000 mean / p99 / share > 5: "
                f"{seams.get('mean', float('nan')):.2f} / {seams.get('p99', float('nan')):.2f} / {seams.get('frac_above_5', float('nan')):.3f}"
                + (f"  (uncorrected images: {seams0.get('mean', float('nan')):.2f} / {seams0.get('p99', float('nan')):.2f} / "
                   f"{seams0.get('frac_above_5', float('nan')):.3f})" if seams0 else "")
            )
    gt = s.get("ground_truth")
    if gt:
        print("mean CIEDE2000 to the ground-truth renders (covered pixels), per view before -> after:")
        print("  " + ", ".join(f"{r['name']} {r['before']:.1f}->{r['after']:.1f}" for r in gt["views"]))
        print(f"  mean over views: {gt['mean_before']:.2f} -> {gt['mean_after']:.2f}")
    for name, fn in STAGES:
        if name not in ("synthetic", "load", "summary", "run", "ground_truth") and name in s:
            print(f"{name}: {json.dumps(s[name], default=str)}")
    print("timings: " + ", ".join(f"{k} {v:.2f} s" for k, v in state.timings.items()))


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out} is a file; give a folder")
    state = DemoState(args=args, out=out)
    t_all = time.perf_counter()
    for name, fn in STAGES:
        t = time.perf_counter()
        logger.info("demo stage %s", name)
        fn(state)
        state.timings[name] = time.perf_counter() - t
    state.timings["total"] = time.perf_counter() - t_all
    write_json(out / "demo_summary.json", {"summary": state.summary, "timings": state.timings})
    _print_summary(state)
    print(f"summary written to {out / 'demo_summary.json'}")
    return 0


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "demo",
        help="run the pipeline on the built-in synthetic scene",
        description="Generate the synthetic room scene into OUT/scene (reused if identical), load it and "
        "summarise it; later stages of the pipeline run on it too.",
    )
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    p.add_argument("--t-npm", type=int, default=400,
                   help="minimum pairwise mappings (vertex units) for a graph edge (default 400; lower it for tiny scenes)")
    add_synthetic_arguments(p, views=12)
    p.set_defaults(func=run)
    return p
