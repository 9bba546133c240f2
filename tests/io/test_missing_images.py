"""Real folders are incomplete (issue 37): every missing or unreadable photo is listed in one error, for
scene.json, COLMAP, Bundler and texrecon camera folders; ``skip_missing=True`` / ``--skip-missing-images``
goes on without them with one warning, and report.json says which were skipped; every photo missing is
an error either way."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import o3d_seqcc as sc
from o3d_seqcc import load_scene
from o3d_seqcc.cli import main
from o3d_seqcc.errors import MissingImagesError, O3dSeqccWarning
from test_bundler import write_bundler
from test_mve import write_cam_folder

FAST = ["--atlas-size", "512", "--no-seams", "--format", "glb", "--t-npm", "10"]


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("missing") / "R", n_views=6, width=80, height=60,
                                   cell_size=0.25, layout="two-rings", seen_only=True, photometric="none")


def _copy(room, dst: Path) -> Path:
    shutil.copytree(room.root, dst)
    return dst


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 3])


def _row(xs) -> str:
    return " ".join(f"{float(x):.17g}" for x in xs)


def write_colmap_text(folder: Path, scene) -> Path:
    """A COLMAP text model (PINHOLE, COLMAP's pixel centres at 0.5; images.txt: QW QX QY QZ TX TY TZ, world-to-camera)
    with the photos in ``folder/images``."""
    model = folder / "sparse"
    model.mkdir(parents=True)
    (folder / "images").mkdir()
    cams, imgs = [], []
    for i, v in enumerate(scene.views, 1):
        K = v.intrinsic
        pinhole = _row([K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5])
        cams.append(f"{i} PINHOLE {v.width} {v.height} {pinhole}\n")
        x, y, z, w = Rotation.from_matrix(v.rotation).as_quat()
        imgs.append(f"{i} " + _row([w, x, y, z, *v.translation]) + f" {i} {v.image.name}\n\n")
        shutil.copy(v.image, folder / "images" / v.image.name)
    (model / "cameras.txt").write_text("# cameras\n" + "".join(cams))
    (model / "images.txt").write_text("# images\n" + "".join(imgs))
    (model / "points3D.txt").write_text("")
    return model


# ------------------------------------------------------------------------------ scene.json


def test_scene_json_lists_every_missing_photo_at_once(room, tmp_path):
    d = _copy(room, tmp_path / "S")
    (d / "images" / "v01.png").unlink()
    (d / "images" / "v03.png").rename(d / "images" / "v03.jpg")  # a near namesake: named in the list
    with pytest.raises(MissingImagesError) as e:
        load_scene(d)
    msg = str(e.value)
    assert msg.startswith(f"{d / 'scene.json'}: 2 of 6 photos are missing or unreadable:\n")
    assert f"view 'v01': image not found: {d / 'images' / 'v01.png'}" in msg
    assert f"view 'v03': image not found: {d / 'images' / 'v03.png'}" in msg and "found v03.jpg beside it" in msg
    assert "--skip-missing-images" in msg and "skip_missing=True" in msg
    assert [m.view for m in e.value.missing] == ["v01", "v03"] and e.value.scene.names == ["v00", "v02", "v04", "v05"]
    # an unreadable photo (cut short) is listed with them
    _truncate(d / "images" / "v04.png")
    with pytest.raises(MissingImagesError, match=r"3 of 6 photos .*\n.*'v01'.*\n.*'v03'.*\n.*'v04'.*v04\.png"):
        load_scene(d)
    # skip_missing: one warning naming them all; the scene records them
    with pytest.warns(O3dSeqccWarning, match=r"going on without 3 of 6 photos.*'v01'.*'v03'.*'v04'") as rec:
        scene = load_scene(d, skip_missing=True)
    assert len([w for w in rec if "going on without" in str(w.message)]) == 1
    assert scene.names == ["v00", "v02", "v05"]
    assert scene.options["skip_missing"] is True
    assert scene.options["skipped_images"] == {n: str(d / "images" / f"{n}.png") for n in ("v01", "v03", "v04")}
    # every photo missing: an error either way
    for v in ("v00", "v02", "v05"):
        (d / "images" / f"{v}.png").unlink()
    for skip in (False, True):
        with pytest.raises(MissingImagesError, match=r"none of the 6 photos can be read") as e:
            load_scene(d, skip_missing=skip)
        assert len(e.value.missing) == 6 and e.value.scene is None


def test_run_stops_naming_both_and_skip_missing_images_finishes_without_them(room, tmp_path, capsys):
    d = _copy(room, tmp_path / "S")
    for n in ("v02", "v04"):
        (d / "images" / f"{n}.png").unlink()
    out = tmp_path / "out"
    assert main(["-q", "run", str(d), "--out", str(out), *FAST]) != 0
    err = capsys.readouterr().err
    assert "2 of 6 photos are missing" in err and str(d / "images" / "v02.png") in err
    assert str(d / "images" / "v04.png") in err and "--skip-missing-images" in err and not out.exists()
    assert main(["-q", "run", str(d), "--out", str(out), "--skip-missing-images", *FAST]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["views"] == ["v00", "v01", "v03", "v05"]
    assert rep["scene_options"]["skip_missing"] is True
    assert sorted(rep["scene_options"]["skipped_images"]) == ["v02", "v04"]
    assert "skipped_images" in (out / "report.html").read_text()
    (out / "report.html").unlink()  # the report reloads the scene the way the run did
    assert main(["-q", "report", str(out)]) == 0 and (out / "report.html").is_file()


def test_library_functions_take_the_scene_flags_for_a_path(room, tmp_path):
    """`o3d-seqcc run --skip-missing-images --allow-unseen` in the library: scene_options= of run / texture /
    correct_scene, load_scene's keywords for a path."""
    d = _copy(room, tmp_path / "S")
    (d / "images" / "v03.png").unlink()
    with pytest.raises(MissingImagesError, match="v03.png"):
        sc.pipeline.texture(d, selection="largest-area")
    with pytest.warns(O3dSeqccWarning, match="going on without 1 of 6 photos"):
        res = sc.pipeline.texture(d, scene_options={"skip_missing": True}, selection="largest-area")
    assert res.scene.names == ["v00", "v01", "v02", "v04", "v05"]
    assert res.scene.options["skipped_images"] == {"v03": str(d / "images" / "v03.png")}
    with pytest.warns(O3dSeqccWarning, match="going on without"):
        cr = sc.pipeline.correct_scene(d, scene_options={"skip_missing": True}, method="reinhard")
    assert cr.scene.names == res.scene.names and len(cr.result.images) == 5
    with pytest.raises(sc.InputError, match=r"load_scene takes no 'skip_missing_images'; valid: .*skip_missing"):
        sc.pipeline.run(d, scene_options={"skip_missing_images": True})
    with pytest.raises(sc.InputError, match="scene_options .* apply when scene is a path"):
        sc.pipeline.run(load_scene(room.root), scene_options={"allow_unseen": True})


# ------------------------------------------------------------------------------ the readers


def test_colmap_lists_the_missing_photos_and_skips_them(room, tmp_path):
    model = write_colmap_text(tmp_path / "C", room.scene)
    mesh = room.scene.mesh
    full = load_scene(model, mesh=mesh)
    for u, v in zip(full.views, room.scene.views):
        np.testing.assert_allclose(u.intrinsic, v.intrinsic, atol=1e-9)
        np.testing.assert_allclose(u.extrinsic, v.extrinsic, atol=1e-9)
    for n in ("v00", "v05"):
        (tmp_path / "C" / "images" / f"{n}.png").unlink()
    with pytest.raises(MissingImagesError) as e:
        load_scene(model, mesh=mesh)
    msg = str(e.value)
    assert "2 of 6 photos" in msg and "'v00'" in msg and "'v05'" in msg and "--image-dir" in msg
    with pytest.warns(O3dSeqccWarning, match="going on without 2 of 6 photos"):
        scene = load_scene(model, mesh=mesh, skip_missing=True)
    assert scene.names == ["v01", "v02", "v03", "v04"]
    assert sorted(scene.options["skipped_images"]) == ["v00", "v05"]


def test_bundler_lists_the_missing_photos_with_their_lines(room, tmp_path):
    bundle = write_bundler(tmp_path / "B", room.scene)  # list.txt: v00, v01, (lost), v02, ...
    for n in ("v01", "v03"):
        (tmp_path / "B" / "images" / f"{n}.png").unlink()
    with pytest.raises(MissingImagesError) as e:
        load_scene(bundle, mesh=room.scene.mesh)
    msg, lst = str(e.value), tmp_path / "B" / "list.txt"
    assert msg.startswith(f"{bundle}: 2 of 6 photos are missing or unreadable:\n")
    assert f"view 'v01': {lst}: line 2: image not found" in msg and f"view 'v03': {lst}: line 5: image not found" in msg
    assert "--image-dir" in msg and "--skip-missing-images" in msg
    with pytest.warns(O3dSeqccWarning, match=r"going on without 2 of 6 photos.*'v01'.*'v03'"):
        scene = load_scene(bundle, mesh=room.scene.mesh, skip_missing=True)
    assert scene.names == ["v00", "v02", "v04", "v05"]
    for u in scene.views:
        np.testing.assert_allclose(u.extrinsic, room.scene.views[room.scene.index(u.name)].extrinsic, atol=1e-9)


def test_cam_folder_lists_the_unreadable_photos(room, tmp_path):
    folder = write_cam_folder(tmp_path / "F", room.scene)
    _truncate(folder / "v02.png")
    (folder / "v04.png").write_bytes(b"not an image")
    with pytest.raises(MissingImagesError) as e:
        load_scene(folder, mesh=room.scene.mesh)
    msg = str(e.value)
    assert "2 of 6 photos" in msg and f"view 'v02': {folder / 'v02.cam'}: " in msg and "'v04'" in msg
    with pytest.warns(O3dSeqccWarning, match=r"going on without 2 of 6 photos.*'v02'.*'v04'"):
        scene = load_scene(folder, mesh=room.scene.mesh, skip_missing=True)
    assert scene.names == ["v00", "v01", "v03", "v05"]
