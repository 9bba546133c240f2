"""Bundler v0.3 (bundle.out + list.txt): a known synthetic scene written by an independent writer that
follows Bundler's README ("Output format": OpenGL axes, p = -P / P.z, p' = f r(p) p from the image
centre, y up), read back to the same cameras; the pixel-centre convention checked with the photo's
own surface points; the radial distortion against the README's formula; `o3d-seqcc info` / `run`."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import o3d_seqcc as sc
from o3d_seqcc import InputError, load_scene
from o3d_seqcc.cli import main
from o3d_seqcc.geometry.camera import project_points

FLIP = np.diag([1.0, -1.0, -1.0])

# ------------------------------------------------------------------------------ the writer (Bundler's README)


def _row(xs) -> str:
    return " ".join(f"{float(x):.17g}" for x in xs)


def bundler_cameras(scene, k=(0.0, 0.0)):
    """(f, k1, k2, R, t) per view: Bundler's camera looks down -z with y up, so R = FLIP R_cv, t = FLIP t_cv."""
    out = []
    for v in scene.views:
        K = v.intrinsic
        assert K[0, 0] == K[1, 1] and (K[0, 2], K[1, 2]) == ((v.width - 1) / 2, (v.height - 1) / 2)
        out.append((K[0, 0], *k, FLIP @ v.extrinsic[:3, :3], FLIP @ v.extrinsic[:3, 3]))
    return out


def write_bundler(root: Path, scene, *, k=(0.0, 0.0), lost: bool = True, points: int = 4) -> Path:
    """bundle/bundle.out + list.txt (images relative to it, with the '0 focal' EXIF column) in ``root``."""
    (root / "bundle").mkdir(parents=True, exist_ok=True)
    (root / "images").mkdir(exist_ok=True)
    cams = bundler_cameras(scene, k)
    names = []
    for v in scene.views:
        shutil.copy(v.image, root / "images" / v.image.name)
        names.append(f"images/{v.image.name} 0 {v.intrinsic[0, 0]:.6f}")
    if lost:  # a camera Bundler could not register: all zeros
        cams.insert(2, (0.0, 0.0, 0.0, np.zeros((3, 3)), np.zeros(3)))
        names.insert(2, "images/not_registered.jpg")
    lines = ["# Bundle file v0.3", f"{len(cams)} {points}"]
    for f, k1, k2, R, t in cams:
        lines += [_row([f, k1, k2]), *(_row(r) for r in R), _row(t)]
    for i in range(points):  # position, colour, view list (camera, key, x, y)
        lines += [_row([0.1 * i, 0.2, 0.3]), "255 128 0", f"2 0 {i} 1.25 -3.5 1 {i} 0.5 2.0"]
    (root / "bundle" / "bundle.out").write_text("\n".join(lines) + "\n")
    (root / "list.txt").write_text("\n".join(names) + "\n")
    return root / "bundle" / "bundle.out"


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("bundler") / "R", n_views=6, width=80, height=60,
                                   cell_size=0.25, layout="two-rings", seen_only=True, photometric="none")


def _assert_same_cameras(a, b, atol=1e-9) -> None:
    assert a.names == b.names
    for u, v in zip(a.views, b.views):
        assert (u.width, u.height) == (v.width, v.height)
        np.testing.assert_allclose(u.intrinsic, v.intrinsic, atol=atol)
        np.testing.assert_allclose(u.extrinsic, v.extrinsic, atol=atol)


# ------------------------------------------------------------------------------ tests


def test_reads_back_the_cameras_from_every_path(room, tmp_path, caplog):
    out = write_bundler(tmp_path / "b", room.scene)
    for path in (tmp_path / "b", out, out.parent):
        scene = load_scene(path, mesh=room.scene.mesh)
        assert scene.source == out and all(v.distortion is None for v in scene.views)
        _assert_same_cameras(scene, room.scene)
    assert "1 camera(s) have focal length 0" in caplog.text and "not_registered.jpg" in caplog.text
    # MeshLab's import: any .out with the header, list.txt beside it
    other = tmp_path / "m"
    other.mkdir()
    shutil.copy(out, other / "recon.out")
    shutil.copy(tmp_path / "b" / "list.txt", other / "list.txt")
    shutil.copytree(tmp_path / "b" / "images", other / "images")
    assert sc.io.load.detect_format(other / "recon.out")[0].name == "bundler"
    _assert_same_cameras(load_scene(other / "recon.out", mesh=room.scene.mesh), room.scene)
    (other / "synth_0.out").write_text("drews 1.0\n0 0\n")  # an MVE bundle is not Bundler's
    assert sc.io.bundler.detect(other / "synth_0.out") is None
    # image_dir: the images by file name
    flat = tmp_path / "flat"
    shutil.copytree(tmp_path / "b" / "images", flat)
    shutil.rmtree(tmp_path / "b" / "images")
    with pytest.raises(InputError, match=r"(?s)list\.txt: line 1: image not found: .*v00\.png.*--image-dir"):
        load_scene(out, mesh=room.scene.mesh)
    _assert_same_cameras(load_scene(out, mesh=room.scene.mesh, image_dir=flat), room.scene)


def test_pixel_centres_a_known_point_projects_where_the_photo_shows_it(room, tmp_path):
    """The photo's own ray-cast surface points project back onto their pixel (c, r), to 0.01 px."""
    scene = load_scene(write_bundler(tmp_path / "b", room.scene), mesh=room.scene.mesh)
    for k in (0, 5):
        pts = room.load_points(k)
        r, c = np.nonzero(np.isfinite(pts[..., 0]))
        uv, z = project_points(pts[r, c].astype(np.float64), scene.views[k].intrinsic, scene.views[k].extrinsic)
        err = np.abs(uv - np.stack([c, r], 1))
        assert len(r) > 1000 and err.max() < 0.01 and (z > 0).all(), err.max()


def _bundler_project(X, f, k1, k2, R, t, w, h):
    """README: P = R X + t, p = -P / P.z, p' = f r(p) p (origin at the image centre, y up); to pixel indices."""
    P = X @ R.T + t
    p = -P[:, :2] / P[:, 2:3]
    n2 = (p * p).sum(1)
    pp = f * (1 + k1 * n2 + k2 * n2 * n2)[:, None] * p
    return np.stack([(w - 1) / 2 + pp[:, 0], (h - 1) / 2 - pp[:, 1]], 1)


@pytest.mark.parametrize("k", [(-0.2, 0.05), (0.15, 0.02)])
def test_distortion_is_bundlers(room, tmp_path, k):
    """A surface point, projected by the README's formula with k1, k2, is where our distorted camera puts it in
    the photo (< 0.01 px); the maps of the undistorted view follow it."""
    scene = load_scene(write_bundler(tmp_path / "b", room.scene, k=k), mesh=room.scene.mesh, check_cameras=False)
    for i in (0, 3):
        v, (f, k1, k2, R, t) = scene.views[i], bundler_cameras(room.scene, k)[i]
        d = v.distortion
        assert d.model == "opencv" and d.coefficients == (k1, k2, 0.0, 0.0)
        pts = room.load_points(i)
        X = pts[np.isfinite(pts[..., 0])].astype(np.float64)
        want = _bundler_project(X, f, k1, k2, R, t, v.width, v.height)
        Pc = X @ v.extrinsic[:3, :3].T + v.extrinsic[:3, 3]
        got = d.distort(Pc[:, :2] / Pc[:, 2:3])
        assert np.abs(got - want).max() < 1e-6
        # the view's pinhole camera: the photo's own for barrel distortion, zoomed in just enough otherwise
        if k1 < 0:
            np.testing.assert_allclose(v.intrinsic, room.scene.views[i].intrinsic, atol=1e-12)
        else:
            assert v.intrinsic[0, 0] > f and np.allclose(v.intrinsic[:2, 2], room.scene.views[i].intrinsic[:2, 2])


def test_errors_name_the_file_and_the_line(room, tmp_path):
    mesh = room.scene.mesh
    out = write_bundler(tmp_path / "b", room.scene)
    good = out.read_text()
    lines = good.splitlines()

    def check(text, pattern, path=out):
        path.write_text(text)
        with pytest.raises(InputError, match=pattern):
            load_scene(out, mesh=mesh)

    check(good.replace("v0.3", "v0.4"), r"bundle\.out: line 1: '# Bundle file v0\.4': only Bundler v0\.3")
    check("hello\n" + good, r"bundle\.out: line 1: not a Bundler file")
    check("\n".join(lines[:1] + ["7"] + lines[2:]), r"bundle\.out: line 2: expected '<num_cameras> <num_points>'")
    check("\n".join(lines[:1] + ["99999999 3"] + lines[2:]), r"bundle\.out: line 2: implausible counts")
    check("\n".join(lines[:8] + ["1 2 nan"] + lines[9:]), r"bundle\.out: line 9: camera 1's rotation row 1: 'nan'")
    check("\n".join(lines[:7] + ["-64 0 0"] + lines[8:]), r"bundle\.out: line 8: camera 1: negative focal length")
    check("\n".join(lines[:9] + ["0 -3 0"] + lines[10:]), r"line 10: camera 1's rotation row 2: the entries of a rotation")
    check("\n".join(lines[:6] + ["1 2"] + lines[7:]), r"bundle\.out: line 7: camera 0's translation needs 3")
    check("\n".join(lines[:20]), r"bundle\.out: the file ends before camera 3's")
    out.write_text(good)
    lst = tmp_path / "b" / "list.txt"
    names = lst.read_text().splitlines()
    check("\n".join(names[:3] + ["my photo.png"] + names[4:]), r"list\.txt: line 4: expected an image path", lst)
    check("\n".join(names[:3] + [""] + names[4:]), r"list\.txt: line 4: expected an image path", lst)
    check("\n".join(names[:-1]) + "\n\n\n", r"bundle\.out has 7 cameras but .*list\.txt lists 6 images", lst)
    lst.unlink()
    check(good, r"bundle\.out: no list\.txt")
    with pytest.raises(InputError, match="holds no mesh.*--mesh"):
        load_scene(out)
    zero = tmp_path / "z" / "bundle.out"
    zero.parent.mkdir()
    zero.write_text("# Bundle file v0.3\n1 0\n0 0 0\n0 0 0\n0 0 0\n0 0 0\n0 0 0\n")
    (zero.parent / "list.txt").write_text("a.jpg\n")
    with pytest.raises(InputError, match="no reconstructed camera"):
        load_scene(zero, mesh=mesh)


def test_info_names_the_format(room, tmp_path, capsys):
    out = write_bundler(tmp_path / "b", room.scene)
    assert main(["-q", "info", str(tmp_path / "b"), "--mesh", str(room.scene.mesh)]) == 0
    capsys.readouterr()
    assert main(["info", str(out), "--mesh", str(room.scene.mesh)]) == 0
    assert capsys.readouterr().out.startswith(f"scene: {out} (bundler)\nviews: 6 (80x60)")


def test_run_on_bundle_out_selects_as_on_scene_json(room, tmp_path):
    out_file = write_bundler(tmp_path / "b", room.scene)
    out, ref = tmp_path / "out", tmp_path / "ref"
    common = ["--t-npm", "20", "--atlas-size", "512", "--no-seams", "--format", "glb"]
    assert main(["-q", "run", str(out_file), "--mesh", str(room.scene.mesh), "--out", str(out), *common,
                 "--depth-dir", str(room.root / "depth")]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert (out / "mesh.glb").is_file() and rep["selection"]["input_faces"] == len(room.scene.load_mesh().faces)
    assert main(["-q", "run", str(room.root), "--out", str(ref), *common]) == 0
    assert np.array_equal(np.load(out / "selection.npy"), np.load(ref / "selection.npy"))
