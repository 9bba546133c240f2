"""The runnable scripts in examples/ run as documented (small settings), from another folder."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _run(script: str, *args: str, cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    r = subprocess.run([sys.executable, str(EXAMPLES / script), *args], cwd=cwd, capture_output=True, text=True,
                       timeout=600, env={**os.environ, **(env or {})})
    assert r.returncode == 0, f"{script} failed:\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}"
    return r


def test_every_example_says_what_it_shows_and_how_to_run_it():
    scripts = sorted(EXAMPLES.glob("*.py"))
    assert {"open3d_fountain.py", "game_engine_glb.py", "meshlab_project.py",
            "meshlab_screenshot.py", "meshlab_plugin_screenshots.py"} <= {p.name for p in scripts}
    for p in scripts:
        doc = p.read_text().split('"""')[1]
        assert "What it shows" in doc and "How to run" in doc, p.name


def test_open3d_fountain_example(fountain_root, tmp_path):
    r = _run("open3d_fountain.py", "--views", "8", "--out", "o", cwd=tmp_path,
             env={"O3D_SEQCC_FOUNTAIN": str(fountain_root)})
    assert "corrected toward view" in r.stdout
    assert (tmp_path / "o" / "textured.obj").is_file() and (tmp_path / "o" / "render.png").stat().st_size > 10_000


def test_game_engine_glb_example(tmp_path):
    r = _run("game_engine_glb.py", "--atlas-size", "1024", "--out", "asset", cwd=tmp_path)
    assert (tmp_path / "asset" / "mesh.glb").is_file()
    from o3d_seqcc.io.gltf_validator import find_validator

    if find_validator() is not None:
        assert "0 errors, 0 warnings" in r.stdout


def test_meshlab_project_example(tmp_path):
    r = _run("meshlab_project.py", "--texture", "--out", "o", cwd=tmp_path)
    assert "corrected 4 rasters toward" in r.stdout and "seqcc_color_correct_rasters" in r.stdout
    assert (tmp_path / "o" / "corrected.mlp").is_file() and "textured" in r.stdout


@pytest.mark.skipif(shutil.which("meshlab") is None or shutil.which("xvfb-run") is None,
                    reason="the MeshLab application (Debian package meshlab, with xvfb) is not installed")
def test_meshlab_screenshot_example(tmp_path):
    r = _run("meshlab_screenshot.py", "--out", "o", "--png", "shot.png", cwd=tmp_path)
    assert (tmp_path / "shot.png").stat().st_size > 10_000 and "loaded in" in r.stdout


@pytest.mark.skipif(not Path("/usr/lib/x86_64-linux-gnu/meshlab/plugins/libfilter_o3d_seqcc.so").is_file()
                    or shutil.which("meshlab") is None or shutil.which("xdotool") is None,
                    reason="the MeshLab plugin is not built (./dev.sh setup builds and installs it) or MeshLab / "
                    "xdotool are not installed")
def test_meshlab_plugin_screenshots_example(tmp_path):
    r = _run("meshlab_plugin_screenshots.py", "--out", "o", "--docs", "shots", cwd=tmp_path)
    assert "from its Filters > Texture menu" in r.stdout
    for name in ("meshlab_plugin_menu.png", "meshlab_plugin_dialog.png", "meshlab_plugin_result.jpg"):
        assert 20_000 < (tmp_path / "shots" / name).stat().st_size < 400_000
    assert (tmp_path / "o" / "room" / "seqcc_textured" / "mesh_meshlab.ply").is_file()
