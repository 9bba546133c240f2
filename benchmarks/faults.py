"""Kill ``o3d-seqcc run`` and ``correct`` at random moments and check that nothing is ever half-written.

Usage::

    .venv/bin/python benchmarks/faults.py [--kills 60] [--seed 0] [--keep DIR]

A small synthetic scene is generated, then each command writes a first complete output. Then, N
times: a ``run`` or ``correct`` with ``--overwrite`` into that output is started and killed
(SIGKILL, or SIGINT one time in four) after a random delay within its usual duration. After
every kill the output folder must be either exactly the previous output (same checksums) or a
complete new one (its manifest lists exactly the files present and ``report.json`` is there), no
visible file may have appeared beside it, and the scene's files must be unchanged. Every fifth
kill the same command is re-run to completion, which must succeed and leave nothing beside the
output folder (staging folders of killed runs are cleaned by the next run).

Prints the counts: kills, outputs intact / replaced whole / partial, inputs changed, re-runs
failed, leftovers.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from o3d_seqcc.io.output import MANIFEST  # noqa: E402
from o3d_seqcc.synthetic import make_synthetic_scene  # noqa: E402

COMMON = ["--t-npm", "50"]
ARGS = {
    "run": ["--atlas-size", "1024", "--save-images", *COMMON],
    "correct": COMMON,
}


def checksums(folder: Path) -> dict[str, str]:
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def command(name: str, scene: Path, out: Path) -> list[str]:
    return [sys.executable, "-m", "o3d_seqcc", "-q", name, str(scene), "--out", str(out), "--overwrite", *ARGS[name]]


def state(out: Path, previous: dict[str, str]) -> str:
    """'intact' (the previous output), 'whole' (a complete new output), 'absent' or 'partial'."""
    if not out.exists():
        return "absent"
    now = checksums(out)
    if now == previous:
        return "intact"
    try:
        listed = set(json.loads((out / MANIFEST).read_text())["files"])
    except (OSError, ValueError, KeyError):
        return "partial"
    present = set(now) - {MANIFEST}
    return "whole" if listed == present and "report.json" in present else "partial"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kills", type=int, default=60, help="number of killed runs (default 60)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--keep", type=Path, default=None, help="work in this folder and keep it")
    args = ap.parse_args()
    rng = random.Random(args.seed)
    work = args.keep or Path(tempfile.mkdtemp(prefix="o3d_seqcc_faults_"))
    work.mkdir(parents=True, exist_ok=True)
    scene = work / "scene"
    if not (scene / "scene.json").is_file():
        make_synthetic_scene(scene, n_views=5, width=160, height=120, seed=2)
    inputs = checksums(scene)
    outs = {name: work / f"out_{name}" for name in ARGS}
    duration = {}
    for name, out in outs.items():
        shutil.rmtree(out, ignore_errors=True)
        t = time.perf_counter()
        subprocess.run(command(name, scene, out), check=True)
        duration[name] = time.perf_counter() - t
    print(f"scene: {scene}; full run durations: " + ", ".join(f"{k} {v:.1f} s" for k, v in duration.items()))
    counts = {"kills": 0, "intact": 0, "whole": 0, "absent": 0, "partial": 0, "inputs_changed": 0,
              "reruns": 0, "reruns_failed": 0, "leftovers": 0}
    for i in range(args.kills):
        name = rng.choice(sorted(ARGS))
        out = outs[name]
        previous = checksums(out)
        sig = signal.SIGINT if rng.random() < 0.25 else signal.SIGKILL
        delay = rng.uniform(0.0, duration[name] * 1.1)
        proc = subprocess.Popen(command(name, scene, out), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(delay)
        proc.send_signal(sig)
        proc.wait()
        counts["kills"] += 1
        st = state(out, previous)
        counts[st] += 1
        if checksums(scene) != inputs:
            counts["inputs_changed"] += 1
        visible = sorted(p.name for p in work.iterdir() if not p.name.startswith("."))
        if visible != sorted(["scene", *(o.name for o in outs.values())]):
            counts["leftovers"] += 1
        print(f"  kill {i + 1:3d}: {name:<7} {sig.name:<7} after {delay:5.2f} s -> {st}"
              + (" (exit %d)" % proc.returncode if proc.returncode not in (-9, 130, -2) else ""))
        if (i + 1) % 5 == 0 or st in ("absent", "partial"):
            counts["reruns"] += 1
            r = subprocess.run(command(name, scene, out), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            hidden = sorted(p.name for p in work.iterdir() if p.name.startswith(f".{out.name}.o3d_seqcc"))
            if r.returncode != 0 or state(out, {}) != "whole":
                counts["reruns_failed"] += 1
                print(f"    re-run failed: {r.stderr.decode()[-300:]}")
            if hidden:
                counts["leftovers"] += 1
                print(f"    left beside the output after a complete re-run: {hidden}")
    print("\n" + ", ".join(f"{k} {v}" for k, v in counts.items()))
    print(f"partial outputs: {counts['partial']}; changed inputs: {counts['inputs_changed']}")
    if args.keep is None:
        shutil.rmtree(work, ignore_errors=True)
    return 0 if counts["partial"] == 0 and counts["inputs_changed"] == 0 and counts["reruns_failed"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
