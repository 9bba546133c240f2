"""OpenMVS interface files (scene.mvs): a known synthetic scene written by an independent writer that
follows OpenMVS's libs/MVS/Interface.h (every version 0-7, cameras in pixels and normalised, a
camera on a rig), read back to the same cameras; the pixel-centre convention checked with the
photo's own surface points; `o3d-seqcc run scene.mvs --mesh MESH`."""

from __future__ import annotations

import json
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

import o3d_seqcc as sc
from o3d_seqcc import InputError, load_scene
from o3d_seqcc.geometry.camera import project_points
from o3d_seqcc.cli import main

NO_ID = 0xFFFFFFFF


# ------------------------------------------------------------------------------ the writer (Interface.h)


def _str(s: str) -> bytes:  # std::string: uint64 size, then the characters
    b = s.encode("utf-8")
    return struct.pack("<Q", len(b)) + b


def _mat(m) -> bytes:  # cv::Matx<double>: row-major doubles
    return struct.pack(f"<{np.size(m)}d", *np.asarray(m, dtype=np.float64).ravel())


def write_interface(path: Path, version: int, platforms: list[dict], images: list[dict],
                    points: np.ndarray | None = None) -> Path:
    """Serialise MVS::Interface as its serialize() methods do for ``version`` (header from version 1)."""
    out = bytearray()
    if version > 0:
        out += b"MVSI" + struct.pack("<II", version, 0)
    out += struct.pack("<Q", len(platforms))
    for p in platforms:
        out += _str(p["name"]) + struct.pack("<Q", len(p["cameras"]))
        for c in p["cameras"]:
            out += _str(c["name"])
            if version > 3:
                out += _str("RGB")
            if version > 0:
                out += struct.pack("<II", c["width"], c["height"])
            out += _mat(c["K"]) + _mat(c["R"]) + _mat(c["C"])
        out += struct.pack("<Q", len(p["poses"]))
        for R, C in p["poses"]:
            out += _mat(R) + _mat(C)
    out += struct.pack("<Q", len(images))
    for k, im in enumerate(images):
        out += _str(im["name"])
        if version > 4:
            out += _str("")
        out += struct.pack("<III", im["platform"], im["camera"], im["pose"])
        if version > 2:
            out += struct.pack("<I", k)
        if version > 6:
            out += struct.pack("<3f", 0.5, 2.0, 6.0) + struct.pack("<Q", 1) + struct.pack("<II4f", 0, 10, 1, 0.1, 0.5, 1)
    pts = np.zeros((0, 3)) if points is None else points
    out += struct.pack("<Q", len(pts))  # vertices: X (3 float32) + views (imageID uint32, confidence float32)
    for x in pts:
        out += struct.pack("<3f", *x) + struct.pack("<Q", 2) + struct.pack("<IfIf", 0, 0.0, 1, 0.0)
    out += struct.pack("<Q", 0) + struct.pack("<Q", len(pts)) + b"\x80\x80\x80" * len(pts)  # normals, colours
    if version > 0:
        out += struct.pack("<QQQ", 0, 0, 0)  # lines, line normals, line colours
        if version > 1:
            out += _mat(np.eye(4))  # transform
            if version > 5:
                out += _mat(np.eye(3)) + _mat(np.zeros(3)) + _mat(np.zeros(3))  # OBB
    path.write_bytes(bytes(out))
    return path


def _scale_k(K: np.ndarray, s: float) -> np.ndarray:
    """MVS::Camera::ScaleK: focal lengths times s, principal point (c + 0.5) s - 0.5."""
    out = K.copy()
    out[0, 0] *= s
    out[0, 1] *= s
    out[1, 1] *= s
    out[:2, 2] = (K[:2, 2] + 0.5) * s - 0.5
    return out


def _rot(axis, deg: float) -> np.ndarray:
    import open3d as o3d

    a = np.asarray(axis, float)
    return o3d.geometry.get_rotation_matrix_from_axis_angle(a / np.linalg.norm(a) * np.deg2rad(deg))


def interface_of(scene, version: int, *, normalise: bool = False, rig: bool = True):
    """The scene's cameras as interface platforms and images: views 0..3 on a rig (a camera mounted
    at an offset on platform 0), the others alone on platform 1, plus an uncalibrated image."""
    v0 = scene.views[0]
    W, H = v0.width, v0.height
    Rc, Cc = (_rot([0.3, 1, 0.2], 25.0), np.array([0.1, -0.05, 0.2])) if rig else (np.eye(3), np.zeros(3))
    plats = [{"name": "rig", "cameras": [], "poses": []}, {"name": "single", "cameras": [], "poses": []}]
    for p, (R, C) in ((0, (Rc, Cc)), (1, (np.eye(3), np.zeros(3)))):
        K = v0.intrinsic
        if normalise or version == 0:  # no resolution stored: K normalised by max(width, height)
            plats[p]["cameras"].append({"name": "cam", "width": 0, "height": 0, "K": _scale_k(K, 1.0 / max(W, H)),
                                        "R": R, "C": C})
        else:
            plats[p]["cameras"].append({"name": "cam", "width": W, "height": H, "K": K, "R": R, "C": C})
    images = []
    for i, v in enumerate(scene.views):
        p = 0 if i < 4 else 1
        R, C = v.rotation, v.center
        Rcam, Ccam = plats[p]["cameras"][0]["R"], plats[p]["cameras"][0]["C"]
        Rp = Rcam.T @ R  # R = R_cam R_pose, C = R_pose^T C_cam + C_pose
        Cp = C - Rp.T @ Ccam
        images.append({"name": f"images/{v.image.name}", "platform": p, "camera": 0,
                       "pose": len(plats[p]["poses"])})
        plats[p]["poses"].append((Rp, Cp))
    images.append({"name": "images/not_calibrated.png", "platform": 1, "camera": 0, "pose": NO_ID})
    return plats, images


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("mvs") / "R", n_views=6, width=80, height=60,
                                   cell_size=0.25, layout="two-rings", seen_only=True, photometric="none")


def _assert_same_cameras(a, b, atol=1e-9) -> None:
    assert len(a.views) == len(b.views)
    for u, v in zip(a.views, b.views):
        assert (u.width, u.height) == (v.width, v.height)
        np.testing.assert_allclose(u.intrinsic, v.intrinsic, atol=atol)
        np.testing.assert_allclose(u.extrinsic, v.extrinsic, atol=atol)


# ------------------------------------------------------------------------------ tests


@pytest.mark.parametrize("version", range(8))
def test_every_version_reads_back_the_cameras(room, version, caplog):
    plats, images = interface_of(room.scene, version)
    path = write_interface(room.root / f"v{version}.mvs", version, plats, images, points=np.ones((3, 3)))
    scene = load_scene(path, mesh=room.scene.mesh)
    assert scene.names == room.scene.names and scene.source == path
    _assert_same_cameras(scene, room.scene)
    assert "1 image(s) have no pose" in caplog.text


def test_normalised_intrinsics_and_the_centred_principal_point(room, tmp_path):
    plats, images = interface_of(room.scene, 7, normalise=True)
    _assert_same_cameras(load_scene(write_interface(room.root / "norm.mvs", 7, plats, images),
                                    mesh=room.scene.mesh), room.scene)
    # a normalised principal point of (0, 0) is the image centre (OpenMVS's ComposeK)
    v = room.scene.views[0]
    plats[1]["cameras"][0]["K"] = np.array([[0.8, 0, 0], [0, 0.8, 0], [0, 0, 1.0]])
    s = load_scene(write_interface(room.root / "centre.mvs", 7, plats, images), mesh=room.scene.mesh,
                   check_cameras=False)
    np.testing.assert_allclose(s.views[4].intrinsic, [[64, 0, 39.5], [0, 64, 29.5], [0, 0, 1]])
    assert (s.views[4].width, s.views[4].height) == (v.width, v.height)


def test_pixel_centres_a_known_point_projects_where_the_photo_shows_it(room):
    """The photo's own ray-cast surface points (pixel (r, c) shows points[r, c]) project back onto
    (c, r) with the cameras read from the .mvs file: to 0.01 px, a half-pixel slip would be 0.5."""
    plats, images = interface_of(room.scene, 6)
    scene = load_scene(write_interface(room.root / "align.mvs", 6, plats, images), mesh=room.scene.mesh)
    for k in (0, 5):  # one view on the rig, one alone
        pts = room.load_points(k)
        r, c = np.nonzero(np.isfinite(pts[..., 0]))
        uv, z = project_points(pts[r, c].astype(np.float64), scene.views[k].intrinsic, scene.views[k].extrinsic)
        err = np.abs(uv - np.stack([c, r], 1))
        assert len(r) > 1000 and err.max() < 0.01, err.max()


def test_mesh_images_and_errors(room, tmp_path):
    plats, images = interface_of(room.scene, 7)
    folder = tmp_path / "openmvs"
    folder.mkdir()
    path = write_interface(folder / "scene.mvs", 7, plats, images)
    # images relative to the file: not there -> an error naming the image and --image-dir
    with pytest.raises(InputError, match=r"(?s)scene\.mvs: image 0 \('images/v00\.png'\).*not found.*--image-dir"):
        load_scene(path, mesh=room.scene.mesh)
    scene = load_scene(path, mesh=room.scene.mesh, image_dir=room.root / "images")
    _assert_same_cameras(scene, room.scene)
    assert main(["-q", "info", str(path), "--mesh", str(room.scene.mesh), "--image-dir", str(room.root / "images")]) == 0
    # the mesh: --mesh, else the .ply of the same name beside the file (TextureMesh's default)
    with pytest.raises(InputError, match=r"holds no mesh, and scene\.ply .* is not beside it: pass the mesh"):
        load_scene(path, image_dir=room.root / "images")
    shutil.copy(room.scene.mesh, folder / "scene.ply")
    assert load_scene(path, image_dir=room.root / "images").mesh == folder / "scene.ply"
    # OpenMVS's own project archive, a newer version, a truncated file
    (folder / "native.mvs").write_bytes(b"MVS\0" + struct.pack("<IIQ", 1, 0, 0) + b"\0" * 64)
    with pytest.raises(InputError, match="project archive.*not the documented interface format"):
        load_scene(folder / "native.mvs", mesh=room.scene.mesh)
    data = path.read_bytes()
    (folder / "v8.mvs").write_bytes(b"MVSI" + struct.pack("<I", 8) + data[8:])
    with pytest.raises(InputError, match="version 8; this reader knows versions 0 to 7"):
        load_scene(folder / "v8.mvs", mesh=room.scene.mesh)
    (folder / "cut.mvs").write_bytes(data[:300])
    with pytest.raises(InputError, match=r"cut\.mvs: truncated OpenMVS interface file"):
        load_scene(folder / "cut.mvs", mesh=room.scene.mesh)
    images[0]["pose"] = 99  # ids out of range
    write_interface(folder / "ids.mvs", 7, plats, images)
    with pytest.raises(InputError, match=r"ids\.mvs: image 0 .*pose 99 does not exist"):
        load_scene(folder / "ids.mvs", mesh=room.scene.mesh, image_dir=room.root / "images")


def test_run_on_scene_mvs_with_mesh(room, tmp_path):
    plats, images = interface_of(room.scene, 6)
    path = write_interface(room.root / "scene.mvs", 6, plats, images)
    out = tmp_path / "out"
    assert main(["-q", "run", str(path), "--mesh", str(room.scene.mesh), "--out", str(out), "--t-npm", "20",
                 "--atlas-size", "512", "--no-seams", "--format", "glb", "--depth-dir", str(room.root / "depth")]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert (out / "mesh.glb").is_file() and rep["selection"]["input_faces"] == len(room.scene.load_mesh().faces)
    ref = tmp_path / "ref"
    assert main(["-q", "run", str(room.root), "--out", str(ref), "--t-npm", "20", "--atlas-size", "512", "--no-seams",
                 "--format", "glb"]) == 0
    assert np.array_equal(np.load(out / "selection.npy"), np.load(ref / "selection.npy"))  # the same cameras
