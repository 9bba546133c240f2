"""Fuzzing the scene loaders with hypothesis: hostile or broken files give an InputError, never a traceback.

Each loader gets 2,000 generated inputs: random documents built from the format's own vocabulary
and mutations of a valid file (a value replaced, a line cut, bytes flipped). The only acceptable
outcomes are a Scene or an :class:`~o3d_seqcc.errors.InputError`.
"""

from __future__ import annotations

import json
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import o3d_seqcc as sc
from o3d_seqcc import InputError
from o3d_seqcc.io import bundler, colmap, meshlab, metashape, mve, nvm, rgbd_folder, scene_json

EXAMPLES = 2000
FUZZ = settings(max_examples=EXAMPLES, deadline=None, database=None, derandomize=True,
                suppress_health_check=list(HealthCheck))

_ROOT = Path(tempfile.mkdtemp(prefix="o3d_seqcc_fuzz_"))


def _valid_scene() -> Path:
    root = _ROOT / "valid"
    if not (root / "scene.json").is_file():
        sc.make_synthetic_scene(root, n_views=2, width=32, height=24, seed=0, cell_size=0.5)
    return root


def _accepts(load, *args, **kw) -> None:
    try:
        load(*args, **kw)
    except InputError:
        pass


def teardown_module(module) -> None:
    shutil.rmtree(_ROOT, ignore_errors=True)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-10**12, 10**12) | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=20) | st.sampled_from(["mesh.ply", "images/v00.png", "../..", "", "o3d_seqcc.scene/1", "\x00"]),
    lambda children: st.lists(children, max_size=5) | st.dictionaries(
        st.sampled_from(["format", "mesh", "views", "name", "image", "width", "height", "intrinsic", "extrinsic",
                         "depth", "depth_scale", "point_cloud", "x"]), children, max_size=6),
    max_leaves=30,
)


def _paths(doc) -> list[tuple]:
    """Every path into a JSON document (keys and list indices)."""
    out = [()]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += [(k, *p) for p in _paths(v)]
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out += [(i, *p) for p in _paths(v)]
    return out


def _replace(doc, path: tuple, value):
    if not path:
        return value
    doc = json.loads(json.dumps(doc))
    node = doc
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return doc


@FUZZ
@given(data=st.data())
def test_fuzz_scene_json(data):
    root = _valid_scene()
    valid = json.loads((root / "scene.json").read_text())
    kind = data.draw(st.sampled_from(["mutate", "random", "bytes"]))
    if kind == "mutate":
        path = data.draw(st.sampled_from(_paths(valid)))
        raw = json.dumps(_replace(valid, path, data.draw(json_values))).encode()
    elif kind == "random":
        raw = json.dumps({"format": "o3d_seqcc.scene/1", **data.draw(st.dictionaries(
            st.sampled_from(["mesh", "views", "x"]), json_values, max_size=3))}).encode()
    else:
        text = (root / "scene.json").read_bytes()
        cut = data.draw(st.integers(0, len(text)))
        raw = text[:cut] + data.draw(st.binary(max_size=8)) + text[cut + data.draw(st.integers(0, 4)):]
    p = root / "fuzz.json"
    p.write_bytes(raw)
    _accepts(scene_json.load, p)
    _accepts(sc.load_scene, p)


log_lines = st.lists(
    st.lists(st.sampled_from(["0", "1", "-1", "0.5", "1e308", "nan", "inf", "x", "", "1 2", "\t", "0 0 1"]),
             min_size=0, max_size=6).map(" ".join), max_size=16)


@FUZZ
@given(lines=log_lines, tail=st.binary(max_size=4))
def test_fuzz_log_trajectory(lines, tail):
    p = _ROOT / "key.log"
    p.write_bytes("\n".join(lines).encode() + tail)
    _accepts(rgbd_folder.read_log_trajectory, p)


tokens = st.sampled_from(["1", "2", "0", "-3", "64", "48", "50.5", "nan", "inf", "1e400", "PINHOLE", "SIMPLE_PINHOLE",
                          "OPENCV", "SIMPLE_RADIAL", "FISHEYE", "a.png", "#", "", "x", "0.1", "\x00"])
colmap_text = st.lists(st.lists(tokens, max_size=12).map(" ".join), max_size=8).map("\n".join)


@FUZZ
@given(cameras=colmap_text, images=colmap_text)
def test_fuzz_colmap_text(cameras, images):
    d = _ROOT / "colmap"
    d.mkdir(exist_ok=True)
    (d / "cameras.txt").write_text(cameras)
    (d / "images.txt").write_text(images)
    _accepts(colmap.load, d, mesh=_valid_scene() / "mesh.ply")


@FUZZ
@given(cameras=st.binary(max_size=200), images=st.binary(max_size=300))
def test_fuzz_colmap_binary(cameras, images):
    d = _ROOT / "colmap_bin"
    d.mkdir(exist_ok=True)
    (d / "cameras.bin").write_bytes(cameras)
    (d / "images.bin").write_bytes(images)
    _accepts(colmap.load, d, mesh=_valid_scene() / "mesh.ply")


def _valid_mlp() -> Path:
    p = _ROOT / "valid.mlp"
    if not p.is_file():
        meshlab.save_mlp(sc.load_scene(_valid_scene()), p)
    return p


attr_values = st.sampled_from(["", "0", "1 2", "0 0 0 1", "nan nan nan", "1e400", "abc", "-1 -1", "32 24",
                               " ".join(["1"] * 16), " ".join(["0"] * 16), "0.0369 0.0369", "2", "\x01", "<", "&amp;"])


@FUZZ
@given(data=st.data())
def test_fuzz_meshlab_project(data):
    text = _valid_mlp().read_text()
    kind = data.draw(st.sampled_from(["attribute", "cut", "element"]))
    if kind == "attribute":
        names = ["TranslationVector", "LensDistortion", "ViewportPx", "PixelSizeMm", "CenterPx", "FocalMm",
                 "RotationMatrix", "CameraType", "fileName", "filename", "label"]
        name = data.draw(st.sampled_from(names))
        start = text.find(f'{name}="')
        if start >= 0:
            end = text.index('"', start + len(name) + 2)
            text = text[: start + len(name) + 2] + data.draw(attr_values).replace('"', "") + text[end:]
    elif kind == "cut":
        cut = data.draw(st.integers(0, len(text)))
        text = text[:cut] + data.draw(st.text(max_size=6))
    else:
        text = text.replace("<MLRaster", data.draw(st.sampled_from(["<MLRaster", "<MLRaster2", "<X"])), 1)
        text = text.replace("MLMatrix44>", data.draw(st.sampled_from(["MLMatrix44>", "MLMatrix44 >"])), 1)
    p = _ROOT / "fuzz.mlp"
    p.write_text(text, encoding="utf-8", errors="surrogatepass") if "\ud800" not in text else p.write_bytes(b"\xff")
    _accepts(meshlab.load_mlp, p)
    _accepts(sc.load_scene, p, validate=False)


def _valid_bundler() -> Path:
    """bundle.out + list.txt of the valid scene (Bundler's README: R and t in OpenGL axes), and a .cam folder."""
    d = _ROOT / "bundler"
    if not (d / "bundle.out").is_file():
        d.mkdir()
        scene, flip = sc.load_scene(_valid_scene(), check_cameras=False), np.diag([1.0, -1.0, -1.0])
        lines = ["# Bundle file v0.3", f"{len(scene.views)} 1"]

        def row(xs) -> str:
            return " ".join(repr(float(x)) for x in xs)

        for v in scene.views:
            E = v.extrinsic
            lines += [row([v.intrinsic[0, 0], -0.05, 0.01]), *(row(r) for r in flip @ E[:3, :3]), row(flip @ E[:3, 3])]
            (d / f"{v.name}.cam").write_text(row([*E[:3, 3], *E[:3, :3].ravel()])
                                             + f"\n{row([v.intrinsic[0, 0] / v.width])} -0.05 0.01 1 0.5 0.5\n")
            shutil.copy(v.image, d / v.image.name)
        (d / "bundle.out").write_text("\n".join(lines + ["0 0 0", "255 0 0", "1 0 3 1.5 -2.5"]) + "\n")
        (d / "list.txt").write_text("\n".join(f"{v.image.name} 0 {v.intrinsic[0, 0]}" for v in scene.views) + "\n")
    return d


text_tokens = st.sampled_from(["0", "1", "-1", "2", "0.5", "-0.05", "1e308", "1e-310", "nan", "inf", "x", "", "1 2",
                               "#", "# Bundle file v0.3", "v00.png", "../..", "\x00", "99999999999", "0.8"])


def _mutate_lines(data, text: str) -> str:
    """A token of a line replaced, a line dropped or duplicated, or the text cut."""
    lines = text.split("\n")
    i = data.draw(st.integers(0, len(lines) - 1))
    kind = data.draw(st.sampled_from(["token", "drop", "repeat", "cut"]))
    if kind == "token":
        toks = lines[i].split() or [""]
        toks[data.draw(st.integers(0, len(toks) - 1))] = data.draw(text_tokens)
        lines[i] = " ".join(toks)
    elif kind == "drop":
        del lines[i]
    elif kind == "repeat":
        lines.insert(i, lines[i])
    else:
        return text[:data.draw(st.integers(0, len(text)))]
    return "\n".join(lines)


@FUZZ
@given(data=st.data())
def test_fuzz_bundler(data):
    d = _valid_bundler()
    which = data.draw(st.sampled_from(["bundle.out", "list.txt"]))
    f = _ROOT / "bundler_fuzz"
    f.mkdir(exist_ok=True)
    for name in ("bundle.out", "list.txt"):
        text = (d / name).read_text()
        (f / name).write_text(_mutate_lines(data, text) if name == which else text)
    _accepts(bundler.load, f / "bundle.out", mesh=_valid_scene() / "mesh.ply", image_dir=d)
    _accepts(sc.load_scene, f / "bundle.out", mesh=_valid_scene() / "mesh.ply", image_dir=d, validate=False)


@FUZZ
@given(data=st.data())
def test_fuzz_mve_cam_and_meta_ini(data):
    d = _valid_bundler()
    f = _ROOT / "cam_fuzz"
    if not f.is_dir():
        shutil.copytree(d, f)
    cam = sorted(d.glob("*.cam"))[0]
    (f / cam.name).write_text(_mutate_lines(data, cam.read_text()))
    _accepts(mve.load_cam_folder, f, mesh=_valid_scene() / "mesh.ply")
    view = _ROOT / "mve_fuzz" / "views" / "view_0000.mve"
    view.mkdir(parents=True, exist_ok=True)
    shutil.copy(d / "v00.png", view / "original.png")
    cam_lines = cam.read_text().split("\n")
    ini = (f"[view]\nid = 0\nname = v00\n[camera]\nfocal_length = {cam_lines[1].split()[0]}\n"
           f"radial_distortion = -0.05 0.01\npixel_aspect = 1\nprincipal_point = 0.5 0.5\n"
           f"rotation = {' '.join(cam_lines[0].split()[3:])}\ntranslation = {' '.join(cam_lines[0].split()[:3])}\n")
    (view / "meta.ini").write_text(_mutate_lines(data, ini))
    _accepts(mve.load, view.parent.parent, mesh=_valid_scene() / "mesh.ply")


def _valid_nvm_and_xml() -> tuple[Path, Path]:
    """An NVM_V3 file (with points) and a Metashape cameras.xml of the valid scene, beside its folder."""
    nvm_path, xml_path = _ROOT / "scene.nvm", _ROOT / "cameras.xml"
    if not xml_path.is_file():
        from scipy.spatial.transform import Rotation

        scene = sc.load_scene(_valid_scene(), check_cameras=False)
        cams = []
        for v in scene.views:
            x, y, z, w = Rotation.from_matrix(v.rotation).as_quat()
            cams.append(f"valid/images/{v.image.name} "
                        + " ".join(repr(float(c)) for c in (v.intrinsic[0, 0], w, x, y, z, *v.center)) + " -0.02 0")
        pts = ["0.5 0.5 0.5 1 2 3 2 0 0 1.5 2.5 1 0 -1.5 2.0", "1 1 1 0 0 0 0"]
        nvm_path.write_text("\n".join(["NVM_V3", "", str(len(cams)), *cams, "", "2", *pts, "", "1", cams[0], "0", "",
                                       "0", ""]))
        T = [" ".join(repr(float(x)) for x in np.linalg.inv(v.extrinsic).ravel()) for v in scene.views]
        v = scene.views[0]
        xml_path.write_text(
            '<?xml version="1.0" encoding="UTF-8"?>\n<document version="1.5.0">\n<chunk>\n<sensors>\n'
            f'<sensor id="0" label="s" type="frame">\n<resolution width="{v.width}" height="{v.height}"/>\n'
            f'<calibration type="frame" class="adjusted">\n<f>{float(v.intrinsic[0, 0])!r}</f>\n<cx>0.5</cx>\n<cy>-0.5</cy>\n'
            '<k1>-0.01</k1>\n<k4>0.001</k4>\n<b2>0.1</b2>\n</calibration>\n</sensor>\n</sensors>\n<cameras>\n'
            + "".join(f'<camera id="{i}" sensor_id="0" label="{u.name}">\n<transform>{t}</transform>\n</camera>\n'
                      for i, (u, t) in enumerate(zip(scene.views, T)))
            + '<camera id="9" sensor_id="0" label="x"/>\n</cameras>\n<transform>\n<rotation>1 0 0 0 0 -1 0 1 0</rotation>\n'
            '<translation>1 2 3</translation>\n<scale>2</scale>\n</transform>\n</chunk>\n</document>\n')
    return nvm_path, xml_path


xml_values = st.sampled_from(["", "0", "-1", "1e400", "nan", "x", "&amp;", "&x;", "<", "]]>", " ".join(["1"] * 16),
                              " ".join(["0"] * 15), "frame", "fisheye", "false", "<f>1</f>", '"', "\x01"])


@FUZZ
@given(data=st.data())
def test_fuzz_nvm(data):
    text = _valid_nvm_and_xml()[0].read_text()
    p = _ROOT / "fuzz.nvm"
    p.write_text(_mutate_lines(data, text))
    _accepts(nvm.load, p, mesh=_valid_scene() / "mesh.ply")
    _accepts(sc.load_scene, p, mesh=_valid_scene() / "mesh.ply", validate=False)


@FUZZ
@given(data=st.data())
def test_fuzz_metashape_xml(data):
    text = _valid_nvm_and_xml()[1].read_text()
    kind = data.draw(st.sampled_from(["value", "cut", "tag"]))
    if kind == "value":  # an element's text or an attribute's value replaced
        spans = [(m.start(g), m.end(g)) for m in re.finditer(r'>([^<]*)<|="([^"]*)"', text) for g in (1, 2)
                 if m.start(g) >= 0]
        a, b = data.draw(st.sampled_from(spans))
        text = text[:a] + data.draw(xml_values) + text[b:]
    elif kind == "cut":
        text = text[:data.draw(st.integers(0, len(text)))] + data.draw(st.text(max_size=6))
    else:
        old = data.draw(st.sampled_from(["<sensor ", "<camera ", "<transform>", "<calibration ", "<chunk>", "<f>"]))
        text = text.replace(old, data.draw(st.sampled_from(["<x ", "<!DOCTYPE d>", "<group>", old + old])), 1)
    p = _ROOT / "fuzz.xml"
    p.write_text(text, encoding="utf-8", errors="surrogatepass")
    _accepts(metashape.load, p, mesh=_valid_scene() / "mesh.ply", image_dir=_valid_scene() / "images")
    _accepts(sc.load_scene, p, mesh=_valid_scene() / "mesh.ply", image_dir=_valid_scene() / "images", validate=False)


def test_fuzzers_run_enough_examples():
    assert EXAMPLES >= 2000 and np.isfinite(EXAMPLES)


@pytest.mark.parametrize("name", ["scene.json", "key.log", "cameras.txt", "project.mlp", "bundle.out", "meta.ini",
                                  "scene.nvm", "cameras.xml"])
def test_each_loader_is_fuzzed(name):
    fuzzed = {"scene.json": test_fuzz_scene_json, "key.log": test_fuzz_log_trajectory,
              "cameras.txt": test_fuzz_colmap_text, "project.mlp": test_fuzz_meshlab_project,
              "bundle.out": test_fuzz_bundler, "meta.ini": test_fuzz_mve_cam_and_meta_ini, "scene.nvm": test_fuzz_nvm,
              "cameras.xml": test_fuzz_metashape_xml}
    assert fuzzed[name].hypothesis.inner_test is not None
