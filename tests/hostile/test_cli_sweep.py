"""The CLI sweep: every case of the hostile-input table (``_cli_cases.CASES``) handled, one test per case.

Each case is a row of data (group, name, the input mutation, the command, the expected outcome); the test runs it on
a fresh copy of a small synthetic scene in a subprocess and asserts :func:`_cli_cases.run_case`'s verdict (refused
with a message naming the fault, inputs untouched, nothing left beside the output, no unsafe HTML, or the case's
own check). Marked ``hostile`` (``pytest -m hostile`` runs them with ``test_hostile.py``) and ``slow`` (a subprocess
per case, about 15-25 minutes on 2 cores: the fast tier ``-m "not slow"`` skips them; the full run has them).
``benchmarks/hostile_inputs.py`` runs this module and prints the tried / handled table per group.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import _cli_cases as hc

pytestmark = [pytest.mark.hostile, pytest.mark.slow]


@pytest.fixture(scope="module")
def sweep(tmp_path_factory) -> tuple[Path, Path]:
    """The sweep's folder (every case's working directory) and its scene; a finished ``run`` output of it as RUN0."""
    root = tmp_path_factory.mktemp("hostile_cli")
    hc.CWD[0] = str(root)
    scene, run0 = root / "scene", root / "run0"
    r = hc.cli("synthetic", scene, "--views", "6", "--width", "160", "--height", "120")
    assert r.returncode == 0, f"cannot make the synthetic scene: {r.stderr}"
    r = hc.cli("run", scene, "--out", run0, *hc.FAST, *hc.TEX)
    assert r.returncode == 0, f"cannot make the run output: {r.stderr}"
    hc.RUN0[0] = run0
    hc.RUN0_TPP[0] = json.loads((run0 / "report.json").read_text())["atlas"]["texels_per_pixel"]
    return root, scene


@pytest.mark.parametrize("index", range(len(hc.CASES)), ids=[f"{c.group}: {c.name}" for c in hc.CASES])
def test_case_is_handled(sweep, tmp_path, index, record_property):
    cs = hc.CASES[index]
    ok, msg = hc.run_case(cs, sweep[1], tmp_path, index)
    for key, value in (("group", cs.group), ("case", cs.name), ("handled", ok), ("message", msg),
                       ("kinds", ",".join(sorted(hc.CATEGORIES.get(index, set()))))):
        record_property(key, value)
    assert ok, f"{cs.group}: {cs.name}: not handled: {msg}"
