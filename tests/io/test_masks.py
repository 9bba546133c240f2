"""Per-photo masks as read: scene.json's "mask", load_scene(masks=DIR), OpenMVS's maskName, Meshroom's view ids,
the wrong size, the other convention and distorted photos."""

from __future__ import annotations

import json
import struct
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import o3d_seqcc.synthetic as sc
from o3d_seqcc.errors import InputError, O3dSeqccWarning
from o3d_seqcc.geometry.distortion import Distortion
from o3d_seqcc.io.images import write_image
from o3d_seqcc.io.load import load_scene, save_scene
from o3d_seqcc.scene import Scene

W, H = 80, 60


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("masks") / "R", n_views=6, width=W, height=H,
                                   cell_size=0.25, layout="two-rings", seen_only=True, photometric="none")


def _mask(path: Path, keep: np.ndarray, *, grey: bool = True) -> Path:
    """A mask file: 255 where ``keep``, 0 elsewhere (grey PNG, or RGB for JPEG / TIFF)."""
    import cv2

    path.parent.mkdir(parents=True, exist_ok=True)
    m = np.where(keep, 255, 0).astype(np.uint8)
    if not grey:
        return write_image(path, np.repeat(m[..., None], 3, axis=2))
    assert cv2.imwrite(str(path), m)
    return path


def _left_half() -> np.ndarray:
    keep = np.ones((H, W), dtype=bool)
    keep[:, : W // 2] = False
    return keep


def test_scene_json_round_trips_the_mask(room, tmp_path):
    m0 = _mask(tmp_path / "masks" / "v00.png", _left_half())
    m1 = _mask(tmp_path / "masks" / "v01.png", ~_left_half())
    v = room.scene.views
    lens = Distortion("opencv", (0.05, 0.0, 0.0, 0.0), v[2].intrinsic, images=False, masks=True)
    views = (replace(v[0], mask=m0), replace(v[1], mask=m1, mask_invert=True), replace(v[2], mask=m0, distortion=lens),
             *v[3:])
    scene = Scene(room.scene.mesh, views)
    path = save_scene(scene, tmp_path / "scene.json")
    data = json.loads(path.read_text())
    assert data["views"][0]["mask"] == "masks/v00.png" and "mask_invert" not in data["views"][0]
    assert data["views"][1]["mask_invert"] is True and data["views"][2]["distortion"]["masks"] is True
    assert "mask" not in data["views"][3]
    back = load_scene(path, check_cameras=False)
    assert back == scene and back.views[1].mask_invert and back.views[2].distortion.masks is True
    assert save_scene(back, tmp_path / "again.json").read_text() == path.read_text()
    assert m0 in back.input_paths()
    np.testing.assert_array_equal(back.views[0].load_mask(), _left_half())
    np.testing.assert_array_equal(back.views[1].load_mask(), _left_half())  # inverted: nonzero = masked out
    data["views"][0]["mask_invert"] = "yes"
    path.write_text(json.dumps(data))
    with pytest.raises(InputError, match=r"views\[0\]: 'mask_invert' must be true or false"):
        load_scene(path, check_cameras=False)


@pytest.mark.filterwarnings("ignore:masks .*no mask for 5 of 6 views")
def test_a_mask_of_the_wrong_size_names_the_file_the_view_and_the_size(room, tmp_path):
    bad = _mask(tmp_path / "masks" / "v03.png", np.ones((30, 40), dtype=bool))
    with pytest.raises(InputError, match=rf"mask {bad} of view 'v03' is 40x30 but the photo is {W}x{H}"):
        load_scene(room.scene.source, masks=tmp_path / "masks")
    scene = Scene(room.scene.mesh, tuple(replace(v, mask=bad) if v.name == "v03" else v for v in room.scene.views))
    path = save_scene(scene, tmp_path / "scene.json")
    with pytest.raises(InputError, match=r"mask .*v03\.png of view 'v03' is 40x30 but the photo is 80x60"):
        load_scene(path)  # checked from the header when the scene is loaded, before any work
    with pytest.raises(InputError, match=r"mask .*v03\.png of view 'v03' is 40x30"):
        scene.views[3].load_mask()
    with pytest.raises(InputError, match=r"view 'v00': the mask must be \(60, 80\).*got shape \(60, 79\)"):
        replace(room.scene.views[0], mask_map=np.ones((60, 79), dtype=bool))


def test_masks_folder_names_and_conventions(room, tmp_path):
    d = tmp_path / "masks"
    keep = _left_half()
    _mask(d / "v00.png", keep)  # the image's stem (= the view's name here)
    _mask(d / "V01.JPG", keep, grey=False)  # any case, JPEG (RGB)
    _mask(d / "v02.png.png", keep)  # COLMAP's <image file name>.png
    _mask(d / "v03.mask.png", keep)  # OpenMVS's <stem>.mask.png
    _mask(d / "v04.tiff", keep, grey=False)
    with pytest.warns(O3dSeqccWarning, match=r"no mask for 1 of 6 views \('v05'\): they are used whole"):
        scene = load_scene(room.scene.source, masks=d)
    names = [None if v.mask is None else v.mask.name for v in scene.views]
    assert names == ["v00.png", "V01.JPG", "v02.png.png", "v03.mask.png", "v04.tiff", None]
    for v in scene.views[:5]:
        m = v.load_mask()
        assert m.shape == (H, W) and m.dtype == bool
        assert (m == keep).mean() > 0.99  # JPEG: a few pixels at the edge
    assert scene.options["masks"] == str(d.resolve()) and "mask_invert" not in scene.options
    with pytest.warns(O3dSeqccWarning):
        inv = load_scene(room.scene.source, masks=d, mask_invert=True)
    assert inv.options["mask_invert"] is True and all(v.mask_invert for v in inv.views[:5])
    np.testing.assert_array_equal(inv.views[0].load_mask(), ~keep)
    with pytest.raises(InputError, match=r"masks .*empty: no mask for any of the 6 views \(for view 'v00' looked for "
                                         r"v00\.png, v00\.jpg"):
        (tmp_path / "empty").mkdir()
        load_scene(room.scene.source, masks=tmp_path / "empty")
    with pytest.raises(InputError, match=r"masks .*nowhere is not a folder"):
        load_scene(room.scene.source, masks=tmp_path / "nowhere")


def test_a_distorted_photos_mask_is_undistorted_nearest_neighbour(room, tmp_path):
    v = room.scene.views[0]
    keep = np.zeros((H, W), dtype=bool)
    keep[10:50, 15:70] = True
    m = _mask(tmp_path / "m.png", keep)
    lens = Distortion("opencv", (-0.2, 0.05, 0.001, 0.0), v.intrinsic)
    view = replace(v, mask=m, distortion=lens)
    expected = lens.undistort(keep.astype(np.uint8), v.intrinsic, nearest=True) != 0
    np.testing.assert_array_equal(view.load_mask(), expected)
    assert not np.array_equal(expected, keep)
    # a photo replaced by its undistorted copy: the mask is still the original photo's
    moved = Scene(room.scene.mesh, (view,)).replace_images([v.image]).views[0]
    assert moved.distortion.images is False and moved.distortion.masks is True
    np.testing.assert_array_equal(moved.load_mask(), expected)
    # masks given for already undistorted photos follow them
    flat = replace(view, distortion=replace(lens, images=False, depth=True))
    np.testing.assert_array_equal(flat.load_mask(), keep)


# ------------------------------------------------------------------------------ OpenMVS (Interface.h, version 5+)


def _str(s: str) -> bytes:
    b = s.encode("utf-8")
    return struct.pack("<Q", len(b)) + b


def _mat(m) -> bytes:
    return struct.pack(f"<{np.size(m)}d", *np.asarray(m, dtype=np.float64).ravel())


def _write_mvs(path: Path, scene, masks: list[str]) -> Path:
    """MVS::Interface version 5: one platform, one camera in pixels, a pose and an image (with maskName) a view."""
    v0 = scene.views[0]
    out = bytearray(b"MVSI" + struct.pack("<II", 5, 0))
    out += struct.pack("<Q", 1) + _str("p") + struct.pack("<Q", 1) + _str("cam") + _str("RGB")
    out += struct.pack("<II", v0.width, v0.height) + _mat(v0.intrinsic) + _mat(np.eye(3)) + _mat(np.zeros(3))
    out += struct.pack("<Q", len(scene.views))
    for v in scene.views:
        out += _mat(v.rotation) + _mat(v.center)
    out += struct.pack("<Q", len(scene.views))
    for k, (v, m) in enumerate(zip(scene.views, masks)):
        out += _str(f"images/{v.image.name}") + _str(m) + struct.pack("<IIII", 0, 0, k, k)
    out += struct.pack("<QQQ", 0, 0, 0) + struct.pack("<QQQ", 0, 0, 0) + _mat(np.eye(4))
    path.write_bytes(bytes(out))
    return path


def test_openmvs_mask_names(room, tmp_path, caplog):
    root = room.root
    _mask(root / "images" / "v00.mask.png", _left_half())
    names = ["images/v00.mask.png"] + [""] * 4 + ["images/gone.mask.png"]
    path = _write_mvs(root / "masked.mvs", room.scene, names)
    try:
        with caplog.at_level("WARNING"):
            scene = load_scene(path, mesh=room.scene.mesh)
        assert scene.views[0].mask == root / "images" / "v00.mask.png"
        assert [v.mask for v in scene.views[1:]] == [None] * 5  # the missing one: warned, used whole
        assert "gone.mask.png is not there: the photo is used whole" in caplog.text
        np.testing.assert_array_equal(scene.views[0].load_mask(), _left_half())  # 0 = masked, as ImportIgnoreMask
    finally:
        (root / "images" / "v00.mask.png").unlink()
        path.unlink()


def test_meshroom_masks_folder_by_view_id(room, tmp_path):
    """AliceVision's tryLoadMask: masksFolder/<viewId>.png first, then the image's name with the mask's suffix."""
    data = {"version": ["1", "2", "4"], "views": [], "intrinsics": [], "poses": []}
    for i, v in enumerate(room.scene.views):
        K = v.intrinsic
        data["views"].append({"viewId": str(1000 + i), "poseId": str(i), "intrinsicId": "0", "path": str(v.image),
                              "width": str(W), "height": str(H)})
        data["poses"].append({"poseId": str(i), "pose": {"transform": {
            "rotation": [str(x) for x in v.rotation.flatten(order="F")], "center": [str(x) for x in v.center]}}})
    data["intrinsics"].append({"intrinsicId": "0", "width": str(W), "height": str(H), "type": "pinhole",
                               "pxFocalLength": [str(K[0, 0]), str(K[1, 1])],
                               "principalPoint": [str(K[0, 2] - W / 2), str(K[1, 2] - H / 2)], "distortionParams": []})
    sfm = tmp_path / "cameras.sfm"
    sfm.write_text(json.dumps(data))
    d = tmp_path / "masks"
    for i in range(6):
        _mask(d / f"{1000 + i}.png", _left_half())
    _mask(d / "v01.png", ~_left_half())  # the view id wins over the name
    scene = load_scene(sfm, mesh=room.scene.mesh, masks=d, check_cameras=False)
    assert [v.mask.name for v in scene.views] == [f"{1000 + i}.png" for i in range(6)]
    np.testing.assert_array_equal(scene.views[1].load_mask(), _left_half())
