"""Tests of the MeshLab-facing layer: .mlp round trip and camera convention, peer runs."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from o3d_seqcc.io.meshlab import CENTER_SHIFT, MeshLayer, load_mlp, project_meshlab, save_mlp, vcg_camera_attributes
from o3d_seqcc.io.images import write_image
from o3d_seqcc.errors import InputError
from o3d_seqcc.scene import Scene, View


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def random_scene(tmp_path: Path, n: int = 4, seed: int = 0) -> Scene:
    rng = np.random.default_rng(seed)
    (tmp_path / "mesh.ply").write_text("ply\n")  # only referenced, never read here
    views = []
    for i in range(n):
        w, h = int(rng.integers(200, 800)), int(rng.integers(150, 600))
        K = np.array([[rng.uniform(300, 900), 0, rng.uniform(0.3, 0.7) * w], [0, rng.uniform(300, 900), rng.uniform(0.3, 0.7) * h], [0, 0, 1]])
        ext = np.eye(4)
        ext[:3, :3] = random_rotation(rng)
        ext[:3, 3] = rng.normal(size=3)
        views.append(View(name=f"v{i}", image=tmp_path / "img" / f"v{i}.png", intrinsic=K, extrinsic=ext, width=w, height=h))
    return Scene(mesh=tmp_path / "mesh.ply", views=tuple(views))


def project_ours(view: View, pts: np.ndarray) -> np.ndarray:
    pc = pts @ view.rotation.T + view.translation
    uv = pc @ view.intrinsic.T
    return uv[:, :2] / uv[:, 2:]


def test_mlp_round_trip_exact(tmp_path: Path):
    scene = random_scene(tmp_path)
    path = save_mlp(scene, tmp_path / "sub" / "project.mlp")
    back = load_mlp(path)
    assert back.mesh.resolve() == scene.mesh.resolve()
    assert back.names == scene.names
    for a, b in zip(scene.views, back.views):
        assert (a.width, a.height) == (b.width, b.height)
        assert b.image.resolve() == a.image.resolve()
        np.testing.assert_allclose(b.intrinsic, a.intrinsic, atol=1e-9, rtol=0)
        np.testing.assert_allclose(b.extrinsic, a.extrinsic, atol=1e-9, rtol=0)
    # other images and the plain (unshifted) convention round-trip as well
    imgs = [tmp_path / f"corrected_{v.name}.png" for v in scene.views]
    p2 = save_mlp(scene, tmp_path / "p2.mlp", images=imgs, center_shift=(0, 0))
    b2 = load_mlp(p2, center_shift=(0, 0))
    assert [v.image.name for v in b2.views] == [p.name for p in imgs]
    for a, b in zip(scene.views, b2.views):
        np.testing.assert_allclose(b.intrinsic, a.intrinsic, atol=1e-9, rtol=0)


def test_projected_point_same_pixel_in_meshlab_convention(tmp_path: Path):
    scene = random_scene(tmp_path, seed=3)
    rng = np.random.default_rng(1)
    for v in scene.views:
        # points in front of the camera
        pc = np.c_[rng.uniform(-1, 1, (20, 2)), rng.uniform(1, 5, 20)]
        pts = (pc - v.translation) @ v.rotation  # R^T (pc - t)
        ours = project_ours(v, pts)
        ml = project_meshlab(pts, vcg_camera_attributes(v))
        sx, sy = CENTER_SHIFT
        np.testing.assert_allclose(ml[:, 0], ours[:, 0] + sx, atol=1e-7)
        np.testing.assert_allclose(ml[:, 1], v.height - ours[:, 1] + sy, atol=1e-7)
        plain = project_meshlab(pts, vcg_camera_attributes(v, center_shift=(0, 0)))
        np.testing.assert_allclose(plain, np.c_[ours[:, 0], v.height - ours[:, 1]], atol=1e-7)
    # the documented attribute values for the PrimeSense default camera
    K = np.array([[525.0, 0, 319.5], [0, 525.0, 239.5], [0, 0, 1]])
    a = vcg_camera_attributes(replace(scene.views[0], intrinsic=K, width=640, height=480))
    assert [float(x) for x in a["CenterPx"].split()] == [320.0, 240.0]
    assert float(a["FocalMm"]) / float(a["PixelSizeMm"].split()[0]) == pytest.approx(525.0)


def test_rigid_placement_folded_into_cameras(tmp_path: Path):
    scene = random_scene(tmp_path, n=2, seed=5)
    path = save_mlp(scene, tmp_path / "p.mlp")
    M = np.eye(4)
    M[:3, :3] = random_rotation(np.random.default_rng(2))
    M[:3, 3] = [0.3, -0.2, 1.0]
    text = path.read_text()
    ident = "\n1 0 0 0 \n0 1 0 0 \n0 0 1 0 \n0 0 0 1 \n"
    assert ident in text
    path.write_text(text.replace(ident, "\n" + "\n".join(" ".join(repr(float(x)) for x in row) for row in M) + "\n"))
    back = load_mlp(path)
    pts = np.random.default_rng(0).normal(size=(10, 3))
    placed = pts @ M[:3, :3].T + M[:3, 3]
    for a, b in zip(scene.views, back.views):
        # MeshLab shows the mesh at M x: the loaded camera sees file coordinates x the same way
        np.testing.assert_allclose(project_ours(b, pts), project_ours(a, placed), atol=1e-6)


def test_mesh_layers_with_placement_and_visibility(tmp_path: Path):
    scene = random_scene(tmp_path, n=2, seed=7)
    M = np.eye(4)
    M[:3, :3] = random_rotation(np.random.default_rng(3))
    M[:3, 3] = [0.125, -2.0, 0.3]
    (tmp_path / "other.ply").write_text("ply\n")
    layers = [MeshLayer(tmp_path / "mesh.ply", label="room", matrix=M), MeshLayer(tmp_path / "other.ply", visible=False)]
    path = save_mlp(scene, tmp_path / "layers.mlp", layers=layers)
    text = path.read_text()
    assert text.count("<MLMesh ") == 2 and 'label="room"' in text and 'label="other.ply"' in text
    assert 'visible="0"' in text and "0 0 0 1 \n" in text
    back = load_mlp(path)  # the first layer; its placement folded into the cameras
    assert back.mesh.resolve() == (tmp_path / "mesh.ply").resolve()
    for a, b in zip(scene.views, back.views):
        np.testing.assert_allclose(b.extrinsic, a.extrinsic @ M, atol=1e-12)
    with pytest.raises(InputError, match="either mesh= or layers="):
        save_mlp(scene, tmp_path / "x.mlp", mesh=tmp_path / "mesh.ply", layers=layers)


def test_load_mlp_bad_input(tmp_path: Path):
    with pytest.raises(InputError, match="not found"):
        load_mlp(tmp_path / "missing.mlp")
    bad = tmp_path / "bad.mlp"
    bad.write_text("<MeshLabProject><MeshGroup><MLMesh filename='m.ply'/></MeshGroup></MeshLabProject>")
    with pytest.raises(InputError, match="no rasters"):
        load_mlp(bad)
    bad.write_text("not xml <")
    with pytest.raises(InputError, match="XML"):
        load_mlp(bad)
    scene = random_scene(tmp_path, n=1)
    p = save_mlp(scene, tmp_path / "d.mlp")
    p.write_text(p.read_text().replace('LensDistortion="0 0"', 'LensDistortion="0.001 0"'))
    assert load_mlp(p).views[0].distortion.model == "meshlab"  # undistorted when read (issue 20)
    p.write_text(p.read_text().replace('LensDistortion="0.001 0"', 'LensDistortion="0.1"'))
    with pytest.raises(InputError, match="LensDistortion needs 2 numbers"):
        load_mlp(p)


# --------------------------------------------------------------------------------------------
# peers on a tiny scene: a bumpy plane seen by one camera whose photo is a smooth random image
# --------------------------------------------------------------------------------------------

W, H = 320, 160


@pytest.fixture(scope="module")
def plane_scene(tmp_path_factory) -> tuple[Scene, np.ndarray]:
    import trimesh
    root = tmp_path_factory.mktemp("plane")
    rng = np.random.default_rng(0)
    img = cv2.resize(rng.integers(0, 256, (20, 40, 3), dtype=np.uint8), (W, H), interpolation=cv2.INTER_CUBIC)
    img = cv2.GaussianBlur(img, (0, 0), 1.5)
    write_image(root / "v0.png", img)
    n = 20
    xs, ys = np.meshgrid(np.linspace(0.2, 1.8, n + 1), np.linspace(0.1, 0.9, n // 2 + 1))
    # a slight bump: MeshLab's filter fails on a perfectly flat bounding box
    verts = np.c_[xs.ravel(), ys.ravel(), 0.02 * np.sin(3 * xs.ravel())]
    faces = []
    for j in range(n // 2):
        for i in range(n):
            a = j * (n + 1) + i
            faces += [[a, a + n + 2, a + 1], [a, a + n + 1, a + n + 2]]  # normals towards the camera
    trimesh.Trimesh(verts, np.array(faces), process=False).export(root / "plane.ply")
    ext = np.eye(4)
    ext[:3, 3] = -np.array([1.0, 0.5, -2.0])
    K = np.array([[W, 0, (W - 1) / 2], [0, W, (H - 1) / 2], [0, 0, 1]])
    view = View(name="v0", image=root / "v0.png", intrinsic=K, extrinsic=ext, width=W, height=H)
    return Scene(mesh=root / "plane.ply", views=(view,)), img


def _render_error(mesh_path: Path, scene: Scene, img: np.ndarray) -> float:
    from o3d_seqcc.evaluation.render import render_textured

    ren = render_textured(mesh_path, scene.views[0])
    centre = (slice(55, 105), slice(140, 180))  # well inside the plane and the raster
    return float(np.abs(ren[centre].astype(int) - img[centre].astype(int)).mean())


def test_meshlab_peer_reproduces_photo(plane_scene, tmp_path: Path):
    """MeshLab's filter, fed our .mlp, textures the plane so that a render from the same camera
    is the photo again: checks the camera convention (incl. the half-pixel shift) end to end."""
    from benchmarks.peers import meshlab_available, run_meshlab

    reason = meshlab_available()
    if reason:
        pytest.skip(reason)
    scene, img = plane_scene
    res = run_meshlab(scene, tmp_path / "ml", texture_size=512)
    assert res.mesh.is_file() and res.texture.is_file() and res.seconds > 0
    assert _render_error(res.mesh, scene, img) < 1.0
    with pytest.raises(InputError, match="exists"):
        run_meshlab(scene, tmp_path / "ml")


def test_open3d_peer_reproduces_photo(plane_scene, tmp_path: Path):
    import open3d  # noqa: F401
    from benchmarks.peers import run_open3d

    scene, img = plane_scene
    res = run_open3d(scene, tmp_path / "o3d", texture_size=512)
    assert res.mesh.is_file() and res.info["faces_textured"] == 400
    assert _render_error(res.mesh, scene, img) < 2.0
