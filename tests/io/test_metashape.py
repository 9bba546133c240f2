"""Agisoft Metashape cameras.xml: a known synthetic scene written by an independent writer that follows
Metashape's export (sensors with adjusted and initial calibrations, f / cx / cy from the image centre,
cameras in groups, camera-to-chunk transforms, a chunk transform with rotation, translation and
scale, or 2.x components), read back to the same cameras; the pixel-centre convention checked with
the photo's own surface points; the manual's frame camera model (K1-K4, P1, P2, B1, B2) against the
loader's undistortion; hostile XML refused; `o3d-seqcc run cameras.xml`."""

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

# ------------------------------------------------------------------------------ the writer (Metashape's export)

CHUNK_R = cv2.Rodrigues(np.array([0.3, -0.5, 0.9]))[0]
CHUNK_T = np.array([12.0, -3.5, 40.25])
CHUNK_S = 2.5


def _nums(a) -> str:
    return " ".join(repr(float(x)) for x in np.ravel(a))


def sensor_xml(sid: str, v, terms: dict | None = None, kind: str = "frame", extra: str = "") -> str:
    """A sensor whose adjusted calibration is the view's camera (and a wrong initial one, listed first)."""
    K, w, h = v.intrinsic.tolist(), v.width, v.height
    cx, cy = K[0][2] + 0.5 - w / 2, K[1][2] + 0.5 - h / 2  # Metashape: from the image centre, pixel corners at integers
    body = "".join(f"<{k}>{x!r}</{k}>" for k, x in (terms or {}).items())
    return (f'<sensor id="{sid}" label="sensor {sid}" type="{kind}">\n'
            f'  <resolution width="{w}" height="{h}"/>\n  <property name="pixel_width" value="0.0039"/>\n'
            f'  <calibration type="frame" class="initial"><resolution width="{w}" height="{h}"/>'
            f'<f>{K[0][0] * 1.2!r}</f></calibration>\n'
            f'  <calibration type="frame" class="adjusted">\n    <resolution width="{w}" height="{h}"/>\n'
            f'    <f>{K[0][0]!r}</f>\n    <cx>{cx!r}</cx>\n    <cy>{cy!r}</cy>\n    {body}{extra}\n'
            '  </calibration>\n</sensor>')


def camera_transform(v, to_world: np.ndarray) -> np.ndarray:
    """The camera-to-chunk pose of a view, given the chunk-to-world similarity (scale s R, translation t)."""
    s = np.cbrt(np.linalg.det(to_world[:3, :3]))
    R, t = to_world[:3, :3] / s, to_world[:3, 3]
    Rw, Cw = v.rotation.T, v.center  # camera-to-world rotation, camera centre
    T = np.eye(4)
    T[:3, :3] = R.T @ Rw
    T[:3, 3] = R.T @ (Cw - t) / s
    return T


def similarity() -> np.ndarray:
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = CHUNK_S * CHUNK_R, CHUNK_T
    return M


def write_xml(path: Path, scene, *, terms: dict | None = None, components: bool = False, labels=None,
              sensor_extra: str = "", header: str = '<?xml version="1.0" encoding="UTF-8"?>') -> Path:
    """Metashape 1.x (a chunk transform) or 2.x (a component transform) export of the scene's cameras, with an
    unaligned camera and a disabled one; cameras 2.. in a group, even cameras labelled without suffix."""
    views = scene.views
    labels = labels or [v.image.stem if i % 2 == 0 else v.image.name for i, v in enumerate(views)]
    M = similarity()
    tr = (f"<transform>\n      <rotation locked=\"true\">{_nums(CHUNK_R)}</rotation>\n"
          f"      <translation locked=\"true\">{_nums(CHUNK_T)}</translation>\n"
          f"      <scale locked=\"true\">{CHUNK_S!r}</scale>\n    </transform>")
    cams = []
    for i, (v, label) in enumerate(zip(views, labels)):
        comp = ' component_id="0"' if components else ""
        cams.append(f'<camera id="{i}" sensor_id="0"{comp} label="{label}">\n'
                    f'  <transform>{_nums(camera_transform(v, M))}</transform>\n'
                    f'  <reference x="1" y="2" z="3" enabled="false"/>\n</camera>')
    cams.append('<camera id="90" sensor_id="0" label="not_aligned"/>')
    cams.append(f'<camera id="91" sensor_id="0" label="disabled" enabled="false"><transform>{_nums(np.eye(4))}'
                '</transform></camera>')
    group = "\n".join(cams[:2]) + '\n<group id="0" label="Group 1" type="folder">\n' + "\n".join(cams[2:]) + "\n</group>"
    comp_xml = (f'<components next_id="1" active_id="0">\n  <component id="0" label="Component 1">\n    {tr}\n'
                '    <region><center>0 0 0</center><size>1 1 1</size></region>\n  </component>\n</components>')
    doc = (f'{header}\n<document version="{"2.0.0" if components else "1.5.0"}">\n  <chunk label="Chunk 1" '
           'enabled="true">\n    <sensors next_id="1">\n'
           f'{sensor_xml("0", views[0], terms, extra=sensor_extra)}\n    </sensors>\n'
           f'{comp_xml if components else ""}\n    <cameras next_id="92" next_group_id="1">\n{group}\n    </cameras>\n'
           f'    {"" if components else tr}\n    <settings><property name="accuracy_tiepoints" value="1"/></settings>\n'
           '  </chunk>\n</document>\n')
    path.write_text(doc)
    return path


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return sc.make_synthetic_scene(tmp_path_factory.mktemp("metashape") / "R", n_views=6, width=80, height=60,
                                   cell_size=0.25, layout="two-rings", seen_only=True, photometric="none")


def _assert_same_cameras(a, b, atol=1e-9) -> None:
    assert len(a.views) == len(b.views)
    for u, v in zip(a.views, b.views):
        assert (u.width, u.height) == (v.width, v.height) and u.image == v.image
        np.testing.assert_allclose(u.intrinsic, v.intrinsic, atol=atol)
        np.testing.assert_allclose(u.extrinsic, v.extrinsic, atol=atol)


# ------------------------------------------------------------------------------ tests


@pytest.mark.parametrize("components", [False, True])
def test_reads_back_the_cameras_through_the_chunk_transform(room, components, caplog):
    path = write_xml(room.root / f"cameras{int(components)}.xml", room.scene, components=components)
    with caplog.at_level(logging.WARNING):
        scene = load_scene(path, mesh=room.scene.mesh, image_dir=room.root / "images")
    assert scene.names == room.scene.names and scene.source == path
    _assert_same_cameras(scene, room.scene)
    assert all(v.distortion is None for v in scene.views)
    assert "2 camera(s) are not aligned (no transform) or disabled and are skipped: not_aligned, disabled" in caplog.text
    if components:  # cameras without a component_id: the active component's transform
        path.write_text(path.read_text().replace(' component_id="0"', ""))
        _assert_same_cameras(load_scene(path, mesh=room.scene.mesh, image_dir=room.root / "images"), room.scene)


def test_a_folder_with_cameras_xml_and_the_images_beside_it(room, tmp_path):
    shutil.copytree(room.root / "images", tmp_path / "images")
    write_xml(tmp_path / "images" / "cameras.xml", room.scene)
    scene = load_scene(tmp_path / "images", mesh=room.scene.mesh)  # detected; images beside the XML
    assert scene.source == tmp_path / "images" / "cameras.xml"
    for u, v in zip(scene.views, room.scene.views):
        np.testing.assert_allclose(u.extrinsic, v.extrinsic, atol=1e-9)
        assert u.image == tmp_path / "images" / v.image.name


def test_pixel_centres_a_known_point_projects_where_the_photo_shows_it(room):
    """The photo's own ray-cast surface points (pixel (r, c) shows points[r, c]) project back onto
    (c, r) with the cameras read from the XML: to 0.01 px, a half-pixel slip would be 0.5."""
    scene = load_scene(write_xml(room.root / "align.xml", room.scene), mesh=room.scene.mesh,
                       image_dir=room.root / "images")
    for k in (0, 5):
        pts = room.load_points(k)
        r, c = np.nonzero(np.isfinite(pts[..., 0]))
        uv, z = project_points(pts[r, c].astype(np.float64), scene.views[k].intrinsic, scene.views[k].extrinsic)
        err = np.abs(uv - np.stack([c, r], 1))
        assert len(r) > 1000 and err.max() < 0.01, err.max()


def _manual_projection(X: np.ndarray, f, cx, cy, w, h, t: dict) -> np.ndarray:
    """Metashape manual, appendix "Camera models", frame cameras: u, v from the image's top-left corner."""
    x, y = X[:, 0] / X[:, 2], X[:, 1] / X[:, 2]
    r2 = x * x + y * y
    radial = 1 + t["k1"] * r2 + t["k2"] * r2**2 + t["k3"] * r2**3 + t["k4"] * r2**4
    xp = x * radial + (t["p1"] * (r2 + 2 * x * x) + 2 * t["p2"] * x * y)
    yp = y * radial + (t["p2"] * (r2 + 2 * y * y) + 2 * t["p1"] * x * y)
    u = w * 0.5 + cx + xp * f + xp * t["b1"] + yp * t["b2"]
    v = h * 0.5 + cy + yp * f
    return np.stack([u, v], 1)


TERMS = {"opencv": {"k1": -0.12, "k2": 0.03, "k3": -0.004, "k4": 0.0, "p1": 0.0021, "p2": -0.0013, "b1": 0.6, "b2": 0.0},
         "metashape": {"k1": -0.09, "k2": -0.07, "k3": 0.11, "k4": -0.076, "p1": -0.0031, "p2": 0.0012, "b1": 0.53,
                       "b2": -0.31}}


@pytest.mark.parametrize("model", ["opencv", "metashape"])
def test_the_manuals_camera_model_is_undone(room, model):
    t = TERMS[model]
    path = write_xml(room.root / f"dist_{model}.xml", room.scene, terms=t)
    scene = load_scene(path, mesh=room.scene.mesh, image_dir=room.root / "images", check_cameras=False)
    v, ref = scene.views[2], room.scene.views[2]
    assert v.distortion is not None and v.distortion.model == model and v.distorted
    K, w, h = ref.intrinsic, ref.width, ref.height
    f, cx, cy = K[0, 0], K[0, 2] + 0.5 - w / 2, K[1, 2] + 0.5 - h / 2
    rng = np.random.default_rng(1)
    X = np.concatenate([rng.uniform(-0.6, 0.6, (500, 2)), np.ones((500, 1))], 1) * rng.uniform(1, 5, (500, 1))
    want = _manual_projection(X, f, cx, cy, w, h, t) - 0.5  # our pixel centres at integers
    got = v.distortion.distort(X[:, :2] / X[:, 2:])
    assert np.abs(got - want).max() < 0.01
    # the view's pinhole camera keeps the principal point and shows only the photo
    np.testing.assert_allclose(v.intrinsic[:2, 2], K[:2, 2])
    P = v.intrinsic
    u, q = np.meshgrid(np.linspace(-0.5, w - 0.5, 30), np.linspace(-0.5, h - 0.5, 20))
    yy = (q.ravel() - P[1, 2]) / P[1, 1]
    d = v.distortion.distort(np.stack([(u.ravel() - P[0, 2] - P[0, 1] * yy) / P[0, 0], yy], 1))
    assert d[:, 0].min() >= -0.5 - 1e-6 and d[:, 0].max() <= w - 0.5 + 1e-6
    assert d[:, 1].min() >= -0.5 - 1e-6 and d[:, 1].max() <= h - 0.5 + 1e-6


def test_errors_name_the_element_and_line(room, tmp_path):
    images = room.root / "images"
    mesh = room.scene.mesh
    good = write_xml(tmp_path / "good.xml", room.scene).read_text()

    def variant(name: str, text: str) -> Path:
        p = tmp_path / name
        p.write_text(text)
        return p

    def line_of(text: str, needle: str) -> int:
        return text[:text.index(needle)].count("\n") + 1

    with pytest.raises(InputError, match=r"Metashape cameras file, which holds no mesh.*--mesh"):
        load_scene(tmp_path / "good.xml", image_dir=images)
    # not well-formed: the line of the error
    cut = good[:good.index("<group")] + "<camera id='x'>\n"
    with pytest.raises(InputError, match=rf"cut\.xml, line {cut.count(chr(10)) + 1}: not well-formed XML"):
        load_scene(variant("cut.xml", cut), mesh=mesh, image_dir=images, format="metashape")
    # hostile XML: a document type (entities) refused before anything is expanded
    bomb = good.replace("<document", '<!DOCTYPE d [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;">]>\n<document', 1)
    with pytest.raises(InputError, match=r"bomb\.xml, line 2: the XML declares a document type or entities"):
        load_scene(variant("bomb.xml", bomb), mesh=mesh, image_dir=images)
    # a camera transform of 15 numbers: the element and its line
    first = good.index("<transform>", good.index("<camera ")) + len("<transform>")
    short = good[:first] + good[first:].split(" ", 1)[1]  # 15 numbers
    with pytest.raises(InputError, match=rf"short\.xml, line {line_of(short, '<camera ') + 1}: <transform>: a camera "
                                         r"<transform> \(4x4, row-major\) must be 16 finite numbers"):
        load_scene(variant("short.xml", short), mesh=mesh, image_dir=images)
    unknown = good.replace('<camera id="3" sensor_id="0"', '<camera id="3" sensor_id="7"')
    with pytest.raises(InputError, match=rf"unknown\.xml, line {line_of(unknown, 'sensor_id=' + chr(34) + '7')}: "
                                         r"<camera>: camera 'v03.png' refers to sensor '7'"):
        load_scene(variant("unknown.xml", unknown), mesh=mesh, image_dir=images)
    fish = good.replace('type="frame">', 'type="fisheye">', 1)
    with pytest.raises(InputError, match=r"fish\.xml, line 5: <sensor>: camera 'v00' uses a 'fisheye' sensor"):
        load_scene(variant("fish.xml", fish), mesh=mesh, image_dir=images)
    old = good.replace("<f>64.0</f>\n", "<fx>64.0</fx><fy>64.0</fy>\n")
    cal = line_of(good, 'class="adjusted"')
    with pytest.raises(InputError, match=rf"old\.xml, line {cal}: <calibration>: an older PhotoScan calibration"):
        load_scene(variant("old.xml", old), mesh=mesh, image_dir=images)
    neg = good.replace("<f>64.0</f>\n", "<f>-64.0</f>\n")
    with pytest.raises(InputError, match=rf"neg\.xml, line {cal}: <calibration>: focal length f = -64.0"):
        load_scene(variant("neg.xml", neg), mesh=mesh, image_dir=images)
    nan = good.replace("<cx>0.0</cx>", "<cx>nan</cx>")
    with pytest.raises(InputError, match=rf"nan\.xml, line {line_of(nan, '<cx>nan')}: <cx>: nan at \[0\] is not a finite normal number"):
        load_scene(variant("nan.xml", nan), mesh=mesh, image_dir=images)
    # images found by label: the missing ones listed, with their lines
    with pytest.raises(InputError, match=r"(?s)good\.xml: none of the 6 photos can be read:\n  view 'v00': \S*good\.xml: "
                                         r"line \d+: no photo named after the label in .*\n  view 'v01': .*--image-dir"):
        load_scene(tmp_path / "good.xml", mesh=mesh)
    same = write_xml(tmp_path / "same.xml", room.scene, labels=["v00", "v01", "v02", "v00.png", "v04", "v05"])
    with pytest.raises(InputError, match=rf"same\.xml, line {line_of(same.read_text(), 'label=' + chr(34) + 'v00.png')}: "
                                         r"<camera>: cameras 'v00' and 'v00.png' both find .*v00.png"):
        load_scene(same, mesh=mesh, image_dir=images)
    (tmp_path / "imgs").mkdir()
    for v in room.scene.views:
        shutil.copy(v.image, tmp_path / "imgs" / v.image.name)
    shutil.copy(room.scene.views[0].image, tmp_path / "imgs" / "v00.jpg")
    with pytest.raises(InputError, match=r"camera 'v00' matches several images .*v00.jpg, v00.png"):
        load_scene(tmp_path / "good.xml", mesh=mesh, image_dir=tmp_path / "imgs")


def test_info_names_the_format(room, capsys):
    path = write_xml(room.root / "info.xml", room.scene)
    args = ["info", str(path), "--mesh", str(room.scene.mesh), "--image-dir", str(room.root / "images")]
    assert main(["-q", *args]) == 0
    capsys.readouterr()
    assert main([*args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["format"] == "metashape" and out["views"] == 6


def test_run_on_cameras_xml_with_mesh(room, tmp_path):
    path = write_xml(tmp_path / "cameras.xml", room.scene)
    out = tmp_path / "out"
    assert main(["-q", "run", str(path), "--mesh", str(room.scene.mesh), "--image-dir", str(room.root / "images"),
                 "--out", str(out), "--t-npm", "20", "--atlas-size", "512", "--no-seams", "--format", "glb",
                 "--depth-dir", str(room.root / "depth")]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert (out / "mesh.glb").is_file() and rep["selection"]["input_faces"] == len(room.scene.load_mesh().faces)
    ref = tmp_path / "ref"
    assert main(["-q", "run", str(room.root), "--out", str(ref), "--t-npm", "20", "--atlas-size", "512", "--no-seams",
                 "--format", "glb"]) == 0
    assert np.array_equal(np.load(out / "selection.npy"), np.load(ref / "selection.npy"))  # the same cameras
