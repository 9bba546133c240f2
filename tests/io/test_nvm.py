"""VisualSFM NVM_V3 files: a known synthetic scene written by an independent writer that follows
VisualSFM's documentation (doc.html#nvm: file name, focal, quaternion WXYZ, camera centre, radial
distortion, 0; points with measurements; several models; FixedK), read back to the same cameras;
the pixel-centre convention checked with the photo's own surface points; VisualSFM's measurement
distortion (x_u = x_d (1 + r |x_d|^2)) against the loader's undistortion; `o3d-seqcc run file.nvm`."""

from __future__ import annotations

import json
import logging
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

# ------------------------------------------------------------------------------ the writer (VisualSFM's doc)


def _quaternion(R: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a rotation matrix (Shepperd's method), w >= 0."""
    tr = np.trace(R)
    cands = [1 + tr, 1 + 2 * R[0, 0] - tr, 1 + 2 * R[1, 1] - tr, 1 + 2 * R[2, 2] - tr]
    i = int(np.argmax(cands))
    s = 2.0 * np.sqrt(cands[i])
    if i == 0:
        q = [s / 4, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif i == 1:
        q = [(R[2, 1] - R[1, 2]) / s, s / 4, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif i == 2:
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, s / 4, (R[1, 2] + R[2, 1]) / s]
    else:
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, s / 4]
    q = np.array(q)
    return q if q[0] >= 0 else -q


def camera_line(name: str, v, radial: float = 0.0) -> str:
    R, t = v.extrinsic[:3, :3], v.extrinsic[:3, 3]
    C = -R.T @ t  # the camera centre, not the translation
    nums = [v.intrinsic[0, 0], *_quaternion(R), *C, radial, 0]
    return name + "\t" + " ".join(repr(float(x)) for x in nums[:-1]) + " 0"


def point_lines(points: np.ndarray, n_cams: int) -> list[str]:
    out = []
    for i, p in enumerate(points):  # X Y Z R G B n (image feature x y)*n
        meas = [(i % n_cams, i, 1.5, -2.0), ((i + 1) % n_cams, i, 0.25, 3.0)]
        out.append(" ".join(map(repr, map(float, p))) + " 128 64 32 2 " + " ".join(f"{a} {b} {x} {y}" for a, b, x, y in meas))
    return out


def write_nvm(path: Path, scene, *, header: str = "NVM_V3", names=None, radial=0.0, points=None,
              extra_models: list[tuple[int, int]] = ()) -> Path:
    """The scene's cameras as the first model; then ``extra_models`` ((cameras, points) each, copies of the
    first cameras); then the 0 that ends the models and a PLY section, as VisualSFM writes it."""
    views = scene.views
    names = names or [f"images/{v.image.name}" for v in views]
    radial = radial if np.ndim(radial) else [radial] * len(views)
    pts = np.zeros((0, 3)) if points is None else points
    out = [header, "", str(len(views))]
    out += [camera_line(n, v, r) for n, v, r in zip(names, views, radial)]
    out += ["", str(len(pts)), *point_lines(pts, len(views)), ""]
    for n_cams, n_pts in extra_models:
        out += [str(n_cams)] + [camera_line(names[i % len(views)], views[i % len(views)]) for i in range(n_cams)]
        out += ["", str(n_pts), *point_lines(pts[:n_pts], n_cams), ""]
    out += ["", "0", "", "#the last part of NVM file points to the PLY files", "0", ""]
    path.write_text("\n".join(out))
    return path


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("nvm") / "R", n_views=6, width=80, height=60,
                                   cell_size=0.25, layout="two-rings", seen_only=True, photometric="none")


def _points(room, n=40):
    return room.scene.load_mesh().vertices[:n]


def _assert_same_cameras(a, b, atol=1e-9) -> None:
    assert len(a.views) == len(b.views)
    for u, v in zip(a.views, b.views):
        assert (u.width, u.height) == (v.width, v.height)
        np.testing.assert_allclose(u.intrinsic, v.intrinsic, atol=atol)
        np.testing.assert_allclose(u.extrinsic, v.extrinsic, atol=atol)


# ------------------------------------------------------------------------------ tests


def test_reads_back_the_cameras_of_the_first_model(room, caplog):
    path = write_nvm(room.root / "scene.nvm", room.scene, points=_points(room), extra_models=[(3, 5), (2, 0)])
    with caplog.at_level(logging.WARNING):
        scene = load_scene(path, mesh=room.scene.mesh)
    assert scene.names == room.scene.names and scene.source == path
    _assert_same_cameras(scene, room.scene)
    assert all(v.distortion is None for v in scene.views)  # zero radial: pinhole views
    assert "holds 3 models (6 cameras, 3 cameras, 2 cameras without points); only the first (6 cameras)" in caplog.text
    # any suffix, Windows separators, a model followed only by the unregistered images: no warning
    caplog.clear()
    names = [f"images\\{v.image.name}" for v in room.scene.views]
    other = write_nvm(room.root / "windows.txt", room.scene, names=names, extra_models=[(2, 0)])
    with caplog.at_level(logging.WARNING):
        _assert_same_cameras(load_scene(other, mesh=room.scene.mesh), room.scene)
    assert "models" not in caplog.text


def test_fixed_calibration(room, caplog):
    K = room.scene.views[0].intrinsic  # FixedK's principal point in VisualSFM's pixels: ours + 0.5
    hdr = "NVM_V3 FixedK " + " ".join(repr(float(x)) for x in (K[0, 0], K[0, 2] + 0.5, K[1, 1], K[1, 2] + 0.5))
    path = write_nvm(room.root / "fixed.nvm", room.scene, header=hdr)
    _assert_same_cameras(load_scene(path, mesh=room.scene.mesh), room.scene)
    # another principal point is used as given; a camera's focal length that differs from FixedK's is reported
    shifted = write_nvm(room.root / "fixed2.nvm", room.scene, header="NVM_V3 FixedK 70 41 66 30 0")
    with caplog.at_level(logging.WARNING):
        s = load_scene(shifted, mesh=room.scene.mesh, check_cameras=False)
    np.testing.assert_allclose(s.views[2].intrinsic, [[70, 0, 40.5], [0, 66, 29.5], [0, 0, 1]])
    assert "6 camera line(s) (line 4, 5, 6, 7, 8 ...) give a focal length other than FixedK's" in caplog.text


def test_pixel_centres_a_known_point_projects_where_the_photo_shows_it(room):
    """The photo's own ray-cast surface points (pixel (r, c) shows points[r, c]) project back onto
    (c, r) with the cameras read from the .nvm file: to 0.01 px, a half-pixel slip would be 0.5."""
    scene = load_scene(write_nvm(room.root / "align.nvm", room.scene), mesh=room.scene.mesh)
    for k in (0, 5):
        pts = room.load_points(k)
        r, c = np.nonzero(np.isfinite(pts[..., 0]))
        uv, z = project_points(pts[r, c].astype(np.float64), scene.views[k].intrinsic, scene.views[k].extrinsic)
        err = np.abs(uv - np.stack([c, r], 1))
        assert len(r) > 1000 and err.max() < 0.01, err.max()


def _vsfm_undistort(d: np.ndarray, K: np.ndarray, r: float) -> np.ndarray:
    """VisualSFM's measurement distortion: the measured (distorted) pixel -> the undistorted focal-normalised point."""
    x = (d - K[:2, 2]) / K[0, 0]
    return x * (1.0 + r * np.sum(x * x, axis=1, keepdims=True))


@pytest.mark.parametrize("r", [0.08, -0.08, 1e-9])
def test_measurement_distortion_is_undone_exactly(room, r):
    path = write_nvm(room.root / f"radial{r}.nvm", room.scene, radial=r)
    scene = load_scene(path, mesh=room.scene.mesh, check_cameras=False)
    v, ref = scene.views[1], room.scene.views[1]
    assert v.distortion is not None and v.distorted
    K = ref.intrinsic  # the photo's own camera: image centre, the file's focal length
    np.testing.assert_allclose(v.distortion.intrinsic, K)
    u, w = np.meshgrid(np.linspace(-0.5, 79.5, 41), np.linspace(-0.5, 59.5, 31))
    d = np.stack([u.ravel(), w.ravel()], 1)  # pixels of the (distorted) photo
    back = v.distortion.distort(_vsfm_undistort(d, K, r))
    assert np.abs(back - d).max() < 1e-3
    # every pixel of the undistorted image comes from inside the photo, the principal point kept
    np.testing.assert_allclose(v.intrinsic[:2, 2], K[:2, 2])
    if r > 0:  # the photo is squeezed: its own camera fits
        np.testing.assert_allclose(v.intrinsic, K)


def test_a_distorted_photo_is_read_as_the_pinhole_one(room, tmp_path):
    """Photos distorted by VisualSFM's formula (written by the test), read back undistorted: the synthetic photos."""
    r = 0.06
    folder = tmp_path / "images"
    folder.mkdir()
    K = room.scene.views[0].intrinsic
    u, w = np.meshgrid(np.arange(80, dtype=np.float64), np.arange(60, dtype=np.float64))
    xu = _vsfm_undistort(np.stack([u.ravel(), w.ravel()], 1), K, r)  # each photo pixel shows this direction
    mx, my = (K[0, 0] * xu[:, 0] + K[0, 2]).reshape(60, 80), (K[1, 1] * xu[:, 1] + K[1, 2]).reshape(60, 80)
    for v in room.scene.views:
        img = read_image(v.image)
        write_image(folder / v.image.name, cv2.remap(img, mx.astype(np.float32), my.astype(np.float32), cv2.INTER_CUBIC,
                                                     borderMode=cv2.BORDER_REPLICATE))
    path = write_nvm(tmp_path / "d.nvm", room.scene, radial=r, names=[f"images/{v.image.name}" for v in room.scene.views])
    scene = load_scene(path, mesh=room.scene.mesh)

    def blur(a):  # resampled twice (bicubic): compare the images' content, away from the border
        return cv2.GaussianBlur(a.astype(np.float32), (0, 0), 1.0)[6:-6, 6:-6]

    for v, ref in zip(scene.views, room.scene.views):
        want = blur(read_image(ref.image))
        assert np.abs(blur(v.load_image()) - want).mean() < 0.5
        assert np.abs(blur(read_image(v.image)) - want).mean() > 1.0  # the distortion is visible


def test_errors_name_the_file_and_line(room, tmp_path):
    good = write_nvm(tmp_path / "good.nvm", room.scene).read_text().split("\n")

    def variant(name, lines):
        p = tmp_path / name
        p.write_text("\n".join(lines))
        return p

    def token(line: str, i: int, value: str) -> str:  # the i-th field from the end replaced
        name, *nums = line.rsplit(None, 10)
        nums[i] = value
        return name + " " + " ".join(nums)

    mesh = room.scene.mesh
    with pytest.raises(InputError, match=r"VisualSFM NVM file.*no mesh.*--mesh"):
        load_scene(write_nvm(room.root / "nomesh.nvm", room.scene))
    bad = good.copy()
    bad[4] = token(bad[4], 2, "x")
    with pytest.raises(InputError, match=r"bad\.nvm, line 5: camera 'images/v01.png': qx: 'x' is not a number"):
        load_scene(variant("bad.nvm", bad), mesh=mesh)
    with pytest.raises(InputError, match=r"hdr\.nvm, line 1: unknown header options 'Foo 1'"):
        load_scene(variant("hdr.nvm", ["NVM_V3 Foo 1"] + good[1:]), mesh=mesh)
    with pytest.raises(InputError, match=r"r9t\.nvm, line 1: not a VisualSFM NVM_V3 file"):
        load_scene(variant("r9t.nvm", ["NVM_V3_R9T"] + good[1:]), mesh=mesh)
    with pytest.raises(InputError, match=r"count\.nvm, line 3: 99999 cameras declared, but the file holds"):
        load_scene(variant("count.nvm", good[:2] + ["99999"] + good[3:]), mesh=mesh)
    nan = good.copy()
    nan[5] = token(nan[5], 8, "nan")
    with pytest.raises(InputError, match=r"nan\.nvm, line 6: camera 'images/v02.png': radial: 'nan' is not a finite normal number"):
        load_scene(variant("nan.nvm", nan), mesh=mesh)
    neg = good.copy()
    neg[6] = token(neg[6], 0, "-64.0")
    with pytest.raises(InputError, match=r"neg\.nvm, line 7: camera 'images/v03.png' has focal length -64.0"):
        load_scene(variant("neg.nvm", neg), mesh=mesh)
    # points: a measurement count that does not match the fields, an image index out of range
    pts = write_nvm(tmp_path / "pts.nvm", room.scene, points=_points(room, 5)).read_text().split("\n")
    cut = pts.copy()
    cut[12] = cut[12].rsplit(" ", 2)[0]
    with pytest.raises(InputError, match=r"cut\.nvm, line 13: expected a point .* with 7 \+ 4 n fields \(n an integer\), got '"):
        load_scene(variant("cut.nvm", cut), mesh=mesh)
    idx = pts.copy()
    idx[13] = idx[13].replace(" 32 2 2 ", " 32 2 17 ", 1)
    with pytest.raises(InputError, match=r"idx\.nvm, line 14: a measurement of image '17', not an image index 0..5"):
        load_scene(variant("idx.nvm", idx), mesh=mesh)
    with pytest.raises(InputError, match=r"short\.nvm, line 11: 5 points declared, but the file holds 3 more lines"):
        load_scene(variant("short.nvm", pts[:14]), mesh=mesh)
    # images: relative to the file, listed when missing; --image-dir looks them up by name
    folder = tmp_path / "elsewhere"
    folder.mkdir()
    moved = write_nvm(folder / "moved.nvm", room.scene)
    with pytest.raises(InputError, match=r"(?s)moved\.nvm: none of the 6 photos can be read:\n  view 'v00': "
                                         r"\S*moved\.nvm: line 4: image not found: .*images/v00\.png.*--image-dir"):
        load_scene(moved, mesh=mesh)
    _assert_same_cameras(load_scene(moved, mesh=mesh, image_dir=room.root / "images"), room.scene)


def test_info_names_the_format(room, capsys):
    path = write_nvm(room.root / "info.nvm", room.scene)
    assert main(["-q", "info", str(path), "--mesh", str(room.scene.mesh)]) == 0
    capsys.readouterr()
    assert main(["info", str(path), "--mesh", str(room.scene.mesh), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["format"] == "nvm" and out["views"] == 6


def test_run_on_an_nvm_file_with_mesh(room, tmp_path):
    shutil.copytree(room.root / "images", tmp_path / "images")
    path = write_nvm(tmp_path / "scene.nvm", room.scene, points=_points(room))
    out = tmp_path / "out"
    assert main(["-q", "run", str(path), "--mesh", str(room.scene.mesh), "--out", str(out), "--t-npm", "20",
                 "--atlas-size", "512", "--no-seams", "--format", "glb", "--depth-dir", str(room.root / "depth")]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert (out / "mesh.glb").is_file() and rep["selection"]["input_faces"] == len(room.scene.load_mesh().faces)
    ref = tmp_path / "ref"
    assert main(["-q", "run", str(room.root), "--out", str(ref), "--t-npm", "20", "--atlas-size", "512", "--no-seams",
                 "--format", "glb"]) == 0
    assert np.array_equal(np.load(out / "selection.npy"), np.load(ref / "selection.npy"))  # the same cameras
