"""Engine-ready atlas (issues 13, 35): Fountain decimated (16k faces), Fountain 300k and a synthetic room, ours vs
before vs peers.

Rows, on the same scene, selection and colour-corrected photos (Fountain: corrected once on the decimated mesh, the
same photos for both meshes; the room, ``room``: 16 photos of 320 x 240 on two rings, ``seen_only``, about 70k faces,
corrected on its own mesh):

- ``ours (xatlas)``: ``bake_texture`` with the library's defaults (xatlas packing, one page cut to the charts, the
  small charts in one block, sampling bake, welded unseen faces, 2-pass local leveling) at ``--atlas-size``
  (default ``auto``, the library's; an integer is a budget), exported as GLB (Y-up, PNG; also JPEG and WebP for the
  size);
- ``before``: the bake of ``--baseline-commit`` (default main eb143f1, before issue 35: square power-of-two pages,
  every chart with its 4-texel gutter; ``--baseline-commit 89e7de7`` gives issue 13's shelf packer), same mesh,
  selection, corner projections and photos. That commit is checked out with ``git worktree
  add`` under a temporary folder (removed at the end) and its own ``bake_texture`` runs in a child
  Python with only that worktree on ``PYTHONPATH``: the retired code is measured as it was, not kept
  alive in the repository;
- ``meshlab``: MeshLab's ``compute_texcoord_parametrization_and_texture_from_registered_rasters``
  (``benchmarks/peers.py``, headless under xvfb-run), texture size = the atlas size;
- ``open3d``: ``compute_uvatlas`` + ``project_images_to_albedo``.

Figures per row: ``coverage`` (triangle area in texels / atlas area), ``used`` (share of the
atlas read by bilinear lookups inside the triangles: the texels within one texel of a triangle;
the same measure for every tool, from its output file), atlas size, pages, GLB bytes (PNG; JPEG
q90 and WebP q90 for ours), output / input vertices, seam metric mean and share of edges > 5
(``o3d_seqcc.evaluation.seams.seam_metric`` on the output file), ``view seams`` (ours and before: CIEDE2000
across every edge between faces textured from two different views, also inside a chart, which the
seam metric scores 0), sharpness of a 3x3-supersampled render from the reference view (16) over
the photo's, and the bake time (ours and before: ``--repeats`` alternating runs in this process,
median; MeshLab and Open3D: their filter's wall time, once). Ours also: the mip-bleed test
(``o3d_seqcc.evaluation.seams.mip_bleed``, levels 1-3), the Khronos validator per texture format, and a Y-up
picture (the Y-up GLB rendered by a Y-up viewer's camera at the reference view, next to the photo).

``--evidence`` adds, on the decimated mesh, the coverage xatlas reaches with other settings
(padding, merging, brute-force placement) against their mip bleed, seams and time: the evidence
for the 70 % coverage target.

Usage::

    python benchmarks/atlas.py [--out /tmp/o3d_seqcc_atlas] [--meshes dec,300k,room] [--repeats 3] [--pack-effort fast|best]
        [--no-meshlab] [--no-open3d] [--peers-300k] [--evidence] [--evidence-brute] [--baseline-commit 89e7de7]

Timings are noisy on a shared 2-core machine: compare rows of one run.
"""

from __future__ import annotations

import argparse
import atexit
import json
import logging
import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "datasets" / "fountain_small"
MESHES = {"dec": ("scene/mesh_decimated_uv_blender.ply", "auto"), "300k": ("scene/tsdf_mesh.ply", "auto"),
          "room": (None, "auto")}
VIEW = 16
#: the synthetic room's view of the sharpness and the Y-up picture
ROOM_VIEW = 8
#: main before issue 35: the bake that ``before`` measures
BASELINE_COMMIT = "eb143f1"

# the child that runs the baseline commit's bake_texture on arrays (argv: input .npz, output .npz, worktree)
_BASELINE_CHILD = r"""
import json, sys, time
from pathlib import Path
from types import SimpleNamespace
import numpy as np
import o3d_seqcc
from o3d_seqcc.texturing import bake_texture

src, dst, tree = sys.argv[1:4]
if not Path(o3d_seqcc.__file__).resolve().is_relative_to(Path(tree).resolve()):
    sys.exit(f"imported {o3d_seqcc.__file__}, not the baseline worktree {tree}")
d = np.load(src)
labels, fuv = d["labels"], d["fuv"]


mesh = SimpleNamespace(vertices=d["vertices"], faces=d["faces"],
                       vertex_normals=d["normals"] if "normals" in d.files else None)
if "vis_uv" in d.files:  # the whole visibility (a bake that reads other views' projections, e.g. to merge charts)
    from o3d_seqcc.scene import Mesh
    from o3d_seqcc.visibility.compute import Visibility

    m = Mesh(vertices=d["vertices"], faces=d["faces"], vertex_normals=d["normals"])
    vis = Visibility.from_arrays(m, d["vis_uv"], d["vis_usable"], area=d["vis_area"], cos_angle=d["vis_cos"])
else:
    class Vis:  # what that commit's bake reads of a visibility: sizes and the selected views' corner projections
        n_views, n_faces = int(d["n_views"]), len(labels)

        def face_uv(self, selection):
            assert np.array_equal(selection, labels)
            return fuv

    vis = Vis()
images = [d[f"image_{i}"] for i in range(int(d["n_views"]))]
t = time.perf_counter()
size = str(d["atlas_size"])
tm = bake_texture(mesh, images, vis, labels, atlas_size=int(size) if size.isdigit() else size, adjacency=d["adjacency"])
seconds = time.perf_counter() - t
np.savez(dst, seconds=seconds, stats=json.dumps(tm.stats, default=str), **{
    k: getattr(tm, k) for k in ("vertices", "faces", "uv", "texture", "normals", "face_view", "vertex_index", "face_chart")})
"""


class Baseline:
    """``commit`` checked out by ``git worktree add`` in a temporary folder; :meth:`bake` runs its bake_texture."""

    def __init__(self, commit: str) -> None:
        sha = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--verify", f"{commit}^{{commit}}"],
                             capture_output=True, text=True)
        if sha.returncode:
            raise SystemExit(f"--baseline-commit {commit}: not a commit of {REPO}: {sha.stderr.strip()}")
        self.commit = sha.stdout.strip()
        self.tmp = Path(tempfile.mkdtemp(prefix="o3d_seqcc_baseline_"))
        self.tree = self.tmp / self.commit[:10]
        subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", "--quiet", str(self.tree), self.commit],
                       check=True)
        self.env = {**os.environ, "PYTHONPATH": str(self.tree)}
        print(f"baseline: {self.commit[:10]} checked out in {self.tree}", flush=True)

    def bake(self, mesh, images, vis, labels, *, adjacency, atlas_size):
        """That commit's ``bake_texture`` on the same arrays: (TexturedMesh, seconds of the bake alone)."""
        from o3d_seqcc.texturing import TexturedMesh

        src, dst = self.tmp / "in.npz", self.tmp / "out.npz"
        normals = getattr(mesh, "vertex_normals", None)
        np.savez(src, vertices=mesh.vertices, faces=mesh.faces, labels=labels, fuv=vis.face_uv(labels),
                 adjacency=adjacency, n_views=len(images), atlas_size=atlas_size, vis_uv=vis.uv,
                 vis_usable=vis.usable, vis_area=vis.area, vis_cos=vis.cos_angle,
                 **({} if normals is None else {"normals": normals}), **{f"image_{i}": im for i, im in enumerate(images)})
        r = subprocess.run([sys.executable, "-c", _BASELINE_CHILD, str(src), str(dst), str(self.tree)], env=self.env,
                           cwd=self.tree, capture_output=True, text=True)  # cwd: `-c` puts it first on sys.path
        if r.returncode:
            raise SystemExit(f"the baseline bake ({self.commit[:10]}) failed:\n{r.stderr[-3000:]}")
        with np.load(dst) as d:
            arrays = {k: d[k] for k in d.files if k not in ("seconds", "stats")}
            seconds, stats = float(d["seconds"]), json.loads(str(d["stats"]))
        return TexturedMesh(**arrays, stats=stats), seconds

    def close(self) -> None:
        subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(self.tree)], check=False)
        import shutil

        shutil.rmtree(self.tmp, ignore_errors=True)

logger = logging.getLogger("benchmarks.atlas")


def used_share(tm) -> float:
    """Share of the atlas within one texel of a triangle (what bilinear lookups inside faces read)."""
    import cv2

    from o3d_seqcc.texturing.bake import edge_texels, rasterize_faces

    H, W = tm.texture.shape[:2]
    txy = tm.texel_xy()
    idx, _, _ = rasterize_faces(txy, tm.faces, H, W)
    eidx, _ = edge_texels(txy, tm.faces, idx, H, W, max_altitude=np.inf)
    m = np.zeros(H * W, np.uint8)
    m[idx] = 1
    m[eidx] = 1
    return float(cv2.dilate(m.reshape(H, W), np.ones((3, 3), np.uint8)).mean())


def coverage(tm) -> float:
    p = tm.texel_xy()[tm.faces]
    a = 0.5 * np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    return float(a.sum() / (tm.texture.shape[0] * tm.texture.shape[1]))


def view_seams(tm, adjacency, wf) -> dict:
    """CIEDE2000 across every edge between seen faces of two different views (inside charts too)."""
    from o3d_seqcc.imaging.arrays import delta_e_2000
    from o3d_seqcc.texturing.leveling import _seam_edge_corners
    from o3d_seqcc.texturing.textured_mesh import sample_texture

    fv = tm.face_view
    a, b = adjacency[:, 0], adjacency[:, 1]
    pairs = adjacency[(fv[a] >= 0) & (fv[b] >= 0) & (fv[a] != fv[b])]
    cp, cq = _seam_edge_corners(wf, pairs)
    txy = tm.texel_xy()
    t = (np.arange(4) + 0.5) / 4
    cols = []
    rows = np.arange(len(pairs))
    for col, cc in ((0, cp), (1, cq)):
        P = txy[tm.faces[pairs[:, col]]]
        e0, e1, third = P[rows, cc[:, 0]], P[rows, cc[:, 1]], P[rows, 3 - cc.sum(axis=1)]
        d = e1 - e0
        n = np.stack([-d[:, 1], d[:, 0]], 1) / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        h = ((third - e0) * n).sum(1)
        off = np.sign(h) * np.minimum(0.5, np.abs(h) / 3.0)
        pts = e0[:, None] + d[:, None] * t[None, :, None] + (off[:, None] * n)[:, None]
        H, W = tm.texture.shape[:2]
        uv = np.stack([(pts[..., 0] + 0.5) / W, 1.0 - (pts[..., 1] + 0.5) / H], -1).reshape(-1, 2)
        cols.append(sample_texture(tm.texture, uv))
    de = delta_e_2000(cols[0], cols[1]).reshape(-1, 4).mean(axis=1)
    return {"view_edges": int(len(pairs)), "view_seam_mean": float(de.mean()), "view_seam_gt5": float((de > 5).mean())}


def measure(path_or_tm, scene, photo, n_in: int, view: int = VIEW) -> dict:
    from o3d_seqcc.evaluation.render import raycast, render_textured, sharpness
    from o3d_seqcc.evaluation.seams import seam_metric
    from o3d_seqcc.texturing import load_textured_mesh
    from o3d_seqcc.texturing.memory import gpu_bytes

    tm = load_textured_mesh(path_or_tm)
    rep = seam_metric(tm)
    h = raycast(tm, scene.views[view])
    img = render_textured(tm, scene.views[view], supersample=3)
    out = {"seam_mean": rep.mean, "seam_gt5": rep.frac_above_5, "seam_edges_gt5": int(round(rep.frac_above_5 * rep.n_edges)),
           "sharpness": sharpness(img, h.mask) / sharpness(photo, h.mask), "vertices": int(len(tm.vertices)),
           "vertex_ratio": len(tm.vertices) / n_in, "coverage": coverage(tm), "used": used_share(tm),
           "atlas": f"{tm.texture.shape[1]}x{tm.texture.shape[0]}",
           "gpu_mib": gpu_bytes(tm.texture.shape[1], tm.texture.shape[0]) / 2**20}
    return out, img


def _fmt(r: dict) -> str:
    glb = r.get("glb_bytes")
    mb = f"{glb / 1e6:6.2f}" if glb else "     -"
    extra = ""
    if "glb_jpg" in r:
        extra = f" (jpg {r['glb_jpg'] / 1e6:.2f}, webp {r['glb_webp'] / 1e6:.2f})"
    vs = f"{r['view_seam_mean']:.3f}/{r['view_seam_gt5']:.4f}" if "view_seam_mean" in r else "-"
    bt = r.get("bake_s")
    return (f"{r['method']:<15} {r['coverage'] * 100:6.1f}% {r['used'] * 100:6.1f}% {r['atlas']:>11} {r.get('pages', 1):5d} "
            f"{r['gpu_mib']:7.1f} "
            f"{mb}{extra:<26} {r['vertex_ratio']:6.3f} {r['seam_mean']:7.4f} {r['seam_gt5']:7.5f} ({r['seam_edges_gt5']:2d}) "
            f"{vs:>15} {r['sharpness']:6.2f} {bt if bt is None else round(bt, 2)!s:>6}")


HEADER = (f"{'method':<15} {'cover':>7} {'used':>7} {'atlas':>11} {'pages':>5} {'GPU MiB':>7} {'GLB MB':>6}{'':<26} {'v out/in':>6} "
          f"{'seams':>7} {'>5':>7} {'(n)':>4} {'view seams/>5':>15} {'sharp':>6} {'bake s':>6}")


def run_mesh(key: str, args, scene, corrected, out: Path, rows: list, notes: list, pictures: dict,
             baseline: Baseline, view: int = VIEW) -> dict:
    from o3d_seqcc.io.export import export_glb
    from o3d_seqcc.io.gltf_validator import find_validator, validate_glb
    from o3d_seqcc.geometry.meshops import face_adjacency, weld_vertices
    from o3d_seqcc.geometry.orientation import up_axis_transform
    from o3d_seqcc.evaluation.seams import mip_bleed
    from o3d_seqcc.texturing import TextureSettings, bake_texture, select_views
    from o3d_seqcc.visibility.compute import compute_visibility

    size = args.atlas_size or MESHES[key][1]
    t = time.perf_counter()
    vis = compute_visibility(scene)
    mesh = vis.mesh
    adj = face_adjacency(mesh.faces, mesh.vertices)
    labels = select_views(vis, method="mrf", adjacency=adj)
    n_in = len(mesh.vertices)
    print(f"\n== {key}: {len(mesh.faces)} faces, {n_in} vertices, {int((labels < 0).sum())} unseen; visibility + "
          f"selection {time.perf_counter() - t:.1f} s; atlas {size}", flush=True)
    wf = weld_vertices(mesh.vertices)[mesh.faces]
    d = out / key
    d.mkdir(parents=True, exist_ok=True)
    times: dict[str, list] = {"ours": [], "shelf": []}
    settings = TextureSettings(atlas_size=size, pack_effort=args.pack_effort,
                               **({} if args.padding is None else {"padding": args.padding}),
                               **({} if args.small_padding is None else {"small_padding": args.small_padding}))
    for r in range(args.repeats):  # alternate: the same load for both
        for name in ("shelf", "ours") if r % 2 else ("ours", "shelf"):
            if name == "ours":
                t = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    tm = bake_texture(mesh, corrected, vis, labels, settings=settings, adjacency=adj)
                times[name].append(time.perf_counter() - t)
            else:  # timed in the child around its bake_texture call alone (not its start-up or the arrays' I/O)
                shelf, seconds = baseline.bake(mesh, corrected, vis, labels, adjacency=adj, atlas_size=size)
                times[name].append(seconds)
    med = {k: statistics.median(v) for k, v in times.items()}
    print(f"bake time, median of {args.repeats} alternating runs: ours {med['ours']:.2f} s, before "
          f"{med['shelf']:.2f} s, ratio {med['ours'] / med['shelf']:.2f} (runs: ours "
          f"{[round(x, 2) for x in times['ours']]}, shelf {[round(x, 2) for x in times['shelf']]})", flush=True)
    st = tm.stats
    ftp = st["face_texels_per_pixel"]
    print(f"ours: {st['pages']} page(s) of {st['page_width']}x{st['page_height']} at {st['texels_per_pixel']:.3f} texels/pixel "
          f"(faces: median {ftp['median']:.3f}, min {ftp['min']:.3f}, p1 {ftp['p1']:.3f}), GPU "
          f"{st['texture_memory']['gpu_bytes'] / 2**20:.1f} MiB "
          f"(density scale {st['density_scale']:.3f}), {st['charts']} charts ({st['merged_tiny_charts']} tiny merged, "
          f"{st['absorbed_faces']} unseen faces absorbed, {st['fallback_charts']} fallback charts), xatlas "
          f"utilization {[round(u, 3) for u in st['xatlas_utilization']]}; pack log {st['pack_log']}")
    print("ours, stage times (last run): " + ", ".join(f"{k[5:-2]} {v:.2f}" for k, v in st.items() if k.startswith("time_")))
    # ours: GLB in the scene frame (measured), Y-up in PNG / JPEG / WebP (shipped sizes, validator)
    R, orient = up_axis_transform(scene, "y")
    glb = export_glb(tm, d / "ours.glb")
    m, img_ours = measure(glb, scene, corrected[view], n_in, view)
    row = {"method": "ours (xatlas)", "mesh": key, "bake_s": med["ours"], "pages": tm.pages, "glb_bytes": glb.stat().st_size,
           **m, **view_seams(tm, adj, wf), "texels_per_pixel": st["texels_per_pixel"],
           "face_texels_per_pixel": st["face_texels_per_pixel"], "pack_log": st["pack_log"]}
    validation = {}
    for fmt in ("png", "jpg", "webp"):
        p = export_glb(tm, d / f"ours_yup_{fmt}.glb", transform=R, texture_format=fmt, quality=90)
        row[f"glb_{fmt}"] = p.stat().st_size
        if find_validator() is not None:
            v = validate_glb(p)
            validation[fmt] = (v["numErrors"], v["numWarnings"])
    row["validator"] = validation
    row["orientation"] = {k: orient[k] for k in ("nearest_axis", "angle_deg", "snapped", "rotation")}
    t = time.perf_counter()
    row["mip_bleed"] = mip_bleed(tm)
    print(f"ours, mip bleed (CIEDE2000 over faces: p99 / share > 2) in {time.perf_counter() - t:.1f} s: " + ", ".join(
        f"level {k} {v['p99']:.3f} / {v['share_gt2'] * 100:.3f} %" for k, v in row["mip_bleed"].items()))
    print(f"ours, Khronos validator (errors, warnings) per texture format of the Y-up GLB: {validation}; up axis: "
          f"{orient['nearest_axis']} ({orient['angle_deg']:.1f} deg off) -> +Y, rotation {np.round(R, 3).tolist()}")
    rows.append(row)
    sm, img_shelf = measure(export_glb(shelf, d / "shelf.glb"), scene, corrected[view], n_in, view)
    rows.append({"method": f"before {baseline.commit[:7]}", "mesh": key, "bake_s": med["shelf"], "pages": 1,
                 "glb_bytes": (d / "shelf.glb").stat().st_size, **sm, **view_seams(shelf, adj, wf),
                 "grew": bool(shelf.stats.get("grew")), "mip_bleed": mip_bleed(shelf, reach=float(4 + 1))})
    pictures[key] = {"ours": img_ours, "before": img_shelf}
    if key == args.yup_mesh:
        pictures["yup"] = yup_picture(tm, R, scene, corrected, d / "ours_yup_png.glb", out / "yup_check.png")
    if key != "room":
        peers(key, args, scene, corrected, size if size != "auto" else tm.atlas_size, d, n_in, rows, notes, pictures)
    return {"tm": tm, "vis": vis, "labels": labels, "adj": adj, "scene": scene}


def _room(out: Path):
    """The synthetic room of ``benchmarks/sharpness.py`` (16 photos of 320 x 240, two rings, seen_only) and its
    photos corrected with the library's defaults: ``(scene, corrected)``."""
    import o3d_seqcc as sc
    from o3d_seqcc.correction import correct

    syn = sc.make_synthetic_scene(out / "room_scene", n_views=16, width=320, height=240, seed=0, layout="two-rings",
                                  seen_only=True, overwrite=True)
    res = correct(syn.scene, reference=syn.scene.names[0])
    return syn.scene, list(res.images)


def yup_picture(tm, R, scene, images, glb: Path, path: Path) -> Path:
    """The Y-up GLB rendered by a Y-up viewer's camera (at the reference view, no roll) next to the photo."""
    import cv2

    from o3d_seqcc.evaluation.render import render_textured
    from o3d_seqcc.scene import View

    v = scene.views[VIEW]
    Rw = v.extrinsic[:3, :3]
    centre = R @ (-Rw.T @ v.extrinsic[:3, 3])
    fwd = R @ Rw[2]
    down = np.array([0.0, -1.0, 0.0]) - (np.array([0.0, -1.0, 0.0]) @ fwd) * fwd
    down /= np.linalg.norm(down)
    E = np.eye(4)
    E[:3, :3] = np.stack([np.cross(down, fwd), down, fwd])
    E[:3, 3] = -E[:3, :3] @ centre
    view = View(name="yup", image=None, intrinsic=v.intrinsic, extrinsic=E, width=v.width, height=v.height,
                pixels=images[VIEW])
    render = render_textured(glb, view)
    # from above: looking down -Y at the mesh centre
    V = tm.vertices @ R.T
    c = 0.5 * (V.min(0) + V.max(0))
    ext = float(np.linalg.norm(V.max(0) - V.min(0)))
    eye = c + np.array([0.0, 1.2 * ext, 0.0])
    fw = np.array([0.0, -1.0, 0.0])
    toward_cams = fwd.copy()
    toward_cams[1] = 0.0
    dn = toward_cams / max(np.linalg.norm(toward_cams), 1e-12)  # image down: towards where the photographers stood
    E2 = np.eye(4)
    E2[:3, :3] = np.stack([np.cross(dn, fw), dn, fw])
    E2[:3, 3] = -E2[:3, :3] @ eye
    K = np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1.0]])
    above = render_textured(glb, View(name="above", image=None, intrinsic=K, extrinsic=E2, width=640, height=480,
                                      pixels=np.zeros((480, 640, 3), np.uint8)))
    tiles = [render, images[VIEW], above]
    tiles = [cv2.resize(t_, (640, 480)) for t_ in tiles]
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.concatenate(tiles, axis=1)[..., ::-1])
    return path


def peers(key, args, scene, corrected, size, d, n_in, rows, notes, pictures) -> None:
    from peers import meshlab_available, run_meshlab, run_open3d

    run_peers = key == "dec" or args.peers_300k
    if not run_peers:
        notes.append(f"{key}: peers skipped (--peers-300k runs them)")
        return
    reason = "--no-meshlab" if args.no_meshlab else meshlab_available()
    if reason:
        notes.append(f"{key}: MeshLab skipped: {reason}")
    else:
        try:
            r = run_meshlab(scene, d / "meshlab", images=corrected, texture_size=size, overwrite=True)
            m, img = measure(r.mesh, scene, corrected[VIEW], n_in)
            rows.append({"method": "meshlab", "mesh": key, "bake_s": r.seconds, "pages": 1, "glb_bytes": None, **m})
            pictures[key]["meshlab"] = img
        except RuntimeError as e:
            notes.append(f"{key}: MeshLab failed: {e}")
    if not args.no_open3d:
        try:
            r = run_open3d(scene, d / "open3d", images=corrected, texture_size=size, overwrite=True)
        except RuntimeError as e:  # compute_uvatlas refuses some meshes (e.g. the 300k one: non-manifold)
            notes.append(f"{key}: Open3D failed: {str(e).strip()[-160:]}")
            return
        m, img = measure(r.mesh, scene, corrected[VIEW], n_in)
        rows.append({"method": "open3d", "mesh": key, "bake_s": r.seconds, "pages": 1, "glb_bytes": None, **m})
        pictures[key]["open3d"] = img


def evidence(ctx: dict, corrected, args, out: Path) -> list[dict]:
    """Coverage against the other constraints on the decimated mesh, at a 2048 atlas."""
    import xatlas

    from o3d_seqcc.geometry.meshops import vertex_normals, weld_vertices
    from o3d_seqcc.evaluation.seams import mip_bleed, seam_metric
    from o3d_seqcc.texturing import bake_texture
    from o3d_seqcc.texturing.charts import build_charts

    vis, labels, adj = ctx["vis"], ctx["labels"], ctx["adj"]
    mesh = vis.mesh
    res = []
    print("\n== coverage evidence (fountain decimated, 2048): library bakes with other settings")
    print(f"{'setting':<34} {'cover':>7} {'t/px':>6} {'mip L2 p99':>10} {'L3 p99':>7} {'seams':>7} {'>5':>4} {'bake s':>7}")
    for name, opts in (("default (padding 4, merge 3)", {}), ("padding 2", {"padding": 2}), ("padding 1", {"padding": 1}),
                       ("merge_charts 0", {"merge_charts": 0}), ("merge_charts 20", {"merge_charts": 20})):
        t = time.perf_counter()
        tm = bake_texture(mesh, corrected, vis, labels, adjacency=adj, atlas_size=2048, **opts)
        dt = time.perf_counter() - t
        mb = mip_bleed(tm, levels=(2, 3))
        sm = seam_metric(tm)
        n5 = int(round(sm.frac_above_5 * sm.n_edges))
        r = {"setting": name, "coverage": tm.stats["coverage"], "texels_per_pixel": tm.stats["texels_per_pixel"],
             "mip2_p99": mb[2]["p99"], "mip3_p99": mb[3]["p99"], "seam_mean": sm.mean, "seam_n_gt5": n5, "bake_s": dt}
        res.append(r)
        print(f"{name:<34} {r['coverage'] * 100:6.1f}% {r['texels_per_pixel']:6.3f} {r['mip2_p99']:10.3f} "
              f"{r['mip3_p99']:7.3f} {r['seam_mean']:7.4f} {n5:4d} {dt:7.2f}", flush=True)
    # xatlas alone on the default charts: the densest single 2048 page found by raising the density
    # 2 % at a time from the library's choice (xatlas' random placement is not monotonic in t)
    normals = vertex_normals(mesh.vertices, mesh.faces, getattr(mesh, "vertex_normals", None))
    cs = build_charts(np.asarray(mesh.vertices, float), np.asarray(mesh.faces), normals, labels,
                      vis.face_uv(labels), vis, adj, wpos=weld_vertices(mesh.vertices))
    p = cs.uv[cs.faces]
    a_src = float((0.5 * np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                                - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))).sum())

    def pack(t, padding, brute, block):
        at = xatlas.Atlas()
        at.add_uv_mesh(cs.uv.astype(np.float32), cs.faces.astype(np.uint32), cs.face_chart.astype(np.uint32).reshape(-1, 1))
        po = xatlas.PackOptions()
        po.texels_per_unit, po.resolution, po.padding = float(t), 2048, int(padding)
        po.bilinear, po.rotate_charts, po.rotate_charts_to_axis = True, True, True
        po.bruteForce, po.blockAlign = bool(brute), bool(block)
        at.generate(xatlas.ChartOptions(), po)
        return at.atlas_count

    print("xatlas placement alone, densest single 2048 page (density raised 2 % per try until two pages):")
    configs = [("random, padding 4", 4, False, False), ("random, padding 2", 2, False, False),
               ("random, padding 1", 1, False, False), ("random, padding 4, blockAlign", 4, False, True)]
    if args.evidence_brute:
        configs += [("brute force, padding 4", 4, True, False), ("brute force, padding 2", 2, True, False)]
    t0 = ctx["tm"].stats["texels_per_pixel"] * 0.97
    for name, pad, brute, block in configs:
        t, best, tries, tt = t0, None, 0, time.perf_counter()
        while tries < 12:
            tries += 1
            if pack(t, pad, brute, block) == 1:
                best = t
                t *= 1.02
            elif best is not None:
                break
            else:
                t *= 0.97
        cov = a_src * best * best / 2048 ** 2 if best else float("nan")
        r = {"setting": f"xatlas {name}", "coverage": cov, "texels_per_pixel": best, "tries": tries,
             "seconds": time.perf_counter() - tt}
        res.append(r)
        print(f"  {name:<32} {cov * 100:6.1f}%  at {best:.3f} texels/pixel ({tries} packs, {r['seconds']:.1f} s)", flush=True)
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="/tmp/o3d_seqcc_atlas", help="output folder (overwritten)")
    ap.add_argument("--meshes", default="dec,300k,room", help="any of dec, 300k, room")
    ap.add_argument("--atlas-size", type=lambda v: v if v == "auto" else int(v), default=None,
                    help="the atlas size, auto or a budget N (default: the library's, auto)")
    ap.add_argument("--pack-effort", choices=("fast", "best"), default="fast", help="ours: the packing effort")
    ap.add_argument("--padding", type=int, default=None, help="ours: the charts' gutter (default: the library's, 4)")
    ap.add_argument("--small-padding", type=int, default=None,
                    help="ours: the small charts' gutter in their block (default: the library's, 1)")
    ap.add_argument("--repeats", type=int, default=3, help="alternating bake runs of ours and before (median)")
    ap.add_argument("--no-meshlab", action="store_true")
    ap.add_argument("--no-open3d", action="store_true")
    ap.add_argument("--peers-300k", action="store_true", help="also run MeshLab and Open3D on the 300k mesh (slow)")
    ap.add_argument("--yup-mesh", default="dec", help="mesh of the Y-up picture")
    ap.add_argument("--evidence", action="store_true", help="coverage against padding / merging / placement")
    ap.add_argument("--evidence-brute", action="store_true", help="with --evidence: xatlas brute-force placement (slow)")
    ap.add_argument("--baseline-commit", default=BASELINE_COMMIT, metavar="SHA",
                    help=f"the commit whose bake is the 'before' row (default {BASELINE_COMMIT}, main before "
                         "issue 35), run from a temporary git worktree")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    if not (DATA / "scene" / "key.log").is_file():
        print(f"fountain data not found at {DATA}", file=sys.stderr)
        return 1
    from o3d_seqcc import load_scene
    from o3d_seqcc.correction import correct
    from o3d_seqcc.io.images import write_image
    from o3d_seqcc.io.json_files import write_json

    baseline = Baseline(args.baseline_commit)  # first: a wrong SHA stops before any work
    atexit.register(baseline.close)  # the worktree goes however the run ends
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scene = load_scene(DATA, mesh=DATA / MESHES["dec"][0])
    t = time.perf_counter()
    res = correct(scene, reference="auto")
    corrected = list(res.images)
    notes = [f"corrected: {res.method}, reference {scene.names[res.reference]}, {time.perf_counter() - t:.1f} s"]
    rows: list[dict] = []
    pictures: dict = {}
    ctx = {}
    notes.append(f"before: the bake of {baseline.commit[:10]}, from a git worktree of that commit")
    for key in [k.strip() for k in args.meshes.split(",") if k.strip()]:
        if key == "room":
            room, room_corrected = _room(out)
            ctx[key] = run_mesh(key, args, room, room_corrected, out, rows, notes, pictures, baseline, ROOM_VIEW)
        else:
            ctx[key] = run_mesh(key, args, load_scene(DATA, mesh=DATA / MESHES[key][0]), corrected, out, rows, notes,
                                pictures, baseline)
    ev = evidence(ctx["dec"], corrected, args, out) if args.evidence and "dec" in ctx else []
    print()
    for key in ctx:
        print(f"{key} (atlas {args.atlas_size or MESHES[key][1]}):")
        print(HEADER)
        print("-" * len(HEADER))
        for r in rows:
            if r["mesh"] == key:
                print(_fmt(r))
        o = next(r for r in rows if r["mesh"] == key and r["method"].startswith("ours"))
        s = next(r for r in rows if r["mesh"] == key and r["method"].startswith("before"))
        print(f"  ours / before: bake time {o['bake_s'] / s['bake_s']:.2f}x, coverage {o['coverage'] / s['coverage']:.2f}x, "
              f"GLB {o['glb_bytes'] / s['glb_bytes']:.2f}x, GPU memory {o['gpu_mib'] / s['gpu_mib']:.2f}x, sharpness "
              f"{o['sharpness'] / s['sharpness']:.3f}x, vertices {o['vertices'] / s['vertices']:.2f}x")
        print("  ours mip bleed p99 L1/L2/L3: " + " / ".join(f"{v['p99']:.3f}" for v in o["mip_bleed"].values())
              + "; before: " + " / ".join(f"{v['p99']:.3f}" for v in s["mip_bleed"].values()))
        print()
    print("(cover: triangle texels / atlas texels; used: texels within 1 texel of a triangle; v out/in: output / input "
          "vertices; seams: seam-metric mean, >5: share of edges above 5 (n: count); view seams: mean and share > 5 "
          "over edges between two views, inside charts too; sharp: render / photo sharpness at view 16; bake s: "
          "ours and before median of alternating runs, peers their filter)")
    for n in notes:
        print("note:", n)
    import cv2

    for key, imgs in pictures.items():
        if key == "yup":
            print(f"Y-up picture (Y-up viewer camera at view {VIEW} | photo | from above): {imgs}")
            continue
        tiles = [cv2.putText(np.ascontiguousarray(im.copy()), name, (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 255, 255), 2)
                 for name, im in imgs.items()]
        write_image(out / f"renders_{key}.png", np.concatenate(tiles, axis=1))
    write_json(out / "results.json", {"rows": rows, "evidence": ev, "notes": notes})
    print(f"wrote {out / 'results.json'}, renders_*.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
