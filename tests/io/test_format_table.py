"""The README's table of scene formats: one row per format of the loader table, and its examples run as written.

Each example is run from a folder laid out as the row's tool writes it (the scene written by the readers' own
test writers, which follow the formats' specifications), and ``info`` must name the row's format. COLMAP,
Meshroom, Metashape and RGB-D folders have their own end-to-end tests (they need pycolmap's writer, a
Meshroom tree, a world-frame mesh or the Fountain data).
"""

from __future__ import annotations

import importlib.util
import json
import re
import shlex
import shutil
from pathlib import Path

import pytest

import o3d_seqcc as sc
from o3d_seqcc.cli import main
from o3d_seqcc.io.load import SCENE_FORMATS
from o3d_seqcc.io.meshlab import save_mlp

REPO = Path(__file__).resolve().parents[2]
ROW = re.compile(r"^\| `([^`]+)` \| (.+?) \| (.+?) \| `(o3d-seqcc [^`]+)` \|$", re.M)


def table() -> dict[str, str]:
    rows = ROW.findall((REPO / "README.md").read_text())
    return {name: example for name, _what, _detected, example in rows}


def _writers(name: str):
    spec = importlib.util.spec_from_file_location(f"_table_{name}", Path(__file__).with_name(f"test_{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_format_has_one_row():
    rows = ROW.findall((REPO / "README.md").read_text())
    assert sorted(r[0] for r in rows) == sorted(SCENE_FORMATS), "README's format table and SCENE_FORMATS differ"
    assert all(r[3].startswith("o3d-seqcc info ") for r in rows)


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("table") / "R", n_views=4, width=64, height=48,
                                   cell_size=0.25, layout="two-rings", seen_only=True, photometric="none")


def _lay_out(fmt: str, room, cwd: Path) -> None:
    """The files the row's example names, in ``cwd``."""
    scene = room.scene
    shutil.copy(scene.mesh, cwd / "mesh.ply")
    (cwd / "images").mkdir()
    for v in scene.views:
        shutil.copy(v.image, cwd / "images" / v.image.name)
    if fmt == "scene.json":
        shutil.copytree(room.root, cwd / "my_scan")
    elif fmt == "meshlab":
        save_mlp(scene, cwd / "project.mlp")
    elif fmt == "openmvs":
        w = _writers("openmvs")
        w.write_interface(cwd / "scene.mvs", 7, *w.interface_of(scene, 7))
    elif fmt == "nvm":
        _writers("nvm").write_nvm(cwd / "model.nvm", scene)
    elif fmt == "mve":
        _writers("mve").write_mve_scene(cwd / "mve_scene", scene)
    elif fmt == "cam-folder":
        _writers("mve").write_cam_folder(cwd / "texrecon_scene", scene)
    elif fmt == "bundler":
        _writers("bundler").write_bundler(cwd, scene)
    else:
        raise AssertionError(fmt)


@pytest.mark.parametrize("fmt", ["scene.json", "meshlab", "openmvs", "nvm", "mve", "cam-folder", "bundler"])
def test_the_example_runs_as_written_and_names_the_format(fmt, room, tmp_path, monkeypatch, capsys):
    example = table()[fmt]
    _lay_out(fmt, room, tmp_path)
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    assert main([*shlex.split(example)[1:], "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == fmt and info["views"] == len(room.scene.views)
