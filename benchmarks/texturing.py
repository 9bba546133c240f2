"""Texturing peers side by side on fountain (issue 5): time, seam metric, sharpness, transitions.

Runs, on the same scene (fountain key frames + the decimated mesh) and the same images
(original photos, and photos colour-corrected by ``o3d_seqcc.correction.correct(scene,
reference="auto")``):

- ours: per-face selection (largest-area, random, mrf) + atlas bake + GLB export
  (``o3d_seqcc.texturing`` / ``o3d_seqcc.io.export``), each without and with global seam leveling
  (``+lev``: ``bake_texture(leveling=True)``) and with global + local seam leveling (``+lev+local``:
  ``bake_texture(leveling=True, local_leveling=True)``, the command-line default);
- MeshLab's ``compute_texcoord_parametrization_and_texture_from_registered_rasters``
  (colorcorrection on) through pymeshlab, in a headless subprocess under xvfb-run;
- Open3D's ``compute_uvatlas`` + ``project_images_to_albedo``.

For each: wall time, seam metric (``o3d_seqcc.evaluation.seams.seam_metric``: CIEDE2000 across interior
edges, UV-seam edges sampled ``--seam-offset`` texels inside each face, edges inside a chart count
0; mean, p99, fraction > 5, number of UV-seam edges and their mean), and the sharpness ratio of a
render from view 16 against that view's photo (variance of the Laplacian inside the mesh
silhouette; 1 = as sharp as the photo). The issue's sharpness criterion (0.8-1.25x) uses the
supersampled render (``--supersample 3``: 3 x 3 rays per pixel, box filter -- a camera integrates
over the pixel footprint, and a viewer with mip-mapping / multisampling shows the same); the
ratio at one ray per pixel (bilinear lookup, aliasing where the texture is minified) is shown
too, for transparency. Prints a table and ratios vs
the peers, writes ``results.json`` and PNG pictures (selection colouring, textured renders from
chosen views: ours with original vs corrected images, with vs without leveling, and the peers)
into ``--out``/pictures.

Usage::

    .venv/bin/python benchmarks/texturing.py [--out /tmp/o3d_seqcc_bench] [--no-open3d]
        [--open3d-originals] [--no-meshlab] [--atlas-size 2048] [--views 16,3,27]

Timings are noisy on a shared machine; MeshLab's time is its filter only (its own visibility
included), Open3D's is uvatlas + albedo, ours is visibility (shared by the three selections,
counted in each) + selection + bake + GLB export.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "datasets" / "fountain_small"
SELECTIONS = ("largest-area", "mrf", "random")

logger = logging.getLogger("benchmarks.texturing")


def _label(img: np.ndarray, text: str) -> np.ndarray:
    import cv2

    out = np.ascontiguousarray(img.copy())
    cv2.rectangle(out, (0, 0), (min(out.shape[1], 12 + 11 * len(text)), 26), (0, 0, 0), -1)
    cv2.putText(out, text, (6, 19), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def _grid(rows: list[list[np.ndarray]]) -> np.ndarray:
    return np.concatenate([np.concatenate(r, axis=1) for r in rows], axis=0)


#: --leveling mode -> method-name suffix
SUFFIX = {"off": "", "on": "+lev", "local": "+lev+local"}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(DATA), help="fountain_small folder")
    ap.add_argument("--mesh", default="scene/mesh_decimated_uv_blender.ply", help="mesh, relative to --data")
    ap.add_argument("--out", default="/tmp/o3d_seqcc_bench", help="output folder (overwritten)")
    ap.add_argument("--atlas-size", type=int, default=2048)
    ap.add_argument("--view", type=int, default=16, help="view index for the sharpness ratio (default 16)")
    ap.add_argument("--views", default="16,3,27", help="view indices for the pictures")
    ap.add_argument("--selections", default=",".join(SELECTIONS))
    ap.add_argument("--supersample", type=int, default=3,
                    help="rays per pixel per axis of the renders (box-filtered; default 3)")
    ap.add_argument("--leveling", default="off,on,local",
                    help="ours without (off) / with global (on) / with global + local (local) seam leveling "
                    "(default off,on,local)")
    ap.add_argument("--leveling-smoothness", type=float, default=None, help="default: the library's")
    ap.add_argument("--seam-offset", type=float, default=0.5, help="seam metric: texels inward from the edge (default 0.5)")
    ap.add_argument("--no-meshlab", action="store_true")
    ap.add_argument("--no-open3d", action="store_true")
    ap.add_argument("--open3d-originals", action="store_true", help="also run Open3D on the original images (slow)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")

    from peers import meshlab_available, run_meshlab, run_open3d
    from o3d_seqcc.io.images import write_image
    from o3d_seqcc.io.export import export_textured_mesh
    from o3d_seqcc.evaluation.render import raycast, render_selection, render_textured, sharpness
    from o3d_seqcc import load_scene
    from o3d_seqcc.geometry.meshops import face_adjacency
    from o3d_seqcc.evaluation.seams import seam_metric
    from o3d_seqcc.texturing import bake_texture, load_textured_mesh, select_views, selection_stats
    from o3d_seqcc.visibility.compute import compute_visibility

    data = Path(args.data)
    if not (data / "scene" / "key.log").is_file():
        print(f"fountain data not found at {data}", file=sys.stderr)
        return 1
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scene = load_scene(data, mesh=data / args.mesh)
    views = [int(x) for x in args.views.split(",") if x.strip()]
    sv = args.view
    selections = [s.strip() for s in args.selections.split(",") if s.strip()]
    levelings = [x.strip() for x in args.leveling.split(",") if x.strip()]
    bad = [x for x in levelings if x not in SUFFIX]
    if bad:
        print(f"--leveling: unknown {bad}; valid: {', '.join(SUFFIX)}", file=sys.stderr)
        return 2

    originals = [v.load_image() for v in scene.views]
    image_sets: dict[str, list[np.ndarray]] = {"original": originals}
    notes: list[str] = []
    t = time.perf_counter()
    try:
        from o3d_seqcc.correction import correct

        res = correct(scene, reference="auto")
        image_sets["corrected"] = list(res.images)
        t_correct = time.perf_counter() - t
        notes.append(f"corrected: seqcc, reference {scene.names[res.reference]} (index {res.reference}), "
                     f"unreachable {res.unreachable}, {t_correct:.2f} s")
    except Exception as e:  # correction module missing or failing: fall back to originals only
        t_correct = float("nan")
        notes.append(f"correction unavailable ({type(e).__name__}: {e}); only original images")
    for name, imgs in image_sets.items():
        if name != "original":
            d = out / f"images_{name}"
            for v, img in zip(scene.views, imgs):
                write_image(d / f"{v.name}.png", img)

    t = time.perf_counter()
    vis = compute_visibility(scene)
    t_vis = time.perf_counter() - t
    mesh = vis.mesh
    adjacency = face_adjacency(mesh.faces, mesh.vertices)
    hits = {k: raycast(mesh, scene.views[k]) for k in sorted(set(views + [sv]))}

    rows: list[dict] = []
    renders: dict[tuple[str, str], dict[int, np.ndarray]] = {}
    labels_by_sel: dict[str, np.ndarray] = {}

    def measure(method: str, images_name: str, mesh_path: Path, seconds: float, extra: dict) -> dict:
        rep = seam_metric(mesh_path, offset=args.seam_offset)
        tm = load_textured_mesh(mesh_path)
        h = raycast(tm, scene.views[sv])
        photo = image_sets[images_name][sv]
        s_photo = sharpness(photo, h.mask)
        img1 = render_textured(tm, scene.views[sv], hits=h)  # one ray per pixel (aliases when minified)
        img = render_textured(tm, scene.views[sv], supersample=args.supersample)
        ratio = sharpness(img, h.mask) / s_photo
        ratio1 = sharpness(img1, h.mask) / s_photo
        renders[(method, images_name)] = {sv: img}
        for k in views:
            if k != sv:
                renders[(method, images_name)][k] = render_textured(tm, scene.views[k], supersample=args.supersample)
        row = {"method": method, "images": images_name, "seconds": seconds, **rep.to_dict(),
               "sharpness_ratio": ratio, "sharpness_ratio_1spp": ratio1, "mesh": str(mesh_path), **extra}
        rows.append(row)
        print(f"  {method:<28} {images_name:<9} {seconds:7.2f} s  seam mean {rep.mean:5.3f}  p99 {rep.p99:6.2f}  "
              f">5 {rep.frac_above_5:6.4f}  sharpness {ratio:5.2f}x ({ratio1:.2f}x at 1 ray/px)", flush=True)
        return row

    print(f"fountain: {len(scene.views)} views, {len(mesh.faces)} faces; visibility {t_vis:.2f} s; " + "; ".join(notes))
    for images_name, imgs in image_sets.items():
        for sel in selections:
            for lev in levelings:
                t = time.perf_counter()
                opts = {"adjacency": adjacency} if sel == "mrf" else {}
                labels = select_views(vis, method=sel, seed=0, **opts)
                t_sel = time.perf_counter() - t
                lev_opts = {} if args.leveling_smoothness is None else {"leveling_smoothness": args.leveling_smoothness}
                tm = bake_texture(mesh, imgs, vis, labels, atlas_size=args.atlas_size, adjacency=adjacency,
                                  leveling=lev != "off", local_leveling=lev == "local", **lev_opts)
                t_bake = time.perf_counter() - t - t_sel
                name = f"ours:{sel}" + SUFFIX[lev]
                d = out / f"ours_{sel}{SUFFIX[lev].replace('+', '_')}_{images_name}"
                files = export_textured_mesh(tm, d, formats=("glb",))
                t_total = time.perf_counter() - t + t_vis
                stats = selection_stats(labels, adjacency, len(scene.views))
                labels_by_sel[sel] = labels
                measure(name, images_name, files["glb"], t_total,
                        {"transitions": stats["transitions"], "unseen_faces": stats["unseen_faces"],
                         "t_selection": t_sel, "t_bake": t_bake, "t_visibility": t_vis,
                         "atlas_size": tm.atlas_size, "leveling": tm.stats.get("leveling"),
                         "local_leveling": tm.stats.get("local_leveling")})

    reason = None if not args.no_meshlab else "--no-meshlab"
    reason = reason or meshlab_available()
    if reason:
        notes.append(f"MeshLab skipped: {reason}")
    else:
        for images_name, imgs in image_sets.items():
            try:
                r = run_meshlab(scene, out / f"meshlab_{images_name}", images=imgs, texture_size=args.atlas_size,
                                overwrite=True)
                measure("meshlab", images_name, r.mesh, r.seconds,
                        {"total_seconds": r.total_seconds, "faces_textured": r.info.get("faces_textured")})
            except RuntimeError as e:
                notes.append(f"MeshLab failed on {images_name}: {e}")
    if not args.no_open3d:
        for images_name, imgs in image_sets.items():
            if images_name == "original" and "corrected" in image_sets and not args.open3d_originals:
                continue
            r = run_open3d(scene, out / f"open3d_{images_name}", images=imgs, texture_size=args.atlas_size, overwrite=True)
            measure("open3d", images_name, r.mesh, r.seconds,
                    {"total_seconds": r.total_seconds, "faces_textured": r.info.get("faces_textured")})

    # ------------------------------------------------------------------ table and ratios
    print()
    hdr = (f"{'method':<28} {'images':<9} {'time s':>7} {'seam mean':>9} {'p99':>6} {'>5':>7} {'UV-seam edges':>13} "
           f"{'seam-edge mean':>14} {'sharp':>6} {'sharp1':>6} {'transitions':>11}")
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        tr = r.get("transitions")
        print(f"{r['method']:<28} {r['images']:<9} {r['seconds']:7.2f} {r['mean']:9.3f} {r['p99']:6.2f} "
              f"{r['frac_above_5']:7.4f} {r['n_seam_edges']:13d} {r['seam_mean']:14.2f} {r['sharpness_ratio']:5.2f}x "
              f"{r['sharpness_ratio_1spp']:5.2f}x {'' if tr is None else tr:>11}")
    print("(seam metric: CIEDE2000 across interior edges, UV-seam edges sampled "
          f"{args.seam_offset:g} texel inside each face, edges inside a chart count 0; sharp = variance of the "
          f"Laplacian of a {args.supersample}x{args.supersample}-supersampled render of view {sv} / the photo's, the "
          "issue's criterion (target 0.8-1.25); sharp1 = 1 ray per pixel)")

    def find(method: str, images_name: str) -> dict | None:
        return next((r for r in rows if r["method"] == method and r["images"] == images_name), None)

    main_set = "corrected" if "corrected" in image_sets else "original"
    print(f"\nratios on {main_set} images (ours / peer; < 1 = ours lower):")
    for sel in selections:
        for lev in levelings:
            name = f"ours:{sel}" + SUFFIX[lev]
            o = find(name, main_set)
            for peer in ("meshlab", "open3d"):
                p = find(peer, main_set)
                if o and p:
                    print(f"  {name:<28} / {peer:<8} seam mean {o['mean'] / p['mean']:5.2f}  "
                          f">5 {o['frac_above_5'] / max(p['frac_above_5'], 1e-12):5.2f}  "
                          f"time {o['seconds'] / p['seconds']:5.2f}")
    for sel, (sa, sb) in ((s, ab) for s in selections for ab in (("", "+lev"), ("+lev", "+lev+local"))):
        a, b = find(f"ours:{sel}{sa}", main_set), find(f"ours:{sel}{sb}", main_set)
        if a and b:
            print(f"  ours:{sel:<13} {'leveling' if not sa else 'local leveling'}: seam mean {a['mean']:.3f} -> {b['mean']:.3f} ({b['mean'] / a['mean']:.2f}x), "
                  f">5 {a['frac_above_5']:.4f} -> {b['frac_above_5']:.4f}, sharpness {a['sharpness_ratio']:.2f}x -> "
                  f"{b['sharpness_ratio']:.2f}x")
    la = next((r for r in (find("ours:largest-area" + SUFFIX[x], main_set) for x in levelings) if r), None)
    mrf = next((r for r in (find("ours:mrf" + SUFFIX[x], main_set) for x in levelings) if r), None)
    if la and mrf:
        print(f"  image transitions: mrf {mrf['transitions']} vs largest-area {la['transitions']} "
              f"({mrf['transitions'] / max(la['transitions'], 1):.2f}x)")
    if "corrected" in image_sets:
        for sel in selections:
            for lev in levelings:
                name = f"ours:{sel}" + SUFFIX[lev]
                a, b = find(name, "original"), find(name, "corrected")
                if a and b:
                    print(f"  {name:<28} corrected / original seam mean {b['mean'] / a['mean']:5.2f} "
                          f"({a['mean']:.3f} -> {b['mean']:.3f})")
    for n in notes:
        print("note:", n)

    # ------------------------------------------------------------------ pictures
    pics = out / "pictures"
    for sel, labels in labels_by_sel.items():
        tiles = [_label(render_selection(mesh, labels, scene.views[k], n_views=len(scene.views), hits=hits[k]),
                        f"{sel} selection, view {k}") for k in views]
        write_image(pics / f"selection_{sel}.png", _grid([tiles]))
    best = SUFFIX["local"] if "local" in levelings else SUFFIX["on"] if "on" in levelings else ""
    for sel in selections:
        rows_img = []
        for images_name in image_sets:
            r = renders.get((f"ours:{sel}{best}", images_name))
            if r:
                rows_img.append([_label(r[k], f"ours {sel}{best}, {images_name}, view {k}") for k in views])
        for images_name in image_sets:
            rows_img.append([_label(image_sets[images_name][k], f"photo {images_name} {k}") for k in views])
        write_image(pics / f"ours_{sel}_original_vs_corrected.png", _grid(rows_img))
        rows_img = []
        for images_name in image_sets:
            for lev in levelings:
                r = renders.get((f"ours:{sel}" + SUFFIX[lev], images_name))
                if r:
                    rows_img.append([_label(r[k], f"ours {sel}, {images_name}, leveling {lev}, view {k}")
                                     for k in views])
        if rows_img:
            write_image(pics / f"ours_{sel}_leveling.png", _grid(rows_img))
    # leveling close-ups: central half of each view, 2x, without / with leveling
    import cv2

    for k in views:
        tiles = []
        for method in ("ours:mrf", "ours:mrf+lev", "ours:mrf+lev+local", "ours:largest-area", "ours:largest-area+lev",
                       "ours:largest-area+lev+local"):
            r = renders.get((method, main_set))
            if r:
                h, w = r[k].shape[:2]
                crop = r[k][h // 4: 3 * h // 4, w // 4: 3 * w // 4]
                tiles.append(_label(cv2.resize(crop, None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST), f"{method}, view {k}"))
        if len(tiles) >= 2:
            tiles += [np.full_like(tiles[0], 255)] * (len(tiles) % 2)
            write_image(pics / f"leveling_closeup_view{k}.png", _grid([tiles[i:i + 2] for i in range(0, len(tiles), 2)]))
    peer_rows = []
    for method in (f"ours:mrf{best}", f"ours:largest-area{best}", "meshlab", "open3d"):
        r = renders.get((method, main_set))
        if r:
            peer_rows.append([_label(r[k], f"{method}, {main_set}, view {k}") for k in views])
    peer_rows.append([_label(image_sets[main_set][k], f"photo {main_set} {k}") for k in views])
    write_image(pics / "peers.png", _grid(peer_rows))
    # close-up crops of view `sv` at full resolution: ours vs peers vs photo
    crops = []
    for method in dict.fromkeys(("ours:mrf", "ours:mrf+lev", f"ours:mrf{best}", "meshlab", "open3d",
                                 f"ours:largest-area{best}")):
        r = renders.get((method, main_set))
        if r:
            crops.append(_label(r[sv][40:300, 100:460], f"{method}"))
    crops.append(_label(image_sets[main_set][sv][40:300, 100:460], "photo"))
    crops += [np.full_like(crops[0], 255)] * (-len(crops) % 4)
    write_image(pics / f"closeup_view{sv}.png", _grid([crops[i:i + 4] for i in range(0, len(crops), 4)]))

    from o3d_seqcc.io.json_files import write_json

    write_json(out / "results.json", {"rows": rows, "notes": notes, "t_visibility": t_vis, "t_correct": t_correct})
    print(f"\nwrote {out / 'results.json'} and pictures in {pics}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
