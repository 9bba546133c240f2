"""The texrecon peer's converter (benchmarks/peers.py): .cam files, welded PLY, scene folder.

CI does not build texrecon: these tests check what we write against texrecon's documented
conventions (mve's ``CameraInfo::fill_calibration``, texrecon's half-pixel shift after
projecting). The last test runs texrecon when a build is cached (``benchmarks/peers.py
--build-only``) and checks that its texture lines up with the photo it came from.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.peers import texrecon_cam, write_texrecon_scene, write_welded_ply
from o3d_seqcc.geometry.camera import project_points
from o3d_seqcc.scene import Mesh, Scene, View, load_mesh


def _rotation(rng) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def _view(rng, W: int, H: int, fx: float, fy: float, name: str = "v") -> View:
    E = np.eye(4)
    E[:3, :3] = _rotation(rng)
    E[:3, 3] = rng.normal(size=3)
    K = np.array([[fx, 0, W / 2 - 0.5 + 3.25], [0, fy, H / 2 - 0.5 - 1.75], [0, 0, 1]])
    return View(name=name, image=None, intrinsic=K, extrinsic=E, width=W, height=H,
                pixels=rng.integers(0, 256, (H, W, 3), dtype=np.uint8))


def _texrecon_project(cam: str, X: np.ndarray, W: int, H: int) -> np.ndarray:
    """texrecon's projection of world points from a .cam text (mve fill_calibration, then -0.5)."""
    l1, l2 = cam.strip().splitlines()
    e = np.array(l1.split(), dtype=np.float64)
    flen, d0, d1, paspect, ppx, ppy = map(float, l2.split())
    assert d0 == 0.0 and d1 == 0.0
    t, R = e[:3], e[3:].reshape(3, 3)
    if W / H * paspect < 1.0:  # portrait
        ax, ay = flen * H / paspect, flen * H
    else:
        ax, ay = flen * W, flen * W * paspect
    K = np.array([[ax, 0, W * ppx], [0, ay, H * ppy], [0, 0, 1]])
    x = (X @ R.T + t) @ K.T
    return x[:, :2] / x[:, 2:] - 0.5


@pytest.mark.parametrize("W,H,fx,fy", [(640, 480, 525.0, 521.0), (480, 640, 600.0, 610.0), (500, 500, 400.0, 400.0)])
def test_cam_projects_as_our_cameras(W, H, fx, fy):
    rng = np.random.default_rng(W + H)
    v = _view(rng, W, H, fx, fy)
    X = (v.center + rng.normal(size=(50, 3)) * 0.3 + v.rotation[2] * 3.0)  # in front of the camera
    ours, z = project_points(X, v.intrinsic, v.extrinsic)
    assert (z > 0).all()
    exact = _texrecon_project(texrecon_cam(v, align_texels=False), X, W, H)
    np.testing.assert_allclose(exact, ours, atol=1e-9)
    # the default moves the principal point half a pixel: texrecon's texture coordinates
    # (projected pixel centre / atlas size) then land where OBJ readers put the texel centres
    aligned = _texrecon_project(texrecon_cam(v), X, W, H)
    np.testing.assert_allclose(aligned, ours + 0.5, atol=1e-9)


def test_cam_refuses_skew():
    from o3d_seqcc.errors import InputError

    v = _view(np.random.default_rng(0), 64, 48, 50.0, 50.0)
    K = v.intrinsic.copy()
    K[0, 1] = 0.5
    with pytest.raises(InputError, match="skew"):
        texrecon_cam(View(name="s", image=None, intrinsic=K, extrinsic=v.extrinsic, width=64, height=48, pixels=v.pixels))


def test_welded_ply_merges_a_soup(tmp_path):
    """A triangle soup (three vertices per face, as Fountain's 16k mesh) is welded; degenerate faces dropped."""
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 1, 1]])  # the last is degenerate
    soup_v = quad[faces.reshape(-1)] + 1e-13  # float noise far below the welding step
    soup_f = np.arange(9).reshape(3, 3)
    info = write_welded_ply(soup_v, soup_f, tmp_path / "m.ply")
    assert (info["vertices_in"], info["vertices"], info["faces_in"], info["faces"]) == (9, 4, 3, 2)
    np.testing.assert_array_equal(info["kept"], [0, 1])
    m = load_mesh(tmp_path / "m.ply")
    assert m.vertices.shape == (4, 3) and m.faces.shape == (2, 3)
    np.testing.assert_allclose(m.vertices[m.faces], quad[faces[:2]], atol=1e-6)  # same triangles, same winding
    head = (tmp_path / "m.ply").read_bytes().split(b"end_header")[0].decode()
    assert "property list uchar int vertex_indices" in head and "binary_little_endian" in head


def test_scene_folder(tmp_path):
    rng = np.random.default_rng(5)
    views = tuple(_view(rng, 32, 24, 30.0, 30.0, name=f"photo{i}") for i in range(12))
    v = np.array([[0, 0, 5], [1, 0, 5], [0, 1, 5]], dtype=np.float64)
    scene = Scene(mesh=Mesh(vertices=v, faces=np.array([[0, 1, 2]]), vertex_normals=np.tile([0, 0, -1.0], (3, 1))),
                  views=views)
    info = write_texrecon_scene(scene, tmp_path / "tx")
    names = sorted(p.name for p in info["images"].iterdir())
    # fixed-width names: "view_0001" must not be a prefix of another view's files
    assert names == sorted([f"view_{i:04d}.cam" for i in range(12)] + [f"view_{i:04d}.png" for i in range(12)])
    assert info["names"][10] == "view_0010"
    from o3d_seqcc.io.images import read_image

    np.testing.assert_array_equal(read_image(info["images"] / "view_0007.png"), views[7].pixels)
    assert (info["images"] / "view_0003.cam").read_text() == texrecon_cam(views[3])
    with pytest.raises(Exception, match="not empty"):
        write_texrecon_scene(scene, tmp_path / "tx")


def test_texrecon_texture_lines_up_with_its_photos(tmp_path):
    """With a cached texrecon build: on a synthetic room (exact cameras and geometry), a render from a
    photo's camera reproduces that photo where texrecon textured the faces from it."""
    from benchmarks.peers import run_texrecon, texrecon_binary
    from o3d_seqcc import load_scene, make_synthetic_scene
    from o3d_seqcc.evaluation.render import gradient_similarity, raycast, render_textured

    exe = texrecon_binary()
    if exe is None:
        pytest.skip("texrecon is not built here (python benchmarks/peers.py --build-only builds it; CI does not)")
    make_synthetic_scene(tmp_path / "room", n_views=6, width=240, height=180, photometric="none")
    scene = load_scene(tmp_path / "room")
    res = run_texrecon(scene, tmp_path / "tx", binary=exe)
    labels = np.fromfile(tmp_path / "tx" / "texrecon_labeling.vec", dtype=np.uint64).astype(np.int64) - 1
    mesh = load_mesh(res.info["mesh"])
    assert len(labels) == len(mesh.faces)
    from dataclasses import replace

    scores = []
    for k in range(len(scene.views)):
        v = scene.views[k]
        own = raycast(mesh, v)
        m = own.mask & (labels[np.maximum(own.face_ids, 0)] == k)
        if m.sum() < 2000:
            continue
        m &= raycast(res.mesh, v).mask
        photo = v.load_image()
        at = gradient_similarity(render_textured(res.mesh, v), photo, m, max_shift=0)  # no misregistration forgiven
        K = v.intrinsic.copy()
        K[:2, 2] -= 0.5  # half a pixel off: what the exact principal point gives
        off = gradient_similarity(render_textured(res.mesh, replace(v, intrinsic=K)), photo, m, max_shift=0)
        scores.append((at, off))
    assert scores, "texrecon textured too few pixels from any view"
    assert all(at > 0.97 and at > off + 0.02 for at, off in scores), scores
