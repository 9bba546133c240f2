"""One report.json schema for every command, and a run's report drawn from what the run returns (issue 23)."""

from __future__ import annotations

import json

import pytest

import o3d_seqcc as sc
from o3d_seqcc.report.schema import KEYS, SCHEMA


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    d = tmp_path_factory.mktemp("schema") / "room"
    sc.make_synthetic_scene(d, n_views=4, width=128, height=96, cell_size=0.2, seed=2)
    return d


def _stage_functions():
    """(module, name) of every pipeline stage a report could re-run."""
    import o3d_seqcc.correction as correction
    import o3d_seqcc.mappings.compute as mappings
    import o3d_seqcc.pipeline as pipeline
    import o3d_seqcc.report.page as page
    import o3d_seqcc.texturing as texturing
    import o3d_seqcc.visibility.compute as visibility

    return [(visibility, "compute_visibility"), (mappings, "compute_mappings"), (correction, "correct"),
            (texturing, "select_views"), (texturing, "bake_texture"), (page, "selection_seams_of"),
            *((pipeline, n) for n in ("compute_visibility", "compute_mappings", "correct", "select_views",
                                      "bake_texture", "seam_metric"))]


def _forbid_stages(monkeypatch) -> list:
    called = []
    for mod, name in _stage_functions():
        def stop(*a, _n=f"{mod.__name__}.{name}", **k):
            called.append(_n)
            raise AssertionError(f"{_n} re-run while the report was written")
        monkeypatch.setattr(mod, name, stop)
    return called


def test_run_and_correct_write_one_schema_drawn_from_the_result(room, tmp_path, monkeypatch):
    """``run`` / ``texture`` / ``correct`` write the same top-level keys (one ``timings_s``, a ``schema``), and
    their report.html is drawn from the result objects: no stage runs again while they are saved."""
    run = sc.pipeline.run(room, t_npm=50)
    tex = sc.pipeline.texture(room)
    cor = sc.pipeline.correct_scene(room, t_npm=50)
    called = _forbid_stages(monkeypatch)
    run.save(tmp_path / "run")
    tex.save(tmp_path / "texture")
    cor.save(tmp_path / "correct")
    monkeypatch.undo()
    assert called == []
    reps = {k: json.loads((tmp_path / k / "report.json").read_text()) for k in ("run", "texture", "correct")}
    for command, rep in reps.items():
        assert list(rep) == list(KEYS), command
        assert rep["schema"] == SCHEMA and rep["command"] == command and "timings" not in rep
        assert rep["timings_s"] and all(isinstance(v, (int, float)) for v in rep["timings_s"].values())
        assert rep["views"] == run.scene.names and (tmp_path / command / "report.html").is_file()
        assert "report" in rep["timings_s"]
    assert reps["texture"]["correction"] is None and reps["correct"]["texture_settings"] is None
    c_run, c_cor = reps["run"]["correction"], reps["correct"]["correction"]
    assert set(c_cor) - set(c_run) == {"lookup_tables"} and set(c_run) <= set(c_cor)
    assert c_run["reference"] == c_cor["reference"] and c_run["paths"] == c_cor["paths"]
    assert reps["correct"]["files"]["report_html"] == str(tmp_path / "correct" / "report.html")


def _schema_1(rep: dict) -> dict:
    """What an o3d_seqcc before report.schema wrote for the same run."""
    old = {k: v for k, v in rep.items() if k not in ("schema", "views") and v is not None and v != {}}
    if rep["command"] != "correct":
        return old
    c = old.pop("correction")
    s = c["settings"]
    out = {k: old[k] for k in ("command", "scene", "scene_path", "mesh") if k in old}
    out.update(seed=s["seed"], method=c["method"], reference=c["reference"], reference_index=c["reference_index"],
               t_npm=s["t_npm"], t_npm_effective=c["t_npm"], mappings=c["mappings"], views=rep["views"],
               graph_edges=c["graph_edges"], paths=c["paths"], unreachable=c["unreachable"])
    if "metrics" in old:
        out["metrics"] = old["metrics"]
    out.update(lookup_tables=c["lookup_tables"], timings=old["timings_s"], graph_weight=s["graph_weight"])
    return out


def test_older_report_json_folders_still_regenerate(room, tmp_path):
    from o3d_seqcc.run_folder.read import read_report_json

    sc.pipeline.correct_scene(room, t_npm=50).save(tmp_path / "correct")
    sc.pipeline.run(room, t_npm=50).save(tmp_path / "run")
    for name in ("correct", "run"):
        folder = tmp_path / name
        new = json.loads((folder / "report.json").read_text())
        (folder / "report.json").write_text(json.dumps(_schema_1(new)))
        back = read_report_json(folder)
        assert list(back)[:len(KEYS)] == list(KEYS) and back["schema"] == "o3d_seqcc.report/1"
        assert back["correction"]["reference"] == new["correction"]["reference"]
        assert back["correction"]["paths"] == new["correction"]["paths"]
        assert back["timings_s"] == new["timings_s"]
        page = sc.regenerate_report(folder).read_text(encoding="utf-8")
        assert f"toward {new['correction']['reference']}" in page or new["correction"]["reference"] in page
        assert "Timings (s)" in page
