"""MVE scenes and texrecon camera folders: a known synthetic scene written by independent writers that
follow MVE's libs/mve/view.cc (meta.ini) and texrecon's .cam files (mvs-texturing
libs/tex/generate_texture_views.cpp), read back to the same cameras; pixels as MVE's
CameraInfo::fill_calibration and texrecon's get_pixel_coords (-0.5) place them; the radial distortion
as MVE's image_undistort_k2k4 / image_undistort_vsfm define it; `o3d-seqcc info` / `run`."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

import o3d_seqcc as sc
from o3d_seqcc import InputError, load_scene
from o3d_seqcc.cli import main
from o3d_seqcc.geometry.camera import project_points
from o3d_seqcc.io.images import read_image, write_image

# ------------------------------------------------------------------------------ the writers (from the specs)


def _g(x) -> str:
    return repr(float(x))


def _normalised(view) -> tuple[float, float, float, float]:
    """(f, paspect, ppx, ppy) of a view's pinhole K as MVE stores it (landscape: f = fx / w, fy = f w paspect)."""
    K, w, h = view.intrinsic, view.width, view.height
    assert w >= h
    return K[0, 0] / w, K[1, 1] / K[0, 0], (K[0, 2] + 0.5) / w, (K[1, 2] + 0.5) / h


def write_cam_folder(folder: Path, scene, *, dist=(0.0, 0.0), ppoint=None, uncalibrated: bool = True) -> Path:
    """texrecon's SCENE_FOLDER: NAME.cam ('tx ty tz R00..R22' / 'f d0 d1 paspect ppx ppy') + NAME.png."""
    folder.mkdir(parents=True, exist_ok=True)
    for v in scene.views:
        f, pa, ppx, ppy = _normalised(v)
        if ppoint is not None:
            ppx, ppy = ppoint
        R, t = v.extrinsic[:3, :3], v.extrinsic[:3, 3]
        (folder / f"{v.name}.cam").write_text(" ".join(map(_g, [*t, *R.ravel()])) + "\n"
                                              + " ".join(map(_g, [f, *dist, pa, ppx, ppy])) + "\n")
        shutil.copy(v.image, folder / f"{v.name}.png")
    if uncalibrated:
        (folder / "nocam.cam").write_text("0 0 0 1 0 0 0 1 0 0 0 1\n0\n")
        shutil.copy(scene.views[0].image, folder / "nocam.jpg.png")  # not nocam's photo: a different stem
        shutil.copy(scene.views[0].image, folder / "nocam.png")
    (folder / "lonely.cam").write_text("0 0 0 1 0 0 0 1 0 0 0 1\n0.8\n")  # no photo: skipped
    return folder


def write_mve_scene(root: Path, scene, *, embedding: str = "undistorted", dist=(0.0, 0.0)) -> Path:
    """An MVE scene: views/view_NNNN.mve/meta.ini ([view] id, name; [camera] ...) + the embedding's image."""
    for i, v in enumerate(scene.views):
        d = root / "views" / f"view_{i:04d}.mve"
        d.mkdir(parents=True, exist_ok=True)
        f, pa, ppx, ppy = _normalised(v)
        R, t = v.extrinsic[:3, :3], v.extrinsic[:3, 3]
        (d / "meta.ini").write_text(
            "# MVE view meta data is stored in INI-file syntax.\n# This file is generated, formatting will get lost.\n"
            f"\n[camera]\nfocal_length = {_g(f)}\npixel_aspect = {_g(pa)}\nprincipal_point = {_g(ppx)} {_g(ppy)}\n"
            f"radial_distortion = {_g(dist[0])} {_g(dist[1])}\nrotation = {' '.join(map(_g, R.ravel()))}\n"
            f"translation = {' '.join(map(_g, t))}\n\n[view]\nid = {i}\nname = {v.name}\n")
        shutil.copy(v.image, d / f"{embedding}.png")
        shutil.copy(v.image, d / "thumbnail.png")
    d = root / "views" / f"view_{len(scene.views):04d}.mve"  # a view SfM did not reconstruct
    d.mkdir(parents=True, exist_ok=True)
    (d / "meta.ini").write_text("[camera]\nfocal_length = 0\n[view]\nid = 99\nname = lost\n")
    shutil.copy(scene.views[0].image, d / "original.png")
    (root / "synth_0.out").write_text("drews 1.0\n0 0\n")
    return root


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("mve") / "R", n_views=6, width=80, height=60,
                                   cell_size=0.25, layout="two-rings", seen_only=True, photometric="none")


def _assert_same_cameras(a, b, atol=1e-9) -> None:
    assert a.names == b.names
    for u, v in zip(a.views, b.views):
        assert (u.width, u.height) == (v.width, v.height)
        np.testing.assert_allclose(u.intrinsic, v.intrinsic, atol=atol)
        np.testing.assert_allclose(u.extrinsic, v.extrinsic, atol=atol)


def _alignment(room, scene, k: int) -> float:
    pts = room.load_points(k)
    r, c = np.nonzero(np.isfinite(pts[..., 0]))
    uv, _ = project_points(pts[r, c].astype(np.float64), scene.views[k].intrinsic, scene.views[k].extrinsic)
    assert len(r) > 1000
    return float(np.abs(uv - np.stack([c, r], 1)).max())


# ------------------------------------------------------------------------------ the cameras


def test_cam_folder_reads_back_the_cameras(room, tmp_path, caplog):
    folder = write_cam_folder(tmp_path / "cams", room.scene)
    scene = load_scene(folder, mesh=room.scene.mesh)
    assert scene.source == folder and all(v.distortion is None for v in scene.views)
    _assert_same_cameras(scene, room.scene)
    assert "without a photo" in caplog.text and "lonely.cam" in caplog.text
    assert "focal length 0" in caplog.text and "nocam.cam" in caplog.text
    assert max(_alignment(room, scene, k) for k in (0, 5)) < 0.01


def test_mve_scene_reads_back_the_cameras_and_skips_views_without_one(room, tmp_path, caplog):
    root = write_mve_scene(tmp_path / "scene", room.scene)
    scene = load_scene(root, mesh=room.scene.mesh)
    _assert_same_cameras(scene, room.scene)
    assert [v.image.name for v in scene.views] == ["undistorted.png"] * 6
    assert "1 view(s) without a camera" in caplog.text and "view_0006.mve" in caplog.text
    assert max(_alignment(room, scene, k) for k in (0, 3)) < 0.01
    # only 'original' images: read with the camera's distortion (none here); another embedding by name
    root2 = write_mve_scene(tmp_path / "orig", room.scene, embedding="original")
    s2 = load_scene(root2, mesh=room.scene.mesh)
    assert [v.image.name for v in s2.views] == ["original.png"] * 6
    _assert_same_cameras(s2, room.scene)
    s3 = sc.io.mve.load(root2, mesh=room.scene.mesh, embedding="thumbnail")
    assert [v.image.name for v in s3.views] == ["thumbnail.png"] * 6
    with pytest.raises(InputError, match="no calibrated view has the 'depth-L0' image"):
        sc.io.mve.load(root2, mesh=room.scene.mesh, embedding="depth-L0")
    # a view without the embedding is skipped, as texrecon skips it
    (root / "views" / "view_0002.mve" / "undistorted.png").unlink()
    caplog.clear()
    assert load_scene(root, mesh=room.scene.mesh).names == [n for n in room.scene.names if n != "v02"]
    assert "without the 'undistorted' image" in caplog.text


def _fill_calibration(f, paspect, ppx, ppy, w, h):
    """MVE's CameraInfo::fill_calibration (libs/mve/camera.cc), pixel centres at +0.5."""
    if w / h * paspect < 1:
        ax, ay = f * h / paspect, f * h
    else:
        ax, ay = f * w, f * w * paspect
    return np.array([[ax, 0, w * ppx], [0, ay, h * ppy], [0, 0, 1.0]])


@pytest.mark.parametrize("size", [(80, 60), (60, 80)])
def test_pixel_aspect_and_principal_point_as_fill_calibration(room, tmp_path, size):
    w, h = size
    folder = tmp_path / "c"
    folder.mkdir()
    write_image(folder / "p.png", np.full((h, w, 3), 128, np.uint8))
    (folder / "p.cam").write_text("0 0 3 1 0 0 0 1 0 0 0 1\n0.9 0 0 1.25 0.45 0.55\n")
    (folder / "q.cam").write_text("0 0 3 1 0 0 0 1 0 0 0 1\n0.9\n")  # defaults: paspect 1, centre
    shutil.copy(folder / "p.png", folder / "q.png")
    scene = sc.io.mve.load_cam_folder(folder, mesh=room.scene.mesh)
    want = _fill_calibration(0.9, 1.25, 0.45, 0.55, w, h)
    want[:2, 2] -= 0.5  # texrecon's get_pixel_coords: -0.5 before sampling
    np.testing.assert_allclose(scene.views[0].intrinsic, want, atol=1e-12)
    q = _fill_calibration(0.9, 1.0, 0.5, 0.5, w, h)
    q[:2, 2] -= 0.5
    np.testing.assert_allclose(scene.views[1].intrinsic, q, atol=1e-12)
    np.testing.assert_allclose(q[:2, 2], [(w - 1) / 2, (h - 1) / 2])


# ------------------------------------------------------------------------------ radial distortion


def _k2k4(p, d0, d1, f, w, h):
    """MVE's image_undistort_k2k4: the undistorted pixel p (integer centres) is read from the photo here."""
    fx = (p[:, 0] + 0.5 - w / 2) / max(w, h)
    fy = (p[:, 1] + 0.5 - h / 2) / max(w, h)
    rd = (fx * fx + fy * fy) / f ** 2
    fac = 1 + d0 * rd + d1 * rd * rd
    return np.stack([fx * fac * max(w, h) + w / 2 - 0.5, fy * fac * max(w, h) + h / 2 - 0.5], 1)


def _vsfm(p, k1, f, w, h):
    """MVE's image_undistort_vsfm, literally (its cubic and its root), for an undistorted pixel index p."""
    norm = f * max(w, h)
    fx, fy = (p[:, 0] - w / 2) / norm, (p[:, 1] - h / 2) / norm
    fy = np.where(fy == 0, 1e-10, fy)
    t2, t4 = fy * fy, fx * fx
    t3, t7 = t2 ** 3, k1 * (t2 + t4)
    if k1 > 0:
        t8 = 1 / t7
        t10 = t3 / (t7 * t7)
        t14 = np.sqrt(t10 * (0.25 + t8 / 27))
        t15 = t2 * t8 * fy * 0.5
        t17 = np.cbrt(t14 + t15)  # std::pow(x, 1/3) of a positive x
        t18 = t17 - t2 * t8 / (t17 * 3)
    else:
        t9, t11 = t3 / (t7 * t7 * 4), t3 / (t7 ** 3 * 27)
        t13 = np.sqrt((t9 + t11).astype(complex))
        t14 = t2 / t7
        t17 = (t13 + t14 * fy * 0.5) ** (1 / 3)
        t18 = (t17 + t14 / (t17 * 3)) * 1j * np.sqrt(3)
        t18 = (-0.5 * (t17 + t18) + t14 / (t17 * 6)).real
    return np.stack([t18 * fx / fy * norm + w / 2, t18 * norm + h / 2], 1)


def _lens_view(room, tmp_path, dist, ppoint=None):
    folder = write_cam_folder(tmp_path / f"d{abs(hash((dist, ppoint)))}", room.scene, dist=dist, ppoint=ppoint,
                              uncalibrated=False)
    return load_scene(folder, mesh=room.scene.mesh, check_cameras=False).views[0]


@pytest.mark.parametrize("dist, ppoint, model", [((-0.3, 0.08), None, "opencv"), ((0.2, -0.05), None, "opencv"),
                                                 ((-0.3, 0.08), (0.45, 0.52), "pixel-radial"),
                                                 ((0.0, 0.1), None, "opencv"),
                                                 ((0.25, 0.0), None, "pixel-radial-inverse"),
                                                 ((-0.2, 0.0), (0.47, 0.5), "pixel-radial-inverse")])
def test_distortion_is_mves(room, tmp_path, dist, ppoint, model):
    """The undistorted image's pixel p (texrecon's camera K0) comes from the photo where MVE's undistortion
    reads it: image_undistort_k2k4 (d1 != 0) or image_undistort_vsfm (d1 == 0), to < 0.01 px."""
    v = _lens_view(room, tmp_path, dist, ppoint)
    d, (w, h) = v.distortion, (v.width, v.height)
    assert d.model == model
    f, pa, ppx, ppy = _normalised(room.scene.views[0])
    K0 = _fill_calibration(f, pa, *(ppoint or (ppx, ppy)), w, h)
    K0[:2, 2] -= 0.5
    np.testing.assert_allclose(d.intrinsic, K0, atol=1e-12)
    # every pixel of the view's pinhole image: the direction it sees, where K0 puts it, where MVE reads it
    u, vv = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    P = v.intrinsic
    xy = np.stack([(u.ravel() - P[0, 2]) / P[0, 0], (vv.ravel() - P[1, 2]) / P[1, 1]], 1)
    p = xy @ K0[:2, :2].T + K0[:2, 2]
    if dist[1] != 0:
        want = _k2k4(p, *dist, f, w, h)
    else:
        want = _vsfm(p, dist[0], f, w, h)
        # and VisualSfM's own forward definition: the photo's pixel d shows c + (d - c) (1 + k rho_d^2)
        c = np.array([w / 2, h / 2])
        q = (want - c) / (f * max(w, h))
        np.testing.assert_allclose(c + (want - c) * (1 + dist[0] * (q * q).sum(1))[:, None], p, atol=1e-9)
    got = d.distort(xy)
    assert np.abs(got - want).max() < 0.01, np.abs(got - want).max()
    assert np.abs(got - want).max() < 1e-6
    m1, m2 = d.maps(w, h, P)  # the cached remap maps (fixed point, 1/32 px) follow the model
    mx, my = cv2.convertMaps(m1, m2, cv2.CV_32FC1)
    assert np.abs(np.stack([mx.ravel(), my.ravel()], 1) - want).max() < 1 / 16
    # the undistorted image takes nothing from outside the photo
    assert want.min() >= -0.5 and want[:, 0].max() <= w - 0.5 and want[:, 1].max() <= h - 0.5


def test_only_the_original_embedding_carries_the_distortion(room, tmp_path):
    """sfmrecon writes undistorted = image_undistort_k2k4(original, ...): the undistorted image is pinhole."""
    und = load_scene(write_mve_scene(tmp_path / "u", room.scene, dist=(-0.2, 0.05)), mesh=room.scene.mesh)
    _assert_same_cameras(und, room.scene)
    assert all(v.distortion is None for v in und.views)
    orig = load_scene(write_mve_scene(tmp_path / "o", room.scene, embedding="original", dist=(-0.2, 0.05)),
                      mesh=room.scene.mesh)
    cams = load_scene(write_cam_folder(tmp_path / "c", room.scene, dist=(-0.2, 0.05)), mesh=room.scene.mesh)
    for u, v in zip(orig.views, cams.views):
        assert u.distortion == v.distortion and u.distortion.model == "opencv"
        assert u.distortion.coefficients == (-0.2, 0.05, 0.0, 0.0)
        np.testing.assert_array_equal(u.intrinsic, v.intrinsic)


def test_a_distorted_photo_is_undistorted_to_the_scene_camera(room, tmp_path):
    """Photos distorted with VisualSfM's model (the photo's pixel d shows c + (d - c)(1 + k rho_d^2) of the
    pinhole photo): read back, they are the scene's photos again, and the views keep the scene's cameras."""
    k = 0.15
    folder = write_cam_folder(tmp_path / "vsfm", room.scene, dist=(k, 0.0), uncalibrated=False)
    v0 = room.scene.views[0]
    w, h = v0.width, v0.height
    c, n = np.array([w / 2, h / 2]), _normalised(v0)[0] * max(w, h)
    u, vv = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    dd = np.stack([u, vv], -1) - c
    src = c + dd * (1 + k * (dd * dd).sum(-1, keepdims=True) / n ** 2)
    smooth = {}  # blurred first, so that resampling twice costs little next to a misplaced pixel
    for v in room.scene.views:
        smooth[v.name] = cv2.GaussianBlur(read_image(v.image), (0, 0), 1.5)
    for v in room.scene.views:
        photo = cv2.remap(smooth[v.name], src[..., 0].astype(np.float32), src[..., 1].astype(np.float32),
                          cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
        write_image(folder / f"{v.name}.png", photo)
    scene = load_scene(folder, mesh=room.scene.mesh)
    _assert_same_cameras(scene, room.scene)  # barrel: the photo's own camera fits
    for k_view in (0, 4):
        want = smooth[scene.names[k_view]].astype(float)
        got = scene.views[k_view].load_image().astype(float)
        raw = read_image(scene.views[k_view].image).astype(float)
        inner = (slice(4, h - 4), slice(4, w - 4))
        err, before = np.abs(got - want)[inner].mean(), np.abs(raw - want)[inner].mean()
        assert err < 0.1 * before, (err, before)


# ------------------------------------------------------------------------------ errors, info, run


def test_errors_name_the_file_and_the_line(room, tmp_path):
    mesh = room.scene.mesh
    folder = write_cam_folder(tmp_path / "bad", room.scene, uncalibrated=False)
    cam = folder / "v01.cam"
    good = cam.read_text()
    for text, pattern in [("1 2 3\n0.8\n", r"v01\.cam: line 1: expected 12 numbers"),
                          ("0 0 0 5 0 0 0 1 0 0 0 1\n0.8\n", r"v01\.cam: line 1: the rotation's entries must lie"),
                          (good.splitlines()[0] + "\n0.8 x\n", r"v01\.cam: line 2: distortion d0: 'x' is not a number"),
                          (good.splitlines()[0] + "\nnan\n", r"v01\.cam: line 2: focal length: 'nan' is not a finite"),
                          (good.splitlines()[0] + "\n-0.8\n", r"v01\.cam: line 2: negative focal length"),
                          (good.splitlines()[0] + "\n0.8 0 0 0 0.5 0.5\n", r"v01\.cam: line 2: pixel aspect 0"),
                          (good.splitlines()[0] + "\n0.8 0 0 1 0.5\n", r"v01\.cam: line 2: expected 'f \[d0"),
                          (good.splitlines()[0] + "\n", r"v01\.cam: a \.cam file has two lines")]:
        cam.write_text(text)
        with pytest.raises(InputError, match=pattern):
            load_scene(folder, mesh=mesh)
    cam.write_text(good)
    with pytest.raises(InputError, match="holds no mesh.*--mesh"):
        load_scene(folder)
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "a.cam").write_text(good)
    with pytest.raises(InputError, match="no calibrated camera with a photo"):
        load_scene(empty, mesh=mesh)
    # MVE: meta.ini lines, missing values, raw images, deprecated views
    root = write_mve_scene(tmp_path / "scene", room.scene)
    meta = root / "views" / "view_0001.mve" / "meta.ini"
    good = meta.read_text()
    lines = good.splitlines()
    for i, bad, pattern in [(4, "focal_length", r"view_0001\.mve/meta\.ini: line 5: expected 'key = value'"),
                            (6, "principal_point = 0.5", r"meta\.ini: line 7: principal_point needs 2 number"),
                            (8, "rotation = 1 0 0 0 1 0 0 0 inf", r"meta\.ini: line 9: rotation: 'inf' is not a finite"),
                            (4, "focal_length = -1", r"meta\.ini: line 5: negative focal length")]:
        meta.write_text("\n".join(lines[:i] + [bad] + lines[i + 1:]) + "\n")
        assert lines[i].split("=")[0].strip() == bad.split("=")[0].strip() or "=" not in bad
        with pytest.raises(InputError, match=pattern):
            load_scene(root, mesh=mesh)
    meta.write_text(good.replace("translation", "# translation"))
    with pytest.raises(InputError, match=r"meta\.ini: \[camera\] has focal_length but no translation"):
        load_scene(root, mesh=mesh)
    meta.write_text("k = 1\n" + good)
    with pytest.raises(InputError, match=r"meta\.ini: line 1: key 'k' before any \[section\]"):
        load_scene(root, mesh=mesh)
    meta.write_text(good)
    img = root / "views" / "view_0001.mve" / "undistorted.png"
    img.rename(img.with_suffix(".mvei"))
    with pytest.raises(InputError, match=r"view_0001\.mve: the 'undistorted' embedding is an MVE raw image"):
        load_scene(root, mesh=mesh)
    img.with_suffix(".mvei").rename(img)
    (root / "views" / "view_0009.mve").write_bytes(b"\x89MVE\n")
    with pytest.raises(InputError, match="deprecated single-file format.*sceneupgrade"):
        load_scene(root, mesh=mesh)
    (root / "views" / "view_0009.mve").unlink()
    with pytest.raises(InputError, match="MVE scene, which holds no mesh.*--mesh"):
        load_scene(root)


def test_info_names_the_format(room, tmp_path, capsys):
    folder = write_cam_folder(tmp_path / "cams", room.scene)
    root = write_mve_scene(tmp_path / "scene", room.scene)
    for path, name in ((folder, "cam-folder"), (root, "mve")):
        assert main(["-q", "info", str(path), "--mesh", str(room.scene.mesh)]) == 0
        capsys.readouterr()
        assert main(["info", str(path), "--mesh", str(room.scene.mesh)]) == 0
        assert capsys.readouterr().out.startswith(f"scene: {path} ({name})\nviews: 6 (80x60)")
        assert main(["info", str(path), "--mesh", str(room.scene.mesh), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["format"] == name
        assert sc.io.load.detect_format(path)[0].name == name


@pytest.mark.parametrize("fmt", ["cam-folder", "mve"])
def test_run_selects_as_on_scene_json(room, tmp_path, fmt):
    folder = (write_cam_folder(tmp_path / "cams", room.scene) if fmt == "cam-folder"
              else write_mve_scene(tmp_path / "scene", room.scene))
    out, ref = tmp_path / "out", tmp_path / "ref"
    common = ["--t-npm", "20", "--atlas-size", "512", "--no-seams", "--format", "glb"]
    assert main(["-q", "run", str(folder), "--mesh", str(room.scene.mesh), "--out", str(out), *common,
                 "--depth-dir", str(room.root / "depth")]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert (out / "mesh.glb").is_file() and rep["selection"]["input_faces"] == len(room.scene.load_mesh().faces)
    assert main(["-q", "run", str(room.root), "--out", str(ref), *common]) == 0
    assert np.array_equal(np.load(out / "selection.npy"), np.load(ref / "selection.npy"))
