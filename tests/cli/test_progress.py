"""Progress bars: shown only when asked (the CLI asks on a terminal without -q), silent otherwise."""

from __future__ import annotations

import os
import pty
import subprocess
import sys

import pytest

import o3d_seqcc as sc
from o3d_seqcc._shared.progress import show_progress, steps, track


def test_track_and_steps_are_silent_unless_shown(capsys):
    assert list(track(range(5), desc="x")) == [0, 1, 2, 3, 4]
    with steps("stage", 2) as step:
        step("a")
        step("b")
    assert capsys.readouterr().err == ""
    with show_progress():
        assert list(track(range(5), desc="loop", total=5)) == [0, 1, 2, 3, 4]
        with steps("stage", 2) as step:
            step("first")
            step("second")
    err = capsys.readouterr().err
    assert "loop:" in err and "stage:" in err


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    root = tmp_path_factory.mktemp("prog")
    return sc.make_synthetic_scene(root / "S", n_views=4, width=96, height=72, seed=5, cell_size=0.2)


def _run_in_terminal(argv: list[str]) -> str:
    """Run the command in a pseudo-terminal (stderr a TTY, as for a user) and return what it printed."""
    pid, fd = pty.fork()
    if pid == 0:  # child
        os.execv(sys.executable, [sys.executable, "-m", "o3d_seqcc", *argv])
    out = b""
    while True:
        try:
            chunk = os.read(fd, 4096)
        except OSError:
            break
        if not chunk:
            break
        out += chunk
    os.waitpid(pid, 0)
    return out.decode(errors="replace")


def test_cli_shows_bars_on_a_terminal_and_not_in_a_pipe(small, tmp_path):
    argv = ["run", str(small.root), "--out", str(tmp_path / "a"), "--t-npm", "20", "--atlas-size", "512"]
    term = _run_in_terminal(argv)
    assert "visibility:" in term and "bake:" in term and "fit edges:" in term, term[-2000:]
    piped = subprocess.run([sys.executable, "-m", "o3d_seqcc", *argv[:3], str(tmp_path / "b"), *argv[4:]],
                           capture_output=True, text=True)
    assert piped.returncode == 0 and "bake:" not in piped.stderr and "\r" not in piped.stderr
    quiet = _run_in_terminal([*argv[:3], str(tmp_path / "c"), *argv[4:], "-q"])
    assert "visibility:" not in quiet and "bake:" not in quiet and "%|" not in quiet
