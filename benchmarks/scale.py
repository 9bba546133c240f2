"""Scale benchmark (issue 15): time and peak memory per stage against views and faces, local and on Dask.

A synthetic street (:func:`make_street`): one long building front with recessed windows and a
pavement, textured procedurally (bricks, window frames, per-brick colour noise), photographed
by ``n_views`` 640x480 cameras walking along it 1 m apart, 7 m away, at alternating heights and
yaws, each with a camera-like photometric change (:func:`o3d_seqcc.evaluation.photometric.sample_photometric`)
and a depth map. The street is as long as the walk (a larger capture covers a larger site, as
in practice), and the mesh has ``n_faces`` faces (85 % facade, 15 % pavement), so the faces a
view sees shrink as the site grows at a fixed face count. Scenes are written to a temporary
folder (``--tmp``, default the system's), never into the repository, and removed afterwards.

Every configuration runs ``o3d_seqcc.pipeline.run`` + ``RunResult.save`` (the command line's
defaults: vertices mappings, seqcc, mrf selection, leveled atlas, GLB + OBJ) in a fresh child
process, so runs do not share caches or memory; a sampling thread (psutil, every 10 ms) records
the peak resident memory of the child per stage (``o3d_seqcc._shared.progress.on_stage``), and on the
cluster backend (a ``dask.distributed.LocalCluster`` of 2 worker processes, 1 thread each,
started and warmed up before the clock starts) that of every worker process too.

Run::

    .venv/bin/python benchmarks/scale.py                       # 50/100/200 views x 250k/1M faces, both backends
    .venv/bin/python benchmarks/scale.py --views 50 --faces 250k --backends local   # one quick point
    .venv/bin/python benchmarks/scale.py --views 10,30 --faces 100k,400k --sizes 0.3,1.2 --backends local
    .venv/bin/python benchmarks/scale.py --views 10 --faces 400k --backends cluster --memory-limit 3GB

``--sizes`` grids the photo size too (megapixels at 4:3: 0.3 is 640 x 480, 12 is 4000 x 3000; the same field
of view), ``--memory-limit`` is the cluster workers' ``memory_limit``. Prints one line per run and a summary
with the log-log slopes of run time and of peak RSS against views, faces and photo size (the others fixed)
and the peak memory at the largest configuration; writes ``docs/scale.png`` (log-log plots, the smallest
photos) and the raw figures as JSON (``--json``).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
W, H = 640, 480
SPACING, DIST, FACADE_H, MARGIN = 1.0, 7.0, 6.0, 10.0
STAGES = ("visibility", "mappings", "correction", "selection", "bake", "seams", "export")


# --------------------------------------------------------------------------------------------
# the street
# --------------------------------------------------------------------------------------------


def _grid(nx: int, ny: int) -> np.ndarray:
    """(2 nx ny, 3) faces of an (nx+1) x (ny+1) vertex grid, x fastest."""
    idx = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    return np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


def _windows(x: np.ndarray, z: np.ndarray) -> np.ndarray:
    """True inside a window (1.2 m wide, 1.5 m high, every 3 m, two storeys)."""
    fx = np.mod(x, 3.0)
    storey = np.floor(z / 3.0)
    fz = z - 3.0 * storey
    return (fx > 0.9) & (fx < 2.1) & (fz > 0.8) & (fz < 2.3) & (storey < 2)


def street_mesh(length: float, n_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of the building front (y = 0, facing +y, windows 0.25 m deep) and pavement."""
    n_front = int(0.85 * n_faces) // 2
    ny = max(2, int(round(np.sqrt(n_front * FACADE_H / length))))
    nx = max(2, n_front // ny)
    xs, zs = np.linspace(0.0, length, nx + 1), np.linspace(0.0, FACADE_H, ny + 1)
    X, Z = np.meshgrid(xs, zs)
    Y = np.where(_windows(X, Z), -0.25, 0.0)  # recessed windows: oblique reveals and occlusions
    front = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
    f_front = _grid(nx, ny)[:, [0, 2, 1]]  # wound to face +y
    n_pave = max(2, (n_faces - len(f_front)) // 2)
    py = max(1, int(round(np.sqrt(n_pave * (DIST + 3.0) / length))))
    px = max(1, n_pave // py)
    PX, PY = np.meshgrid(np.linspace(0.0, length, px + 1), np.linspace(0.0, DIST + 3.0, py + 1))
    pave = np.stack([PX.ravel(), PY.ravel(), np.zeros(PX.size)], 1)
    f_pave = _grid(px, py) + len(front)  # faces +z
    return np.concatenate([front, pave]), np.concatenate([f_front, f_pave])


def _albedo(P: np.ndarray, rng_table: np.ndarray) -> np.ndarray:
    """(n, 3) float colours of world points: bricks with per-brick noise, dark windows, grey pavement."""
    x, y, z = P[:, 0], P[:, 1], P[:, 2]
    row = np.floor(z / 0.08).astype(np.int64)
    col = np.floor((x + 0.12 * (row % 2)) / 0.24).astype(np.int64)
    h = rng_table[(row * 7919 + col * 104729) % len(rng_table)]
    brick = np.stack([0.55 + 0.25 * h[:, 0], 0.28 + 0.15 * h[:, 1], 0.18 + 0.12 * h[:, 2]], 1)
    mortar = (np.mod(z, 0.08) < 0.012) | (np.mod(x + 0.12 * (row % 2), 0.24) < 0.012)
    brick[mortar] = 0.75
    win = _windows(x, z) | (y < -0.01)
    brick[win] = np.stack([0.10 + 0.1 * h[win, 0], 0.16 + 0.1 * h[win, 1], 0.25 + 0.15 * h[win, 2]], 1)
    ground = z < 1e-6
    g = 0.35 + 0.1 * h[ground, 0][:, None] + 0.25 * (np.mod(x[ground], 4.0) < 0.15)[:, None]
    brick[ground] = np.clip(g, 0, 1) * np.array([1.0, 1.0, 0.97])
    return np.clip(brick, 0.0, 1.0)


def make_street(out: Path, n_views: int, n_faces: int, *, seed: int = 0, width: int = W, height: int = H) -> Path:
    """Write a street scene (see the module docstring) to ``out``, photos of ``width`` x ``height`` (the 640 x 480
    camera's field of view at any size); returns its ``scene.json``."""
    import cv2
    import open3d as o3d
    import open3d.core as o3c

    from o3d_seqcc import Scene, View, save_scene
    from o3d_seqcc.evaluation.photometric import apply_photometric, identity_photometric, sample_photometric
    from o3d_seqcc.synthetic.room import look_extrinsic

    rng = np.random.default_rng(seed)
    out = Path(out)
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "depth").mkdir(exist_ok=True)
    length = n_views * SPACING + 2 * MARGIN
    V, F = street_mesh(length, n_faces)
    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32)))
    m.compute_vertex_normals()
    o3d.io.write_triangle_mesh(str(out / "mesh.ply"), m, write_ascii=False)
    rs = o3d.t.geometry.RaycastingScene()
    rs.add_triangles(o3c.Tensor(V.astype(np.float32)), o3c.Tensor(F.astype(np.uint32)))
    W, H = int(width), int(height)  # noqa: N806 - the module's names for a photo's size
    f = 525.0 * W / 640.0
    K = np.array([[f, 0.0, (W - 1) / 2], [0.0, f, (H - 1) / 2], [0.0, 0.0, 1.0]])
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    d_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1).reshape(-1, 3)
    table = rng.random((4096, 3))
    views = []
    for i in range(n_views):
        c = np.array([MARGIN + i * SPACING + rng.uniform(-0.2, 0.2), DIST + rng.uniform(-0.5, 0.5),
                      1.6 + 1.2 * (i % 3) + rng.uniform(-0.1, 0.1)])
        yaw = np.deg2rad(rng.uniform(-15, 15))
        E = look_extrinsic(c, np.pi / 2 + yaw - np.pi, np.deg2rad(rng.uniform(-5, 10)), 0.0)
        R = E[:3, :3]
        d = d_cam @ R
        ans = rs.cast_rays(o3c.Tensor(np.concatenate([np.broadcast_to(c, d.shape), d], 1).astype(np.float32)))
        th = ans["t_hit"].numpy().astype(np.float64)
        hit = np.isfinite(th)
        col = np.full((H * W, 3), 0.8)  # sky
        col[hit] = _albedo(c + d[hit] * th[hit, None], table)
        prm = identity_photometric() if i == 0 else sample_photometric(rng)
        img = np.clip(np.rint(apply_photometric(col.reshape(H, W, 3), prm) * 255), 0, 255).astype(np.uint8)
        name = f"v{i:04d}"
        cv2.imwrite(str(out / "images" / f"{name}.png"), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
        depth = np.where(hit, th, 0.0).reshape(H, W)  # ray parameter = camera z (d_cam has z = 1)
        cv2.imwrite(str(out / "depth" / f"{name}.png"), np.clip(np.rint(depth * 1000), 0, 65535).astype(np.uint16))
        views.append(View(name=name, image=out / "images" / f"{name}.png", intrinsic=K, extrinsic=E, width=W,
                          height=H, depth=out / "depth" / f"{name}.png", depth_scale=1000.0))
    save_scene(Scene(out / "mesh.ply", tuple(views)), out / "scene.json")
    return out / "scene.json"


# --------------------------------------------------------------------------------------------
# one run, in a child process
# --------------------------------------------------------------------------------------------


class _Sampler:
    """Peak RSS (MB) of this process and of its child processes, per pipeline stage."""

    def __init__(self, watch_children: bool) -> None:
        import psutil

        self.me = psutil.Process()
        self.watch = watch_children
        self.stage = "setup"
        self.peak: dict[str, float] = {}
        self.peak_workers: dict[str, float] = {}
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)

    def on_stage(self, name: str, event: str, _t: float) -> None:
        self.sample()
        self.stage = name if event == "start" else "between"

    def sample(self) -> None:
        rss = self.me.memory_info().rss / 2**20
        self.peak[self.stage] = max(self.peak.get(self.stage, 0.0), rss)
        if self.watch:
            for p in self.me.children(recursive=True):
                try:
                    w = p.memory_info().rss / 2**20
                except Exception:  # the process ended meanwhile
                    continue
                self.peak_workers[self.stage] = max(self.peak_workers.get(self.stage, 0.0), w)

    def _run(self) -> None:
        while not self._stop.wait(0.01):
            self.sample()

    def __enter__(self) -> "_Sampler":
        self._t.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._t.join()


def _warm() -> None:
    import open3d  # noqa: F401
    import sklearn.svm  # noqa: F401

    import o3d_seqcc.correction  # noqa: F401
    import o3d_seqcc.visibility.per_view  # noqa: F401


def child(scene: str, backend: str, out: str, memory_limit: str = "auto") -> dict:
    """One run of the pipeline on ``scene``; returns the figures (printed as JSON by ``--child``)."""
    import logging

    import o3d_seqcc as sc
    from o3d_seqcc._shared.parallel import use as use_executor
    from o3d_seqcc._shared.progress import on_stage

    logging.getLogger("o3d_seqcc").setLevel(logging.ERROR)
    client = cluster = None
    if backend == "cluster":
        from dask.distributed import Client, LocalCluster

        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                               silence_logs=logging.ERROR, memory_limit=memory_limit)
        client = Client(cluster)
        client.run(_warm)
    _warm()
    fig: dict = {"backend": backend}
    with _Sampler(watch_children=backend == "cluster") as smp, on_stage(smp.on_stage):
        t0 = time.perf_counter()
        res = sc.pipeline.run(scene, client=client)
        with use_executor(client):
            res.save(out, overwrite=True)
        fig["wall_s"] = time.perf_counter() - t0
    fig["stages_s"] = {k: round(res.timings.get(k, 0.0), 3) for k in STAGES}
    fig["peak_rss_mb"] = {k: round(v) for k, v in smp.peak.items()}
    fig["peak_worker_rss_mb"] = {k: round(v) for k, v in smp.peak_workers.items()}
    fig["ru_maxrss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    fig["faces"] = int(res.visibility.n_faces)
    fig["views"] = int(res.visibility.n_views)
    fig["usable_incidences"] = int(res.visibility.stats["usable"])
    fig["records_mb"] = round(res.visibility.nbytes / 2**20, 1)
    fig["atlas"] = int(res.textured.atlas_size)
    fig["graph_edges"] = len(res.correction.graph_edges)
    if client is not None:
        client.close()
        cluster.close()
    return fig


# --------------------------------------------------------------------------------------------
# driver
# --------------------------------------------------------------------------------------------


def reference_timing(sizes=(400, 1000), seed: int = 0) -> None:
    """Time ``reference="auto"`` (graph + choice + paths) against an explicit reference (graph + paths)
    on street-like overlap graphs: every view shares mappings with its 8 neighbours on each side."""
    from o3d_seqcc.correction.graph import build_graph, choose_reference, correction_paths

    rng = np.random.default_rng(seed)
    choose_reference(build_graph({(0, 1): 500, (1, 2): 500}, 3, t_npm=400))  # imports (SciPy's Dijkstra) not timed
    for n in sizes:
        counts = {(a, a + d): int(rng.integers(400, 40000) // d) for a in range(n) for d in range(1, 9) if a + d < n}
        t = time.perf_counter()
        g = build_graph(counts, n, t_npm=400)
        ref = choose_reference(g)
        correction_paths(g, ref)
        t_auto = time.perf_counter() - t
        t = time.perf_counter()
        g = build_graph(counts, n, t_npm=400)
        correction_paths(g, 0)
        t_fixed = time.perf_counter() - t
        print(f"reference='auto' on a {n}-view street graph ({g.number_of_edges()} edges): {t_auto:.3f} s; explicit "
              f"reference {t_fixed:.3f} s (ratio {t_auto / max(t_fixed, 1e-9):.1f}x)", flush=True)


def _same_outputs(a: Path, b: Path) -> dict:
    """Whether two run folders hold the same selection, texture, GLB bytes and Table 2 (the cluster's against the
    local run)."""
    import hashlib

    import cv2

    sel = bool(np.array_equal(np.load(a / "selection.npy"), np.load(b / "selection.npy")))
    ta, tb = (cv2.imread(str(p / "mesh.png"), cv2.IMREAD_UNCHANGED) for p in (a, b))
    tex = ta is not None and tb is not None and ta.shape == tb.shape and bool(np.array_equal(ta, tb))
    ma, mb = (json.loads((p / "report.json").read_text()).get("metrics") for p in (a, b))
    ga, gb = (hashlib.sha256((p / "mesh.glb").read_bytes()).hexdigest() if (p / "mesh.glb").is_file() else None
              for p in (a, b))
    return {"selection": sel, "texture": tex, "glb": ga is not None and ga == gb, "table2": ma == mb}


def _faces(s: str) -> int:
    s = s.strip().lower()
    return int(float(s[:-1]) * (1000 if s.endswith("k") else 10**6)) if s[-1] in "km" else int(s)


def _slope(x: list[float], y: list[float]) -> float:
    return float(np.polyfit(np.log(x), np.log(y), 1)[0]) if len(x) >= 2 else float("nan")


def plot(results: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(11, 8.5))
    faces = sorted({r["faces_target"] for r in results})
    views = sorted({r["views"] for r in results})
    for backend, ls in (("local", "-"), ("cluster", "--")):
        # column 0: against views at a fixed face count; column 1: against faces at a fixed view count
        for col, group, x, values, fmt in ((0, "faces_target", "views", faces, lambda F: f"{F / 1e6:g}M faces"),
                                           (1, "views", "faces", views, lambda V: f"{V} views")):
            for g in values:
                rs = sorted((r for r in results if r["backend"] == backend and r[group] == g), key=lambda r: r[x])
                if not rs:
                    continue
                lab = f"{backend}, {fmt(g)}"
                xs = [r[x] for r in rs]
                ax[0, col].plot(xs, [r["wall_s"] for r in rs], ls, marker="o", label=lab)
                ax[1, col].plot(xs, [r["peak_mb"] for r in rs], ls, marker="o", label=lab + " (client)")
                if backend == "cluster":
                    ax[1, col].plot(xs, [r["worker_mb"] for r in rs], ":", marker="s", label=lab + " (per worker)")
    titles = [["run time vs views", "run time vs faces"], ["peak RSS vs views", "peak RSS vs faces"]]
    for i in range(2):
        for j in range(2):
            a = ax[i, j]
            a.set_xscale("log")
            a.set_yscale("log")
            a.set_title(titles[i][j])
            a.set_xlabel("views" if j == 0 else "faces")
            a.set_ylabel("seconds (pipeline.run + save)" if i == 0 else "MB")
            a.grid(True, which="both", alpha=0.3)
            a.legend(fontsize=7)
    fig.suptitle("o3d_seqcc on a synthetic street (640x480 photos), 2 cores; benchmarks/scale.py", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--views", default="50,100,200")
    p.add_argument("--faces", default="250k,1M")
    p.add_argument("--sizes", default="0.3", help="photo sizes in megapixels (4:3; 0.3 is 640x480), e.g. 0.3,3,12")
    p.add_argument("--memory-limit", default="auto",
                   help="the cluster's memory_limit per worker (dask: e.g. 4GB; auto: the machine's share)")
    p.add_argument("--backends", default="local,cluster")
    p.add_argument("--tmp", default=None, help="folder for the generated scenes (default: the system's temp)")
    p.add_argument("--plot", default=str(REPO / "docs" / "scale.png"))
    p.add_argument("--json", default=None, help="also write the figures to this JSON file")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--child", nargs=3, metavar=("SCENE", "BACKEND", "OUT"), help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        print("RESULT " + json.dumps(child(*args.child, memory_limit=args.memory_limit)), flush=True)
        return 0
    reference_timing()
    results = []
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)}
    grid = [(F, V, mp) for mp in [float(s) for s in args.sizes.split(",")] for F in [_faces(s) for s in args.faces.split(",")]
            for V in [int(s) for s in args.views.split(",")]]
    for F, V, mp in grid:
        w = int(16 * round(np.sqrt(mp * 1e6 * 4 / 3) / 16))  # 0.3 -> 640 x 480, 3 -> 2000 x 1500, 12 -> 4000 x 3000
        h = w * 3 // 4
        tmp = Path(tempfile.mkdtemp(prefix="o3d_seqcc_scale_", dir=args.tmp))
        try:
            t = time.perf_counter()
            scene = make_street(tmp / "scene", V, F, seed=args.seed, width=w, height=h)
            t_gen = time.perf_counter() - t
            for backend in args.backends.split(","):
                cmd = [sys.executable, __file__, "--child", str(scene), backend, str(tmp / f"out_{backend}"),
                       "--memory-limit", args.memory_limit]
                proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
                line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")), None)
                if proc.returncode or line is None:
                    print(f"{V} views x {F} faces, {backend}: FAILED\n{proc.stderr[-3000:]}")
                    continue
                r = json.loads(line[7:])
                r["faces_target"] = F
                r["mp"], r["photo"] = mp, f"{w}x{h}"
                r["peak_mb"] = max(r["peak_rss_mb"].values())
                r["worker_mb"] = max(r["peak_worker_rss_mb"].values(), default=0)
                results.append(r)
                stage = " ".join(f"{k} {r['stages_s'][k]:.1f}" for k in STAGES)
                mem = " ".join(f"{k} {v}" for k, v in r["peak_rss_mb"].items())
                wmem = " ".join(f"{k} {v}" for k, v in r["peak_worker_rss_mb"].items())
                print(f"{V:4d} views of {w}x{h} x {r['faces']:8d} faces ({backend:7s}): run+save {r['wall_s']:6.1f} s "
                      f"[{stage}]; peak RSS {r['peak_mb']} MB [{mem}]"
                      + (f"; per worker {r['worker_mb']} MB [{wmem}]" if wmem else "")
                      + f"; {r['usable_incidences']} usable face-views, records {r['records_mb']} MB, "
                      f"atlas {r['atlas']}, scene generated in {t_gen:.0f} s", flush=True)
            if (tmp / "out_local").is_dir() and (tmp / "out_cluster").is_dir():
                same = _same_outputs(tmp / "out_local", tmp / "out_cluster")
                for r in results[-2:]:
                    r["cluster_same_as_local"] = same
                print(f"     cluster outputs against local: {same}", flush=True)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    if not results:
        return 1
    print("\nsummary (log-log slopes of run time and of peak RSS against views, faces and photo size, the others "
          "fixed; <= 1 is at most linear)")
    for backend in sorted({r["backend"] for r in results}):
        rs = [r for r in results if r["backend"] == backend]
        for x, fixed, unit in (("views", ("faces_target", "mp"), "views"), ("faces", ("views", "mp"), "faces"),
                               ("mp", ("faces_target", "views"), "MP")):
            for key in sorted({tuple(r[k] for k in fixed) for r in rs}):
                s = sorted((r for r in rs if tuple(r[k] for k in fixed) == key), key=lambda r: r[x])
                if len(s) < 2:
                    continue
                xs = [r[x] for r in s]
                at = ", ".join(f"{k} {v:g}" for k, v in zip(fixed, key))
                pts = ", ".join(f"{r[x]:g}: {r['wall_s']:.1f} s / {r['peak_mb']} MB" for r in s)
                print(f"  {backend:7s} against {unit} ({at}): time slope {_slope(xs, [r['wall_s'] for r in s]):.2f}, "
                      f"peak RSS slope {_slope(xs, [r['peak_mb'] for r in s]):.2f} ({pts})")
        big = max(rs, key=lambda r: (r["views"] * r["mp"], r["faces"]))
        print(f"  {backend:7s} largest ({big['views']} views of {big['photo']} x {big['faces']} faces): peak RSS "
              f"{big['peak_mb']} MB" + (f", per worker {big['worker_mb']} MB" if backend == "cluster" else ""))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    first = [r for r in results if r["mp"] == min(r_["mp"] for r_ in results)]  # the plot: the smallest photos
    if args.plot and len(first) > 1:
        plot(first, Path(args.plot))
        print(f"plot: {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
