"""The report says what was done (issue 38): its sentences about settings are derived from the run's settings and
the library's defaults, not written by hand."""

from __future__ import annotations

import re

import pytest

import o3d_seqcc as sc
from o3d_seqcc.correction.settings import CorrectionSettings

FAST = {"t_npm": 10, "atlas_size": 256, "seams": False}


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("sentences") / "R", n_views=4, width=64, height=48,
                                   seen_only=True, cell_size=0.25)


def _text(html: str) -> str:
    html = re.sub(r"<script.*?</script>|data:[^\"']+", "", html, flags=re.S)
    return " ".join(re.sub(r"<[^>]+>", " ", html).split())


@pytest.mark.parametrize("mappings", ["surface", "dense"])
def test_table2_callout_names_corrects_defaults_and_this_runs_mappings(room, tmp_path, mappings):
    d = CorrectionSettings()
    out = tmp_path / "o"
    sc.pipeline.run(room.scene, mappings=mappings, **FAST).save(out, formats="glb")
    text = _text((out / "report.html").read_text(encoding="utf-8"))
    assert f"--mappings {mappings}" in text
    assert f"correct's own defaults, reference {d.reference} and {d.mappings} mappings" in text
    same = "as this run's" if mappings == d.mappings else f"this run used {mappings} mappings"
    assert f"{d.mappings} mappings ({same})" in text
    at = text.index("correct's own defaults")
    callout = text[text.rindex("o3d-seqcc correct", 0, at):text.index("PSNR dB", at)]
    assert ("vertex mappings" in callout) == (d.mappings == "vertices" or mappings == "vertices")


def test_a_texture_report_talks_about_no_correction(room, tmp_path):
    out = tmp_path / "t"
    sc.pipeline.texture(room.scene, **{k: v for k, v in FAST.items() if k != "t_npm"}).save(out, formats="glb")
    text = _text((out / "report.html").read_text(encoding="utf-8"))
    assert "this command corrects no colours" in text and "what the correction" not in text
    run = tmp_path / "r"
    sc.pipeline.run(room.scene, **FAST).save(run, formats="glb")
    assert "shows what the correction (and the seam leveling) changes" in _text((run / "report.html").read_text())


def test_the_depth_filter_turned_off_is_named(room, tmp_path):
    from dataclasses import replace

    with_depth = sc.pipeline.texture(room.scene, **{k: v for k, v in FAST.items() if k != "t_npm"})
    page = _text(sc.report.html_report(with_depth))
    assert "depth_consistency on for every photo" in page
    bare = sc.Scene(room.scene.mesh, tuple(replace(v, depth=None) for v in room.scene.views[:3]) + room.scene.views[3:])
    res = sc.pipeline.texture(bare, **{k: v for k, v in FAST.items() if k != "t_npm"})
    page = _text(sc.report.html_report(res))
    assert "depth_consistency off for 3 of 4 photos (no depth map or point cloud): v00, v01, v02" in page
