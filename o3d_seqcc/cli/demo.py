"""Run the whole job on the built-in synthetic scene and score it against its ground truth.

Generates the synthetic room scene into OUT/scene (reused if identical), runs the whole job on
it into OUT/run and compares the corrected images with the ground-truth renders.
"""

from __future__ import annotations

import argparse

from ..demo import run_demo
from .synthetic import add_synthetic_arguments


def _print_summary(res) -> None:
    s = res.summary
    ld, syn = s["load"], s["synthetic"]
    print(f"scene: {ld['scene']} ({'reused' if syn['reused'] else 'generated'}), {ld['views']} views "
          f"{ld['image_size']}, mesh {ld['mesh_vertices']} vertices / {ld['mesh_faces']} faces")
    summ = s["summary"]
    print(f"photometric changes ({summ['photometric']}, seed {summ['seed']}); |image - ground truth| in DN:")
    print(f"  {'view':<6}{'gain':>7}  {'white balance':<21}{'gamma':<21}{'S':>6}{'|diff|':>9}")
    for r in summ["views"]:
        wb = " ".join(f"{x:.2f}" for x in r["white_balance"])
        ga = " ".join(f"{x:.2f}" for x in r["gamma"])
        print(f"  {r['name']:<6}{r['gain']:>7.2f}  {wb:<21}{ga:<21}{r['s_curve']:>6.2f}{r['mean_abs_diff']:>9.2f}")
    print(f"  mean |diff| over views: {summ['mean_abs_diff_mean']:.2f} DN")
    run_ = s["run"]
    print(f"run: reference {run_['reference']}, outputs in {res.out / 'run'}: {', '.join(run_['outputs'])}")
    seams, seams0 = run_["seams"], run_["seams_original"]
    if seams:
        line = f"  seam CIEDE2000 mean / p99 / share > 5: {seams['mean']:.2f} / {seams['p99']:.2f} / {seams['frac_above_5']:.3f}"
        if seams0:
            line += (f"  (uncorrected images: {seams0['mean']:.2f} / {seams0['p99']:.2f} / "
                     f"{seams0['frac_above_5']:.3f})")
        print(line)
    gt = s["ground_truth"]
    print("mean CIEDE2000 to the ground-truth renders (covered pixels), per view before -> after:")
    print("  " + ", ".join(f"{r['name']} {r['before']:.1f}->{r['after']:.1f}" for r in gt["views"]))
    print(f"  mean over views: {gt['mean_before']:.2f} -> {gt['mean_after']:.2f}")
    print("timings: " + ", ".join(f"{k} {v:.2f} s" for k, v in res.timings.items()))
    print(f"summary written to {res.out / 'demo_summary.json'}")


def run(args: argparse.Namespace) -> int:
    res = run_demo(args.out, t_npm=args.t_npm, overwrite=args.overwrite, n_views=args.views, width=args.width,
                   height=args.height, seed=args.seed, photometric=args.photometric, cell_size=args.cell_size)
    _print_summary(res)
    return 0




def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    p.add_argument("--t-npm", type=int, default=400,
                   help="minimum pairwise mappings (vertex units) for a graph edge (default 400; lower it for tiny scenes)")
    add_synthetic_arguments(p, views=12)
