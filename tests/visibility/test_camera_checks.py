"""Camera sanity before any work: each camera mistake of issue 20 ends in an InputError naming the fix,
the options that state the convention load the scene right, and correct scenes pass (rooms, an
object seen from outside, Fountain), also with junk triangles far away."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
import pytest

import o3d_seqcc as sc
from o3d_seqcc import InputError, load_scene
from o3d_seqcc.visibility.camera_checks import FLIP, check_cameras
from o3d_seqcc.cli import main
from o3d_seqcc.io.meshlab import save_mlp


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    """A synthetic room seen from inside (two rings of cameras), the kind the issue's 37,808-face room is."""
    root = tmp_path_factory.mktemp("room")
    return sc.make_synthetic_scene(root / "R", n_views=8, width=64, height=48, cell_size=0.3, layout="two-rings",
                                   photometric="none")


def _look_at(c: np.ndarray, target=(0.0, 0.0, 0.0)) -> np.ndarray:
    f = np.asarray(target, float) - c
    f /= np.linalg.norm(f)
    right = np.cross(f, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(f, right)
    E = np.eye(4)
    E[:3, :3] = np.stack([right, down, f])
    E[:3, 3] = -E[:3, :3] @ c
    return E


@pytest.fixture(scope="module")
def statue(tmp_path_factory):
    """An object seen from outside: a sphere of radius 0.5 m at the origin, 8 cameras on a ring 1.4 m away."""
    root = tmp_path_factory.mktemp("statue")
    mesh = o3d.geometry.TriangleMesh.create_sphere(0.5, resolution=20)
    mesh.compute_vertex_normals()
    o3d.io.write_triangle_mesh(str(root / "mesh.ply"), mesh)
    (root / "images").mkdir()
    views = []
    for i in range(8):
        a = 2 * np.pi * i / 8
        c = np.array([1.4 * np.cos(a), 1.4 * np.sin(a), 0.3])
        cv2.imwrite(str(root / "images" / f"v{i}.png"), np.full((48, 64, 3), 128, np.uint8))
        views.append({"name": f"v{i}", "image": f"images/v{i}.png", "width": 64, "height": 48,
                      "intrinsic": [[60.0, 0, 31.5], [0, 60.0, 23.5], [0, 0, 1]], "extrinsic": _look_at(c).tolist()})
    (root / "scene.json").write_text(json.dumps({"format": "o3d_seqcc.scene/1", "mesh": "mesh.ply", "views": views}))
    return root


def _copy_with(src: Path, dst: Path, change, *, mesh: str | None = None) -> Path:
    """``src``'s scene.json written to ``dst`` with every extrinsic passed through ``change`` (absolute paths)."""
    d = json.loads((src / "scene.json").read_text())
    for v in d["views"]:
        v["extrinsic"] = change(np.array(v["extrinsic"])).tolist()
        for k in ("image", "depth"):
            if k in v:
                v[k] = str(src / v[k])
    d["mesh"] = mesh or str(src / d["mesh"])
    dst.mkdir(parents=True, exist_ok=True)
    (dst / "scene.json").write_text(json.dumps(d))
    return dst / "scene.json"


def _same_cameras(a, b) -> None:
    for u, v in zip(a.views, b.views):
        np.testing.assert_allclose(u.extrinsic, v.extrinsic, atol=1e-9)


# ------------------------------------------------------------------------------ correct scenes pass


def test_correct_scenes_pass(room, statue):
    for path, seen in ((room.root, 0.3), (statue, 0.5)):  # 8 views of the room see a third of it
        scene = load_scene(path)
        rep = check_cameras(scene)
        assert rep.mistake is None and not rep.warnings
        assert rep.front_fraction > 0.4 and rep.area_seen > seen
        assert rep.seconds < 5


def test_fountain_passes(fountain_root):
    rep = check_cameras(load_scene(fountain_root, mesh="scene/mesh_decimated_uv_blender.ply"))
    assert rep.mistake is None and rep.front_fraction > 0.5 and rep.area_seen > 0.9


def test_junk_far_away_raises_no_alarm_and_hides_no_mistake(statue, tmp_path):
    """Two huge triangles 1 km away (stray geometry) neither veto a correct scene nor hide a mistake."""
    m = o3d.io.read_triangle_mesh(str(statue / "mesh.ply"))
    junk = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector([[1000, 0, 0], [1000, 400, 0], [1000, 0, 400],
                                                                 [0, 1000, 0], [400, 1000, 0], [0, 1000, 400]]),
                                     o3d.utility.Vector3iVector([[0, 1, 2], [3, 4, 5]]))
    m += junk
    m.compute_vertex_normals()
    o3d.io.write_triangle_mesh(str(tmp_path / "junk.ply"), m)
    check_cameras(load_scene(statue, mesh=tmp_path / "junk.ply"))
    bad = _copy_with(statue, tmp_path / "c2w", np.linalg.inv, mesh=str(tmp_path / "junk.ply"))
    with pytest.raises(InputError, match="--extrinsic camera-to-world"):
        load_scene(bad)


# ------------------------------------------------------------------------------ one test per mistake


def test_camera_to_world_given_as_extrinsic(room, tmp_path):
    bad = _copy_with(room.root, tmp_path / "c2w", np.linalg.inv)
    with pytest.raises(InputError) as e:
        load_scene(bad)
    msg = str(e.value)
    assert "poses look inverted" in msg and "--extrinsic camera-to-world" in msg and str(bad) in msg
    assert "as given: 0%" in msg
    fixed = load_scene(bad, extrinsic="camera-to-world")
    _same_cameras(fixed, room.scene)
    # and before any work on the command line: nothing is written
    assert main(["-q", "run", str(bad), "--out", str(tmp_path / "out")]) == 2
    assert not (tmp_path / "out").exists()
    assert main(["-q", "info", str(bad), "--extrinsic", "camera-to-world"]) == 0
    # a run states it; report.json records it, so the report can be made again from the folder
    out = tmp_path / "stated"
    assert main(["-q", "run", str(bad), "--extrinsic", "camera-to-world", "--out", str(out), "--t-npm", "10",
                 "--format", "glb", "--no-seams", "--atlas-size", "256"]) == 0
    assert json.loads((out / "report.json").read_text())["scene_options"] == {"extrinsic": "camera-to-world"}
    (out / "report.html").unlink()
    assert main(["-q", "report", str(out)]) == 0 and (out / "report.html").is_file()


def test_opengl_axes_given_as_opencv(statue, tmp_path):
    bad = _copy_with(statue, tmp_path / "gl", lambda E: FLIP @ E)
    with pytest.raises(InputError, match=r"cameras look OpenGL.*--axes opengl"):
        load_scene(bad)
    _same_cameras(load_scene(bad, axes="opengl"), load_scene(statue))


def test_nerf_poses_camera_to_world_opengl(statue, tmp_path):
    bad = _copy_with(statue, tmp_path / "nerf", lambda E: np.linalg.inv(FLIP @ E))
    with pytest.raises(InputError, match=r"camera-to-world in OpenGL.*--extrinsic camera-to-world --axes opengl"):
        load_scene(bad)
    _same_cameras(load_scene(bad, extrinsic="camera-to-world", axes="opengl"), load_scene(statue))


def test_mesh_in_millimetres_cameras_in_metres(statue, tmp_path):
    m = o3d.io.read_triangle_mesh(str(statue / "mesh.ply"))
    m.scale(1000.0, center=(0.0, 0.0, 0.0))
    o3d.io.write_triangle_mesh(str(tmp_path / "mm.ply"), m)
    with pytest.raises(InputError, match=r"mesh looks 1000x the cameras' units.*scale the mesh by 0\.001"):
        load_scene(statue, mesh=tmp_path / "mm.ply")
    assert main(["-q", "info", str(statue), "--mesh", str(tmp_path / "mm.ply"), "--no-camera-check"]) == 0


def _rgbd_folder(room, root: Path) -> Path:
    """The room as an Open3D RGB-D folder: its 64x48 images, camera-to-world poses in key.log."""
    (root / "image").mkdir(parents=True)
    (root / "scene").mkdir()
    with open(root / "scene" / "key.log", "w") as fh:
        for i, v in enumerate(room.scene.views):
            shutil.copy(v.image, root / "image" / f"{i:06d}.png")
            T = np.linalg.inv(v.extrinsic)
            fh.write(f"{i} {i} {i + 1}\n" + "".join(" ".join(f"{x:.17g}" for x in r) + "\n" for r in T))
    return root


def test_rgbd_intrinsic_of_another_image_size(room, tmp_path):
    root = _rgbd_folder(room, tmp_path / "rgbd")
    mesh = room.scene.mesh
    with pytest.raises(InputError, match=r"64x48 images.*PrimeSense.*640x480.*fx = fy = 52\.5.*--intrinsic FILE"):
        load_scene(root, mesh=mesh)
    K = room.scene.views[0].intrinsic
    good = tmp_path / "intrinsic.json"
    o3d.io.write_pinhole_camera_intrinsic(str(good), o3d.camera.PinholeCameraIntrinsic(64, 48, K[0, 0], K[1, 1],
                                                                                       K[0, 2], K[1, 2]))
    scene = load_scene(root, mesh=mesh, intrinsic=good)
    np.testing.assert_allclose(scene.views[0].intrinsic, K)
    _same_cameras(scene, room.scene)
    other = tmp_path / "other.json"
    o3d.io.write_pinhole_camera_intrinsic(str(other), o3d.camera.PinholeCameraIntrinsic(
        o3d.camera.PinholeCameraIntrinsicParameters.PrimeSenseDefault))
    with pytest.raises(InputError, match=r"other\.json is for 640x480 images but image/ holds 64x48"):
        load_scene(root, mesh=mesh, intrinsic=other)
    with pytest.raises(InputError, match=r"principal point at \(319\.5, 239\.5\), outside the 64x48"):
        load_scene(root, mesh=mesh, intrinsic=sc.scene.PRIMESENSE_INTRINSIC)
    assert main(["-q", "info", str(root), "--mesh", str(mesh), "--intrinsic", str(good)]) == 0
    # key.log holding world-to-camera matrices: the check says so, --extrinsic world-to-camera reads them
    log = root / "scene" / "key.log"
    text = []
    for i, v in enumerate(room.scene.views):
        text.append(f"{i} {i} {i + 1}\n" + "".join(" ".join(f"{x:.17g}" for x in r) + "\n" for r in v.extrinsic))
    log.write_text("".join(text))
    with pytest.raises(InputError, match="--extrinsic world-to-camera"):
        load_scene(root, mesh=mesh, intrinsic=good)
    _same_cameras(load_scene(root, mesh=mesh, intrinsic=good, extrinsic="world-to-camera"), room.scene)


def test_most_of_the_mesh_outside_every_camera_is_refused_unless_allowed(statue, tmp_path):
    def aside(E):  # every camera 10 m to its left, looking past the object
        E = E.copy()
        E[0, 3] += 10.0
        return E

    away = _copy_with(statue, tmp_path / "away", aside)
    with pytest.raises(InputError, match=r"the camera check finds only 0% of the mesh seen .*--allow-unseen"):
        load_scene(away)
    with pytest.warns(sc.errors.O3dSeqccWarning, match=r"only 0% of the mesh faces a camera"):
        load_scene(away, allow_unseen=True)


def test_a_mesh_from_another_scene_is_refused_unless_allow_unseen(room, tmp_path, capsys):
    """The room's mesh 100 m below its cameras (another scene's frame) is an error naming the camera check and
    --allow-unseen, before any work; a mesh of which the photos show a sliver runs with --allow-unseen."""
    m = o3d.io.read_triangle_mesh(str(room.scene.mesh))
    far = o3d.geometry.TriangleMesh(m).translate((0.0, 0.0, -100.0))
    o3d.io.write_triangle_mesh(str(tmp_path / "far.ply"), far)
    with pytest.raises(InputError, match=r"the camera check finds only 0% of the mesh seen by the 8 cameras .*"
                                         r"mesh of another scene.*--mesh.*--extrinsic camera-to-world.*--allow-unseen"):
        load_scene(room.root, mesh=tmp_path / "far.ply")
    out = tmp_path / "out"
    assert main(["-q", "run", str(room.root), "--mesh", str(tmp_path / "far.ply"), "--out", str(out)]) == 2
    assert "camera check finds only 0%" in capsys.readouterr().err and not out.exists()
    assert main(["-q", "info", str(room.root), "--mesh", str(tmp_path / "far.ply")]) == 2
    assert "--allow-unseen" in capsys.readouterr().err
    assert main(["-q", "info", str(room.root), "--mesh", str(tmp_path / "far.ply"), "--allow-unseen"]) == 0
    # a 2 m x 1.6 m piece of one wall where the photos are, the rest 100 m below: 3 % seen
    V, F = np.asarray(m.vertices), np.asarray(m.triangles)
    c = V[F].mean(axis=1)
    piece = o3d.geometry.TriangleMesh(m.vertices, o3d.utility.Vector3iVector(F[np.all((c > [4.9, 1.0, 0.5]) & (
        c < [5.1, 3.0, 2.1]), axis=1)]))
    sliver = far + piece.remove_unreferenced_vertices()
    o3d.io.write_triangle_mesh(str(tmp_path / "sliver.ply"), sliver.compute_vertex_normals())
    with pytest.raises(InputError, match=r"finds only [1-9]% of the mesh seen.*--allow-unseen"):
        load_scene(room.root, mesh=tmp_path / "sliver.ply")
    with pytest.warns(sc.errors.O3dSeqccWarning, match=r"only [1-9]% of the mesh faces a camera"):
        assert load_scene(room.root, mesh=tmp_path / "sliver.ply", allow_unseen=True).options == {"allow_unseen": True}
    assert main(["-q", "run", str(room.root), "--mesh", str(tmp_path / "sliver.ply"), "--allow-unseen", "--out",
                 str(out), "--t-npm", "10", "--format", "glb", "--no-seams", "--atlas-size", "256"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["scene_options"] == {"allow_unseen": True}
    assert 0 < rep["selection"]["unseen_faces"] < rep["selection"]["faces"]


def test_convention_options_are_checked(room, statue, tmp_path):
    with pytest.raises(InputError, match="unknown extrinsic convention 'c2w'; valid: world-to-camera, camera-to-world"):
        load_scene(statue, extrinsic="c2w")
    with pytest.raises(InputError, match="unknown camera axes 'gl'"):
        load_scene(statue, axes="gl")
    mlp = save_mlp(room.scene, tmp_path / "p.mlp")
    with pytest.raises(InputError, match=r"extrinsic= does not apply to a MeshLab project"):
        load_scene(mlp, extrinsic="camera-to-world")
    with pytest.raises(InputError, match=r"intrinsic= does not apply"):
        load_scene(statue, intrinsic=tmp_path / "x.json")
    # a stated convention is not second-guessed: the wrong one sees nothing (refused as such), and loads with
    # allow_unseen (and only warns)
    with pytest.raises(InputError, match="the photos do not show this mesh.*--allow-unseen"):
        load_scene(statue, extrinsic="camera-to-world")
    with pytest.warns(sc.errors.O3dSeqccWarning, match="faces a camera"):
        load_scene(statue, extrinsic="camera-to-world", allow_unseen=True)


def test_info_prints_text_then_json(room, tmp_path, capsys):
    assert main(["info", str(room.root)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"scene: {room.root / 'scene.json'} (scene.json)\nviews: 8 (64x48), 8 with depth maps")
    assert "of the mesh faces a camera" in out
    assert main(["info", str(room.root), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert {"views", "names", "image_size", "with_depth", "mesh_faces", "mesh_bounds", "camera_centre_bounds"} <= set(d)
    assert d["format"] == "scene.json" and d["camera_check"]["mistake"] is None and d["warnings"] == []
    bad = _copy_with(room.root, tmp_path / "c2w", np.linalg.inv)
    assert main(["info", str(bad)]) == 2
    cap = capsys.readouterr()
    assert "likely camera mistake: the poses look inverted" in cap.out and "--extrinsic camera-to-world" in cap.err


def test_open3d_front_door_checks_the_cameras(statue):
    """correct_images / texture_mesh with camera-to-world poses where extrinsics belong: an error naming the fix."""
    scene = load_scene(statue)
    mesh = o3d.io.read_triangle_mesh(str(statue / "mesh.ply"))
    images = [v.load_image() for v in scene.views]
    Ks = [v.intrinsic for v in scene.views]
    with pytest.raises(InputError, match=r"cameras: the poses look inverted.*numpy\.linalg\.inv"):
        sc.correct_images(mesh, images, (Ks, [np.linalg.inv(v.extrinsic) for v in scene.views]))
    with pytest.raises(InputError, match=r"cameras: the cameras look OpenGL.*numpy\.diag"):
        sc.texture_mesh(mesh, images, (Ks, [FLIP @ v.extrinsic for v in scene.views]))
