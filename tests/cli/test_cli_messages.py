"""What a person reads on a first day: quiet means quiet, warnings one line per kind, errors that say what to do."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

import o3d_seqcc as sc
from o3d_seqcc.cli import main
from o3d_seqcc.io.images import write_image

FAST = ["--t-npm", "50", "--atlas-size", "512", "--format", "glb", "--fallback", "flat", "--no-seams"]


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("msg") / "scene", n_views=4, width=96, height=72, seed=2)


def test_quiet_prints_nothing_on_success(small, tmp_path, capfd):
    assert main(["-q", "run", str(small.root / "scene.json"), "--out", str(tmp_path / "o"), *FAST]) == 0
    assert capfd.readouterr() == ("", "")
    assert (tmp_path / "o" / "report.html").is_file()
    # -q after the command too; errors still show
    assert main(["correct", str(small.root / "scene.json"), "--out", str(tmp_path / "c"), "--t-npm", "50", "-q"]) == 0
    assert capfd.readouterr() == ("", "")
    assert main(["-q", "info", str(tmp_path / "missing")]) == 2
    out, err = capfd.readouterr()
    assert out == "" and err.startswith("o3d-seqcc info: error: scene not found")


def test_warnings_are_one_line_per_kind_with_a_count(small, tmp_path, capfd):
    # every view's depth maps in the wrong units: the same warnings for each of the 4 views, then the error
    S = tmp_path / "S"
    shutil.copytree(small.root, S)
    doc = json.loads((S / "scene.json").read_text())
    for v in doc["views"]:
        v["depth_scale"] = v.get("depth_scale", 1000.0) * 3
    (S / "scene.json").write_text(json.dumps(doc))
    assert main(["correct", str(S / "scene.json"), "--out", str(tmp_path / "o"), "--t-npm", "50", "--no-metrics"]) == 2
    err = capfd.readouterr().err
    lines = [line for line in err.splitlines() if "disagree with its depth" in line]
    assert len(lines) == 1, err
    assert err.splitlines()[-1].startswith("o3d-seqcc correct: error: no overlap")  # the warnings come before it
    assert lines[0].startswith("o3d-seqcc correct: warning (4 times): view 'v00': ") and "also 'v01', 'v02', 'v03'" in lines[0]
    # the CLI's own format: no logger names, no Python warning source lines
    assert "py.warnings" not in err and "O3dSeqccWarning" not in err and not re.search(r"\.py:\d+", err)
    # the library keeps Python's warnings (one per view)
    with pytest.warns(sc.errors.O3dSeqccWarning, match="disagree with its depth") as rec:
        sc.compute_visibility(sc.load_scene(S / "scene.json"))
    assert len([w for w in rec if "disagree" in str(w.message)]) == 4


def _colmap_text(folder: Path, names: list[str]) -> Path:
    """A COLMAP text model with one PINHOLE camera and the named images (identity-ish poses)."""
    model = folder / "sparse"
    model.mkdir(parents=True)
    (model / "cameras.txt").write_text("# camera\n1 PINHOLE 64 48 60 60 31.5 23.5\n")
    rows = [f"{i + 1} 1 0 0 0 {0.1 * i} 0 2 1 {n}\n\n" for i, n in enumerate(names)]
    (model / "images.txt").write_text("# images\n" + "".join(rows))
    (model / "points3D.txt").write_text("")
    return model


def test_errors_name_what_the_user_typed_and_near_misses(small, tmp_path, capsys, monkeypatch):
    model = _colmap_text(tmp_path, ["img00.png", "img01.png"])
    images = tmp_path / "images"
    images.mkdir()
    rng = np.random.default_rng(0)
    for n in ("img00.jpg", "img01.jpg"):  # the model names .png, the folder holds .jpg
        write_image(images / n, rng.integers(0, 255, (48, 64, 3), dtype=np.uint8))
    shutil.copy(small.root / "mesh.ply", tmp_path / "mesh.ply")
    monkeypatch.chdir(tmp_path)
    # --mesh as typed, not joined onto the model folder
    assert main(["info", str(model), "--mesh", "nothere.ply"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("o3d-seqcc info: error: mesh nothere.ply not found") and str(tmp_path) in err
    assert str(model / "nothere.ply") not in err
    # the image the model names is missing, a namesake with another extension is there
    assert main(["info", str(model), "--mesh", "mesh.ply"]) == 2
    err = capsys.readouterr().err
    assert "img00.png" in err and "found img00.jpg beside it: did you mean it?" in err
    with pytest.raises(sc.InputError, match="found img00.jpg beside it"):
        sc.load_scene(model, mesh="mesh.ply")


def test_a_typo_in_a_command_option_gets_that_commands_usage(small, capsys):
    assert main(["run", str(small.root), "--out", "x", "--t-nmp", "5"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: o3d-seqcc run ") and "--t-npm auto|N" in err
    assert err.rstrip().endswith("o3d-seqcc run: error: unrecognized arguments: --t-nmp 5 (--t-nmp: did you mean "
                                 "--t-npm?)")


def test_offline_fountain_in_cli_and_python_words(tmp_path, capsys, monkeypatch):
    import open3d as o3d

    def offline():
        raise RuntimeError("[Open3D Error] Download.cpp:182: Downloading failed from available mirrors.")

    monkeypatch.setattr(o3d.data, "SampleFountainRGBDImages", offline)
    monkeypatch.delenv("O3D_SEQCC_FOUNTAIN", raising=False)
    assert main(["demo", "--dataset", "fountain", "--out", str(tmp_path / "g")]) == 2
    err = capsys.readouterr().err
    assert "give it with --data-root DIR" in err and "O3D_SEQCC_FOUNTAIN=DIR" in err and "root=" not in err
    assert "Traceback" not in err
    with pytest.raises(sc.InputError) as e:
        sc.datasets.fountain()
    assert "pass it as fountain(root=DIR)" in str(e.value) and "O3D_SEQCC_FOUNTAIN" in str(e.value)
    assert "--data-root" not in str(e.value)
    from o3d_seqcc.demo import run_demo

    with pytest.raises(sc.InputError, match=r"run_demo\(\.\.\., data_root=DIR\)"):
        run_demo(tmp_path / "h", dataset="fountain")


def test_a_missing_extra_is_named(small, capsys, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "distributed" else real(name, *a))
    assert main(["--scheduler", "tcp://127.0.0.1:1", "info", str(small.root)]) == 2
    err = capsys.readouterr().err
    assert "--scheduler (a Dask cluster) needs distributed" in err and "pip install 'o3d-seqcc[dask]'" in err


@pytest.mark.parametrize("argv, command", [
    (["run", "s", "--out", "o"], "run"), (["-q", "-j", "2", "run", "s", "--out", "o", "-j", "1"], "run"),
    (["--jobs=2", "-v", "texture", "s", "--out", "o"], "texture"),
    (["-j2", "--max-image-pixels", "10", "info", "s"], "info"), (["--scheduler", "run", "seams", "x"], "seams"),
    (["--help"], None), (["bogus", "run"], None), (["--version"], None), ([], None), (["-x", "run"], None)])
def test_a_command_line_is_parsed_with_its_command_alone(argv, command):
    from o3d_seqcc.cli import build_parser, command_of

    assert command_of(argv) == command
    if command is not None:  # the one command's parser reads it as the whole parser does
        one, full = build_parser(commands=[command]).parse_args(argv), build_parser().parse_args(argv)
        assert {k: v for k, v in vars(one).items() if k != "_subparsers"} == \
            {k: v for k, v in vars(full).items() if k != "_subparsers"}


def test_starting_a_command_imports_no_other_commands_modules():
    import subprocess
    import sys

    code = ("import sys\nfrom o3d_seqcc.cli import main\nassert main(['run', '--help']) == 0\n"
            "print(sorted(m for m in sys.modules if m.startswith(('o3d_seqcc.cli.', 'o3d_seqcc.demo', 'o3d_seqcc.synthetic', "
            "'matplotlib'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    harness = ["console", "correction_flags", "parser", "runtime", "scene_flags", "texture_flags"]  # run's flags
    assert out.strip().splitlines()[-1] == str(sorted(f"o3d_seqcc.cli.{m}" for m in harness + ["run"]))


def test_the_interpreter_exit_skips_its_cycle_collections():
    """main() registers gc.freeze at exit, once: a run's modules' objects are not traversed again at exit."""
    import subprocess
    import sys

    code = ("import atexit, gc\nfrom o3d_seqcc.cli import main\nn = atexit._ncallbacks()\n"
            "main(['run', '--help']); main(['info', '--help'])\nassert atexit._ncallbacks() == n + 1\n"
            "assert gc.get_freeze_count() == 0\natexit._run_exitfuncs()\nprint(gc.get_freeze_count() > 0)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "True"


def test_a_command_limits_mallocs_arenas_unless_the_user_did(monkeypatch):
    import ctypes
    import sys

    import o3d_seqcc.cli as cli

    calls = []

    class Libc:
        def mallopt(self, option, value):
            calls.append((option, value))
            return 1

    monkeypatch.setattr(ctypes, "CDLL", lambda name: Libc())
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.delenv("MALLOC_ARENA_MAX", raising=False)
    cli._fewer_malloc_arenas()
    assert calls == [(-8, cli.MALLOC_ARENAS)]  # M_ARENA_MAX
    monkeypatch.setenv("MALLOC_ARENA_MAX", "4")
    cli._fewer_malloc_arenas()
    monkeypatch.delenv("MALLOC_ARENA_MAX")
    monkeypatch.setattr(sys, "platform", "darwin")
    cli._fewer_malloc_arenas()
    assert len(calls) == 1
