"""Scene formats behind the loader table: COLMAP binary/text (fixtures written by pycolmap), Meshroom
cameras.sfm, MeshLab .mlp through load_scene, and the table's own checks."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
import pycolmap
import pytest

import o3d_seqcc as sc
from o3d_seqcc import InputError, Scene, View, load_scene
from o3d_seqcc.geometry.camera import project_points
from o3d_seqcc.cli import main
from o3d_seqcc.io.load import SCENE_FORMATS
from o3d_seqcc.io.meshlab import save_mlp

W, H = 64, 48


def _write_image(path: Path, rng) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), rng.integers(0, 256, (H, W, 3), dtype=np.uint8))


def _mesh(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    o3d.io.write_triangle_mesh(str(path), o3d.geometry.TriangleMesh.create_box(1.0, 1.0, 1.0))
    return path


def _random_pose(rng) -> tuple[np.ndarray, np.ndarray]:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return q, rng.normal(size=3)


@pytest.fixture
def colmap_model(tmp_path, rng):
    """A reconstruction with a PINHOLE and a SIMPLE_PINHOLE camera, written by pycolmap as text and binary."""
    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(pycolmap.Camera(model="PINHOLE", width=W, height=H, params=[50.0, 52.0, 31.5, 23.5],
                                                    camera_id=1))
    rec.add_camera_with_trivial_rig(pycolmap.Camera(model="SIMPLE_PINHOLE", width=W, height=H, params=[60.0, 32.0, 24.0],
                                                    camera_id=2))
    for i in range(3):
        q, t = _random_pose(rng)  # x, y, z, w for Rotation3d
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(q), t)
        rec.add_image_with_trivial_frame(pycolmap.Image(name=f"img{i}.png", camera_id=1 + i % 2, image_id=i + 1), pose)
        _write_image(tmp_path / "images" / f"img{i}.png", rng)
    for kind in ("txt", "bin"):
        d = tmp_path / f"sparse_{kind}"
        d.mkdir()
        (rec.write_text if kind == "txt" else rec.write_binary)(str(d))
    return rec, tmp_path, _mesh(tmp_path / "mesh.ply")


def test_colmap_binary_and_text_agree_with_pycolmap(colmap_model, rng):
    rec, root, mesh = colmap_model
    scenes = {k: load_scene(root / f"sparse_{k}", mesh=mesh, image_dir=root / "images") for k in ("txt", "bin")}
    assert scenes["txt"] == scenes["bin"]
    scene = scenes["bin"]
    assert scene.names == ["img0", "img1", "img2"]
    X = rng.normal(size=(20, 3)) * 0.3
    for image_id, view in zip(sorted(rec.images), scene.views):
        im = rec.images[image_id]
        E = im.cam_from_world().matrix()
        np.testing.assert_allclose(view.extrinsic[:3], E, atol=1e-12)
        Xc = X @ E[:, :3].T + E[:, 3]
        Xc[:, 2] = np.abs(Xc[:, 2]) + 1.0  # in front of the camera
        Xw = (Xc - E[:, 3]) @ E[:, :3]
        theirs = rec.cameras[im.camera_id].img_from_cam(Xc)  # COLMAP: top-left pixel centre at (0.5, 0.5)
        ours, _ = project_points(Xw, view.intrinsic, view.extrinsic)
        np.testing.assert_allclose(ours, theirs - 0.5, atol=1e-9)


def test_colmap_binary_bad_input(colmap_model, tmp_path):
    _, root, mesh = colmap_model
    d = root / "sparse_bin"
    data = (d / "images.bin").read_bytes()
    (d / "images.bin").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=r"images\.bin: truncated binary model"):
        load_scene(d, mesh=mesh, image_dir=root / "images")
    with pytest.raises(InputError, match="pass the mesh"):
        load_scene(root / "sparse_txt")
    for model, params, err in (("OPENCV", [50, 50, 32, 24, 0.1, 0, 0, 0], None),  # undistorted when read
                               ("FOV", [50, 50, 32, 24, 0.1], r"camera model FOV is not supported.*undistort")):
        rec = pycolmap.Reconstruction()
        rec.add_camera_with_trivial_rig(pycolmap.Camera(model=model, width=W, height=H, params=params, camera_id=1))
        rec.add_image_with_trivial_frame(pycolmap.Image(name="img0.png", camera_id=1, image_id=1),
                                         pycolmap.Rigid3d(pycolmap.Rotation3d(np.array([0, 0, 0, 1.0])), np.zeros(3)))
        dist = tmp_path / f"distorted_{model}"
        dist.mkdir()
        rec.write_binary(str(dist))
        if err is None:
            view = load_scene(dist, mesh=mesh, image_dir=root / "images").views[0]
            assert view.distortion.model == "opencv" and view.distortion.coefficients == (0.1, 0.0, 0.0, 0.0)
            assert view.distorted and view.load_image().shape == (H, W, 3)
        else:
            with pytest.raises(InputError, match=r"cameras\.bin: camera 1: " + err):
                load_scene(dist, mesh=mesh, image_dir=root / "images")


@pytest.fixture
def meshroom_cameras(tmp_path, rng):
    """Known cameras written the way AliceVision writes cameras.sfm (column-major world-to-camera R, centre C)."""
    mesh = _mesh(tmp_path / "Texturing" / "texturedMesh.obj")
    cams = []
    data = {"version": ["1", "2", "4"], "views": [], "intrinsics": [], "poses": []}
    for i in range(3):
        q, _ = _random_pose(rng)
        R = o3d.geometry.get_rotation_matrix_from_quaternion(q)  # (w, x, y, z)
        C = rng.normal(size=3)
        fx, fy, off = 55.0 + i, 56.0 + i, np.array([0.7, -1.2])
        cams.append((R, C, fx, fy, off))
        _write_image(tmp_path / "images" / f"IMG_{i}.JPG", rng)
        data["views"].append({"viewId": str(100 + i), "poseId": str(200 + i), "intrinsicId": str(300 + i),
                              "path": str(tmp_path / "images" / f"IMG_{i}.JPG"), "width": str(W), "height": str(H)})
        data["intrinsics"].append({"intrinsicId": str(300 + i), "width": str(W), "height": str(H), "type": "pinhole",
                                   "pxFocalLength": [str(fx), str(fy)], "principalPoint": [str(off[0]), str(off[1])],
                                   "distortionParams": []})
        data["poses"].append({"poseId": str(200 + i), "pose": {"transform": {
            "rotation": [str(x) for x in R.flatten(order="F")], "center": [str(x) for x in C]}}})
    path = tmp_path / "cameras.sfm"
    path.write_text(json.dumps(data, indent=1))
    return path, mesh, cams, data


def test_meshroom_cameras_sfm(meshroom_cameras, rng):
    path, mesh, cams, _ = meshroom_cameras
    scene = load_scene(path, mesh=mesh)
    assert scene.names == ["IMG_0", "IMG_1", "IMG_2"]
    X = rng.normal(size=(10, 3))
    for view, (R, C, fx, fy, off) in zip(scene.views, cams):
        np.testing.assert_allclose(view.intrinsic, [[fx, 0, W / 2 + off[0]], [0, fy, H / 2 + off[1]], [0, 0, 1]])
        np.testing.assert_allclose(view.center, C, atol=1e-12)
        xc = (X - C) @ R.T  # AliceVision's Pose3: R (X - C)
        want = xc[:, :2] / xc[:, 2:3] * [fx, fy] + [W / 2 + off[0], H / 2 + off[1]]
        got, _ = project_points(X, view.intrinsic, view.extrinsic)
        ok = xc[:, 2] > 0
        np.testing.assert_allclose(got[ok], want[ok], atol=1e-9)
    assert load_scene(path.parent, mesh=mesh) == scene  # the folder holding cameras.sfm


def test_meshroom_versions_unposed_views_and_distortion(meshroom_cameras, tmp_path, caplog):
    path, mesh, cams, data = meshroom_cameras
    old = json.loads(json.dumps(data))
    old["version"] = ["1", "0", "0"]  # before 1.2.1 the principal point is absolute
    old["intrinsics"][0]["principalPoint"] = ["30.0", "20.0"]
    old["poses"] = old["poses"][:2]  # the third view was not reconstructed
    p = tmp_path / "old.sfm"
    p.write_text(json.dumps(old))
    scene = load_scene(p, mesh=mesh, allow_unseen=True)  # random cameras: the mesh is hardly in the photos
    assert scene.names == ["IMG_0", "IMG_1"] and "no pose" in caplog.text
    np.testing.assert_allclose(scene.views[0].intrinsic[:2, 2], [30.0, 20.0])
    bad = json.loads(json.dumps(data))
    bad["intrinsics"][1]["type"] = "radial3"  # AliceVision's radial3: removed when read
    bad["intrinsics"][1]["distortionParams"] = ["0.1", "0", "0"]
    p.write_text(json.dumps(bad))
    assert load_scene(p, mesh=mesh, allow_unseen=True).views[1].distortion.coefficients == (0.1, 0.0, 0.0, 0.0, 0.0)
    bad["intrinsics"][1]["type"] = "3deanamorphic4"
    p.write_text(json.dumps(bad))
    with pytest.raises(InputError, match=r"3deanamorphic4.*not supported.*undistort"):
        load_scene(p, mesh=mesh)
    bad = json.loads(json.dumps(data))
    bad["poses"][0]["pose"]["transform"]["rotation"] = ["1", "0"]
    p.write_text(json.dumps(bad))
    with pytest.raises(InputError, match=r"poses\[0\]: 'rotation' must be a list of 9 numbers"):
        load_scene(p, mesh=mesh)
    with pytest.raises(InputError, match="pass the mesh"):
        load_scene(path)


def test_mlp_through_load_scene_and_cli(tmp_path, rng, capsys):
    mesh = _mesh(tmp_path / "mesh.ply")
    views = []
    for i in range(2):
        q, t = _random_pose(rng)
        E = np.eye(4)
        E[:3, :3] = o3d.geometry.get_rotation_matrix_from_quaternion(q)
        E[:3, 3] = t
        _write_image(tmp_path / "images" / f"v{i}.png", rng)
        views.append(View(name=f"v{i}", image=tmp_path / "images" / f"v{i}.png",
                          intrinsic=[[60.0, 0, 31.5], [0, 61.0, 23.5], [0, 0, 1]], extrinsic=E, width=W, height=H))
    scene = Scene(mesh=mesh, views=tuple(views))
    mlp = save_mlp(scene, tmp_path / "project.mlp")
    back = load_scene(mlp, allow_unseen=True)  # random cameras: the mesh is hardly in the photos
    assert back.names == scene.names and back.mesh == scene.mesh
    for a, b in zip(back.views, scene.views):
        np.testing.assert_allclose(a.intrinsic, b.intrinsic, atol=1e-9)
        np.testing.assert_allclose(a.extrinsic, b.extrinsic, atol=1e-9)
    assert main(["info", str(mlp), "--json", "--allow-unseen"]) == 0
    assert json.loads(capsys.readouterr().out)["views"] == 2


def test_loader_table_checks(tmp_path, colmap_model):
    _, root, mesh = colmap_model
    assert list(SCENE_FORMATS) == ["scene.json", "meshlab", "meshroom", "rgbd-folder", "colmap", "openmvs", "nvm",
                                 "metashape", "mve", "cam-folder", "bundler"]
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError) as e:
        load_scene(tmp_path / "empty")
    assert all(f.description in str(e.value) for f in SCENE_FORMATS.values())
    with pytest.raises(InputError, match="unknown scene format 'ply'; valid: bundler, cam-folder, colmap, meshlab, meshroom, metashape, mve, nvm, "
                       "openmvs, rgbd-folder, scene.json, or 'auto'"):
        load_scene(root / "sparse_txt", format="ply", mesh=mesh)
    with pytest.raises(InputError, match="is not a MeshLab project"):
        load_scene(root / "sparse_txt", format="meshlab", mesh=mesh)
    with pytest.raises(InputError, match="intrinsic= does not apply to a COLMAP model"):
        load_scene(root / "sparse_txt", mesh=mesh, intrinsic=np.eye(3))
    scene = load_scene(root / "sparse_txt", format="colmap", mesh=mesh, image_dir=root / "images")
    assert len(scene) == 3


def test_mlp_without_depth_warns_and_depth_dir_turns_the_filter_on(tmp_path):
    syn = sc.make_synthetic_scene(tmp_path / "S", n_views=3, width=64, height=48, seed=0, cell_size=0.3)
    mlp = save_mlp(syn.scene, tmp_path / "project.mlp")
    scene = load_scene(mlp)
    assert not any(v.has_depth for v in scene.views)
    with pytest.warns(sc.errors.O3dSeqccWarning, match="depth-consistency filter is off"):
        sc.compute_visibility(scene)
    with_depth = load_scene(mlp, depth_dir=tmp_path / "S" / "depth")
    assert [v.depth.name for v in with_depth.views] == ["v00.png", "v01.png", "v02.png"]
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", sc.errors.O3dSeqccWarning)
        vis = sc.compute_visibility(with_depth)
    assert vis.stats["depth_inconsistent"] > 0  # the depth filter ran (and the room's occluders trip it)
    with pytest.raises(InputError, match="no depth map for view 'v00'"):
        load_scene(mlp, depth_dir=tmp_path)
    assert main(["-q", "info", str(mlp), "--depth-dir", str(tmp_path / "S" / "depth")]) == 0
