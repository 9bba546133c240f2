"""Every shell and Python block of the README runs as written, from a folder outside the repository.

The two set-up commands (``./dev.sh demo`` / ``./dev.sh test``) are what CI itself runs, so they
are not run again here. The Fountain data come from ``../shared`` through ``O3D_SEQCC_FOUNTAIN``
(a user without it gets Open3D's download).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BLOCK = re.compile(r"^```(bash|python)\n(.*?)^```", re.S | re.M)


def readme_blocks() -> list[tuple[str, str]]:
    return [(lang, code) for lang, code in BLOCK.findall((REPO / "README.md").read_text()) if "./dev.sh" not in code]


def test_readme_has_the_two_setup_commands_and_runnable_blocks():
    text = (REPO / "README.md").read_text()
    setup = [code for lang, code in BLOCK.findall(text) if "./dev.sh" in code]
    assert len(setup) == 1 and "./dev.sh demo" in setup[0] and "./dev.sh test" in setup[0]
    assert "./dev.sh test" in (REPO / ".ci" / "run").read_text()
    kinds = [lang for lang, _ in readme_blocks()]
    assert kinds.count("bash") >= 2 and kinds.count("python") >= 2
    assert "../shared" not in "".join(code for _, code in readme_blocks())


@pytest.mark.parametrize("index", range(len(readme_blocks())))
def test_readme_block_runs(index, tmp_path, fountain_root):
    lang, code = readme_blocks()[index]
    env = {**os.environ, "O3D_SEQCC_FOUNTAIN": str(fountain_root), "MPLBACKEND": "Agg",
           "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    cmd = ["bash", "-euo", "pipefail", "-c", code] if lang == "bash" else [sys.executable, "-c", code]
    r = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, f"README {lang} block {index} failed:\n{code}\n--- stdout\n{r.stdout[-3000:]}\n" \
                              f"--- stderr\n{r.stderr[-3000:]}"
