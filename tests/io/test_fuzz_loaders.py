"""Fuzzing the scene loaders with hypothesis: hostile or broken files give an InputError, never a traceback.

Each loader gets 2,000 generated inputs: random documents built from the format's own vocabulary
and mutations of a valid file (a value replaced, a line cut, bytes flipped). The only acceptable
outcomes are a Scene or an :class:`~o3d_seqcc.errors.InputError`.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import o3d_seqcc as sc
from o3d_seqcc import InputError
from o3d_seqcc.io import colmap, meshlab, rgbd_folder, scene_json

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


def test_fuzzers_run_enough_examples():
    assert EXAMPLES >= 2000 and np.isfinite(EXAMPLES)


@pytest.mark.parametrize("name", ["scene.json", "key.log", "cameras.txt", "project.mlp"])
def test_each_loader_is_fuzzed(name):
    fuzzed = {"scene.json": test_fuzz_scene_json, "key.log": test_fuzz_log_trajectory,
              "cameras.txt": test_fuzz_colmap_text, "project.mlp": test_fuzz_meshlab_project}
    assert fuzzed[name].hypothesis.inner_test is not None
