"""Speed and memory work of issue 21 that must not change a result: same values, same bytes, no dense arrays.

Speed itself is measured by ``benchmarks/profile_run.py`` and ``benchmarks/peers.py``, not here.
"""

from __future__ import annotations

import struct
import warnings
import zlib

import numpy as np

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

    from o3d_seqcc.io.files import read_image

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


def test_colour_samples_from_uint8_are_the_float_samples():
    """The colour sampling of seqcc-global reads uint8 / uint16 photos directly, bit for bit the float path."""
    from o3d_seqcc.correction.methods.edge_summaries import _sample_flat, _sample_levels
    from o3d_seqcc.imaging.arrays import img_as_float

    rng = np.random.default_rng(1)
    for dtype, top in ((np.uint8, 256), (np.uint16, 65536)):
        img = rng.integers(0, top, (37, 53, 3)).astype(dtype)
        uv = np.concatenate([rng.uniform(-2, 55, (500, 2)), [[0, 0], [52, 36], [52.5, 36.7], [51.999, 35.2]]])
        for interp in ("bilinear", "nearest"):
            want = _sample_flat(img_as_float(img), uv, interp)
            got = _sample_levels(img, uv, interp)
            assert got.dtype == want.dtype == np.float32
            assert np.array_equal(got, want), (dtype, interp)


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
