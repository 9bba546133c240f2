"""The library pipeline: same defaults and byte-identical outputs as the command line."""

from __future__ import annotations

import json
import re
from dataclasses import fields

import numpy as np
import pytest

import o3d_seqcc as sc
from o3d_seqcc.cli import build_parser, main
from o3d_seqcc.cli.texture_flags import texture_settings_from_args
from o3d_seqcc.texturing import TextureSettings, bake_texture

SMALL = ["--t-npm", "50", "--atlas-size", "1024"]


@pytest.fixture(scope="module")
def small_scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("pipe")
    return sc.make_synthetic_scene(root / "scene", n_views=5, width=160, height=120, seed=3)


def _without_timings(report: dict) -> dict:
    out = {}
    for k, v in report.items():
        if "timings" in k or k == "files" or (k == "atlas" and isinstance(v, dict)):
            continue
        out[k] = _without_timings(v) if isinstance(v, dict) else v
    return out


def test_library_run_equals_command_line_byte_for_byte(small_scene, tmp_path):
    scene_json = str(small_scene.root / "scene.json")
    assert main(["-q", "run", scene_json, "--out", str(tmp_path / "cli"), *SMALL]) == 0
    res = sc.pipeline.run(scene_json, t_npm=50, atlas_size=1024)
    res.save(tmp_path / "lib")
    names = sorted(p.name for p in (tmp_path / "cli").iterdir())
    assert names == sorted(p.name for p in (tmp_path / "lib").iterdir())
    assert {"mesh.glb", "mesh.obj", "mesh.mtl", "mesh.png", "selection.npy", "selection.png", "report.json",
            "report.html"} <= set(names)
    for n in names:
        if n not in ("report.json", "report.html"):
            assert (tmp_path / "cli" / n).read_bytes() == (tmp_path / "lib" / n).read_bytes(), n
    # the HTML report too, but for its timings (the only part that changes from run to run)
    pages = [re.sub(r"<!-- timings -->.*?<!-- /timings -->", "", (tmp_path / d / "report.html").read_text(), flags=re.S)
             for d in ("cli", "lib")]
    assert pages[0] == pages[1] and pages[0] != (tmp_path / "cli" / "report.html").read_text()
    a = json.loads((tmp_path / "cli" / "report.json").read_text())
    b = json.loads((tmp_path / "lib" / "report.json").read_text())
    assert _without_timings(a) == _without_timings(b)
    assert a["seams"]["mean"] == pytest.approx(res.seams.mean) and a["selection"]["method"] == "mrf"


def test_library_defaults_are_the_command_line_defaults(small_scene):
    args = build_parser().parse_args(["run", "scene.json", "--out", "x"])
    assert texture_settings_from_args(args) == TextureSettings()
    d = TextureSettings()
    assert d.selection == "mrf" and d.leveling and d.local_leveling  # what the CLI has always done
    for f in fields(TextureSettings):  # every CLI texture option reads its default from TextureSettings
        if hasattr(args, f.name):
            assert getattr(args, f.name) == getattr(d, f.name), f.name
    assert (args.reference, args.method, args.t_npm, args.mappings) == ("auto", "seqcc-global", "auto", "surface")
    rs = sc.RunSettings()  # the library's defaults (every entry point's: tests/test_settings.py)
    assert (rs.correction.t_npm, rs.correction.mappings, rs.visibility.split_faces) \
        == (args.t_npm, args.mappings, args.split_faces) == ("auto", "surface", True)


def test_texture_only_and_textured_mesh_conversions(small_scene, tmp_path):
    res = sc.pipeline.texture(small_scene.scene, atlas_size=1024)
    assert res.correction is None and res.textured.stats["leveling"] is not None
    tm = res.textured
    # the same bake through the stage function with the same settings
    again = bake_texture(res.visibility.mesh, res.images, res.visibility, res.selection, atlas_size=1024)
    np.testing.assert_array_equal(again.texture, tm.texture)
    o3m = tm.to_open3d()
    assert o3m.triangle.texture_uvs.shape == (len(tm.faces), 3, 2)
    np.testing.assert_allclose(o3m.triangle.texture_uvs.numpy(), tm.uv[tm.faces], atol=1e-6)
    np.testing.assert_array_equal(o3m.material.texture_maps["albedo"].as_tensor().numpy(), tm.texture)
    import open3d as o3d

    assert o3d.t.io.write_triangle_mesh(str(tmp_path / "o3d.obj"), o3m)
    tri = tm.to_trimesh()
    np.testing.assert_allclose(tri.visual.uv, tm.uv)
    assert tri.visual.material.image.size == (tm.texture.shape[1], tm.texture.shape[0])
    with pytest.raises(TypeError, match=r"unknown setting\(s\) \['atlas_sise'\] \(did you mean 'atlas_size'"):
        sc.pipeline.texture(small_scene.scene, atlas_sise=1024)


def test_bad_arguments_fail_before_heavy_work(small_scene, monkeypatch):
    calls = []
    monkeypatch.setattr(sc.pipeline, "compute_visibility", lambda *a, **k: calls.append(1))
    with pytest.raises(sc.InputError, match="unknown view 'nope'"):
        sc.pipeline.run(small_scene.scene, reference="nope")
    with pytest.raises(sc.InputError, match="unknown correction method 'bogus'; valid: "):
        sc.pipeline.run(small_scene.scene, method="bogus")
    with pytest.raises(sc.InputError, match="unknown selection method"):
        sc.pipeline.run(small_scene.scene, selection="best")
    with pytest.raises(sc.InputError, match="unknown mappings mode"):
        sc.pipeline.run(small_scene.scene, mappings="sparse")
    assert not calls
