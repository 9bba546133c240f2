"""Any coordinates: a scene far from the origin (UTM-like) gives what it gives at the origin, and its files keep its frame."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

import o3d_seqcc as sc
from o3d_seqcc.io.export import export_glb, export_meshlab_ply, export_obj, export_ply
from o3d_seqcc.evaluation.metrics import image_delta_e
from o3d_seqcc.evaluation.render import raycast, render_textured
from o3d_seqcc.texturing import load_textured_mesh
from o3d_seqcc.visibility.compute import compute_visibility

ROOM = {"n_views": 8, "width": 160, "height": 120, "layout": "two-rings", "seen_only": True, "cell_size": 1.0}
SHIFTS = {"origin": 0.0, "5e5": 5e5, "1e7": 1e7}


@pytest.fixture(scope="module")
def rooms(tmp_path_factory):
    root = tmp_path_factory.mktemp("far")
    return {k: sc.make_synthetic_scene(root / k, origin=(s, -0.5 * s, 0.1 * s), **ROOM) for k, s in SHIFTS.items()}


def test_the_generator_moves_mesh_and_cameras_not_the_images(rooms):
    a, b = rooms["origin"], rooms["1e7"]
    shift = np.array(b.metadata["origin"])
    np.testing.assert_allclose(b.scene.load_mesh().vertices - shift, a.scene.load_mesh().vertices, atol=1e-8)
    for va, vb in zip(a.scene.views, b.scene.views):
        np.testing.assert_allclose(vb.center - shift, va.center, atol=1e-8)
        assert np.array_equal(va.load_image(), vb.load_image())


@pytest.mark.parametrize("far", ["5e5", "1e7"])
def test_far_scene_has_the_same_faces_and_visibility_as_at_the_origin(rooms, far):
    """Same split faces, same filter bits per view (ray casting in a local frame; float32 at 1e7 m holds metres)."""
    a = compute_visibility(rooms["origin"].scene)
    b = compute_visibility(rooms[far].scene)
    assert a.stats["split"]["faces_split"] > 0 and a.n_faces == b.n_faces
    np.testing.assert_array_equal(a.mesh.faces, b.mesh.faces)
    for ra, rb in zip(a.records, b.records):
        np.testing.assert_array_equal(ra.faces, rb.faces)
        np.testing.assert_array_equal(ra.flags, rb.flags)
        np.testing.assert_allclose(ra.area, rb.area, rtol=1e-4)


def test_far_scene_gives_the_same_texture_as_at_the_origin(rooms):
    """The whole run at 1e7 m: the same unseen counts, and its texture rendered from every view within 0.5 CIEDE2000
    of the origin's (the renders themselves ray cast in a local frame)."""
    runs = {k: sc.pipeline.run(rooms[k].scene, reference=0) for k in ("origin", "1e7")}
    sa, sb = runs["origin"].selection_stats, runs["1e7"].selection_stats
    for key in ("faces", "unseen_faces", "unseen_input_faces", "partly_seen_input_faces"):
        assert sa[key] == sb[key], key
    de = [image_delta_e(render_textured(runs["origin"].textured, va), render_textured(runs["1e7"].textured, vb))
          for va, vb in zip(rooms["origin"].scene.views, rooms["1e7"].scene.views)]
    assert max(de) < 0.5, de


def test_renders_of_a_far_mesh_hit_the_same_faces(rooms):
    a, b = rooms["origin"], rooms["1e7"]
    ma, mb = a.scene.load_mesh(), b.scene.load_mesh()
    for va, vb in zip(a.scene.views[:3], b.scene.views[:3]):
        ha, hb = raycast(ma, va), raycast(mb, vb)
        assert np.mean(ha.face_ids == hb.face_ids) > 0.999
        np.testing.assert_allclose(ha.depth[ha.mask], hb.depth[ha.mask], atol=1e-4)


def _far_textured(shift: float):
    """A textured quad 1 m wide at ``shift`` from the origin."""
    from o3d_seqcc.texturing import TexturedMesh

    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.2]], float) + [shift, -shift / 3, 12.5]
    f = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    tex = np.random.default_rng(0).integers(0, 255, (8, 8, 3), dtype=np.uint8)
    return TexturedMesh(vertices=v, faces=f, uv=uv, texture=tex, face_view=np.zeros(2, np.int64))


def test_files_of_a_far_mesh_keep_its_frame(tmp_path):
    """GLB: float32 positions relative to the node's translation (the box centre); OBJ: enough digits; PLY: double
    positions; MeshLab's layer relative to an offset. Read back, every file gives the positions to 1e-6 m."""
    tm = _far_textured(1e7)
    glb = export_glb(tm, tmp_path / "m.glb")
    data = glb.read_bytes()
    n = struct.unpack("<I", data[12:16])[0]
    node = json.loads(data[20:20 + n])["nodes"][0]
    np.testing.assert_allclose(node["translation"], tm.vertices.min(0) / 2 + tm.vertices.max(0) / 2)
    for path in (glb, export_obj(tm, tmp_path / "m.obj")):
        back = load_textured_mesh(path)
        d = np.abs(back.vertices[:, None, :] - tm.vertices[None]).max(axis=2).min(axis=1)
        assert d.max() < 1e-6, (path.name, d.max())
    ply = export_ply(tm, tmp_path / "c.ply")
    assert b"property double x" in ply.read_bytes()[:400]
    off = np.array([1e7, -1e7 / 3, 12.5])
    layer = export_meshlab_ply(tm, tmp_path / "l.ply", offset=off)
    assert b"property float x" in layer.read_bytes()[:400]  # small numbers relative to the offset
    near = export_glb(_far_textured(0.0), tmp_path / "n.glb").read_bytes()
    n = struct.unpack("<I", near[12:16])[0]
    assert "translation" not in json.loads(near[20:20 + n])["nodes"][0]  # a scene near the origin: unchanged


def test_a_far_run_writes_its_outputs_in_the_input_frame(rooms, tmp_path):
    """o3d-seqcc run on the room at 1e7 m: mesh.glb and mesh.obj hold the input's coordinates, the MeshLab project
    places its layer back there, and the project reloads with the same cameras."""
    from o3d_seqcc.io.meshlab import load_mlp

    syn = rooms["1e7"]
    res = sc.pipeline.run(syn.scene, reference=0, seams=False)
    res.save(tmp_path / "out", report=False)
    lo, hi = syn.scene.load_mesh().vertices.min(0), syn.scene.load_mesh().vertices.max(0)
    R = np.asarray(json.loads((tmp_path / "out" / "report.json").read_text())["export"]["orientation"]["rotation"])
    for name in ("mesh.obj", "mesh.glb"):
        v = load_textured_mesh(tmp_path / "out" / name).vertices @ R  # undo the recorded Y-up rotation
        assert (v.min(0) >= lo - 1e-3).all() and (v.max(0) <= hi + 1e-3).all(), name
    import xml.etree.ElementTree as ET

    root = ET.parse(tmp_path / "out" / "project.mlp").getroot()
    T = np.array([float(x) for x in root.find("MeshGroup/MLMesh/MLMatrix44").text.split()]).reshape(4, 4)
    assert abs(T[0, 3]) > 1e6 and np.allclose(T[:3, :3], np.eye(3))
    layer = sc.load_mesh(tmp_path / "out" / "mesh_meshlab.ply").vertices + T[:3, 3]
    assert (layer.min(0) >= lo - 1e-3).all() and (layer.max(0) <= hi + 1e-3).all()
    back = load_mlp(tmp_path / "out" / "project.mlp")  # the placement folded into the cameras: the layer's frame
    for vb, v in zip(back.views, syn.scene.views):
        np.testing.assert_allclose(vb.center + T[:3, 3], v.center, atol=1e-3)
