"""Run the whole job on a built-in scene: the synthetic room (scored against its ground truth) or Fountain.

The synthetic room (16 cameras looking up and down, a mesh of what they see) is generated into
OUT/scene (reused if identical), the whole job runs into OUT/run, and the corrected images are
compared with the ground-truth renders. --dataset fountain runs the real Fountain set instead
(from --data-root, else Open3D's download). The last line names the report.
"""

from __future__ import annotations

import argparse

from ..datasets import DatasetUnavailable
from ..demo import DATASETS, DEMO_SCENE, run_demo
from ..errors import InputError
from ..run_folder.layout import DEMO_SUMMARY, REPORT_HTML, REPORT_JSON
from .correction_flags import add_t_npm_argument
from .texture_flags import (
    add_atlas_arguments,
    add_export_arguments,
    save_options_from_args,
    texture_settings_from_args,
)
from .synthetic import add_synthetic_arguments, scene_options


def _print_summary(res) -> None:
    s = res.summary
    ld = s["load"]
    how = ("reused" if s["synthetic"]["reused"] else "generated") if "synthetic" in s else "real photos"
    print(f"scene: {ld['scene']} ({how}), {ld['views']} views {ld['image_size']}, mesh {ld['mesh_vertices']} "
          f"vertices / {ld['mesh_faces']} faces")
    if "summary" in s:
        _print_photometric(s["summary"])
    run_ = s["run"]
    print(f"run: reference {run_['reference']}, {run_['faces'] - run_['unseen_faces']} of {run_['faces']} faces "
          f"textured from the photos, atlas {run_['atlas']['page_width']}x{run_['atlas']['page_height']} with "
          f"{run_['atlas']['charts']} charts ({100 * run_['atlas']['coverage']:.0f}% covered, "
          f"{run_['texture_memory_bytes'] / 2**20:.1f} MiB of GPU memory); "
          f"outputs in {res.out / 'run'}: {', '.join(run_['outputs'])}")
    steps, seams = run_.get("selection_seams"), run_["seams"]
    if steps:
        a, b = steps["photos"], steps["corrected"]
        print(f"  colour step at the {a['n_edges']} seams between photos (CIEDE2000 mean / share > 5): "
              f"{a['mean']:.2f} / {a['frac_above_5']:.3f} as taken -> {b['mean']:.2f} / {b['frac_above_5']:.3f} corrected")
    if seams:
        print(f"  seam CIEDE2000 of the texture after seam leveling, mean / p99 / share > 5: {seams['mean']:.2f} / "
              f"{seams['p99']:.2f} / {seams['frac_above_5']:.3f}")
    if "ground_truth" in s:
        gt = s["ground_truth"]
        print("mean CIEDE2000 to the ground-truth renders (covered pixels), per view before -> after:")
        print("  " + ", ".join(f"{r['name']} {r['before']:.1f}->{r['after']:.1f}" for r in gt["views"]))
        print(f"  mean over views: {gt['mean_before']:.2f} -> {gt['mean_after']:.2f}")
        if "texture" in gt:
            t = gt["texture"]
            print(f"textured mesh rendered from every view vs the ground truth: CIEDE2000 {t['mean']:.2f}, "
                  f"{100 * t['holes']:.2f}% of the covered pixels untextured")
    print("timings: " + ", ".join(f"{k} {v:.2f} s" for k, v in res.timings.items()))
    print(f"summary written to {res.out / DEMO_SUMMARY}")
    report = res.out / REPORT_HTML
    print(f"report: {report if report.is_file() else res.out / 'run' / REPORT_JSON}")


def _print_photometric(summ: dict) -> None:
    print(f"photometric changes ({summ['photometric']}, seed {summ['seed']}); |image - ground truth| in DN:")
    print(f"  {'view':<6}{'gain':>7}  {'white balance':<21}{'gamma':<21}{'S':>6}{'|diff|':>9}")
    for r in summ["views"]:
        wb = " ".join(f"{x:.2f}" for x in r["white_balance"])
        ga = " ".join(f"{x:.2f}" for x in r["gamma"])
        print(f"  {r['name']:<6}{r['gain']:>7.2f}  {wb:<21}{ga:<21}{r['s_curve']:>6.2f}{r['mean_abs_diff']:>9.2f}")
    print(f"  mean |diff| over views: {summ['mean_abs_diff_mean']:.2f} DN")


def run(args: argparse.Namespace) -> int:
    options = scene_options(args) if args.dataset == "synthetic" else {}
    settings, save_options = texture_settings_from_args(args), save_options_from_args(args)
    try:
        res = run_demo(args.out, dataset=args.dataset, data_root=args.data_root, t_npm=args.t_npm,
                       overwrite=args.overwrite, settings=settings, save_options=save_options, **options)
    except DatasetUnavailable as e:
        raise InputError(e.cli_message("--data-root DIR")) from None
    _print_summary(res)
    return 0




def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    add_t_npm_argument(p)  # CorrectionSettings.t_npm
    p.add_argument("--dataset", choices=DATASETS, default="synthetic",
                   help="the synthetic room (default, scored against its ground truth) or the real Fountain set")
    p.add_argument("--data-root", help="fountain: a local copy of the set (default: the folder named by "
                   "O3D_SEQCC_FOUNTAIN, else Open3D's download)")
    add_synthetic_arguments(p, defaults=DEMO_SCENE)
    add_atlas_arguments(p)
    add_export_arguments(p)
