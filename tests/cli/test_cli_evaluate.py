"""Tests of ``o3d-seqcc evaluate`` on a small synthetic scene."""

from __future__ import annotations

import json

import numpy as np
import pytest

from o3d_seqcc.cli import COMMANDS, main


@pytest.fixture(scope="module")
def syn(tmp_path_factory):
    import o3d_seqcc.synthetic as synthetic
    out = tmp_path_factory.mktemp("syn") / "scene"
    return synthetic.make_synthetic_scene(out, n_views=12, width=160, height=120, seed=0, photometric="camera")


def test_evaluate_registered():
    assert "evaluate" in COMMANDS


def test_evaluate_prints_and_writes_json(syn, tmp_path, capsys):
    from o3d_seqcc.mappings.compute import compute_mappings
    from o3d_seqcc.evaluation.metrics import evaluate

    js = tmp_path / "ev.json"
    assert main(["evaluate", str(syn.root / "scene.json"), "--json", str(js)]) == 0
    text = capsys.readouterr().out
    assert "PSNR" in text and "CIEDE2000" in text
    d = json.loads(js.read_text())
    ev = evaluate([v.load_image() for v in syn.scene.views], compute_mappings(syn.scene, mappings="vertices"))
    assert d["evaluation"]["psnr"]["mean"] == pytest.approx(ev.psnr.mean)
    assert d["evaluation"]["ciede2000"]["weighted_mean"] == pytest.approx(ev.ciede2000.weighted_mean)
    assert d["evaluation"]["n_pairs"] == ev.n_pairs and len(d["evaluation"]["pairs"]) == ev.n_pairs
    # --holdout scores the held-out faces only: fewer mappings
    js2 = tmp_path / "ev2.json"
    assert main(["-q", "evaluate", str(syn.root / "scene.json"), "--holdout", "0.5", "--json", str(js2)]) == 0
    d2 = json.loads(js2.read_text())
    assert 0 < d2["evaluation"]["n_mappings"] < d["evaluation"]["n_mappings"]


def test_evaluate_with_method_fits_and_scores(syn, tmp_path, capsys):
    import o3d_seqcc.correction  # noqa: F401
    js = tmp_path / "m.json"
    argv = ["-q", "evaluate", str(syn.root / "scene.json"), "--method", "gain-compensation", "--holdout", "0.5",
            "--reference", "v00", "--t-npm", "20", "--mappings", "dense", "--json", str(js)]
    assert main(argv) == 0
    d = json.loads(js.read_text())
    assert d["reference"] == "v00" and set(d["methods"]) == {"none", "gain-compensation"}
    none, gc = d["methods"]["none"], d["methods"]["gain-compensation"]
    assert gc["in_sample"]["ciede2000"]["mean"] < none["in_sample"]["ciede2000"]["mean"]
    assert gc["held_out"]["ciede2000"]["mean"] < none["held_out"]["ciede2000"]["mean"]
    assert main(["-q", "evaluate", str(syn.root / "scene.json"), "--method", "bogus"]) == 2
    assert "valid" in capsys.readouterr().err


def test_correct_chains_into_evaluate(syn, tmp_path):
    out = tmp_path / "out"
    rc = main(["-q", "correct", str(syn.root / "scene.json"), "--reference", "v00", "--t-npm", "20",
               "--mappings", "dense", "--out", str(out)])
    assert rc == 0
    js = tmp_path / "after.json"
    assert main(["-q", "evaluate", str(out / "scene.json"), "--json", str(js)]) == 0
    js0 = tmp_path / "before.json"
    assert main(["-q", "evaluate", str(syn.root / "scene.json"), "--json", str(js0)]) == 0
    after = json.loads(js.read_text())["evaluation"]["ciede2000"]["mean"]
    before = json.loads(js0.read_text())["evaluation"]["ciede2000"]["mean"]
    assert np.isfinite(after) and after < before
