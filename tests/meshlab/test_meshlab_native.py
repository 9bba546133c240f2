"""What the native MeshLab plugin is built with (meshlab_filters.native) and the --progress-lines it reads.

These need no MeshLab: the table the C++ plugin is generated from must carry the library's
defaults and help texts and name options the command line has.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest

import o3d_seqcc as sc
from meshlab_filters import get_filter
from meshlab_filters.native import (CORRECT_TITLE, NATIVE_FILTERS, TEXTURE_TITLE, cli_arguments, cpp_header,
                                    filter_script, native_filters)
from o3d_seqcc.settings import CorrectionSettings
from o3d_seqcc.texturing import TextureSettings


def test_filter_names_are_the_contract():
    assert [f["title"] for f in native_filters()] == [
        "Sequential colour correction of rasters (o3d_seqcc)", "Seamless texture from rasters (o3d_seqcc)"]
    assert (CORRECT_TITLE, TEXTURE_TITLE) == tuple(f.title for f in NATIVE_FILTERS)


def test_parameters_carry_the_library_defaults_and_help_texts():
    table = {f["title"]: {p["name"]: p for p in f["parameters"]} for f in native_filters()}
    tex, cor = table[TEXTURE_TITLE], table[CORRECT_TITLE]
    ts = TextureSettings()
    assert tex["atlassize"]["default"] == str(ts.atlas_size) and tex["atlassize"]["flag"] == "--atlas-size"
    assert tex["texelsperpixel"]["default"] == str(ts.texels_per_pixel)
    assert tex["selection"]["default"] == ts.selection and ts.selection in tex["selection"]["values"]
    cs = CorrectionSettings()  # every default from the settings (tests/test_settings.py checks all of them)
    assert cor["tnpm"]["default"] == str(cs.t_npm)
    assert cor["method"]["default"] == cs.method
    for f in NATIVE_FILTERS:
        reg = get_filter(f.registry)
        for p in table[f.title].values():
            if p["name"] != "savedir":
                assert p["tooltip"] == reg.parameter(p["name"]).description and p["tooltip"]
            assert p["label"] == reg.parameter(p["name"]).label
    assert tex["reference"]["kind"] == "raster" and tex["overwrite"]["kind"] == "bool"


def test_cli_arguments_are_options_of_the_commands():
    from o3d_seqcc.cli import build_parser

    parser = build_parser()
    for title in (CORRECT_TITLE, TEXTURE_TITLE):
        args = cli_arguments(title, {"savedir": "O"})
        parsed = parser.parse_args([args[0], "scene.json", *args[1:]])  # argparse would exit on an unknown one
        assert parsed.out == "O"
    run = parser.parse_args(["run", "s", *cli_arguments(TEXTURE_TITLE, {"tnpm": 7, "overwrite": True})[1:]])
    assert run.t_npm == 7 and run.overwrite and run.reference == "auto"
    off = cli_arguments(TEXTURE_TITLE, {"colorcorrection": False})
    assert off[0] == "texture" and "--t-npm" not in off and "--atlas-size" in off
    with pytest.raises(TypeError, match="unknown parameter"):
        cli_arguments(TEXTURE_TITLE, {"t_npm": 3})


def test_generated_header_and_filter_script(tmp_path):
    text = cpp_header()
    literal = re.search(r'R"o3dseqcc\((.*)\)o3dseqcc"', text, re.S).group(1)
    assert json.loads(literal) == native_filters()
    r = subprocess.run([sys.executable, "-m", "meshlab_filters.native", "header", str(tmp_path / "h.h")],
                       capture_output=True, text=True)
    assert r.returncode == 0 and (tmp_path / "h.h").read_text() == text
    mlx = filter_script((TEXTURE_TITLE, {"reference": 2, "method": "seqcc", "tnpm": 9}))
    params = re.findall(r'<Param name="(\w+)" type="(\w+)"[^>]* value="([^"]*)"', mlx)
    assert [p[0] for p in params] == [p["name"] for p in native_filters()[1]["parameters"]]  # all, in order
    values = {n: v for n, _, v in params}
    assert values["reference"] == "3" and values["tnpm"] == "9"  # raster 2 = enum index 3 (0 is "auto")
    assert values["method"] == str(native_filters()[1]["parameters"][2]["values"].index("seqcc"))


def test_progress_lines_of_the_command_line(tmp_path):
    scene = sc.make_synthetic_scene(tmp_path / "S", n_views=4, width=96, height=72, seed=5, cell_size=0.2)
    r = subprocess.run([sys.executable, "-m", "o3d_seqcc", "correct", str(scene.root), "--out", str(tmp_path / "C"),
                        "--t-npm", "20", "--no-metrics", "--progress-lines"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("o3d-seqcc-progress ")]
    percents = [int(ln.split()[1]) for ln in lines]
    assert percents[0] == 0 and percents[-1] == 100 and percents == sorted(percents) and len(lines) >= 6
    stages = [ln.split(maxsplit=2)[2] for ln in lines]
    assert "mappings" in stages and "correction" in stages and "export" in stages and stages[-1] == "done"
    assert any(s.startswith("mappings: visibility ") for s in stages)  # a loop inside a stage: "desc i/n"
    quiet = subprocess.run([sys.executable, "-m", "o3d_seqcc", "correct", str(scene.root), "--out",
                            str(tmp_path / "D"), "--t-npm", "20", "--no-metrics"], capture_output=True, text=True)
    assert quiet.returncode == 0 and "o3d-seqcc-progress" not in quiet.stderr
