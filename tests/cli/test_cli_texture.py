"""Tests of the ``o3d-seqcc texture`` and ``o3d-seqcc run`` sub-commands on a small synthetic scene."""

from __future__ import annotations

import json

import numpy as np
import pytest

from o3d_seqcc.cli import main


@pytest.fixture(scope="module")
def syn(tmp_path_factory):
    from o3d_seqcc.synthetic import make_synthetic_scene

    return make_synthetic_scene(tmp_path_factory.mktemp("syn") / "scene", n_views=12, width=160, height=120, seed=0)


def _report(out) -> dict:
    return json.loads((out / "report.json").read_text())


def test_texture_writes_outputs_and_refuses_existing_folder(syn, tmp_path, capsys):
    scene_json = str(syn.root / "scene.json")
    out = tmp_path / "tex"
    assert main(["-q", "texture", scene_json, "--out", str(out), "--format", "glb,obj", "--selection", "largest-area"]) == 0
    for name in ("mesh.glb", "mesh.obj", "mesh.mtl", "mesh.png", "selection.npy", "selection.png", "report.json"):
        assert (out / name).is_file(), name
    rep = _report(out)
    # selection picture (Figure 9a) from the view that sees the most faces, at that view's size
    from o3d_seqcc.io.images import read_image

    pic = read_image(out / "selection.png")
    assert pic.shape == (syn.scene.views[0].height, syn.scene.views[0].width, 3)
    assert rep["selection"]["picture_view"] in syn.scene.names
    assert len(np.unique(pic.reshape(-1, 3), axis=0)) > 3
    # global seam leveling on by default
    lev = rep["atlas"]["leveling"]
    assert lev is not None and lev["seam_pairs"] > 0 and lev["seam_step_after"] < lev["seam_step_before"]
    sel = rep["selection"]
    assert sel["method"] == "largest-area" and sel["faces"] == len(np.load(out / "selection.npy"))
    assert sel["unseen_faces"] == int((np.load(out / "selection.npy") < 0).sum())
    assert {"transitions", "interior_edges", "views_used"} <= set(sel)
    assert rep["seams"]["n_edges"] > 0 and 0 <= rep["seams"]["frac_above_5"] <= 1
    assert rep["timings_s"]["total"] > 0
    # existing output folder: refused (exit code 2, clear message), accepted with --overwrite
    capsys.readouterr()
    assert main(["-q", "texture", scene_json, "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(["-q", "texture", scene_json, "--out", str(out), "--overwrite", "--selection", "mrf",
                 "--format", "glb", "--no-seams", "--no-leveling", "--selection-view", "none"]) == 0
    rep_mrf = _report(out)
    assert rep_mrf["selection"]["method"] == "mrf" and rep_mrf["seams"] is None
    assert rep_mrf["atlas"]["leveling"] is None and "picture_view" not in rep_mrf["selection"]
    assert rep_mrf["selection"]["transitions"] <= sel["transitions"]


def test_texture_bad_format(syn, tmp_path, capsys):
    scene_json = str(syn.root / "scene.json")
    assert main(["-q", "texture", scene_json, "--out", str(tmp_path / "x"), "--format", "fbx", "--no-seams"]) == 2
    assert "fbx" in capsys.readouterr().err


def test_texture_with_images_folder(syn, tmp_path):
    """--images: texture with other images named after the views (here the ground-truth renders)."""
    gt_dir = next(iter(syn.gt_images.values())).parent
    out = tmp_path / "gt"
    assert main(["-q", "texture", str(syn.root / "scene.json"), "--out", str(out), "--images", str(gt_dir),
                 "--format", "glb"]) == 0
    assert _report(out)["images"] == str(gt_dir)
    assert main(["-q", "texture", str(syn.root / "scene.json"), "--out", str(tmp_path / "bad"), "--images",
                 str(tmp_path)]) == 2


def test_run_corrects_and_textures(syn, tmp_path):
    scene_json = str(syn.root / "scene.json")
    out = tmp_path / "run"
    assert main(["-q", "run", scene_json, "--out", str(out), "--format", "glb", "--compare-original"]) == 0
    rep = _report(out)
    assert rep["command"] == "run" and rep["correction"]["reference"] in syn.scene.names
    assert (out / "mesh.glb").is_file()
    for key in ("visibility", "correction", "selection", "bake", "export", "seams", "total"):
        assert key in rep["timings_s"], key
    assert rep["seams"]["mean"] >= 0 and rep["seams_original_images"]["mean"] >= 0


def test_texture_engine_options(syn, tmp_path, capsys):
    """Atlas budget, pages, up axis and texture format from the command line, recorded in report.json:
    the GLB is Y-up (the room's cameras say z is up: positions rotated by the recorded rotation), the
    MeshLab layer keeps the scene's frame and refers to the OBJ's JPEG pages."""
    import trimesh

    from o3d_seqcc.scene import load_mesh

    scene_json = str(syn.root / "scene.json")
    out = tmp_path / "engine"
    assert main(["-q", "texture", scene_json, "--out", str(out), "--format", "glb,obj", "--no-seams",
                 "--atlas-size", "128", "--atlas-overflow", "pages", "--padding", "2", "--texture-format", "jpg",
                 "--jpeg-quality", "80", "--selection-view", "none"]) == 0
    rep = _report(out)
    atlas = rep["atlas"]
    P = atlas["pages"]
    assert P >= 2 and atlas["atlas_size"] == 128 and 0 < atlas["texels_per_pixel"] <= 1.0
    assert {"coverage", "utilization", "density_scale", "charts", "vertices_out", "vertices_in"} <= set(atlas)
    exp = rep["export"]
    assert exp["texture_format"] == "jpg" and exp["jpeg_quality"] == 80
    o = exp["orientation"]
    assert o["up_axis"] == "y" and o["nearest_axis"] == "+z" and o["snapped"] and "glb" in o["applies_to"]
    R = np.array(o["rotation"])
    np.testing.assert_allclose(R @ [0.0, 0.0, 1.0], [0.0, 1.0, 0.0], atol=1e-12)  # z up -> y up
    assert all((out / f"mesh_{p}.jpg").is_file() for p in range(P)) and not (out / "mesh.png").exists()
    head = (out / "mesh_meshlab.ply").read_bytes().split(b"end_header")[0].decode()
    assert head.count("comment TextureFile mesh_") == P and ".jpg" in head
    glb = trimesh.load(str(out / "mesh.glb"), force="mesh", process=False)
    layer = load_mesh(out / "mesh_meshlab.ply")
    # z became y (trimesh repeats the shared vertex buffer per page primitive: compare the bounds)
    np.testing.assert_allclose(glb.bounds, np.stack(
        [(layer.vertices @ R.T).min(0), (layer.vertices @ R.T).max(0)]), atol=1e-4)
    np.testing.assert_allclose(glb.bounds[:, 1], [layer.vertices[:, 2].min(), layer.vertices[:, 2].max()], atol=1e-4)
    # --up-axis none keeps the scene's frame; bad values are refused before any work
    out2 = tmp_path / "none"
    assert main(["-q", "texture", scene_json, "--out", str(out2), "--format", "glb", "--no-seams", "--up-axis", "none",
                 "--selection-view", "none"]) == 0
    assert _report(out2)["export"]["orientation"] == {"up_axis": "none", "rotation": np.eye(3).tolist(),
                                                      "applies_to": ["glb"]}
    capsys.readouterr()
    assert main(["-q", "texture", scene_json, "--out", str(tmp_path / "q"), "--jpeg-quality", "0"]) == 2
    assert "quality" in capsys.readouterr().err
    assert main(["-q", "texture", scene_json, "--out", str(tmp_path / "t"), "--texels-per-pixel", "dense"]) == 2
    assert "texels_per_pixel" in capsys.readouterr().err


def test_atlas_flags_power_of_two_and_texture_memory(syn, tmp_path, capsys):
    """The default page is cut to the charts (sides multiples of 4), --power-of-two makes it a square power of two;
    report.json gives every page's size, coverage and GPU bytes, and the summary prints the total."""
    from o3d_seqcc.texturing.memory import gpu_bytes

    scene_json = str(syn.root / "scene.json")
    reps = {}
    for flag in ("--no-power-of-two", "--power-of-two"):
        out = tmp_path / flag.strip("-")
        assert main(["texture", scene_json, "--out", str(out), "--format", "glb", "--no-seams", flag]) == 0
        printed = capsys.readouterr().out
        a = _report(out)["atlas"]
        mem = a["texture_memory"]
        assert f"texture memory: {mem['gpu_bytes'] / 2**20:.1f} MiB on the GPU" in printed
        assert mem["gpu_bytes"] == sum(p["gpu_bytes"] for p in mem["pages"])
        assert all(p["gpu_bytes"] == gpu_bytes(a["page_width"], a["page_height"]) for p in mem["pages"])
        reps[flag] = a
    cut, square = reps["--no-power-of-two"], reps["--power-of-two"]
    assert cut["page_width"] % 4 == 0 and cut["page_height"] % 4 == 0 and not cut["power_of_two"]
    w = square["page_width"]
    assert w == square["page_height"] and w & (w - 1) == 0 and square["power_of_two"]
    assert cut["page_width"] * cut["page_height"] <= w * w and cut["coverage"] >= square["coverage"]
