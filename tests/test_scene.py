"""Scene model, loaders and their bad-input messages."""

from __future__ import annotations

import hashlib
import json
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
import pytest

from o3d_seqcc import InputError, Scene, View, load_scene, save_scene
from o3d_seqcc.scene import PRIMESENSE_INTRINSIC, load_mesh

K = np.array([[100.0, 0, 31.5], [0, 100.0, 23.5], [0, 0, 1]])


def _look_at(center, target) -> np.ndarray:
    """World-to-camera extrinsic (OpenCV axes) of a camera at ``center`` looking at ``target``."""
    z = np.asarray(target, float) - center
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, -1.0, 0.0])
    if np.linalg.norm(x) < 1e-9:
        x = np.array([1.0, 0, 0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = -R @ center
    return T


def _write_rgb(path: Path, img: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))


@pytest.fixture
def tiny(tmp_path, rng) -> Path:
    """A box mesh, two 64x48 views with depth maps and a point cloud, as scene.json."""
    root = tmp_path / "tiny"
    mesh = o3d.geometry.TriangleMesh.create_box(1.0, 1.0, 1.0)
    (root / "scans").mkdir(parents=True)
    o3d.io.write_triangle_mesh(str(root / "mesh.ply"), mesh)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rng.random((50, 3))))
    o3d.io.write_point_cloud(str(root / "scans" / "s0.ply"), pc)
    views = []
    for i, c in enumerate(([0.5, 0.5, -2.0], [1.5, 0.5, -2.0])):
        _write_rgb(root / "images" / f"v{i}.png", rng.integers(0, 256, (48, 64, 3), dtype=np.uint8))
        d = root / "depth" / f"v{i}.png"
        d.parent.mkdir(exist_ok=True)
        cv2.imwrite(str(d), rng.integers(500, 3000, (48, 64)).astype(np.uint16))
        views.append(
            View(
                name=f"v{i}",
                image=root / "images" / f"v{i}.png",
                intrinsic=K,
                extrinsic=_look_at(np.array(c), [0.5, 0.5, 0.5]),
                width=64,
                height=48,
                depth=d,
                depth_scale=1000.0,
                point_cloud=(root / "scans" / "s0.ply") if i == 0 else None,
            )
        )
    save_scene(Scene(root / "mesh.ply", tuple(views)), root / "scene.json")
    return root


def _tree_digest(root: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        if p.is_file():
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def _edit(root: Path, fn) -> Path:
    data = json.loads((root / "scene.json").read_text())
    fn(data)
    (root / "scene.json").write_text(json.dumps(data))
    return root / "scene.json"


# ------------------------------------------------------------------------------ happy paths


def test_manifest_format_is_the_documented_one(tiny):
    data = json.loads((tiny / "scene.json").read_text())
    assert data["format"] == "o3d_seqcc.scene/1"
    assert data["mesh"] == "mesh.ply"
    v0 = data["views"][0]
    assert set(v0) == {"name", "image", "width", "height", "intrinsic", "extrinsic", "depth", "depth_scale", "point_cloud"}
    assert v0["image"] == "images/v0.png" and v0["depth"] == "depth/v0.png" and v0["point_cloud"] == "scans/s0.ply"
    assert "point_cloud" not in data["views"][1]
    assert np.array(v0["extrinsic"]).shape == (4, 4)


def test_round_trip_is_exact(tiny, tmp_path):
    s1 = load_scene(tiny / "scene.json")
    # perturb poses with irrational-looking numbers so exactness is tested for real
    ext = s1.views[0].extrinsic.copy()
    ext[:3, 3] += [np.pi / 7, -np.e / 11, 1 / 3]
    s1 = Scene(s1.mesh, (replace(s1.views[0], extrinsic=ext),) + s1.views[1:])
    out = tmp_path / "elsewhere" / "scene.json"
    save_scene(s1, out)
    s2 = load_scene(out)
    assert s2 == s1
    assert np.array_equal(s2.views[0].extrinsic, ext)
    assert s2.views[0].image.resolve() == (tiny / "images" / "v0.png").resolve()
    # saving the loaded scene next to the first manifest gives identical bytes
    save_scene(s2, out.parent / "again.json")
    assert (out.parent / "again.json").read_bytes() == out.read_bytes()


def test_folder_with_manifest_and_lazy_images(tiny):
    s = load_scene(tiny)
    assert s.names == ["v0", "v1"]
    img = s.views[0].load_image()
    assert img.shape == (48, 64, 3) and img.dtype == np.uint8
    d = s.views[0].load_depth()
    assert d.shape == (48, 64) and d.dtype == np.float64 and 0.5 <= d.min() and d.max() < 3.0
    assert s.index("v1") == 1 and s.index(0) == 0


def test_camera_helpers(tiny):
    v = load_scene(tiny).views[0]
    assert np.allclose(v.center, [0.5, 0.5, -2.0])
    assert np.allclose(v.axis, [0, 0, 1])
    p = v.to_open3d()
    assert np.allclose(p.intrinsic.intrinsic_matrix, K) and np.allclose(p.extrinsic, v.extrinsic)


def test_16bit_image_loads_as_uint16(tiny):
    img16 = (np.arange(48 * 64 * 3).reshape(48, 64, 3) * 20).astype(np.uint16)
    _write_rgb(tiny / "images" / "v0.png", img16)
    got = load_scene(tiny).views[0].load_image()
    assert got.dtype == np.uint16 and np.array_equal(got, img16)


def test_arrays_are_read_only(tiny):
    v = load_scene(tiny).views[0]
    with pytest.raises(ValueError):
        v.extrinsic[0, 0] = 2.0


def test_loading_never_writes_into_the_input(tiny):
    before = _tree_digest(tiny)
    s = load_scene(tiny)
    s.views[0].load_image()
    s.load_mesh()
    assert _tree_digest(tiny) == before


def test_mesh_without_normals_gets_them(tmp_path):
    m = o3d.geometry.TriangleMesh.create_sphere(1.0)
    o3d.io.write_triangle_mesh(str(tmp_path / "s.ply"), m, write_vertex_normals=False)
    mesh = load_mesh(tmp_path / "s.ply")
    assert np.allclose(np.linalg.norm(mesh.vertex_normals, axis=1), 1.0)
    # outward on a sphere
    assert (np.sum(mesh.vertex_normals * mesh.vertices, axis=1) > 0).all()


# ------------------------------------------------------------------------------ bad input


@pytest.mark.parametrize(
    "edit, match",
    [
        (lambda d: d["views"][0].update(image="images/nope.png"), r"v0.*image not found.*nope\.png"),
        (lambda d: d["views"][0].update(width=65), r"v0.*64x48 but the scene says 65x48"),
        (lambda d: d["views"][0]["extrinsic"][0].__setitem__(3, float("nan")), r"v0.*NaN"),
        (lambda d: d["views"][0].update(extrinsic=(np.eye(4) * [2, 2, 2, 1]).tolist()), r"v0.*not rigid"),
        (lambda d: d["views"][0].update(extrinsic=np.diag([1.0, 1, -1, 1]).tolist()), r"v0.*not rigid"),
        (lambda d: d["views"][1]["intrinsic"][0].__setitem__(0, 0.0), r"v1.*non-positive focal"),
        (lambda d: d["views"][1].update(intrinsic=[[-5, 0, 1], [0, 5, 1], [0, 0, 1]]), r"non-positive focal"),
        (lambda d: d["views"][1].update(name="v0"), r"duplicate view name 'v0'"),
        (lambda d: d.update(format="o3d_seqcc.scene/2"), r"unknown scene format 'o3d_seqcc.scene/2'"),
        (lambda d: d.pop("format"), r"unknown scene format None"),
        (lambda d: d.update(mesh="missing.ply"), r"mesh not found.*missing\.ply"),
        (lambda d: d["views"][0].pop("intrinsic"), r"views\[0\].*missing intrinsic"),
        (lambda d: d["views"][0].update(depth="depth/none.png"), r"v0.*depth map not found"),
        (lambda d: d["views"][0].update(point_cloud="scans/none.ply"), r"v0.*point cloud not found"),
        (lambda d: d["views"][0].update(colour="red"), r"unknown keys \['colour'\]"),
        (lambda d: d.update(views=[]), r"no views"),
        (lambda d: d["views"][0].update(depth_scale=0), r"depth_scale must be between 1e-06 and 1e\+09"),
        (lambda d: d["views"][0].update(name="a/b"), r"file name"),
    ],
)
def test_bad_manifest_entries(tiny, edit, match):
    path = _edit(tiny, edit)
    with pytest.raises(InputError, match=match):
        load_scene(path)


def test_invalid_json(tiny):
    (tiny / "scene.json").write_text("{not json")
    with pytest.raises(InputError, match=r"scene\.json: not valid JSON"):
        load_scene(tiny / "scene.json")


def test_unreadable_image(tiny):
    (tiny / "images" / "v1.png").write_bytes(b"definitely not a png")
    with pytest.raises(InputError, match=r"v1.*cannot read image .*v1\.png"):
        load_scene(tiny)


def test_grey_image(tiny):
    cv2.imwrite(str(tiny / "images" / "v0.png"), np.zeros((48, 64), np.uint8))
    with pytest.raises(InputError, match=r"v0.*grey-scale"):
        load_scene(tiny)
    # the lazy loader says the same when validation is skipped
    s = load_scene(tiny, validate=False)
    with pytest.raises(InputError, match=r"grey-scale.*RGB"):
        s.views[0].load_image()


def test_alpha_image(tiny):
    cv2.imwrite(str(tiny / "images" / "v1.png"), np.zeros((48, 64, 4), np.uint8))
    with pytest.raises(InputError, match=r"v1.*alpha channel"):
        load_scene(tiny)
    with pytest.raises(InputError, match=r"alpha channel"):
        load_scene(tiny, validate=False).views[1].load_image()


def test_depth_map_of_wrong_size(tiny):
    cv2.imwrite(str(tiny / "depth" / "v0.png"), np.ones((10, 10), np.uint16))
    with pytest.raises(InputError, match=r"depth map .*v0\.png is 10x10 but the view is 64x48"):
        load_scene(tiny)  # from the header, before any work
    s = load_scene(tiny, validate=False)
    with pytest.raises(InputError, match=r"depth map .*v0\.png is 10x10 but the view is 64x48"):
        s.views[0].load_depth()


def test_empty_and_non_triangle_meshes(tiny):
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.random.default_rng(0).random((10, 3))))
    o3d.io.write_point_cloud(str(tiny / "mesh.ply"), pc)
    with pytest.raises(InputError, match=r"mesh .*mesh\.ply has no triangles"):
        load_scene(tiny)
    (tiny / "mesh.ply").write_bytes(b"")
    with pytest.raises(InputError, match=r"empty file"):
        load_scene(tiny)


def test_unknown_layout(tmp_path):
    with pytest.raises(InputError, match=r"unknown scene layout"):
        load_scene(tmp_path)
    with pytest.raises(InputError, match=r"scene not found"):
        load_scene(tmp_path / "missing")


# ------------------------------------------------------------------------------ other formats


def test_open3d_rgbd_folder(tmp_path, rng):
    root = tmp_path / "rgbd"
    poses = []
    (root / "scene").mkdir(parents=True)
    for i in range(3):
        _write_rgb(root / "image" / f"{i:03d}.jpg", rng.integers(0, 255, (480, 640, 3), dtype=np.uint8))
        (root / "depth").mkdir(exist_ok=True)
        cv2.imwrite(str(root / "depth" / f"{i:03d}.png"), np.full((480, 640), 1500, np.uint16))
        T = np.linalg.inv(_look_at(np.array([i * 0.1, 0.0, -2.0]), [0, 0, 0]))
        poses.append(T)
    with open(root / "scene" / "key.log", "w", newline="\r\n") as fh:
        for i, T in enumerate(poses):
            fh.write(f"{i} {i} {i + 1}\n")
            for row in T:
                fh.write(" ".join(f"{x:.17g}" for x in row) + "\n")
    o3d.io.write_triangle_mesh(str(root / "scene" / "m.ply"), o3d.geometry.TriangleMesh.create_box())
    with pytest.raises(InputError, match=r"pass the mesh explicitly.*m\.ply"):
        load_scene(root)
    s = load_scene(root, mesh="scene/m.ply")
    assert len(s) == 3 and s.names == ["000", "001", "002"]
    assert np.allclose(s.views[1].center, [0.1, 0.0, -2.0])
    assert np.array_equal(s.views[0].intrinsic, PRIMESENSE_INTRINSIC)
    assert s.views[2].depth.name == "002.png"
    assert s.views[0].load_depth()[0, 0] == pytest.approx(1.5)
    # NaN pose
    text = (root / "scene" / "key.log").read_text().replace(f"{poses[1][0, 0]:.17g}", "nan", 1)
    (root / "scene" / "key.log").write_text(text)
    with pytest.raises(InputError, match=r"key\.log: pose 1: nan at \[0, 0\] is not a finite normal number"):
        load_scene(root, mesh="scene/m.ply")


def test_colmap_text_model(tmp_path, rng):
    root = tmp_path / "colmap"
    (root / "sparse").mkdir(parents=True)
    _write_rgb(root / "images" / "a.png", rng.integers(0, 255, (48, 64, 3), dtype=np.uint8))
    _write_rgb(root / "images" / "b.png", rng.integers(0, 255, (48, 64, 3), dtype=np.uint8))
    (root / "sparse" / "cameras.txt").write_text(
        "# Camera list\n1 PINHOLE 64 48 100 110 32 24\n2 SIMPLE_PINHOLE 64 48 90 32 24\n"
    )
    # 90 degrees about y: q = (cos45, 0, sin45, 0)
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    (root / "sparse" / "images.txt").write_text(
        "# Image list\n"
        "1 1 0 0 0 0.1 0.2 0.3 1 a.png\n\n"
        f"2 {c} 0 {s} 0 0 0 1 2 b.png\n1.0 2.0 -1\n"
    )
    o3d.io.write_triangle_mesh(str(root / "mesh.ply"), o3d.geometry.TriangleMesh.create_box())
    sc = load_scene(root / "sparse", mesh=root / "mesh.ply")
    assert sc.names == ["a", "b"]
    a, b = sc.views
    assert np.allclose(a.intrinsic, [[100, 0, 31.5], [0, 110, 23.5], [0, 0, 1]])
    assert np.allclose(a.translation, [0.1, 0.2, 0.3]) and np.allclose(a.rotation, np.eye(3))
    assert np.allclose(b.rotation, [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-12)
    assert b.intrinsic[0, 0] == b.intrinsic[1, 1] == 90
    # distortion is removed when the images are read; models without an OpenCV form are refused with the fix
    (root / "sparse" / "cameras.txt").write_text("1 OPENCV 64 48 100 100 32 24 0.1 0 0 0\n2 PINHOLE 64 48 1 1 1 1\n")
    assert load_scene(root / "sparse", mesh=root / "mesh.ply").views[0].distortion.model == "opencv"
    (root / "sparse" / "cameras.txt").write_text("1 THIN_PRISM_FISHEYE 64 48 100 100 32 24 0.1 0 0 0 0 0 0 0\n"
                                                 "2 PINHOLE 64 48 1 1 1 1\n")
    with pytest.raises(InputError, match=r"cameras\.txt: camera line .*THIN_PRISM_FISHEYE is not supported.*undistort"):
        load_scene(root / "sparse", mesh=root / "mesh.ply")


# ------------------------------------------------------------------------------ real data


def test_fountain_loads_33_views(fountain_scene):
    assert len(fountain_scene) == 33
    v = fountain_scene.views[0]
    assert (v.width, v.height) == (640, 480) and v.depth is not None
    assert fountain_scene.load_mesh().faces.shape == (16328, 3)


def test_fountain_mesh_projects_onto_depth_map(fountain_scene):
    """Visible mesh vertices projected into a view land on the depth map (median |error| < 5 cm)."""
    mesh = fountain_scene.load_mesh()
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)), o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    errs = []
    for idx in (0, 16, 32):
        v = fountain_scene.views[idx]
        X = mesh.vertices @ v.rotation.T + v.translation
        z = X[:, 2]
        uv = X[:, :2] / np.maximum(z, 1e-9)[:, None] * np.diag(v.intrinsic)[:2] + v.intrinsic[:2, 2]
        px = np.round(uv).astype(int)
        keep = (z > 0.1) & (px[:, 0] >= 0) & (px[:, 0] < v.width) & (px[:, 1] >= 0) & (px[:, 1] < v.height)
        # not occluded: the first hit from the camera centre is (about) the vertex itself
        d = mesh.vertices[keep] - v.center
        dist = np.linalg.norm(d, axis=1)
        rays = np.hstack([np.broadcast_to(v.center, d.shape), d / dist[:, None]]).astype(np.float32)
        t_hit = rc.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
        visible = t_hit > dist - 0.01
        depth = v.load_depth()
        sensor = depth[px[keep, 1], px[keep, 0]][visible]
        ok = sensor > 0
        assert ok.sum() > 1000
        errs.append(np.median(np.abs(sensor[ok] - z[keep][visible][ok])))
    assert max(errs) < 0.05, errs


def test_repr_is_one_line_and_save_keeps_symlinked_paths(tiny, tmp_path):
    scene = load_scene(tiny)
    text = repr(scene)
    assert "\n" not in text and len(text) < 200 and "2 views 64x48" in text and "v0" in text
    link = tmp_path / "linked"
    link.symlink_to(tiny, target_is_directory=True)
    through = load_scene(link)
    out = save_scene(through, tmp_path / "copy" / "scene.json")
    doc = json.loads(out.read_text())
    assert doc["mesh"] == "../linked/mesh.ply"  # the path as given, not the link's target
    assert load_scene(out) == through
