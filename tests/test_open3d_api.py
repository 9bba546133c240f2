"""The Open3D front door: correct_images / texture_mesh take and give Open3D objects."""

from __future__ import annotations

import json

import cv2
import numpy as np
import open3d as o3d
import pytest

import o3d_seqcc as sc
from o3d_seqcc import InputError
from o3d_seqcc.cli import main
from o3d_seqcc.evaluation.render import render_textured
from o3d_seqcc.texturing import TexturedMesh


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    root = tmp_path_factory.mktemp("o3dapi")
    syn = sc.make_synthetic_scene(root / "S", n_views=5, width=160, height=120, seed=4)
    scene = syn.scene
    mesh = o3d.io.read_triangle_mesh(str(scene.mesh))
    images = [o3d.io.read_image(str(v.image)) for v in scene.views]
    depths = [o3d.io.read_image(str(v.depth)) for v in scene.views]
    params = []
    for v in scene.views:
        p = o3d.camera.PinholeCameraParameters()
        K = v.intrinsic
        p.intrinsic = o3d.camera.PinholeCameraIntrinsic(v.width, v.height, K[0, 0], K[1, 1], K[0, 2], K[1, 2])
        p.extrinsic = v.extrinsic
        params.append(p)
    return syn, mesh, images, depths, params


def test_correct_images_gives_back_the_types_that_came_in(small):
    syn, mesh, images, depths, params = small
    traj = o3d.camera.PinholeCameraTrajectory()
    traj.parameters = params
    want = sc.pipeline.correct_scene(syn.scene, t_npm=50).result.images  # the same job on the files
    out, report = sc.correct_images(mesh, images, traj, depths=depths, t_npm=50, return_report=True)
    assert all(isinstance(o, o3d.geometry.Image) for o in out)
    for o, w in zip(out, want):
        np.testing.assert_array_equal(np.asarray(o), w)
    assert "metrics" in report and report["metrics"]["after"]["ciede2000"]["mean"] < report["metrics"]["before"][
        "ciede2000"]["mean"]
    # tensor images, (K, E) matrices as project_images_to_albedo takes them, legacy mesh as tensor mesh
    timgs = [o3d.t.geometry.Image(o3d.core.Tensor(np.asarray(i))) for i in images]
    Ks = [o3d.core.Tensor(p.intrinsic.intrinsic_matrix) for p in params]
    Es = [o3d.core.Tensor(p.extrinsic) for p in params]
    tout = sc.correct_images(o3d.t.geometry.TriangleMesh.from_legacy(mesh), timgs, (Ks, Es), depths=depths, t_npm=50)
    assert all(isinstance(o, o3d.t.geometry.Image) for o in tout)
    # the tensor mesh holds float32 vertices: the mappings differ in their last bits, and the default
    # method solves all views jointly over every pair, so a few pixels move by a level at most
    d = np.abs(tout[2].as_tensor().numpy().astype(np.int64) - want[2])
    assert d.max() <= 1 and (d > 0).mean() < 0.02
    # float arrays in [0, 1] come back as float arrays of the same dtype
    fimgs = [np.asarray(i).astype(np.float32) / 255 for i in images]
    fout = sc.correct_images(mesh, fimgs, params, depths=depths, t_npm=50)
    assert fout[1].dtype == np.float32 and fout[1].shape == fimgs[1].shape
    # float images are corrected at 16 bits (finer tables): a level at most, but for the pixels a photo clipped,
    # whose level goes through another view's table near its top (measured 2.1 on view 1's clipped green)
    d = np.abs(fout[1] * 255 - want[1])
    clipped = (np.asarray(images[1]) == 255)
    assert d[~clipped].max() <= 1.5 and d[clipped].max() <= 2.5 and d.mean() < 0.3


def test_texture_mesh_is_an_open3d_textured_mesh(small, tmp_path):
    syn, mesh, images, depths, params = small
    tm, res = sc.texture_mesh(mesh, images, params, depths=depths, t_npm=50, atlas_size=1024, return_result=True)
    assert isinstance(tm, o3d.t.geometry.TriangleMesh)
    F = len(res.textured.faces)
    assert tm.triangle.texture_uvs.shape == (F, 3, 2) and tm.triangle.indices.shape == (F, 3)
    assert tm.material.texture_maps["albedo"].rows == res.textured.texture.shape[0]
    assert o3d.t.io.write_triangle_mesh(str(tmp_path / "m.obj"), tm)
    back = o3d.io.read_triangle_mesh(str(tmp_path / "m.obj"), enable_post_processing=False)
    assert len(back.triangles) == F and back.has_triangle_uvs()
    plain = sc.texture_mesh(mesh, images, params, depths=depths, correct=False, atlas_size=1024)
    assert plain.triangle.indices.shape == (F, 3)  # the same faces split as with the correction


@pytest.mark.parametrize("call, match", [
    (lambda m, i, c: sc.correct_images("mesh.ply", i, c), "mesh must be an o3d.geometry.TriangleMesh"),
    (lambda m, i, c: sc.correct_images(m, i[:2], c), "cameras: 5 cameras for 2 images"),
    (lambda m, i, c: sc.correct_images(m, [np.zeros((120, 160), np.uint8)] * 5, c), r"images\[0\] has shape"),
    (lambda m, i, c: sc.correct_images(m, i, "key.log"), "cameras must be an o3d.camera.PinholeCameraTrajectory"),
    (lambda m, i, c: sc.correct_images(m, i, c, depths=[np.zeros((10, 10))] * 5), r"depths\[0\] has shape"),
    (lambda m, i, c: sc.correct_images(m, i, c, depths=[None] * 4), "depths: 4 given for 5 images"),
    (lambda m, i, c: sc.correct_images(m, i, c, reference=9), "view index 9 out of range"),
])
def test_wrong_types_and_sizes_name_the_argument(small, call, match):
    _, mesh, images, _, params = small
    with pytest.raises(InputError, match=match):
        call(mesh, images, params)


def test_fountain_through_open3d_readers_equals_the_command_line(fountain_root, tmp_path):
    """Open3D's own readers in, the same selection and texture as `o3d-seqcc run` out, rendered the right way up."""
    mesh_path = fountain_root / "scene" / "mesh_decimated_uv_blender.ply"
    out = tmp_path / "cli"
    assert main(["-q", "run", str(fountain_root), "--mesh", str(mesh_path), "--out", str(out), "--no-seams"]) == 0
    scene = sc.load_scene(fountain_root, mesh=mesh_path)
    traj = o3d.io.read_pinhole_camera_trajectory(str(fountain_root / "scene" / "key.log"))
    images = [o3d.io.read_image(str(v.image)) for v in scene.views]
    depths = [o3d.io.read_image(str(v.depth)) for v in scene.views]
    tm, res = sc.texture_mesh(o3d.io.read_triangle_mesh(str(mesh_path)), images, traj, depths=depths,
                              seams=False, return_result=True)
    np.testing.assert_array_equal(res.selection, np.load(out / "selection.npy"))
    cli_tex = cv2.cvtColor(cv2.imread(str(out / "mesh.png")), cv2.COLOR_BGR2RGB)
    assert cli_tex.shape == res.textured.texture.shape
    assert np.abs(cli_tex.astype(int) - res.textured.texture).max() <= 1
    report = json.loads((out / "report.json").read_text())
    assert report["correction"]["reference"] == scene.names[res.correction.reference]
    # Open3D's renderer (offscreen, Vulkan on the CPU), from the camera of view 16: the texture is the right way up
    view = scene.views[16]
    photo = cv2.cvtColor(view.load_image(), cv2.COLOR_RGB2GRAY).astype(float)
    flipped = o3d.t.geometry.TriangleMesh(tm)
    uv = tm.triangle.texture_uvs.numpy().copy()
    uv[..., 1] = 1.0 - uv[..., 1]
    flipped.triangle.texture_uvs = o3d.core.Tensor(uv)
    renders, mask = _open3d_render([tm, flipped], res.textured.texture, view)

    def ncc(img):
        a = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY).astype(float)[mask]
        b = photo[mask]
        a, b = a - a.mean(), b - b.mean()
        return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))

    right, wrong = ncc(renders[0]), ncc(renders[1])
    assert mask.mean() > 0.3 and right > 0.35 and right > wrong + 0.3, (right, wrong)


def _open3d_render(meshes, texture, view):
    """Renders of Open3D textured meshes from ``view``'s camera, and the mesh's pixel mask."""
    import open3d.visualization.rendering as rendering

    r = rendering.OffscreenRenderer(view.width, view.height)
    r.setup_camera(view.intrinsic, view.extrinsic, view.width, view.height)
    out = []
    for m in meshes:
        mat = rendering.MaterialRecord()
        mat.shader = "defaultUnlit"
        mat.albedo_img = o3d.geometry.Image(np.ascontiguousarray(texture))
        r.scene.clear_geometry()
        r.scene.add_geometry("mesh", m, mat)
        out.append(np.asarray(r.render_to_image()))
    depth = np.asarray(r.render_to_depth_image(z_in_view_space=True))
    r.scene.clear_geometry()
    return out, np.isfinite(depth) & (depth > 0)


def test_open3d_mesh_back_to_our_textured_mesh_renders_like_the_photo(small):
    """Round trip through Open3D's types keeps the UV convention: our ray-cast render of the Open3D mesh's
    UVs and albedo reproduces the (corrected) photo where the mesh is seen."""
    syn, mesh, images, depths, params = small
    tm, res = sc.texture_mesh(mesh, images, params, depths=depths, t_npm=50, atlas_size=1024, return_result=True,
                              leveling=False, local_leveling=False)
    uv = tm.triangle.texture_uvs.numpy().reshape(-1, 2).astype(np.float64)
    faces = np.arange(len(uv)).reshape(-1, 3)
    verts = tm.vertex.positions.numpy()[tm.triangle.indices.numpy()].reshape(-1, 3)
    again = TexturedMesh(vertices=verts, faces=faces, uv=uv,
                         texture=tm.material.texture_maps["albedo"].as_tensor().numpy())
    k = int(np.argmax(res.selection_stats["faces_per_view"]))
    view = syn.scene.views[k]
    render = render_textured(again, view)
    # the selection is per face of the split mesh (issue 20): the input faces all of whose parts are from view k
    ids = syn.load_face_ids(k)
    parent = res.visibility.parent_faces
    whole = np.ones(int(parent.max()) + 1 if parent is not None else len(res.selection), bool)
    np.logical_and.at(whole, parent if parent is not None else np.arange(len(res.selection)), res.selection == k)
    seen = (ids >= 0) & whole[np.maximum(ids, 0)]
    diff = np.abs(render.astype(float) - res.images[k])[seen].mean()
    assert seen.mean() > 0.2 and diff < 6.0, diff
