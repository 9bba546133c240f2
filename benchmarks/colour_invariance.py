"""Colour invariance on real and generated few-view scenes: how much of a camera's change each method undoes.

Usage::

    .venv/bin/python benchmarks/colour_invariance.py [--scenes fountain,fountain-11,fountain-9,room-6mp,room-6mp-hard,hard-room]
        [--methods default,seqcc,...] [--seeds 0] [--fountain PATH] [--json FILE] [--stride N]

The protocol (:mod:`o3d_seqcc.evaluation.semireal`): every photo but the reference gets a hidden camera-like
change (exposure 0.6-1.6, white balance +-20 %, per-channel gamma 0.64-1.51, S-curve 0-0.6, in linear light,
8-bit), one draw per seed; each method corrects the changed photos and, separately, the untouched ones, as
``o3d-seqcc correct`` would with its defaults (surface mappings, ``t_npm`` auto, reference auto). Scores,
mean CIEDE2000 over the pixels the mesh covers:

- **invariance**: the correction of the changed photos vs the same correction of the untouched photos. A
  method that undid the change exactly scores what 8-bit quantisation and clipping leave (the oracle rows).
- **truth**: on the generated scenes, whose photos are consistent renders of one albedo, the correction of
  the changed photos vs the untouched renders (the true colours).
- **cast**: the largest, over photos, mean CIEDE2000 between a corrected photo's pixels that were neutral grey
  in the original (CIELAB chroma < 4) and their own grey (the same L*, a* = b* = 0), minus the original's.
- **joint > seq**: photos that the joint refinement (``refine=True``) leaves further from the truth than its
  sequential step (``refine=False``), by more than 0.05 (generated scenes).

Oracle rows (no method can do better with per-channel curves):

- ``oracle inverse``: the exact inverse of each hidden change (quantisation and clipping only);
- ``oracle fit``: per photo and channel, the monotone curve fitted on the exact truth pairs (the changed and
  the untouched value of every covered pixel of that photo): the floor of the curve model (on ``hard-room``,
  the photo and its true colours).

The error breakdown (printed under each scene): *correspondence* = a method's truth score with the
registration error minus the same with exact poses (generated scenes); *curve fit* = ``oracle fit`` minus
``oracle inverse``; *composition* = the sequential step's invariance minus the ``oracle fit``'s (what the
path composition and the edge estimates add).

Scenes:

- ``fountain``: the 33 Fountain photos (640x480, real registration error of 2-17 px);
- ``fountain-11`` / ``fountain-9``: every 3rd / 4th Fountain photo (wide baselines, few views);
- ``room-6mp``: a generated room, 10 photos of 3000x2000 on an arc 25 deg apart, poses off by ~1.2 px, mesh
  vertices moved by 2 mm along their normals;
- ``room-6mp-hard``: 8 photos of 3072x2048 on two rings, poses off by ~2 px, 2 mm mesh noise, a specular patch
  per photo (view-dependent) and two occluders per photo that the mesh lacks (scored without them);
- ``hard-room``: the synthetic hard room (15 photos 320x240, ``photometric="camera-hard"``), each method
  scored against its true colours (no hidden change: the scene's own changes are the test).

Timings are wall time on a shared machine: compare methods within one run only.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from o3d_seqcc.correction import correct  # noqa: E402
from o3d_seqcc.evaluation.semireal import (  # noqa: E402
    camera_change_lut,
    coverage_masks,
    make_semireal,
    view_errors,
)
from o3d_seqcc.mappings.compute import compute_mappings  # noqa: E402
from o3d_seqcc.scene import Scene  # noqa: E402

DEFAULT_FOUNTAIN = ROOT.parent / "shared" / "datasets" / "fountain_small"
SCENES = ("fountain", "fountain-11", "fountain-9", "room-6mp", "room-6mp-hard", "hard-room")
#: label -> (registry name, options); "default" is what `o3d-seqcc correct` runs
METHOD_SPECS = {
    "default": (None, {}),
    "seqcc": ("seqcc", {}),
    "global own values": ("seqcc-global", {"values": "own"}),
    "global normalised": ("seqcc-global", {"values": "normalised"}),
    "global no guard": ("seqcc-global", {"guard": False}),
    "global encoded own": ("seqcc-global", {"own_light": None}),
    "global one-pass outliers": ("seqcc-global", {"outlier_rounds": None, "outlier_k": 3.0}),
    "global no own margin": ("seqcc-global", {"own_margin": 0.0}),
    "main before issue 34's fourth pass": ("seqcc-global", {"max_mappings": 8000, "edge_fraction": 1.0, "guard": False}),
    "global graph edges only": ("seqcc-global", {"edge_fraction": 1.0}),
    "global 8000 mappings": ("seqcc-global", {"max_mappings": 8000}),
    "main before issue 34's third pass": ("seqcc-global", {"own_light": None, "outlier_rounds": None, "outlier_k": 3.0,
                                                           "own_margin": 0.0, "guard": True}),
    "global sequential": ("seqcc-global", {"refine": False}),
    "global no clip levels": ("seqcc-global", {"clip_levels": False}),
    "global encoded power": ("seqcc-global", {"light": "encoded"}),
    "global no direct prior": ("seqcc-global", {"prior_direct": None}),
    "reinhard": ("reinhard", {}),
    "none": ("none", {}),
}
NEUTRAL_CHROMA = 4.0

logger = logging.getLogger("colour_invariance")


def _subset(scene: Scene, step: int) -> Scene:
    return Scene(mesh=scene.mesh, views=tuple(scene.views[::step]), source=scene.source, options=scene.options)


def _noisy_mesh_scene(scene: Scene, out: Path, sigma: float, seed: int) -> Scene:
    """The scene with its mesh's vertices moved along their normals by N(0, sigma) metres (a reconstruction's
    noise; the photos stay renders of the exact mesh)."""
    import open3d as o3d

    m = o3d.io.read_triangle_mesh(str(scene.mesh))
    m.compute_vertex_normals()
    v = np.asarray(m.vertices)
    n = np.asarray(m.vertex_normals)
    rng = np.random.default_rng(seed)
    m.vertices = o3d.utility.Vector3dVector(v + n * rng.normal(0.0, sigma, size=(len(v), 1)))
    path = out / "mesh_noisy.ply"
    o3d.io.write_triangle_mesh(str(path), m)
    return Scene(mesh=path, views=scene.views, source=scene.source, options=scene.options)


def _blemishes(images: list, masks: list, seed: int, *, speculars: int, occluders: int) -> tuple[list, list]:
    """Per photo: ``speculars`` view-dependent highlights (blended toward white) and ``occluders`` solid ellipses
    the mesh lacks (people, cars). Returns the photos and the masks of the pixels still true to the surface."""
    rng = np.random.default_rng(1000 + seed)
    out, keep = [], []
    for img, m in zip(images, masks):
        H, W = img.shape[:2]
        yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
        f = img.astype(np.float32) / 255.0
        good = m.copy()
        for _ in range(speculars):
            cx, cy, r = rng.uniform(0.2, 0.8) * W, rng.uniform(0.2, 0.8) * H, rng.uniform(0.03, 0.06) * W
            a = np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * r * r))[..., None] * 0.85
            f = f * (1 - a) + a
            good &= a[..., 0] < 0.02
        for _ in range(occluders):
            cx, cy = rng.uniform(0.1, 0.9) * W, rng.uniform(0.3, 0.9) * H
            rx, ry = rng.uniform(0.03, 0.08) * W, rng.uniform(0.1, 0.25) * H
            inside = ((xx - cx) / rx) ** 2 + ((yy - cy) / ry) ** 2 <= 1.0
            f[inside] = rng.uniform(0.05, 0.95, size=3)
            good &= ~inside
        out.append(np.clip(np.round(f * 255.0), 0, 255).astype(np.uint8))
        keep.append(good)
    return out, keep


def load_scene(name: str, args, tmp: Path) -> dict:
    """Scene ``name``: its scene, photos, scored masks and, for generated scenes, an exact-pose twin."""
    from o3d_seqcc import datasets
    from o3d_seqcc.synthetic import make_synthetic_scene, perturb_poses

    if name.startswith("fountain"):
        scene = datasets.fountain(args.fountain)
        if name != "fountain":
            scene = _subset(scene, {"fountain-11": 3, "fountain-9": 4}[name])
        images = [v.load_image() for v in scene.views]
        return {"scene": scene, "images": images, "masks": coverage_masks(scene), "exact": None, "truth": None}
    if name == "hard-room":
        syn = make_synthetic_scene(tmp / name, n_views=15, seed=0, photometric="camera-hard")
        images = [v.load_image() for v in syn.scene.views]
        truth = [syn.load_gt(v.name) for v in syn.scene.views]
        masks = [syn.load_face_ids(v.name) >= 0 for v in syn.scene.views]
        # the truth is in v00's colours (v00 is the unchanged photo): corrected toward it
        return {"scene": syn.scene, "images": images, "masks": masks, "exact": None, "truth": truth, "hidden": False,
                "reference": 0}
    hard = name == "room-6mp-hard"
    w, h, n, layout, px = (3072, 2048, 8, "two-rings", 2.0) if hard else (3000, 2000, 10, "ring", 1.2)
    t0 = time.perf_counter()
    syn = make_synthetic_scene(tmp / name, n_views=n, width=w, height=h, seed=3 if hard else 2, photometric="none",
                               layout=layout, seen_only=True)
    logger.info("%s generated in %.0f s", name, time.perf_counter() - t0)
    masks = [syn.load_face_ids(v.name) >= 0 for v in syn.scene.views]
    images = [v.load_image() for v in syn.scene.views]
    truth = [im.copy() for im in images]
    if hard:
        images, masks = _blemishes(images, masks, 0, speculars=1, occluders=2)
    fx = float(syn.scene.views[0].intrinsic[0, 0])
    noisy = _noisy_mesh_scene(syn.scene, tmp / name, 0.002, seed=5)
    scene = perturb_poses(noisy, float(np.rad2deg(px / fx)), seed=7, keep=())
    return {"scene": scene, "images": images, "masks": masks, "exact": syn.scene, "truth": truth}


def _neutral_cast(corrected: list, originals: list, masks: list, skip: int, stride: int) -> float:
    """Largest over photos (with at least 200 scored neutral pixels) of the mean CIEDE2000 between the corrected
    pixels that were neutral in the original and their own grey, minus that of the original."""
    from skimage.color import deltaE_ciede2000, rgb2lab

    worst = 0.0
    for v, (c, o, m) in enumerate(zip(corrected, originals, masks)):
        if v == skip:
            continue
        sl = (slice(None, None, stride), slice(None, None, stride))
        lo, lc = rgb2lab(o[sl]), rgb2lab(c[sl])
        neutral = m[sl] & (np.hypot(lo[..., 1], lo[..., 2]) < NEUTRAL_CHROMA)
        if neutral.sum() < 200:
            continue

        def off(lab):
            grey = lab[neutral].copy()
            grey[:, 1:] = 0.0
            return float(np.mean(deltaE_ciede2000(lab[neutral], grey)))

        worst = max(worst, off(lc) - off(lo))
    return worst


def _oracle_fit(changed: list, originals: list, masks: list, ref: int) -> list:
    """Per photo and channel, the mean original value of each changed level over the covered pixels, made monotone
    and filled between levels: the best per-channel curve for that photo."""
    out = []
    for v, (c, o, m) in enumerate(zip(changed, originals, masks)):
        if v == ref:
            out.append(np.array(o, copy=True))
            continue
        res = np.empty_like(c)
        for ch in range(3):
            x, y = c[..., ch][m].astype(np.int64), o[..., ch][m].astype(np.float64)
            cnt = np.bincount(x, minlength=256)
            mean = np.bincount(x, weights=y, minlength=256) / np.maximum(cnt, 1)
            seen = cnt > 0
            lut = np.interp(np.arange(256), np.flatnonzero(seen), mean[seen])
            # weighted isotonic fit (pool adjacent violators) of the level means
            from sklearn.isotonic import IsotonicRegression

            iso = IsotonicRegression(out_of_bounds="clip").fit(np.flatnonzero(seen), mean[seen], sample_weight=cnt[seen])
            lut = iso.predict(np.arange(256))
            res[..., ch] = np.clip(np.round(lut), 0, 255).astype(np.uint8)[c[..., ch]]
        out.append(res)
    return out


def run_scene(name: str, data: dict, methods: list[str], args) -> dict:
    scene, originals, masks = data["scene"], data["images"], data["masks"]
    hidden = data.get("hidden", True)
    t0 = time.perf_counter()
    mappings = compute_mappings(scene)
    exact_mappings = compute_mappings(data["exact"]) if data["exact"] is not None else None
    logger.info("%s: mappings in %.1f s", name, time.perf_counter() - t0)
    ref = data.get("reference")
    if ref is None:  # what `o3d-seqcc correct` chooses ("auto")
        ref = correct(scene, mappings=mappings, images=originals, method="none").reference
    rows: dict[str, dict] = {}

    def run(label: str, imgs: list, mp) -> tuple[list, float]:
        name_, opts = METHOD_SPECS[label]
        kw = {} if name_ is None else {"method": name_}
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            res = correct(scene, mappings=mp, images=imgs, reference=ref, **kw, **opts)
        return list(res.images), time.perf_counter() - t

    stride = args.stride if originals[0].shape[1] <= 1000 else max(args.stride, 4)
    per_seed = []
    for seed in args.seeds if hidden else [None]:
        if hidden:
            case = make_semireal(originals, reference=ref, seed=int(seed))
            changed, params = list(case.images), case.params
        else:
            changed, params = originals, None
        seed_rows: dict[str, dict] = {}
        for label in methods:
            out, secs = run(label, changed, mappings)
            row = {"seconds": secs}
            if hidden:
                base, _ = run(label, originals, mappings)
                inv = view_errors(out, base, masks, skip=(ref,), stride=stride)
                row["invariance"] = inv
                row["cast"] = _neutral_cast(out, originals, masks, ref, stride)
            if data["truth"] is not None:
                row["truth"] = view_errors(out, data["truth"], masks, skip=(ref,), stride=stride)
                if exact_mappings is not None and label in ("default", "seqcc"):
                    ex, _ = run(label, changed, exact_mappings)
                    row["truth_exact_poses"] = view_errors(ex, data["truth"], masks, skip=(ref,), stride=stride)
            seed_rows[label] = row
            logger.info("%s seed %s %s: %.1f s", name, seed, label, secs)
        if hidden:
            undone = [np.array(im, copy=True) if v == ref else
                      _apply_lut(camera_change_lut(p, size=4096, inverse=True), im) for v, (im, p) in enumerate(zip(changed, params))]
            truth = data["truth"] if data["truth"] is not None else originals
            seed_rows["oracle inverse"] = {"invariance": view_errors(undone, originals, masks, skip=(ref,), stride=stride)}
            fit = _oracle_fit(changed, originals, masks, ref)
            seed_rows["oracle fit"] = {"invariance": view_errors(fit, originals, masks, skip=(ref,), stride=stride)}
            if data["truth"] is not None:
                seed_rows["oracle inverse"]["truth"] = view_errors(undone, truth, masks, skip=(ref,), stride=stride)
                seed_rows["oracle fit"]["truth"] = view_errors(fit, truth, masks, skip=(ref,), stride=stride)
        elif data["truth"] is not None:  # the scene's own changes: the curves fitted on its photos' exact truth pairs
            fit = _oracle_fit(changed, data["truth"], masks, ref)
            seed_rows["oracle fit"] = {"truth": view_errors(fit, data["truth"], masks, skip=(ref,), stride=stride)}
        per_seed.append(seed_rows)
    # averaged over seeds, per photo
    for label in per_seed[0]:
        agg = {}
        for key in ("invariance", "truth", "truth_exact_poses"):
            if key in per_seed[0][label]:
                arr = np.nanmean(np.stack([s[label][key] for s in per_seed]), axis=0)
                agg[key] = {"mean": float(np.nanmean(arr)), "worst": float(np.nanmax(arr)),
                            "per_photo": [None if not np.isfinite(x) else round(float(x), 3) for x in arr]}
        if "cast" in per_seed[0][label]:
            agg["cast"] = float(max(s[label]["cast"] for s in per_seed))
        if "seconds" in per_seed[0][label]:
            agg["seconds"] = float(np.mean([s[label]["seconds"] for s in per_seed]))
        rows[label] = agg
    if "global sequential" in rows and "default" in rows and "truth" in rows["global sequential"]:
        a = np.array(rows["default"]["truth"]["per_photo"], dtype=float)
        b = np.array(rows["global sequential"]["truth"]["per_photo"], dtype=float)
        rows["default"]["joint_worse_than_seq"] = int(np.nansum(a > b + 0.05))
    _print_scene(name, scene, ref, rows, hidden)
    return {"reference": scene.names[ref], "views": len(scene.views),
            "size": f"{originals[0].shape[1]}x{originals[0].shape[0]}", "methods": rows}


def _apply_lut(lut: np.ndarray, img: np.ndarray) -> np.ndarray:
    from o3d_seqcc.correction import LutTransform

    return LutTransform(lut).apply_levels(img)


def _print_scene(name: str, scene, ref: int, rows: dict, hidden: bool) -> None:
    print(f"\n=== {name}: {len(scene.views)} photos, reference {scene.names[ref]!r} ===")
    print(f"{'method':<22} {'invariance':>10} {'worst':>6} | {'truth':>6} {'worst':>6} | {'exact poses':>11} | "
          f"{'cast':>5} | {'s':>5}")
    for label, r in rows.items():
        inv, tr, ex = r.get("invariance"), r.get("truth"), r.get("truth_exact_poses")
        print(f"{label:<22} {inv['mean'] if inv else float('nan'):10.2f} {inv['worst'] if inv else float('nan'):6.2f} | "
              f"{tr['mean'] if tr else float('nan'):6.2f} {tr['worst'] if tr else float('nan'):6.2f} | "
              f"{ex['mean'] if ex else float('nan'):11.2f} | {r.get('cast', float('nan')):5.2f} | "
              f"{r.get('seconds', float('nan')):5.1f}")
    if "default" in rows and "invariance" in rows["default"]:
        print("per photo invariance, default:", " ".join(f"{x:.2f}" if x is not None else "-"
                                                     for x in rows["default"]["invariance"]["per_photo"]))
    for label in ("default", "oracle fit"):
        if label in rows and "truth" in rows[label]:
            print(f"per photo truth, {label}:", " ".join(f"{x:.2f}" if x is not None else "-"
                                                      for x in rows[label]["truth"]["per_photo"]))
    if "oracle fit" in rows and "invariance" in rows["oracle fit"]:
        fit, inv = rows["oracle fit"]["invariance"]["mean"], rows["oracle inverse"]["invariance"]["mean"]
        parts = [f"curve fit {fit - inv:+.2f}"]
        if "global sequential" in rows:
            parts.append(f"composition {rows['global sequential']['invariance']['mean'] - fit:+.2f}")
        if "default" in rows and "truth_exact_poses" in rows["default"]:
            parts.append(f"correspondence {rows['default']['truth']['mean'] - rows['default']['truth_exact_poses']['mean']:+.2f}")
        print("error breakdown (mean CIEDE2000):", ", ".join(parts))
    if "default" in rows and "joint_worse_than_seq" in rows["default"]:
        print("photos the joint refinement leaves further from the truth than its sequential step:",
              rows["default"]["joint_worse_than_seq"])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default=",".join(SCENES), help=f"comma-separated, of {', '.join(SCENES)}")
    ap.add_argument("--methods", default=",".join(METHOD_SPECS), help=f"comma-separated, of {', '.join(METHOD_SPECS)}")
    ap.add_argument("--seeds", type=lambda v: [int(x) for x in v.split(",")], default=[0], help="hidden-change seeds (default 0)")
    ap.add_argument("--fountain", default=str(DEFAULT_FOUNTAIN), help="fountain_small folder")
    ap.add_argument("--stride", type=int, default=2, help="scoring pixel stride (default 2; 4 at least for large photos)")
    ap.add_argument("--json", help="write the figures to this file")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s", stream=sys.stderr)
    logging.getLogger("o3d_seqcc").setLevel(logging.WARNING)
    scenes = [s.strip() for s in args.scenes.split(",") if s.strip()]
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    for s in scenes:
        if s not in SCENES:
            ap.error(f"unknown scene {s!r}; valid: {', '.join(SCENES)}")
    for m in methods:
        if m not in METHOD_SPECS:
            ap.error(f"unknown method {m!r}; valid: {', '.join(METHOD_SPECS)}")
    if any(s.startswith("fountain") for s in scenes) and not Path(args.fountain).is_dir():
        print(f"no Fountain folder at {args.fountain}: skipping the Fountain scenes (give --fountain PATH)")
        scenes = [s for s in scenes if not s.startswith("fountain")]
    out = {}
    with tempfile.TemporaryDirectory(prefix="colour_invariance_") as tmp:
        for s in scenes:
            t0 = time.perf_counter()
            data = load_scene(s, args, Path(tmp))
            out[s] = run_scene(s, data, methods, args)
            out[s]["seconds"] = time.perf_counter() - t0
            del data
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
