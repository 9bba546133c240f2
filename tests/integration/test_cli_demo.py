"""``o3d-seqcc demo``: the whole job on a small synthetic scene, scored against ground truth."""

from __future__ import annotations

import json

import pytest

from o3d_seqcc.cli import main


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "demo"
    args = ["demo", "--out", str(out), "--views", "6", "--width", "160", "--height", "120", "--cell-size", "0.1",
            "--t-npm", "100"]
    assert main(args) == 0
    return out, args


def test_demo_writes_the_textured_mesh_and_a_summary(demo_run):
    out, _ = demo_run
    summ = json.loads((out / "demo_summary.json").read_text())["summary"]
    assert summ["load"]["views"] == 6
    for name in ("mesh.glb", "mesh.obj", "mesh.png", "report.json"):
        assert (out / "run" / name).is_file(), name
    assert summ["run"]["reference"] == "v00" and summ["run"]["unreachable"] == []
    assert summ["run"]["seams"]["n_edges"] > 0
    # the result to open sits at the top of --out, the same offline page as run/report.html
    assert (out / "report.html").read_bytes() == (out / "run" / "report.html").read_bytes()


def test_demo_correction_moves_views_toward_ground_truth(demo_run):
    out, _ = demo_run
    gt = json.loads((out / "demo_summary.json").read_text())["summary"]["ground_truth"]
    assert gt["views"][0]["before"] == 0.0  # v00 is the unchanged reference
    assert gt["mean_after"] < 0.5 * gt["mean_before"], gt
    # what the correction bought at the seams: the colour steps between the photos at least halve
    run = json.loads((out / "demo_summary.json").read_text())["summary"]["run"]
    steps = run["selection_seams"]
    assert steps["corrected"]["mean"] < 0.5 * steps["photos"]["mean"], steps
    assert steps == json.loads((out / "run" / "report.json").read_text())["selection_seams"]


def test_demo_reuses_an_identical_scene_and_refuses_other_parameters(demo_run, capsys):
    out, args = demo_run
    assert main(args) == 0
    assert json.loads((out / "demo_summary.json").read_text())["summary"]["synthetic"]["reused"] is True
    other = list(args)
    other[other.index("--views") + 1] = "5"
    assert main(other) == 2
    assert "overwrite" in capsys.readouterr().err


def test_demo_on_fountain_and_its_offline_message(fountain_root, tmp_path, capsys, monkeypatch):
    out = tmp_path / "f"
    assert main(["demo", "--dataset", "fountain", "--data-root", str(fountain_root), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "real photos" in text and text.strip().splitlines()[-1].startswith("report: ")
    summ = json.loads((out / "demo_summary.json").read_text())["summary"]
    assert summ["load"]["views"] == 33 and "ground_truth" not in summ
    assert summ["run"]["unseen_area"] < 0.05 and summ["run"]["unseen_input_faces"] < 0.05 * summ["run"]["input_faces"]
    import open3d as o3d

    def offline():
        raise RuntimeError("[Open3D Error] Download.cpp:182: Downloading failed from available mirrors.")

    monkeypatch.setattr(o3d.data, "SampleFountainRGBDImages", offline)
    assert main(["demo", "--dataset", "fountain", "--out", str(tmp_path / "g")]) == 2
    assert "give it with --data-root DIR" in capsys.readouterr().err


def test_demo_scene_is_mostly_seen_and_quiet(demo_run, capsys):
    out, args = demo_run
    summ = json.loads((out / "demo_summary.json").read_text())["summary"]
    r = summ["run"]  # (faces split into parts: the unseen ones are counted in area and in input faces)
    assert r["unseen_area"] < 0.15 and r["unseen_input_faces"] < 0.15 * r["input_faces"], r


def test_demo_never_replaces_a_report_it_did_not_write(tmp_path):
    """A report.html in --out that no demo wrote (no demo_summary.json beside it) is refused before any work."""
    from o3d_seqcc.demo import run_demo
    from o3d_seqcc.errors import InputError

    (tmp_path / "report.html").write_text("mine")
    with pytest.raises(InputError, match="report.html that no demo wrote"):
        run_demo(tmp_path, n_views=4)
    assert (tmp_path / "report.html").read_text() == "mine" and sorted(p.name for p in tmp_path.iterdir()) == ["report.html"]
