"""Where the seconds and the megabytes of ``o3d-seqcc run`` go: per stage and per fixed cost (issue 21).

Each scene is run as ``o3d-seqcc run SCENE --out OUT --overwrite`` (the command line's defaults)
in a fresh child process, started through :func:`benchmarks.peers.run_measured` (wall time, CPU
time and peak RSS of the whole process, as ``/usr/bin/time`` reports them). Inside the child a
recorder (this file's ``_child`` entry, which then calls the command's own ``main``) notes:

- ``start-up``: from the process's start (``/proc/self/stat``) to the command's ``main``: the
  interpreter and the imports of the command line;
- ``load``: ``load_scene`` (reading the cameras and the mesh, the camera check);
- the pipeline's stages as :func:`o3d_seqcc._shared.progress.on_stage` reports them (visibility,
  mappings, correction, selection, bake, seams, export; the report is written inside
  ``export`` and shown on its own line from ``report.json``'s ``timings_s``);
- ``exit``: the command's end to the process's end (interpreter shutdown, threads joined).

For every span: wall seconds, CPU seconds of the whole process (``os.times``: all threads), so
``CPU / wall`` says how many of the cores it kept busy, and the peak RSS sampled every 10 ms
(``/proc/self/statm``). Imports that happen inside a stage (a module first used there) are in
that stage; ``--importtime`` also prints the slowest top-level imports of the command
(``python -X importtime``).

Scenes: ``16k`` and ``300k`` (Fountain, ``../shared/datasets/fountain_small``, the two meshes
of ``benchmarks/peers.py``) and ``6mp`` (a synthetic room, 10 photos of 3000 x 2000, made once
with ``o3d-seqcc synthetic --views 10 --width 3000 --height 2000 --seen-only`` under ``--tmp``).

Run::

    python benchmarks/profile_run.py                      # 16k, 300k, 6mp
    python benchmarks/profile_run.py --scenes 16k --repeat 3 --json prof.json
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "datasets" / "fountain_small"
FOUNTAIN_MESHES = {"16k": "scene/mesh_decimated_uv_blender.ply", "300k": "scene/tsdf_mesh.ply"}
#: the synthetic scene's generator options (10 photos of 6 MP)
SYNTHETIC_6MP = ("--views", "10", "--width", "3000", "--height", "2000", "--seen-only")
SCENES = ("16k", "300k", "6mp")
ORDER = ("start-up", "load", "visibility", "mappings", "correction", "selection", "bake", "seams", "export",
         "(report)", "exit")


# --------------------------------------------------------------------------------------------
# the child: the command's own main, with a recorder around it


def _process_start() -> float:
    """This process's start on the ``time.monotonic()`` clock (``/proc/self/stat`` field 22, boot-relative)."""
    ticks = os.sysconf("SC_CLK_TCK")
    start = int(open("/proc/self/stat").read().rsplit(")", 1)[1].split()[19]) / ticks
    up = float(open("/proc/uptime").read().split()[0])
    return time.monotonic() - (up - start)


class _Recorder:
    """Spans (name, wall start/end, CPU start/end, peak RSS) of one command run."""

    def __init__(self) -> None:
        self.page = os.sysconf("SC_PAGE_SIZE")
        self.spans: list[dict] = []
        self.current: dict | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._lock = threading.Lock()

    def rss(self) -> int:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * self.page

    def begin(self, name: str, wall: float | None = None, cpu: float | None = None) -> None:
        with self._lock:
            if self.current is not None:
                self._close()
            t = os.times()
            self.current = {"name": name, "t0": time.monotonic() if wall is None else wall,
                            "c0": (t.user + t.system) if cpu is None else cpu, "rss": self.rss()}

    def _close(self) -> None:
        t = os.times()
        cur = self.current
        cur.update(t1=time.monotonic(), c1=t.user + t.system, rss=max(cur["rss"], self.rss()))
        self.spans.append(cur)
        self.current = None

    def end(self) -> None:
        with self._lock:
            if self.current is not None:
                self._close()

    def _run(self) -> None:
        while not self._stop.wait(0.01):
            with self._lock:
                if self.current is not None:
                    self.current["rss"] = max(self.current["rss"], self.rss())

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()


def _child(argv: list[str]) -> int:
    """``profile_run.py _child RECORD.json -- o3d-seqcc arguments``: run the command, write the spans."""
    record, args = argv[0], argv[argv.index("--") + 1:]
    rec = _Recorder()
    rec.start()
    # the interpreter's start, with the CPU it used so far (imports of this file are negligible)
    rec.begin("start-up", wall=_process_start(), cpu=0.0)
    import o3d_seqcc.cli as cli  # the command's imports: part of start-up
    import o3d_seqcc.io.load as load_mod
    import o3d_seqcc.pipeline as pipeline_mod
    from o3d_seqcc._shared.progress import on_stage

    inner = load_mod.load_scene

    @functools.wraps(inner)  # the command line reads the library's defaults from its signature
    def timed_load(*a, **k):
        rec.begin("load")
        try:
            return inner(*a, **k)
        finally:
            rec.begin("between")

    # the CLI and the pipeline reach load_scene through these modules' globals
    for mod in (load_mod, pipeline_mod, sys.modules.get("o3d_seqcc.cli.scene_flags"), sys.modules.get("o3d_seqcc.io")):
        if mod is not None and getattr(mod, "load_scene", None) is inner:
            mod.load_scene = timed_load
    import o3d_seqcc

    if getattr(o3d_seqcc, "__dict__", {}).get("load_scene") is inner:
        o3d_seqcc.load_scene = timed_load
    rec.begin("between")

    def listener(name: str, event: str, _t: float) -> None:
        rec.begin(name if event == "start" else "between")

    with on_stage(listener):
        rc = cli.main(args)
    rec.end()
    rec.stop()
    # the interpreter's shutdown after this is measured by the parent ("exit": to the process's end)
    with open(record, "w") as f:
        json.dump({"rc": rc, "spans": rec.spans, "end": time.monotonic()}, f)
    return rc


# --------------------------------------------------------------------------------------------
# the parent


def synthetic_scene(tmp: Path) -> Path:
    """The 6 MP synthetic room (made once under ``tmp``)."""
    folder = tmp / "synthetic_6mp"
    if not (folder / "scene.json").is_file():
        subprocess.run([sys.executable, "-m", "o3d_seqcc", "-q", "synthetic", str(folder), *SYNTHETIC_6MP, "--overwrite"],
                       check=True)
    return folder


def scene_args(key: str, data: Path, tmp: Path) -> list[str]:
    if key in FOUNTAIN_MESHES:
        return [str(data), "--mesh", str(data / FOUNTAIN_MESHES[key])]
    return [str(synthetic_scene(tmp))]


def profile_once(key: str, data: Path, tmp: Path, extra: list[str]) -> dict:
    """One child run of ``o3d-seqcc run`` on scene ``key``: process figures and spans."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from peers import run_measured

    out = tmp / f"profile_{key}"
    record = tmp / f"profile_{key}.json"
    record.unlink(missing_ok=True)
    cmd = [sys.executable, str(Path(__file__).resolve()), "_child", str(record), "--",
           "run", *scene_args(key, data, tmp), "--out", str(out), "--overwrite", "-q", *extra]
    run = run_measured(cmd, log_prefix=tmp / f"profile_{key}_log")
    t_end = time.monotonic()
    if run.returncode != 0 or not record.is_file():
        raise RuntimeError(f"{key}: o3d-seqcc run failed (exit {run.returncode}):\n{run.tail()}")
    rec = json.loads(record.read_text())
    rep = json.loads((out / "report.json").read_text())
    rows: dict[str, dict] = {}
    for s in rec["spans"]:
        name = s["name"]
        r = rows.setdefault(name, {"wall": 0.0, "cpu": 0.0, "rss": 0})
        r["wall"] += s["t1"] - s["t0"]
        r["cpu"] += s["c1"] - s["c0"]
        r["rss"] = max(r["rss"], s["rss"])
    # the recorder's clock and the parent's are the same monotonic clock: the time after the record
    rows.setdefault("exit", {"wall": 0.0, "cpu": 0.0, "rss": 0})["wall"] += max(0.0, t_end - rec["end"])
    rows["(report)"] = {"wall": float(rep.get("timings_s", {}).get("report", 0.0)), "cpu": float("nan"), "rss": 0}
    return {"scene": key, "wall": run.seconds, "cpu": run.cpu_seconds, "peak_rss": run.peak_rss, "rows": rows,
            "faces": rep.get("selection", {}).get("faces"), "atlas": rep.get("atlas", {}).get("size")}


def _median_rows(runs: list[dict]) -> dict:
    names = [n for n in ORDER if any(n in r["rows"] for r in runs)]
    names += sorted({n for r in runs for n in r["rows"]} - set(names))
    out = {}
    for n in names:
        vals = [r["rows"].get(n, {"wall": 0.0, "cpu": 0.0, "rss": 0}) for r in runs]
        out[n] = {k: statistics.median(v[k] for v in vals) for k in ("wall", "cpu", "rss")}
    return out


def print_profile(key: str, runs: list[dict]) -> None:
    rows = _median_rows(runs)
    wall = statistics.median(r["wall"] for r in runs)
    each = ", ".join(f"{r['wall']:.2f}" for r in runs)
    print(f"\n== {key}: o3d-seqcc run, {len(runs)} run(s), median; faces {runs[0]['faces']}; "
          f"process wall {wall:.2f} s (runs {each}), "
          f"CPU {statistics.median(r['cpu'] for r in runs):.1f} s, "
          f"peak RSS {statistics.median(r['peak_rss'] for r in runs) / 1e6:.0f} MB")
    print(f"  {'span':<12}{'wall s':>8}{'share':>7}{'CPU s':>8}{'cores':>7}{'peak RSS MB':>13}")
    for n, r in rows.items():
        if n == "between" and r["wall"] < 0.005:
            continue
        cores = r["cpu"] / r["wall"] if r["wall"] > 0.01 and r["cpu"] == r["cpu"] else float("nan")
        cpu = f"{r['cpu']:8.2f}" if r["cpu"] == r["cpu"] else f"{'':>8}"
        share = f"{100 * r['wall'] / wall:6.1f}%" if n != "(report)" else f"{'':>7}"
        rss = f"{r['rss'] / 1e6:13.0f}" if r["rss"] else f"{'':>13}"
        print(f"  {n:<12}{r['wall']:8.2f}{share}{cpu}{'' if cores != cores else format(cores, '7.2f'):>7}{rss}")


def importtime(args: list[str], top: int = 12) -> list[tuple[float, str]]:
    """The slowest top-level imports (self + children, seconds) of ``o3d-seqcc ARGS --help``-free parsing."""
    code = "import sys; from o3d_seqcc.cli import build_parser; build_parser().parse_args(sys.argv[1:])"
    r = subprocess.run([sys.executable, "-X", "importtime", "-c", code, *args], capture_output=True, text=True)
    rows = []
    for line in r.stderr.splitlines():
        if not line.startswith("import time:") or "|" not in line:
            continue
        _, cum, name = line[len("import time:"):].split("|")
        if cum.strip().isdigit() and not name.startswith("  "):
            rows.append((int(cum) / 1e6, name.strip()))
    return sorted(rows, reverse=True)[:top]


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["_child"]:
        return _child(argv[1:])
    ap = argparse.ArgumentParser(prog="benchmarks/profile_run.py", description=__doc__.split("\n", 1)[0])
    ap.add_argument("--scenes", default=",".join(SCENES), help=f"comma-separated among {', '.join(SCENES)}")
    ap.add_argument("--repeat", type=int, default=1, help="runs per scene (medians; default 1)")
    ap.add_argument("--data", default=str(DATA), help="fountain_small folder")
    ap.add_argument("--tmp", default="/tmp/o3d_seqcc_profile", help="working folder (outputs, the synthetic scene)")
    ap.add_argument("--importtime", action="store_true", help="also list the command's slowest top-level imports")
    ap.add_argument("--json", help="write the figures to this file")
    ap.add_argument("extra", nargs="*", help="more o3d-seqcc run options (after --)")
    a = ap.parse_args(argv)
    keys = [k.strip() for k in a.scenes.split(",") if k.strip()]
    if any(k not in SCENES for k in keys) or a.repeat < 1:
        print(f"scenes among {', '.join(SCENES)}; --repeat >= 1", file=sys.stderr)
        return 2
    data, tmp = Path(a.data).resolve(), Path(a.tmp).resolve()
    tmp.mkdir(parents=True, exist_ok=True)
    if any(k in FOUNTAIN_MESHES for k in keys) and not (data / "scene" / "key.log").is_file():
        print(f"Fountain not found at {data} (--data)", file=sys.stderr)
        return 1
    load0 = os.getloadavg()[0]
    results = {}
    for k in keys:
        runs = [profile_once(k, data, tmp, a.extra) for _ in range(a.repeat)]
        results[k] = runs
        print_profile(k, runs)
    if a.importtime:
        print("\nslowest top-level imports of the command line (python -X importtime, s):")
        for s, name in importtime(["run", "x", "--out", "y"]):
            print(f"  {s:6.3f}  {name}")
    print(f"\nload average: start {load0:.2f}, end {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores)")
    if a.json:
        Path(a.json).write_text(json.dumps({"load": [load0, os.getloadavg()[0]], "results": results}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
