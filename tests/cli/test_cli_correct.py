"""``o3d-seqcc correct``: outputs, atomic folder, refusal to overwrite, 16-bit, chaining."""

from __future__ import annotations

import json

import numpy as np
import pytest

from o3d_seqcc.io.images import read_image, write_image
from o3d_seqcc.cli import main
from o3d_seqcc import load_scene, save_scene


@pytest.fixture(scope="module")
def synth(tmp_path_factory):
    import o3d_seqcc.synthetic as synthetic
    out = tmp_path_factory.mktemp("synth")
    return synthetic.make_synthetic_scene(out, n_views=6, width=160, height=120, seed=3)


def test_correct_writes_images_scene_report_and_chains(synth, tmp_path):
    out = tmp_path / "corrected"
    scene_json = synth.scene.views[0].image.parents[1] / "scene.json"
    assert main(["correct", str(scene_json), "--reference", "auto", "--out", str(out)]) == 0
    scene = load_scene(out / "scene.json")
    assert scene.names == synth.scene.names
    for v, orig in zip(scene.views, synth.scene.views):
        assert v.image == (out / "images" / f"{v.name}.png").resolve()
        assert v.depth == orig.depth  # depth maps still point at the originals
        assert read_image(v.image).dtype == np.uint8
    rep = json.loads((out / "report.json").read_text())
    c = rep["correction"]  # report.schema: the correction where run's report has it
    assert rep["schema"] == "o3d_seqcc.report/2" and rep["command"] == "correct"
    assert c["method"] == "seqcc-global" and c["reference"] in scene.names  # the default
    assert c["graph_edges"] and {"a", "b", "n", "weight"} <= set(c["graph_edges"][0])
    assert set(c["paths"]) | set(c["unreachable"]) == set(scene.names)
    assert rep["metrics"]["after"]["ciede2000"]["mean"] < rep["metrics"]["before"]["ciede2000"]["mean"]
    assert len(c["lookup_tables"]["tables"]) == len(scene.names)
    assert "fit" in c["timings_s"] and {"mappings", "correction", "metrics", "write_images", "report"} <= set(rep["timings_s"])
    assert rep["files"]["scene_json"] == str(out / "scene.json")
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary leftovers
    # refuses a non-empty OUT, replaces it with --overwrite
    assert main(["correct", str(scene_json), "--out", str(out), "--method", "none"]) == 2
    assert json.loads((out / "report.json").read_text())["correction"]["method"] == "seqcc-global"
    assert main(["correct", str(scene_json), "--out", str(out), "--method", "none", "--overwrite"]) == 0
    assert json.loads((out / "report.json").read_text())["correction"]["method"] == "none"
    # chains: the corrected scene is a valid input of the next command
    assert main(["info", str(out / "scene.json")]) == 0


def test_correct_sixteen_bit_and_bad_reference(synth, tmp_path, capsys):
    scene = synth.scene
    paths = []
    for v in scene.views:
        p = tmp_path / "img16" / f"{v.name}.png"
        write_image(p, read_image(v.image).astype(np.uint16) * 257)
        paths.append(p)
    s16 = tmp_path / "s16" / "scene.json"
    save_scene(scene.replace_images(paths), s16)
    out = tmp_path / "out16"
    assert main(["correct", str(s16), "--out", str(out), "--no-metrics"]) == 0
    img = read_image(out / "images" / f"{scene.names[1]}.png")
    assert img.dtype == np.uint16
    assert json.loads((out / "report.json").read_text())["metrics"] is None
    assert main(["correct", str(s16), "--out", str(tmp_path / "x"), "--reference", "nope"]) == 2
    err = capsys.readouterr().err
    assert "nope" in err and scene.names[0] in err
    assert not (tmp_path / "x").exists()
