"""Any mesh resolution, any coordinates: a low-poly synthetic room against the same room finely tessellated.

Usage (from a checkout)::

    python benchmarks/lowpoly.py [--compare /tmp/main-checkout] [--no-far] [--json FILE] [--keep DIR]

Scenes (generated once, by this checkout's :func:`o3d_seqcc.make_synthetic_scene`): the synthetic
room of the demo layout (16 views 320x240, two rings of cameras looking up and down, the mesh of
what they see, camera-like photometric changes on every view but ``v00``) tessellated in cells of
1 m (177 faces: what a room scan is often decimated to) and of 10 cm (11,685 faces); with
``--far`` (default on) the 1 m room also moved 5e5 m and 1e7 m from the origin (UTM-like
coordinates: the same images, the mesh and the cameras moved).

Each scene runs :func:`o3d_seqcc.pipeline.run` with its defaults except ``reference="v00"`` (the
unchanged photo: the truth's colours; ``"auto"`` picks a changed photo and the texture would then
carry its exposure), in a subprocess per run with this checkout or ``--compare``'s on
``PYTHONPATH``. The texture is scored against the true albedo by
:func:`o3d_seqcc.demo.texture_ground_truth` (every view renders the textured mesh; mean
CIEDE2000 to its ground-truth render over the covered pixels; holes = covered pixels on faces no
photo textured). The far scenes are also compared with the origin's render by render
(CIEDE2000 between the two textures' renders) and by their unseen counts.

Figures printed per run: faces in and out, input faces unseen / partly seen, unseen share of the
surface, CIEDE2000 to the truth, holes, wall time of the run. Then the issue's targets: the 1 m
room within 1.5 CIEDE2000 of the 10 cm room with holes <= 1 %, and the far rooms within 0.5 of
the origin's with the same unseen counts.

Measured on this 2-core machine (load 2-4 from other jobs), ``--compare`` = main at 952a400::

    case            checkout  faces in -> out  unseen in / partly  unseen area  CIEDE2000  holes   time
    room 1 m        main      177 -> 177       fails: "no view pair has t_npm=400 or more mappings
                                               (the largest count is 3, between 'v02' and 'v04')"
    room 10 cm      main      11685 -> 11685   895 / 0             -            4.13       5.03 %  10 s
    room 1 m        i20a      see the report of issue 20 (numbers printed by this script)

(main by hand on the 1 m room: no ``t_npm`` gives ``v00`` an edge; its largest pair count is 3
vertex mappings.)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if "--worker" not in sys.argv:  # a worker imports the checkout on its PYTHONPATH
    sys.path.insert(0, str(REPO))

SCENE = {"n_views": 16, "layout": "two-rings", "seen_only": True, "width": 320, "height": 240, "seed": 0}
CASES = (("room 1 m", 1.0, 0.0), ("room 10 cm", 0.1, 0.0))
FAR = (("room 1 m at 5e5 m", 1.0, 5e5), ("room 1 m at 1e7 m", 1.0, 1e7))


def _moved(scene, shift: float):
    """The scene with its mesh and cameras moved by ``(shift, -shift / 3, shift / 4)`` (in memory, float64)."""
    from dataclasses import replace

    from o3d_seqcc.scene import Mesh, Scene

    s = np.array([shift, -shift / 3, shift / 4])
    m = scene.load_mesh()
    views = []
    for v in scene.views:
        E = np.array(v.extrinsic, dtype=np.float64)
        E[:3, 3] -= E[:3, :3] @ s
        views.append(replace(v, extrinsic=E))
    return Scene(mesh=Mesh(vertices=m.vertices + s, faces=m.faces, vertex_normals=m.vertex_normals),
                 views=tuple(views), source=scene.source)


def _worker(scene_dir: str, out: str, reference: str, shift: str = "0") -> int:
    """Run the pipeline of whatever o3d_seqcc is first on sys.path; save the textured mesh's arrays."""
    import o3d_seqcc as sc

    t = time.perf_counter()
    try:
        if (Path(scene_dir) / "scene" / "key.log").is_file():  # Fountain, moved in memory by ``shift``
            scene = sc.datasets.fountain(scene_dir, mesh="scene/mesh_decimated_uv_blender.ply")
            scene = _moved(scene, float(shift)) if float(shift) else scene
        else:
            scene = str(Path(scene_dir) / "scene.json")
        res = sc.pipeline.run(scene, reference=reference)
    except Exception as e:  # the figure is the failure itself
        Path(out).with_suffix(".json").write_text(json.dumps({"error": f"{type(e).__name__}: {e}"}))
        return 0
    tm = res.textured
    np.savez(out, vertices=tm.vertices, faces=tm.faces, uv=tm.uv, texture=tm.texture, face_view=tm.face_view)
    st = {k: v for k, v in res.selection_stats.items() if isinstance(v, (int, float))}
    Path(out).with_suffix(".json").write_text(json.dumps({"seconds": time.perf_counter() - t, "stats": st,
                                                          "timings": res.timings, "package": sc.__file__}))
    return 0


def _run(checkout: Path, scene_dir: Path, out: Path, reference: str, shift: float = 0.0) -> dict:
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", str(scene_dir), str(out), reference, repr(shift)]
    subprocess.run(cmd, env=env, check=True, cwd=str(checkout))
    info = json.loads(out.with_suffix(".json").read_text())
    if "error" not in info:
        from o3d_seqcc.texturing import TexturedMesh

        z = np.load(out)
        info["mesh"] = TexturedMesh(vertices=z["vertices"], faces=z["faces"], uv=z["uv"], texture=z["texture"],
                                    face_view=z["face_view"])
    return info


def _resolution(root: Path) -> dict:
    """This checkout's pair counts on Fountain's 16k- and 300k-face meshes (same photos): surface vs vertex mappings."""
    import o3d_seqcc as sc
    from o3d_seqcc.correction.graph import resolve_t_npm
    from o3d_seqcc.mappings.compute import compute_mappings

    counts = {}
    for mesh in ("mesh_decimated_uv_blender.ply", "tsdf_mesh.ply"):
        scene = sc.datasets.fountain(root, mesh=f"scene/{mesh}")
        vis = sc.compute_visibility(scene)
        surf, vert = compute_mappings(scene, visibility=vis), compute_mappings(scene, visibility=vis, mappings="vertices")
        counts[mesh] = (surf.counts, vert.counts, resolve_t_npm("auto", surf)[0], vis.stats["split"]["input_faces"])
    (a_s, a_v, t, fa), (b_s, b_v, _, fb) = counts.values()
    keys = sorted(set(a_s) & set(b_s))
    rs = np.array([b_s[k] / a_s[k] for k in keys if a_s[k] >= t])
    rv = np.array([b_v.get(k, 0) / a_v[k] for k in keys if a_v.get(k, 0) >= 400])
    row = {"case": "fountain counts 300k / 16k", "surface_ratio": np.percentile(rs, [10, 50, 90]).round(3).tolist(),
           "vertex_ratio": np.percentile(rv, [10, 50, 90]).round(3).tolist(),
           "edges_auto": [int(sum(v >= t for v in a_s.values())), int(sum(v >= t for v in b_s.values()))],
           "edges_400_vertices": [int(sum(v >= 400 for v in a_v.values())), int(sum(v >= 400 for v in b_v.values()))]}
    print(f"\nFountain pair counts, {fb}-face mesh over the {fa}-face one (same photos, pairs over the threshold; "
          f"10 / 50 / 90 %): shared surface in px {row['surface_ratio']}, vertex mappings {row['vertex_ratio']}; "
          f"graph edges at t_npm auto ({t} px) {row['edges_auto']}, at 400 vertex mappings {row['edges_400_vertices']}")
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--compare", action="append", default=[], help="another checkout to run beside this one")
    ap.add_argument("--no-far", dest="far", action="store_false", help="skip the rooms moved 5e5 m and 1e7 m")
    ap.add_argument("--json", help="write the figures to this file")
    ap.add_argument("--keep", help="generate the scenes in this folder (kept) instead of a temporary one")
    ap.add_argument("--fountain", default=str(REPO.parent / "shared" / "datasets" / "fountain_small"),
                    help="Fountain folder for the far-from-origin runs (skipped when absent)")
    ap.add_argument("--no-fountain", dest="fountain", action="store_const", const="", help="skip Fountain")
    ap.add_argument("--no-resolution", dest="resolution", action="store_false",
                    help="skip the pair counts of Fountain's 16k- and 300k-face meshes")
    ap.add_argument("--worker", nargs=4, metavar=("SCENE", "OUT", "REFERENCE", "SHIFT"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        return _worker(*args.worker)

    import o3d_seqcc as sc
    from o3d_seqcc.demo import texture_ground_truth
    from o3d_seqcc.evaluation.metrics import image_delta_e
    from o3d_seqcc.evaluation.render import render_textured
    from o3d_seqcc.synthetic import load_synthetic

    checkouts = [("this", REPO)] + [(Path(c).name or c, Path(c).resolve()) for c in args.compare]
    cases = CASES + (FAR if args.far else ())
    tmp = tempfile.TemporaryDirectory(prefix="lowpoly_") if args.keep is None else None
    root = Path(args.keep or tmp.name)
    rows, renders = [], {}
    print(f"{'case':<20} {'checkout':<10} {'faces in -> out':>16} {'unseen in/partly':>17} {'unseen area':>11} "
          f"{'CIEDE2000':>9} {'holes':>7} {'time':>6}")
    for name, cell, far in cases:
        d = root / f"room_{cell:g}_{far:g}"
        if not (d / "synthetic.json").is_file():
            sc.make_synthetic_scene(d, cell_size=cell, origin=(far, -far / 3, far / 4), overwrite=True, **SCENE)
        syn = load_synthetic(d)
        for label, path in checkouts:
            info = _run(path, d, root / f"{d.name}_{label}.npz", "v00")
            row = {"case": name, "checkout": label, "cell": cell, "origin": far}
            if "error" in info:
                row["error"] = info["error"]
                print(f"{name:<20} {label:<10} fails: {info['error'][:150]}")
                rows.append(row)
                continue
            gt = texture_ground_truth(syn, info["mesh"])
            st = info["stats"]
            row.update(faces_in=st.get("input_faces", st["faces"]), faces_out=st["faces"],
                       unseen_input=st.get("unseen_input_faces", st["unseen_faces"]),
                       partly=st.get("partly_seen_input_faces", 0), unseen_area=st.get("unseen_area"),
                       ciede2000=gt["mean"], holes=gt["holes"], seconds=round(info["seconds"], 1))
            renders[(name, label)] = [render_textured(info["mesh"], v) for v in syn.scene.views]
            ua = "-" if row["unseen_area"] is None else f"{100 * row['unseen_area']:.1f} %"
            print(f"{name:<20} {label:<10} {row['faces_in']:>7} -> {row['faces_out']:<6} "
                  f"{row['unseen_input']:>8} / {row['partly']:<6} {ua:>11} {row['ciede2000']:>9.2f} "
                  f"{100 * row['holes']:>6.2f}% {row['seconds']:>5.1f}s", flush=True)
            rows.append(row)
    by = {(r["case"], r["checkout"]): r for r in rows}
    print("\ntargets (issue 20):")
    for label, _ in checkouts:
        lo, hi = by.get(("room 1 m", label), {}), by.get(("room 10 cm", label), {})
        if "ciede2000" in lo and "ciede2000" in hi:
            gap = lo["ciede2000"] - hi["ciede2000"]
            print(f"  {label}: 1 m room {lo['ciede2000']:.2f} vs 10 cm room {hi['ciede2000']:.2f}: gap {gap:+.2f} "
                  f"(target <= 1.5), holes {100 * lo['holes']:.2f} % (target <= 1 %)")
        else:
            print(f"  {label}: 1 m room {lo.get('error', 'not run')[:120]}")
        base = by.get(("room 1 m", label))
        for name, _, far in FAR if args.far else ():
            r = by.get((name, label))
            if not r or "ciede2000" not in r or not base or "ciede2000" not in base:
                continue
            moved = [image_delta_e(a, b) for a, b in zip(renders[(name, label)], renders[("room 1 m", label)])]
            r["vs_origin_ciede2000"] = round(float(np.mean(moved)), 3)
            same = (r["unseen_input"], r["partly"], r["faces_out"]) == (base["unseen_input"], base["partly"],
                                                                          base["faces_out"])
            print(f"  {label}: {name}: unseen {r['unseen_input']} / {r['partly']} vs {base['unseen_input']} / "
                  f"{base['partly']} at the origin ({'same' if same else 'DIFFERENT'}; faces out {r['faces_out']} vs "
                  f"{base['faces_out']}), renders vs the origin's {r['vs_origin_ciede2000']:.3f} CIEDE2000 "
                  "(target <= 0.5)")
    if args.fountain and (Path(args.fountain) / "scene" / "key.log").is_file():
        from o3d_seqcc.datasets import fountain

        scene = fountain(args.fountain, mesh="scene/mesh_decimated_uv_blender.ply")
        print("\nFountain (33 photos, 16k faces), reference auto, moved (s, -s/3, s/4) from the origin:")
        for label, path in checkouts:
            base = None
            for shift in (0.0, 5e5, 1e7):
                info = _run(path, Path(args.fountain), root / f"fountain_{shift:g}_{label}.npz", "auto", shift)
                row = {"case": f"fountain at {shift:g} m", "checkout": label, "origin": shift}
                if "error" in info:
                    row["error"] = info["error"]
                    print(f"  {label} {shift:g} m: fails: {info['error'][:150]}")
                    rows.append(row)
                    continue
                st = info["stats"]
                views = _moved(scene, shift).views if shift else scene.views
                imgs = [render_textured(info["mesh"], v) for v in views]
                row.update(faces_out=st["faces"], unseen=st["unseen_faces"],
                           unseen_input=st.get("unseen_input_faces", st["unseen_faces"]),
                           unseen_area=st.get("unseen_area"), seconds=round(info["seconds"], 1))
                if base is None:
                    base = (row, imgs)
                else:
                    row["vs_origin_ciede2000"] = round(float(np.mean([image_delta_e(a, b) for a, b in zip(imgs, base[1])])), 3)
                ua = "-" if row["unseen_area"] is None else f"{100 * row['unseen_area']:.2f} %"
                vs = f", renders vs the origin's {row['vs_origin_ciede2000']:.3f} CIEDE2000" if "vs_origin_ciede2000" in row \
                    else ""
                print(f"  {label:<10} {shift:>8g} m: faces out {row['faces_out']}, unseen {row['unseen']} "
                      f"(input faces {row['unseen_input']}, area {ua}){vs}, {row['seconds']:.1f} s", flush=True)
                rows.append(row)
    if args.resolution and args.fountain and (Path(args.fountain) / "scene" / "tsdf_mesh.ply").is_file():
        rows.append(_resolution(Path(args.fountain)))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
