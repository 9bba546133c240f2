"""``--uv keep`` (issue 35): ``o3d-seqcc run`` bakes into the mesh's own UV layout and hands the mesh back as it was."""

from __future__ import annotations

import json

import numpy as np
import pytest

from o3d_seqcc.cli import main


@pytest.fixture(scope="module")
def room_uv(tmp_path_factory):
    """A small synthetic room and an OBJ of its mesh with xatlas's UV layout (vt, separate from v)."""
    import trimesh
    import xatlas

    from o3d_seqcc import load_scene
    from o3d_seqcc.synthetic import make_synthetic_scene

    root = tmp_path_factory.mktemp("uvkeep")
    syn = make_synthetic_scene(root / "scene", n_views=8, width=160, height=120, seed=1)
    m = load_scene(syn.root / "scene.json").load_mesh()
    vmap, faces, uv = xatlas.parametrize(np.asarray(m.vertices, np.float32), np.asarray(m.faces, np.uint32))
    t = trimesh.Trimesh(vertices=np.asarray(m.vertices)[vmap], faces=faces, process=False,
                        visual=trimesh.visual.TextureVisuals(uv=uv))
    path = root / "room_uv.obj"
    path.write_text(trimesh.exchange.obj.export_obj(t, include_normals=False, include_texture=True,
                                                    write_texture=False, mtl_name=None), encoding="utf-8")
    return syn.root / "scene.json", path


def _corners(path):
    from o3d_seqcc.io.mesh_files import read_corner_uv, read_mesh

    v, f, _ = read_mesh(path)
    return v[f], read_corner_uv(path, v, f)


def test_run_uv_keep_keeps_positions_faces_and_uvs(room_uv, tmp_path, capsys):
    scene, mesh = room_uv
    out = tmp_path / "keep"
    assert main(["run", str(scene), "--mesh", str(mesh), "--out", str(out), "--uv", "keep", "--no-seams"]) == 0
    printed = capsys.readouterr().out
    assert "texture memory:" in printed and "MiB" in printed
    want_pos, want_uv = _corners(mesh)
    for name in ("mesh.obj", "mesh.glb"):
        pos, uv = _corners(out / name)
        assert pos.shape == want_pos.shape  # the same faces, in order
        np.testing.assert_allclose(pos, want_pos, atol=1e-6)  # float32 in the files; the frame kept
        np.testing.assert_allclose(uv, want_uv, atol=1e-6)
    rep = json.loads((out / "report.json").read_text())
    a = rep["atlas"]
    assert a["uv"] == "keep" and a["pages"] == 1 and a["page_width"] == a["page_height"]
    assert a["uv_layout"]["overlapping_faces"] == 0 and a["uv_layout"]["zero_area_faces"] == 0
    mem = a["texture_memory"]
    assert mem["gpu_bytes"] > 4 * a["page_width"] * a["page_height"]  # the mip chain on top of the base level
    assert rep["export"]["orientation"]["up_axis"] == "none"  # --up-axis auto: the mesh's own frame with --uv keep


def test_uv_keep_on_a_mesh_without_uvs_is_refused_before_any_work(room_uv, tmp_path, capsys):
    scene, _ = room_uv
    out = tmp_path / "none"
    assert main(["-q", "run", str(scene), "--out", str(out), "--uv", "keep"]) == 2
    err = capsys.readouterr().err
    assert "has no texture coordinates" in err and "--uv keep" in err
    assert not out.exists()


def test_uv_keep_through_the_open3d_front_door(room_uv):
    import open3d as o3d

    from o3d_seqcc import load_scene
    from o3d_seqcc.open3d_api import texture_mesh

    scene_path, mesh_path = room_uv
    sc = load_scene(scene_path)
    m = o3d.io.read_triangle_mesh(str(mesh_path))
    assert m.has_triangle_uvs()
    images = [v.load_image() for v in sc.views]
    cams = [v.to_open3d() for v in sc.views]
    out = texture_mesh(m, images, cams, uv="keep", correct=False)
    np.testing.assert_allclose(out.triangle.texture_uvs.numpy().reshape(-1, 3, 2),
                               np.asarray(m.triangle_uvs).reshape(-1, 3, 2), atol=1e-6)
    pos = out.vertex.positions.numpy()[out.triangle.indices.numpy()]
    np.testing.assert_allclose(pos, np.asarray(m.vertices)[np.asarray(m.triangles)], atol=1e-6)
