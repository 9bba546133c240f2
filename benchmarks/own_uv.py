"""Baking into the mesh's own UVs (issue 35, ``--uv keep``) against the auto atlas, on meshes that carry a layout.

Scenes:

- ``fountain``: Fountain's 33 photos and its decimated mesh with Blender's UV layout
  (``scene/mesh_decimated_uv_blender.ply``, per-vertex ``s``/``t``);
- ``room``: the synthetic room (12 photos of 640 x 480, ``photometric="camera"``), its mesh unwrapped by xatlas
  (``xatlas.parametrize``: its own charts and packing) and written as an OBJ with ``vt``.

For each, ``o3d_seqcc.pipeline.run`` (the defaults of ``o3d-seqcc run``) with ``uv="atlas"`` and with
``uv="keep"``; both saved as ``o3d-seqcc run`` saves them. Printed per scene:

- **identity**: the largest difference between the input's and the saved ``mesh.obj`` / ``mesh.glb``'s per-corner
  positions and UVs (float32 in the files), and whether the faces are the input's, in order;
- **renders**: every photo's camera renders both textured meshes (``render_textured``, pixel centres at integers,
  as ours everywhere); mean CIEDE2000 between the two renders over the pixels both hit (median over the views),
  the same after a 2-pixel Gaussian on both (the colour, without the resampling's pixel-level differences),
  and the detail each keeps: :func:`~o3d_seqcc.evaluation.sharpness.gradient_similarity` against the corrected
  photo (structure, which seams and aliasing do not raise) and the ratio of their Laplacian variances
  (:func:`~o3d_seqcc.evaluation.sharpness.sharpness`), keep over atlas, median over the views;
- the floor of any bake whose texel grid is not the photo's pixel grid: the atlas at 1.25 texels per pixel (every
  texel resampled) against the atlas at 1 (every texel a copy of a pixel), by the same measures;
- the keep run's page, coverage, texels per pixel, UV problems (zero-area, mirrored, overlapping faces) and
  texture memory, beside the atlas run's;
- a picture per scene (``OUT/<scene>_views.png``): the corrected photo, the atlas render and the keep render from
  one camera, for looking at.

Usage::

    .venv/bin/python benchmarks/own_uv.py [--scenes fountain,room] [--out /tmp/o3d_seqcc_own_uv]
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
FOUNTAIN = REPO.parent / "shared" / "datasets" / "fountain_small"

logger = logging.getLogger("own_uv")


def _room(out: Path):
    """The synthetic room and an OBJ of its mesh with xatlas's UV layout: ``(scene path, mesh path)``."""
    import trimesh
    import xatlas

    from o3d_seqcc.synthetic import make_synthetic_scene

    syn = make_synthetic_scene(out / "room", n_views=12, width=640, height=480, seed=0, overwrite=True)
    scene_path = out / "room" / "scene.json"
    from o3d_seqcc import load_scene

    sc = load_scene(scene_path)
    m = sc.load_mesh()
    vmap, faces, uv = xatlas.parametrize(np.asarray(m.vertices, dtype=np.float32), np.asarray(m.faces, np.uint32))
    t = trimesh.Trimesh(vertices=np.asarray(m.vertices)[vmap], faces=faces, process=False,
                        visual=trimesh.visual.TextureVisuals(uv=uv))
    mesh_path = out / "room_xatlas_uv.obj"
    mesh_path.write_text(trimesh.exchange.obj.export_obj(t, include_normals=False, include_texture=True,
                                                         write_texture=False, mtl_name=None), encoding="utf-8")
    del syn
    return scene_path, mesh_path


def _identity(mesh_path: Path, out: Path) -> dict:
    """Largest per-corner position / UV difference between the input mesh and the saved OBJ and GLB."""
    import trimesh

    from o3d_seqcc.io.mesh_files import read_corner_uv, read_mesh

    v, f, _ = read_mesh(mesh_path)
    uv = read_corner_uv(mesh_path, v, f)
    res = {}
    for name in ("mesh.obj", "mesh.glb"):
        t = trimesh.load(out / name, process=False, maintain_order=True, force="mesh")
        tv, tf = np.asarray(t.vertices), np.asarray(t.faces)
        same = tf.shape == f.shape
        res[name] = {"faces": int(len(tf)), "same_face_count": bool(same),
                     "position": float(np.abs(tv[tf] - v[f]).max()) if same else None,
                     "uv": float(np.abs(np.asarray(t.visual.uv)[tf] - uv).max()) if same else None}
    return res


def _renders(scene, corrected, atlas_tm, keep_tm) -> dict:
    from o3d_seqcc.evaluation.render import render_textured
    from o3d_seqcc.evaluation.sharpness import gradient_similarity, sharpness
    from o3d_seqcc.imaging.arrays import delta_e_2000

    import cv2

    de, de_lp, ratio, gs_a, gs_k, pictures = [], [], [], [], [], []
    for v, view in enumerate(scene.views):
        a = render_textured(atlas_tm, view, background=(0, 0, 0))
        k = render_textured(keep_tm, view, background=(0, 0, 0))
        hit_a = render_textured(atlas_tm, view, background=(255, 0, 255)) != a
        hit_k = render_textured(keep_tm, view, background=(255, 0, 255)) != k
        hit = ~(hit_a.any(axis=2) | hit_k.any(axis=2))
        if hit.sum() < 1000:
            continue
        de.append(float(delta_e_2000(a[hit] / 255.0, k[hit] / 255.0).mean()))
        ab, kb = (cv2.GaussianBlur(x.astype(np.float32), (0, 0), 2.0) for x in (a, k))
        de_lp.append(float(delta_e_2000(ab[hit] / 255.0, kb[hit] / 255.0).mean()))
        ratio.append(sharpness(k, hit) / max(sharpness(a, hit), 1e-12))
        photo = np.asarray(corrected[v])
        gs_a.append(gradient_similarity(a, photo, hit))
        gs_k.append(gradient_similarity(k, photo, hit))
        pictures.append((v, photo, a, k))
    return {"views": len(de), "ciede2000_median": float(np.median(de)), "ciede2000_max": float(np.max(de)),
            "ciede2000_lowpass_median": float(np.median(de_lp)),
            "laplacian_variance_keep_over_atlas": float(np.median(ratio)),
            "gradient_similarity_atlas": float(np.median(gs_a)), "gradient_similarity_keep": float(np.median(gs_k)),
            "_pictures": pictures}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", default="fountain,room")
    p.add_argument("--out", type=Path, default=Path("/tmp/o3d_seqcc_own_uv"))
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    import cv2

    from o3d_seqcc import load_scene
    from o3d_seqcc.pipeline import run

    args.out.mkdir(parents=True, exist_ok=True)
    report = {}
    for name in [s.strip() for s in args.scenes.split(",") if s.strip()]:
        if name == "fountain":
            if not FOUNTAIN.is_dir():
                print(f"fountain: skipped, {FOUNTAIN} is missing")
                continue
            scene_path, mesh_path = FOUNTAIN, FOUNTAIN / "scene" / "mesh_decimated_uv_blender.ply"
        elif name == "room":
            scene_path, mesh_path = _room(args.out)
        else:
            raise SystemExit(f"unknown scene {name!r}; valid: fountain, room")
        scene = load_scene(scene_path, mesh=mesh_path)
        runs = {}
        for uv in ("atlas", "keep", "resampled"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                res = run(scene, uv="atlas", texels_per_pixel=1.25) if uv == "resampled" else run(scene, uv=uv)
            if uv != "resampled":
                res.save(args.out / f"{name}_{uv}", overwrite=True)
            runs[uv] = res
        row = {"identity": _identity(mesh_path, args.out / f"{name}_keep")}
        rend = _renders(runs["keep"].scene, runs["keep"].images, runs["atlas"].textured, runs["keep"].textured)
        pics = rend.pop("_pictures")
        row["renders"] = rend
        floor = _renders(runs["keep"].scene, runs["keep"].images, runs["atlas"].textured, runs["resampled"].textured)
        floor.pop("_pictures")
        row["resampled_atlas"] = floor
        for uv in ("atlas", "keep"):
            st = runs[uv].textured.stats
            row[uv] = {k: st.get(k) for k in ("page_width", "page_height", "coverage", "texels_per_pixel",
                                               "density_scale")}
            row[uv]["gpu_mib"] = st["texture_memory"]["gpu_bytes"] / 2**20
            row[uv]["median_face_texels_per_pixel"] = st["face_texels_per_pixel"]["median"]
            if uv == "keep":
                row[uv]["uv_layout"] = {k: v for k, v in st["uv_layout"].items() if k != "examples"}
        v, photo, a, k = pics[len(pics) // 2]
        strip = np.concatenate([np.asarray(photo, np.uint8), a, k], axis=1)
        cv2.imwrite(str(args.out / f"{name}_views.png"), strip[..., ::-1])
        report[name] = row
        ident = row["identity"]
        print(f"\n{name}: keep vs atlas, {rend['views']} cameras")
        for f_, d in ident.items():
            print(f"  {f_}: {d['faces']} faces, same count {d['same_face_count']}, max corner position diff "
                  f"{d['position']:.2e}, max UV diff {d['uv']:.2e}")
        print(f"  renders: CIEDE2000 keep vs atlas median {rend['ciede2000_median']:.3f} (max view "
              f"{rend['ciede2000_max']:.3f}); Laplacian variance keep / atlas {rend['laplacian_variance_keep_over_atlas']:.3f}; "
              f"gradient similarity to the photo: atlas {rend['gradient_similarity_atlas']:.3f}, keep "
              f"{rend['gradient_similarity_keep']:.3f}; after a 2-px Gaussian (the colour) "
              f"{rend['ciede2000_lowpass_median']:.3f}")
        print(f"  floor of a texel grid that is not the photo's: the atlas at 1.25 texels/pixel vs the atlas: "
              f"CIEDE2000 {floor['ciede2000_median']:.3f} (low-pass {floor['ciede2000_lowpass_median']:.3f}), "
              f"gradient similarity {floor['gradient_similarity_keep']:.3f}")
        for uv in ("atlas", "keep"):
            r = row[uv]
            print(f"  {uv}: page {r['page_width']}x{r['page_height']}, coverage {100 * r['coverage']:.1f} %, "
                  f"{r['texels_per_pixel']:.3f} texels/pixel (median face {r['median_face_texels_per_pixel']:.3f}), "
                  f"GPU {r['gpu_mib']:.1f} MiB" + (f", UV layout {r['uv_layout']}" if uv == "keep" else ""))
        print(f"  picture: {args.out / f'{name}_views.png'} (photo {v} | atlas | keep)")
    (args.out / "own_uv.json").write_text(json.dumps(report, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
