"""Speed and memory work of issue 21 that must not change a result: same values, same bytes, no dense arrays.

Speed itself is measured by ``benchmarks/profile_run.py`` and ``benchmarks/peers.py``, not here.
"""

from __future__ import annotations

import struct
import warnings
import zlib

import numpy as np
import pytest

import o3d_seqcc as sc


def _png_with_exif_after_pixels(path, img: np.ndarray, orientation: int) -> None:
    """A PNG whose eXIf chunk follows its IDAT (allowed by the PNG 1.5 extension; Pillow writes it before)."""
    from PIL import Image

    exif = Image.Exif()
    exif[0x0112] = orientation
    payload = exif.tobytes()[6:] if exif.tobytes().startswith(b"Exif\x00\x00") else exif.tobytes()

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    h, w = img.shape[:2]
    raw = b"".join(b"\x00" + img[y].tobytes() for y in range(h))
    data = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"eXIf", payload) + chunk(b"IEND", b""))
    path.write_bytes(data)


def test_png_exif_orientation_found_without_decoding_twice(tmp_path, monkeypatch):
    """read_image decodes a PNG once (OpenCV): its eXIf chunk, even after the pixels, is found from the chunk
    headers, not by Pillow decoding the image (which doubled every photo read)."""
    from PIL import ImageFile

    from o3d_seqcc.io.images import read_image

    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (30, 40, 3), dtype=np.uint8)
    _png_with_exif_after_pixels(tmp_path / "rot.png", img, 6)
    from PIL import Image

    Image.fromarray(img).save(tmp_path / "plain.png")
    with Image.open(tmp_path / "rot.png") as im:  # Pillow itself sees the tag only by decoding the image
        assert im.getexif().get(0x0112) == 6

    def no_decode(self, *a, **k):
        raise AssertionError("Pillow decoded the image")

    monkeypatch.setattr(ImageFile.ImageFile, "load", no_decode)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        a = read_image(tmp_path / "rot.png")
        b = read_image(tmp_path / "plain.png")
    assert np.array_equal(a, img) and np.array_equal(b, img)
    msgs = [str(w.message) for w in rec if "EXIF orientation" in str(w.message)]
    assert len(msgs) == 1 and "rot.png has EXIF orientation 6" in msgs[0]


def _float32_samples(img: np.ndarray, uv: np.ndarray, interp: str) -> np.ndarray:
    """(n, 3): the colour samples as first written, on a float32 copy of the float image (the reference)."""
    H, W = img.shape[:2]
    flat = np.ascontiguousarray(img, dtype=np.float32).reshape(-1, 3)
    x, y = np.clip(uv[:, 0], 0.0, W - 1.0), np.clip(uv[:, 1], 0.0, H - 1.0)
    if interp == "nearest":
        xi = np.minimum(np.floor(x + 0.5).astype(np.int64), W - 1)
        yi = np.minimum(np.floor(y + 0.5).astype(np.int64), H - 1)
        return np.take(flat, yi * W + xi, axis=0)
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    dx = (x0 < W - 1).astype(np.int64)
    i00 = y0 * W + x0
    i10 = i00 + np.where(y0 < H - 1, W, 0)
    fx, fy = (x - x0).astype(np.float32)[:, None], (y - y0).astype(np.float32)[:, None]
    top = np.take(flat, i00, axis=0) * (1.0 - fx) + np.take(flat, i00 + dx, axis=0) * fx
    bot = np.take(flat, i10, axis=0) * (1.0 - fx) + np.take(flat, i10 + dx, axis=0) * fx
    return top * (1.0 - fy) + bot * fy


def test_colour_samples_from_uint8_are_the_float_samples():
    """The colour sampling of seqcc-global reads uint8 / uint16 photos directly, channel planes and a level
    table, bit for bit the float32 samples of the float image."""
    from o3d_seqcc.correction.methods.edge_summaries import _sample_image
    from o3d_seqcc.imaging.arrays import img_as_float

    rng = np.random.default_rng(1)
    for dtype, top, n in ((np.uint8, 256, 500), (np.uint16, 65536, 500), (np.uint8, 256, 3000), (np.uint16, 65536, 3000)):
        img = rng.integers(0, top, (37, 53, 3)).astype(dtype)  # 500 samples: pixel by pixel; 3000: channel planes
        uv = np.concatenate([rng.uniform(-2, 55, (n, 2)), [[0, 0], [52, 36], [52.5, 36.7], [51.999, 35.2]]])
        for interp in ("bilinear", "nearest"):
            want = _float32_samples(img_as_float(img), uv, interp).T
            for got in (_sample_image(img, uv, interp), _sample_image(img_as_float(img), uv, interp)):
                assert got.dtype == want.dtype == np.float32
                assert np.array_equal(got, want), (dtype, interp)


def test_bilinear_samples_from_the_flat_image_are_the_indexed_ones():
    """sample_bilinear gathers the four neighbours from the flattened image and multiplies them as float64 in
    the products: bit for bit the 2-D indexed, converted-first samples, any dtype, channels, query shape."""
    from o3d_seqcc.imaging.arrays import sample_bilinear

    def indexed(img, x, y):  # as first written
        h, w = img.shape[:2]
        x = np.clip(np.asarray(x, dtype=np.float64), 0.0, w - 1.0)
        y = np.clip(np.asarray(y, dtype=np.float64), 0.0, h - 1.0)
        x0, y0 = np.floor(x).astype(np.intp), np.floor(y).astype(np.intp)
        x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
        fx, fy = x - x0, y - y0
        if img.ndim == 3:
            fx, fy = fx[..., None], fy[..., None]
        top = img[y0, x0].astype(np.float64) * (1.0 - fx) + img[y0, x1].astype(np.float64) * fx
        bot = img[y1, x0].astype(np.float64) * (1.0 - fx) + img[y1, x1].astype(np.float64) * fx
        return top * (1.0 - fy) + bot * fy

    rng = np.random.default_rng(4)
    for dtype in (np.uint8, np.uint16, np.float32, np.float64):
        for shape in ((31, 47, 3), (31, 47), (9, 6, 4), (1, 1, 3)):
            img = (rng.random(shape) * (1000 if dtype == np.uint16 else 255 if dtype == np.uint8 else 1)).astype(dtype)
            for image in (img, img[::2, ::-1]):
                h, w = image.shape[:2]
                for q in ((500,), (40, 9), ()):
                    x, y = rng.uniform(-2, w + 1, q), rng.uniform(-2, h + 1, q)
                    want, got = indexed(image, x, y), sample_bilinear(image, x, y)
                    assert got.dtype == want.dtype == np.float64 and got.shape == want.shape
                    assert np.array_equal(got, want), (dtype, shape, q)


def test_raycast_in_chunks_is_the_whole_image_cast(monkeypatch, tmp_path):
    """raycast casts rows in chunks (memory): every array is bit for bit the one-chunk cast."""
    from o3d_seqcc.evaluation import render

    sc.make_synthetic_scene(tmp_path / "room", n_views=2, width=160, height=120, cell_size=0.15)
    scene = sc.load_scene(tmp_path / "room")
    mesh, view = scene.load_mesh(), scene.views[0]
    monkeypatch.setattr(render, "RAY_CHUNK", 1 << 30)
    whole = render.raycast(mesh, view)
    monkeypatch.setattr(render, "RAY_CHUNK", 1000)  # 6 rows per chunk, the last one short
    parts = render.raycast(mesh, view)
    assert len(np.unique(whole.face_ids)) > 100
    for name in ("face_ids", "bary", "depth", "cos_angle"):
        assert np.array_equal(getattr(whole, name), getattr(parts, name)), name


#: the dense (V, F) views of a Visibility, for tests and figures only
DENSE = ("valid", "occluded", "depth_inconsistent", "oblique", "usable", "area", "cos_angle", "uv", "depth")


def test_default_run_builds_no_views_by_faces_array(tmp_path, monkeypatch):
    """`o3d-seqcc run`'s whole path (the command: load, pipeline.run, the export, selection.png, Table 2 and the
    report) reads the sparse per-view records only: every dense (V, F) view of a visibility raises inside it
    (the properties, :meth:`to_dense` of Visibility and of the selection's ScoredVisibility, DenseVisibility)."""
    from o3d_seqcc.cli import main
    from o3d_seqcc.texturing.data_costs import ScoredVisibility
    from o3d_seqcc.visibility.compute import Visibility
    from o3d_seqcc.visibility.dense import DenseVisibility

    sc.make_synthetic_scene(tmp_path / "room", n_views=6, width=160, height=120, cell_size=0.15)
    used = []

    def forbidden(name):
        def get(self, *a, **k):
            used.append(name)
            raise AssertionError(f"dense Visibility.{name} read on the default path")
        return get

    for name in DENSE:
        monkeypatch.setattr(Visibility, name, property(forbidden(name)))
    for name in ("stage_masks", "to_dense", "_dense_mask", "_dense_values", "_dense_projection"):
        monkeypatch.setattr(Visibility, name, forbidden(name))
    monkeypatch.setattr(ScoredVisibility, "to_dense", forbidden("ScoredVisibility.to_dense"))
    monkeypatch.setattr(DenseVisibility, "__init__", forbidden("DenseVisibility"))
    res = sc.pipeline.run(tmp_path / "room", t_npm=50)
    res.save(tmp_path / "out")
    assert main(["-q", "run", str(tmp_path / "room"), "--out", str(tmp_path / "cli"), "--t-npm", "50"]) == 0
    assert used == []
    assert (tmp_path / "out" / "report.html").is_file() and (tmp_path / "cli" / "report.html").is_file()
    monkeypatch.undo()
    assert res.visibility.to_dense().usable.shape == (6, len(res.selection))  # the dense views still exist for tests


def _digest(folder) -> dict:
    """sha1 of every output file; report.json without its timings, report.html without its timings table."""
    import hashlib
    import json
    import re

    def strip(x):
        if isinstance(x, dict):
            return {k: strip(v) for k, v in x.items() if not (k.startswith("timings") or k == "time_s" or k == "files")}
        return [strip(v) for v in x] if isinstance(x, list) else x

    out = {}
    for p in sorted(folder.rglob("*")):
        if not p.is_file() or p.name == ".o3d_seqcc.json":
            continue
        data = p.read_bytes()
        if p.name == "report.html":
            data = re.sub(rb"<!-- timings -->.*?<!-- /timings -->", b"", data, flags=re.S)
        if p.name == "report.json":
            data = json.dumps(strip(json.loads(data)), sort_keys=True).encode()
        out[str(p.relative_to(folder))] = hashlib.sha1(data).hexdigest()
    return out


def test_same_bytes_for_any_jobs(tmp_path):
    """`o3d-seqcc run -j 1` and `-j 2` (threads in every stage, the export beside the report) write the same files."""
    from o3d_seqcc.cli import main

    sc.make_synthetic_scene(tmp_path / "room", n_views=6, width=160, height=120, cell_size=0.15)
    digests = []
    for jobs in ("1", "2"):
        out = tmp_path / f"j{jobs}"
        assert main(["-q", "-j", jobs, "run", str(tmp_path / "room"), "--out", str(out), "--t-npm", "50",
                     "--save-images"]) == 0
        digests.append(_digest(out))
    assert {"mesh.glb", "mesh.obj", "mesh.png", "report.html", "report.json", "selection.png"} <= set(digests[0])
    assert digests[0] == digests[1]


def test_thinned_pairs_are_the_full_pairs_taken(tmp_path):
    """A pair's picked mappings built alone (the correction's 8000, Table 2's 200 of a pair) are bit for bit
    the full build's at those indices, in every mapping mode; the count comes without building."""
    from o3d_seqcc.mappings.compute import compute_mappings
    from o3d_seqcc.mappings.pairs import thinned
    from o3d_seqcc.visibility.compute import compute_visibility

    sc.make_synthetic_scene(tmp_path / "room", n_views=4, width=160, height=120, cell_size=0.15)
    scene = sc.load_scene(tmp_path / "room")
    vis = compute_visibility(scene)
    rng = np.random.default_rng(3)
    for mode in ("surface", "vertices", "dense"):
        m = compute_mappings(scene, visibility=vis, mappings=mode)
        src = m.pairs.source
        levels = 0
        for key in m.pairs:
            full = src.build(*key)
            levels += len(np.unique(src._plan(*key)[1]))
            assert src.size(*key) == full.n > 0
            picks = [np.sort(rng.choice(full.n, min(full.n, 97), replace=False)), np.arange(full.n),
                     np.zeros(0, np.int64), np.array([0, full.n - 1])]
            for idx in picks:
                n, part = thinned(m.pairs, key, lambda n, idx=idx: idx)
                want = full.take(idx)
                assert n == full.n and part.n == len(idx)
                for name in ("uv_a", "uv_b", "face_ids", "weights"):
                    x, y = getattr(part, name), getattr(want, name)
                    assert (x is None) == (y is None), (mode, name)
                    assert x is None or (x.dtype == y.dtype and np.array_equal(x, y)), (mode, key, name)
            assert thinned(m.pairs, key, lambda n: None)[1].n == full.n
        assert mode == "vertices" or levels > len(m.pairs)  # faces of several levels in a pair: groups crossed


def test_push_pull_fill_in_bands_is_the_whole_page_fill(monkeypatch):
    """The gutter fill of an even-sided page pulls and pushes its full-resolution level in row bands (no
    float copy of the page): the same bytes as the whole-page pyramid, for bands that do or do not divide it."""
    import cv2

    from o3d_seqcc.texturing import fill

    rng = np.random.default_rng(5)
    for H, W, band in ((512, 384, 64), (640, 256, 96), (514, 258, 128)):
        img = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
        blobs = cv2.resize(rng.random((H // 16 + 1, W // 16 + 1)).astype(np.float32), (W, H),
                           interpolation=cv2.INTER_NEAREST)
        mask = (blobs > 0.55) & (rng.random((H, W)) > 0.05)
        monkeypatch.setattr(fill, "FILL_BAND_ROWS", 1 << 20)  # one band: the whole-page path
        whole = fill.push_pull_fill(img, mask)
        monkeypatch.setattr(fill, "FILL_BAND_ROWS", band)
        banded = fill.push_pull_fill(img, mask)
        assert np.array_equal(whole[mask], img[mask]) and not np.array_equal(whole, img)
        assert np.array_equal(banded, whole), (H, W, band)


def test_background_report_parts_are_what_save_computes(tmp_path):
    """run() starts the report's Table 2 and correction figures on a thread right after the correction, the selection
    seams after the selection; save() takes them only for the correction (and selection) they were started for, and
    they are the numbers and pictures the report would compute itself."""
    import dataclasses
    import json

    from o3d_seqcc.evaluation.seams import selection_seams_of
    from o3d_seqcc.report.background import table2_metrics
    from o3d_seqcc.report import cached_images
    from o3d_seqcc.report.parts import correction_parts

    sc.make_synthetic_scene(tmp_path / "room", n_views=5, width=160, height=120, cell_size=0.15)
    res = sc.pipeline.run(tmp_path / "room", t_npm=50)
    bg = res._background
    assert bg is not None and bg.matches(res)
    images = cached_images(res.originals, res.images)
    direct = table2_metrics(images, res.mappings, res.correction.paths)
    assert bg.result() == direct and direct["before"] != direct["after"]
    assert not bg.matches(dataclasses.replace(res, mappings=sc.compute_mappings(res.scene, visibility=res.visibility)))
    assert bg.matches(dataclasses.replace(res, source="elsewhere"))  # what the command line's replace() keeps
    parts, want = bg.parts(), correction_parts(*images, res.correction, res.mappings)
    assert parts.jih_thumbs == want.jih_thumbs and len(parts.jihs) > 1 and parts.width == want.width
    for e, (a, b) in want.jihs.items():
        assert np.array_equal(parts.jihs[e][0], a) and (b is None) == (parts.jihs[e][1] is None)
    assert all(np.array_equal(x, y) for got, exp in zip(parts.thumbs, want.thumbs) for x, y in zip(got, exp))
    mesh = res.visibility.mesh
    seams = selection_seams_of(mesh.vertices, mesh.faces, res.selection, res.scene.views,
                               {"photos": images[0], "corrected": images[1]})
    got = bg.seams(res.selection)
    assert all(np.array_equal(got[k].delta_e, seams[k].delta_e) for k in seams) and len(seams["photos"].delta_e)
    assert bg.seams(res.selection.copy()) is None  # another selection: measured again by save
    res.save(tmp_path / "out")
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    assert rep["metrics"] == json.loads(json.dumps(direct))
    assert rep["selection_seams"] == {k: v.summary() for k, v in seams.items()}


def test_seam_metric_measured_beside_what_follows_the_run(tmp_path, monkeypatch):
    """With local threads, texture() / run() return before the seam metric is done (it runs beside save()'s files);
    ``seams`` waits for it and is the metric of the textured mesh, the report's ``seams`` too; one thread: measured
    in the run."""
    import json
    import pickle
    import threading

    from joblib import parallel_config

    import o3d_seqcc.pipeline as pipeline
    from o3d_seqcc.evaluation.seams import seam_metric

    sc.make_synthetic_scene(tmp_path / "room", n_views=4, width=160, height=120, cell_size=0.15)
    gate, calls = threading.Event(), []

    def gated(tm):
        calls.append(threading.current_thread().name)
        assert gate.wait(20)
        return seam_metric(tm)

    monkeypatch.setattr(pipeline, "seam_metric", gated)
    with parallel_config(n_jobs=2):
        res = pipeline.texture(tmp_path / "room")  # returns with the metric held at the gate
    assert calls and calls[0] != threading.current_thread().name and not res._seams.done()
    gate.set()
    want = seam_metric(res.textured)
    assert res.seams.to_dict() == want.to_dict() and want.n_seam_edges > 0 and res.timings["seams"] > 0
    res.save(tmp_path / "out")
    assert json.loads((tmp_path / "out" / "report.json").read_text())["seams"]["mean"] == pytest.approx(want.mean)
    back = pickle.loads(pickle.dumps(res))  # pickled with the metric, as a result measured in the run was
    assert back.seams.to_dict() == want.to_dict() and np.array_equal(back.selection, res.selection)
    calls.clear()
    with parallel_config(n_jobs=1):
        one = pipeline.texture(tmp_path / "room")
    assert calls == [threading.current_thread().name] and one.seams.to_dict() == want.to_dict()


def test_data_costs_same_for_any_threads(tmp_path):
    """face_view_statistics runs one task per view on threads: the same GMI and colours for 1 and 2 threads."""
    from joblib import parallel_config

    from o3d_seqcc.imaging.sequences import scene_photos
    from o3d_seqcc.texturing.data_costs import face_view_statistics
    from o3d_seqcc.visibility import compute_visibility

    sc.make_synthetic_scene(tmp_path / "room", n_views=5, width=160, height=120, cell_size=0.15)
    scene = sc.load_scene(tmp_path / "room")
    vis = compute_visibility(scene)
    indptr, faces, area = vis.usable_entries()[:3]
    out = []
    for jobs in (1, 2):
        with parallel_config(n_jobs=jobs):
            out.append(face_view_statistics(vis, scene_photos(scene.views), indptr, faces, area, colour=True))
    (g1, c1), (g2, c2) = out
    assert len(g1) == len(faces) > 100 and (g1 > 0).mean() > 0.5
    assert np.array_equal(g1, g2) and np.array_equal(c1, c2)


def test_report_jih_mappings_are_the_full_pairs_thinned(tmp_path):
    """The report's JIHs build only the mappings they draw: the full pair's at thin_indices, either orientation."""
    from o3d_seqcc.mappings.compute import compute_mappings
    from o3d_seqcc.evaluation.metrics import thin_indices
    from o3d_seqcc.report.parts import thinned_pair as _thinned_pair

    sc.make_synthetic_scene(tmp_path / "room", n_views=4, width=160, height=120, cell_size=0.15)
    m = compute_mappings(sc.load_scene(tmp_path / "room"))
    checked = 0
    for a, b in m.pairs:
        for t, s in ((a, b), (b, a)):
            full = m.pair(t, s)
            for k in (50, 10**9):
                idx = thin_indices(full.n, k)
                want = full if idx is None else full.take(idx)
                got = _thinned_pair(m, t, s, k)
                assert (got.a, got.b) == (t, s) and np.array_equal(got.uv_a, want.uv_a)
                assert np.array_equal(got.uv_b, want.uv_b) and np.array_equal(got.face_ids, want.face_ids)
                checked += idx is not None
    assert checked > 0


def test_command_line_imports_open3d_without_dash():
    """A command's `import open3d` skips dash (Open3D's draw_plotly_server only), which still works after."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from o3d_seqcc.cli import _open3d_without_dash\n"
        "with _open3d_without_dash():\n"
        "    import open3d\n"
        "    assert 'dash.html' not in sys.modules\n"
        "assert 'dash' not in sys.modules, 'the stand-in left behind'\n"
        "dp = sys.modules['open3d.visualization.draw_plotly']\n"
        "import dash\n"
        "assert dp.html.Div is dash.html.Div and dp.dcc.Graph is dash.dcc.Graph and dp.Dash._target() is dash.Dash\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]
