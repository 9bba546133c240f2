"""Run the hostile-input tests (``pytest -m hostile``) and print which cases were handled, per group.

Usage::

    python benchmarks/hostile_inputs.py [--only TEXT] [-- PYTEST ARGS...]

The cases are data run by pytest: the CLI sweep's table (``tests/hostile/_cli_cases.py``: 300 bad inputs, faults
and hostile files, each a subprocess ``python -m o3d_seqcc ...`` on a fresh copy of a small synthetic scene,
checked by ``tests/hostile/test_cli_sweep.py``) and the library's case tables per class
(``tests/hostile/test_hostile.py``). This script runs ``python -m pytest -m hostile tests/hostile`` with a JUnit
report in a temporary folder and prints one line per CLI case (group, name, handled yes/no, the message's first
line), the totals per group and overall ("cases tried N, handled M"), what went wrong by kind (tracebacks,
crashes, hangs, damage, files beside the output, unsafe HTML, inputs not named), then the library tests' count.
``--only TEXT`` keeps the cases whose id contains TEXT (pytest's ``-k``); arguments after ``--`` go to pytest.
Exits with pytest's exit code (0: every case handled). About 15-25 minutes on a 2-core machine, one case at a time.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
KINDS = ("traceback", "crash", "hang", "damage", "beside", "unsafe-html", "unnamed", "other")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", default=None, help="only the cases whose id contains this text (pytest -k)")
    args = ap.parse_args(argv[: argv.index("--")] if "--" in argv else argv)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)}
    with tempfile.TemporaryDirectory(prefix="o3d_seqcc_hostile_") as tmp:
        xml = Path(tmp) / "hostile.xml"
        cmd = [sys.executable, "-m", "pytest", "-m", "hostile", str(REPO / "tests" / "hostile"), "-q", "-p",
               "no:cacheprovider", f"--junitxml={xml}", "-o", "junit_family=xunit1",  # xunit1: the cases' properties
               *(["-k", args.only] if args.only else []), *extra]
        print("running:", " ".join(cmd), flush=True)
        t0 = time.perf_counter()
        rc = subprocess.run(cmd, cwd=REPO, env=env).returncode
        seconds = time.perf_counter() - t0
        if not xml.is_file():
            print("pytest wrote no report")
            return rc or 1
        cases = ET.parse(xml).getroot().iter("testcase")
        sweep, library = [], []
        for tc in cases:
            props = {p.get("name"): p.get("value") for p in tc.iter("property")}
            skipped = tc.find("skipped") is not None
            failed = tc.find("failure") is not None or tc.find("error") is not None
            if "group" in props:
                sweep.append((props["group"], props["case"], props["handled"] == "True" and not failed,
                              props.get("message", ""), set(filter(None, props.get("kinds", "").split(",")))))
            elif failed and "test_cli_sweep" in tc.get("classname", ""):  # failed before its verdict (fixture)
                sweep.append(("(setup)", tc.get("name"), False, "error before the case ran", {"other"}))
            else:
                library.append((tc.get("name"), "skipped" if skipped else "failed" if failed else "passed"))
    print()
    for g, n, ok, msg, _ in sweep:
        print(f"{g:<22} | {n:<58} | {'yes' if ok else 'NO ':<3} | {msg.splitlines()[0][:150] if msg else ''}")
    print()
    groups: dict[str, list[int]] = {}
    for g, _, ok, _, _ in sweep:
        t = groups.setdefault(g, [0, 0])
        t[0] += 1
        t[1] += ok
    for g in sorted(groups, key=lambda s: (not s[0].isdigit(), s)):
        print(f"{g:<22} tried {groups[g][0]:3d}, handled {groups[g][1]:3d}")
    print(f"\ncases tried {len(sweep)}, handled {sum(c[2] for c in sweep)} ({seconds:.0f} s for the whole pytest run)")
    print("not handled, by kind: " + ", ".join(f"{k} {sum(k in c[4] for c in sweep if not c[2])}" for k in KINDS))
    bad = [c for c in sweep if not c[2]]
    if bad:
        print("not handled:")
        for g, n, _, m, _ in bad:
            print(f"  {g}: {n}: {m[:200]}")
    states = {s: sum(st == s for _, st in library) for s in ("passed", "failed", "skipped")}
    print(f"library cases (tests/hostile/test_hostile.py): {len(library)} run, {states['passed']} passed, "
          f"{states['failed']} failed, {states['skipped']} skipped")
    return rc


if __name__ == "__main__":
    sys.exit(main())
