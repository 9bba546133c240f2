"""As sharp as the photos (issue 19): the synthetic room's texture against its true albedo, main beside this checkout.

The synthetic room (:func:`o3d_seqcc.synthetic.make_synthetic_scene`, ``--views`` cameras in two rings looking up and
down, a mesh of what they see, camera-like photometric changes; ``--width`` x ``--height`` photos) has a ground truth:
``gt/vNN.png``, the render of the surface albedo itself from each camera. ``o3d_seqcc.pipeline.run`` (the command
line's defaults, reference ``v00``, dense mappings) textures the mesh from the corrected photos; the textured mesh is
ray-cast from every camera (:func:`o3d_seqcc.evaluation.render.render_textured`, one ray per pixel, bilinear lookup) and compared
with the truth over the pixels the mesh covers (eroded by 2 px):

- ``sharpness``: variance of the Laplacian of the render over that of the truth (:func:`o3d_seqcc.evaluation.render.sharpness`;
  1 = as sharp as the albedo), mean and minimum over the views;
- ``photo_sharpness``: the same ratio for the corrected photo itself (what a texture can keep at most: the
  photos are renders of the albedo, antialiased, with camera-like changes), mean over the views;
- ``ciede2000``: mean CIEDE2000 between render and truth (:func:`o3d_seqcc.evaluation.metrics.image_delta_e`), mean over views;
- the atlas (page size, pages, texels per photo pixel) and the seam metric.

With ``--baseline REF`` (default ``main``) the same measurement runs first on that commit of this repository, in a
subprocess on a ``git archive`` of it (nothing is checked out here), and both rows are printed side by side.

Usage::

    python benchmarks/sharpness.py [--baseline main|none] [--views 16] [--width 320 --height 240] [--seed 0]
        [--set data_term=area ...] [--json FILE]

``--set KEY=VALUE`` passes a :class:`~o3d_seqcc.texturing.TextureSettings` field to this checkout's run (not the
baseline's). Targets (issue 19): sharpness >= 0.7 of the truth's, mean CIEDE2000 no worse than main's.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _value(text: str):
    try:
        return json.loads(text)
    except ValueError:
        return text


def measure(views: int, width: int, height: int, seed: int, options: dict) -> dict:
    """The room at these settings, textured with the library's defaults (plus ``options``), scored against the truth."""
    import numpy as np

    import o3d_seqcc as sc
    from o3d_seqcc.evaluation.metrics import image_delta_e
    from o3d_seqcc.evaluation.render import raycast, render_textured, sharpness

    with tempfile.TemporaryDirectory(prefix="o3d_seqcc_sharp_") as tmp:
        syn = sc.make_synthetic_scene(Path(tmp) / "room", n_views=views, width=width, height=height, seed=seed,
                                      layout="two-rings", seen_only=True)
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = sc.pipeline.run(syn.scene, reference=syn.scene.names[0], mappings="dense", t_npm=100, **options)
        wall = time.perf_counter() - t
        tm = res.textured
        rows = []
        for i, view in enumerate(syn.scene.views):
            gt = syn.load_gt(i)
            hits = raycast(tm, view)
            mask = hits.mask & (syn.load_face_ids(i) >= 0)
            img = render_textured(tm, view, hits=hits)
            rows.append({"view": view.name, "sharpness": sharpness(img, mask) / sharpness(gt, mask),
                         "photo_sharpness": sharpness(res.images[i], mask) / sharpness(gt, mask),
                         "ciede2000": image_delta_e(img, gt, mask=mask),
                         "photo_ciede2000": image_delta_e(res.images[i], gt, mask=mask)})
        st = tm.stats
        return {
            "views": rows,
            "sharpness_mean": float(np.mean([r["sharpness"] for r in rows])),
            "sharpness_min": float(np.min([r["sharpness"] for r in rows])),
            "ciede2000_mean": float(np.mean([r["ciede2000"] for r in rows])),
            "photo_sharpness_mean": float(np.mean([r.get("photo_sharpness", np.nan) for r in rows])),
            "photo_ciede2000_mean": float(np.mean([r["photo_ciede2000"] for r in rows])),
            "atlas": f"{st['pages']} x {st['atlas_size']}^2", "texels_per_pixel": float(st["texels_per_pixel"]),
            "seams": None if res.seams is None else float(res.seams.mean),
            "transitions": int(res.selection_stats["transitions"]), "wall_s": wall,
        }


def _baseline(ref: str, args) -> dict:
    """:func:`measure` on commit ``ref`` of this repository (a ``git archive`` of it, in a subprocess)."""
    with tempfile.TemporaryDirectory(prefix="o3d_seqcc_base_") as tmp:
        arch = subprocess.run(["git", "-C", str(REPO), "archive", "--format=tar", ref], check=True, capture_output=True)
        subprocess.run(["tar", "-x", "-C", tmp], input=arch.stdout, check=True)
        env = {**os.environ, "PYTHONPATH": tmp}
        out = Path(tmp) / "result.json"
        cmd = [sys.executable, str(Path(__file__).resolve()), "--baseline", "none", "--views", str(args.views),
               "--width", str(args.width), "--height", str(args.height), "--seed", str(args.seed),
               "--measure-only", str(out)]
        subprocess.run(cmd, check=True, env=env, cwd=tmp)
        return json.loads(out.read_text())


def _row(name: str, r: dict) -> str:
    return (f"{name:<12} {r['sharpness_mean']:9.3f} {r['sharpness_min']:9.3f} {r.get('photo_sharpness_mean', float('nan')):9.3f} "
            f"{r['ciede2000_mean']:9.2f} "
            f"{r['photo_ciede2000_mean']:9.2f} {r['atlas']:>14} {r['texels_per_pixel']:6.2f} "
            f"{r['seams'] if r['seams'] is None else round(r['seams'], 4)!s:>7} {r['transitions']:6d} {r['wall_s']:6.1f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--baseline", default="main", help="git commit measured beside this checkout ('none': skip)")
    ap.add_argument("--views", type=int, default=16)
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=240)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a TextureSettings field for this checkout's run (repeatable)")
    ap.add_argument("--json", default=None, help="also write the figures to this file")
    ap.add_argument("--measure-only", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    options = dict((k, _value(v)) for k, v in (kv.split("=", 1) for kv in args.set))
    if args.measure_only:
        sys.path.insert(0, os.environ.get("PYTHONPATH", str(REPO)).split(os.pathsep)[0])
        Path(args.measure_only).write_text(json.dumps(measure(args.views, args.width, args.height, args.seed, options)))
        return 0
    sys.path.insert(0, str(REPO))
    results = {}
    if args.baseline != "none":
        results[args.baseline] = _baseline(args.baseline, args)
    results["this"] = measure(args.views, args.width, args.height, args.seed, options)
    print(f"synthetic room, {args.views} views {args.width}x{args.height}, seed {args.seed}; render vs the true albedo "
          f"over the covered pixels{'; this: ' + str(options) if options else ''}")
    print(f"{'':<12} {'sharp':>9} {'sharp min':>9} {'photo shp':>9} {'CIEDE2000':>9} {'photos':>9} {'atlas':>14} {'tpp':>6} "
          f"{'seams':>7} {'trans':>6} {'wall s':>6}")
    for name, r in results.items():
        print(_row(name, r))
    if args.baseline != "none":
        b, n = results[args.baseline], results["this"]
        print(f"this / {args.baseline}: sharpness {n['sharpness_mean'] / b['sharpness_mean']:.2f}x, CIEDE2000 "
              f"{n['ciede2000_mean'] - b['ciede2000_mean']:+.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
