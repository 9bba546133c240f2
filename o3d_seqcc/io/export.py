"""Export of a :class:`~o3d_seqcc.texturing.TexturedMesh`: OBJ + MTL + textures, glTF 2.0 binary (GLB), PLY.

MeshLab projects get a textured PLY in MeshLab's own layout (:func:`export_meshlab_ply`).

UV conventions. ``TexturedMesh.uv`` has its origin at the bottom-left corner of the atlas with
v up (the OBJ convention, see :mod:`o3d_seqcc.texturing.textured_mesh`).

- OBJ/MTL: the same convention, so ``vt = (u, v)``.
- glTF 2.0: origin top-left (the first pixel of the image), so ``TEXCOORD_0 = (u, 1 - v)``.

An atlas of several pages (``TexturedMesh.pages``) is written as one texture file per page: one
material and one primitive per page in the GLB (the primitives share one vertex buffer), one
``usemtl`` per page in the OBJ, ``TextureFile`` comments and a per-face ``texnumber`` in MeshLab's
PLY. Textures are PNG (lossless), JPEG (``quality``) or WebP (``quality``; in the GLB through the
``EXT_texture_webp`` extension, required). ``transform`` (a 3 x 3 rotation, e.g. from
:func:`o3d_seqcc.geometry.orientation.up_axis_transform`) is applied to positions and normals.

Far from the origin (geo-referenced scans: UTM-like coordinates of 1e5-1e7 m) the files keep the
input's frame at full precision: OBJ writes as many digits as the coordinates need, PLY writes
``double`` positions, and the GLB, whose positions are float32, stores them relative to the
node's ``translation`` (the bounding box's centre, :func:`float32_offset`). MeshLab's PLY layer
(:func:`export_meshlab_ply`) takes an ``offset`` the project's layer matrix adds back.

Every file is written atomically (temporary file in the destination folder, then rename), and
for OBJ the textures and material are written before the ``.obj`` that refers to them.

The GLB holds one mesh with one primitive per page (POSITION, NORMAL, TEXCOORD_0, uint32
indices), one material per page (``baseColorTexture`` = the embedded image, ``metallicFactor`` 0,
``roughnessFactor`` 1, optionally ``KHR_materials_unlit``), a sampler with linear mip-mapped
filtering and clamp-to-edge wrapping; every bufferView starts on a 4-byte boundary and both
chunks are padded as the specification requires (JSON with spaces, BIN with zeros). It passes
the Khronos glTF-Validator without errors or warnings (see ``tests/io/test_export.py``).
"""

from __future__ import annotations

import itertools
import json
import logging
import os
import struct
from pathlib import Path
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, Iterable

import numpy as np

from ..errors import InputError
from ..imaging.arrays import sample_bilinear
from .atomic import atomic_path, atomic_write_bytes
from .obj_text import obj_lines
from ..geometry.meshops import float32_offset, vertex_normals
from ..geometry.orientation import UP_AXES

__all__ = [
    "DEFAULT_FORMATS", "EXPORT_UP_AXES", "FORMATS", "TEXTURE_FORMATS", "check_export_options", "encode_png", "encode_texture",
    "export_glb", "export_meshlab_ply", "export_obj", "export_ply", "export_textured_mesh", "float32_offset",
    "parse_formats", "texture_file_names", "FILE_SUFFIXES",
]

logger = logging.getLogger(__name__)

#: formats known to :func:`export_textured_mesh`
FORMATS = ("glb", "obj", "ply")
#: texture image formats: name -> (file extension, MIME type)
TEXTURE_FORMATS = {"png": ("png", "image/png"), "jpg": ("jpg", "image/jpeg"), "webp": ("webp", "image/webp")}
#: ``up_axis`` of the exports: the orientation's axes, and "auto" (:meth:`o3d_seqcc.pipeline.RunResult.save`)
EXPORT_UP_AXES = ("auto", *UP_AXES)
#: export formats written by default (:meth:`o3d_seqcc.pipeline.RunResult.save`)
DEFAULT_FORMATS = ("glb", "obj")


def parse_formats(formats: str | Iterable[str]) -> list[str]:
    """``"glb,obj"`` or ``["glb", "obj"]`` -> ``["glb", "obj"]``; unknown names raise InputError listing the valid ones."""
    items = formats.split(",") if isinstance(formats, str) else list(formats)
    out = list(dict.fromkeys(str(f).strip().lower() for f in items if str(f).strip()))
    bad = [f for f in out if f not in FORMATS]
    if bad or not out:
        raise InputError(f"unknown export format(s) {bad or formats!r}; valid: {', '.join(FORMATS)}")
    return out


def check_export_options(*, up_axis: str = "y", texture_format: str = "png", jpeg_quality: int = 90) -> str:
    """Validate :meth:`o3d_seqcc.pipeline.RunResult.save`'s export options (the command line calls it before any work).

    Returns the texture format's canonical name; raises InputError naming the bad option.
    """
    if str(up_axis).lower() not in EXPORT_UP_AXES:
        raise InputError(f"unknown up axis {up_axis!r}; valid: {', '.join(EXPORT_UP_AXES)}")
    fmt = "jpg" if str(texture_format).lower() == "jpeg" else str(texture_format).lower()
    if fmt not in TEXTURE_FORMATS:
        raise InputError(f"unknown texture format {texture_format!r}; valid: {', '.join(TEXTURE_FORMATS)}")
    if isinstance(jpeg_quality, bool) or int(jpeg_quality) != jpeg_quality or not 1 <= int(jpeg_quality) <= 100:
        raise InputError(f"jpeg_quality must be an integer in 1..100, got {jpeg_quality!r}")
    return fmt


def _check(textured: Any) -> None:
    for name in ("vertices", "faces", "uv", "texture"):
        if getattr(textured, name, None) is None:
            raise InputError(f"export: the textured mesh has no {name!r}")
    v, f, uv, tex = textured.vertices, textured.faces, textured.uv, textured.texture
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or uv.shape != (len(v), 2):
        raise InputError(f"export: inconsistent shapes vertices {v.shape}, faces {f.shape}, uv {uv.shape}")
    if len(f) == 0:
        raise InputError("export: the mesh has no faces")
    if f.min() < 0 or f.max() >= len(v):
        raise InputError("export: face indices outside the vertex array")
    if tex.ndim != 3 or tex.shape[2] != 3 or tex.dtype != np.uint8:
        raise InputError(f"export: texture must be (H, W, 3) uint8, got {tex.shape} {tex.dtype}")
    pages = int(getattr(textured, "pages", 1))
    if pages < 1 or tex.shape[0] % pages:
        raise InputError(f"export: a texture of {tex.shape[0]} rows cannot hold {pages} pages")


def _check_format(texture_format: str, quality: int) -> str:
    fmt = "jpg" if str(texture_format).lower() == "jpeg" else str(texture_format).lower()
    if fmt not in TEXTURE_FORMATS:
        raise InputError(f"unknown texture format {texture_format!r}; valid: {', '.join(TEXTURE_FORMATS)}")
    if isinstance(quality, bool) or int(quality) != quality or not 1 <= int(quality) <= 100:
        raise InputError(f"texture quality must be an integer in 1..100, got {quality!r}")
    return fmt


def encode_png(image: np.ndarray, *, compression: int = 1) -> bytes:
    """PNG bytes of an (H, W, 3) uint8 RGB image (OpenCV encoder; ``compression`` 0-9)."""
    import cv2

    ok, buf = cv2.imencode(".png", np.ascontiguousarray(image[..., ::-1]), [cv2.IMWRITE_PNG_COMPRESSION, int(compression)])
    if not ok:  # pragma: no cover
        raise OSError("OpenCV could not encode the texture as PNG")
    return buf.tobytes()


def encode_texture(image: np.ndarray, texture_format: str = "png", *, quality: int = 90,
                   png_compression: int = 1) -> bytes:
    """Bytes of an (H, W, 3) uint8 RGB image as PNG, JPEG or WebP (OpenCV encoders).

    Parameters
    ----------
    texture_format : {"png", "jpg", "webp"}
    quality : int, default 90
        JPEG / WebP quality (1-100); PNG is lossless.
    png_compression : int, default 1
        zlib level of a PNG (0-9).
    """
    import cv2

    fmt = _check_format(texture_format, quality)
    if fmt == "png":
        return encode_png(image, compression=png_compression)
    flag = cv2.IMWRITE_JPEG_QUALITY if fmt == "jpg" else cv2.IMWRITE_WEBP_QUALITY
    ok, buf = cv2.imencode(f".{fmt}", np.ascontiguousarray(image[..., ::-1]), [flag, int(quality)])
    if not ok:  # pragma: no cover
        raise OSError(f"OpenCV could not encode the texture as {fmt}")
    return buf.tobytes()


def _encoded_pages(textured: Any, texture_format: str, quality: int, png_compression: int,
                   encoded: list[bytes] | Callable[[], list[bytes]] | None) -> list[bytes]:
    if encoded is not None:  # given, or being encoded on another thread (a callable waiting for it)
        return list(encoded() if callable(encoded) else encoded)
    return [encode_texture(p, texture_format, quality=quality, png_compression=png_compression)
            for p in _pages(textured)]


def _pages(textured: Any) -> list[np.ndarray]:
    tex = textured.texture
    n = int(getattr(textured, "pages", 1))
    h = tex.shape[0] // n
    return [tex[p * h:(p + 1) * h] for p in range(n)]


def _face_page(textured: Any) -> np.ndarray:
    fp = getattr(textured, "face_page", None)
    return fp() if callable(fp) else np.zeros(len(textured.faces), dtype=np.int64)


def _page_uv(textured: Any) -> np.ndarray:
    pu = getattr(textured, "page_uv", None)
    return np.asarray(pu() if callable(pu) else textured.uv, dtype=np.float64)


def _normals(textured: Any) -> np.ndarray:
    """(M, 3) unit normals: the mesh's where usable, else area-weighted face normals."""
    return vertex_normals(textured.vertices, textured.faces, getattr(textured, "normals", None))


def _digits(verts: np.ndarray) -> int:
    """Significant digits an OBJ needs for these positions: 9 near the origin, more far from it (up to 17)."""
    if not len(verts):
        return 9
    size = float(np.max(np.ptp(verts, axis=0)))
    far = float(np.max(np.abs(verts)))
    return int(min(17, 9 + max(0, int(np.ceil(np.log10(max(far / max(size, 1e-12), 1.0)))))))


def _geometry(textured: Any, transform: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Positions and unit normals with ``transform`` (3 x 3) applied."""
    v = np.asarray(textured.vertices, dtype=np.float64)
    n = _normals(textured)
    if transform is not None:
        R = np.asarray(transform, dtype=np.float64)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise InputError(f"export: transform must be a 3 x 3 rotation, got {R.tolist()}")
        v, n = v @ R.T, n @ R.T
    return v, n


def texture_file_names(stem: str, texture_format: str, pages: int) -> list[str]:
    """The texture files :func:`export_obj` writes next to ``<stem>.obj``: ``<stem>.png``, or ``<stem>_<page>.png``."""
    ext = TEXTURE_FORMATS[_check_format(texture_format, 90)][0]
    return [f"{stem}.{ext}"] if pages == 1 else [f"{stem}_{p}.{ext}" for p in range(pages)]


def export_obj(
    textured: Any, path: str | os.PathLike, *, png_compression: int = 1, png: bytes | None = None,
    texture_format: str = "png", quality: int = 90, transform: np.ndarray | None = None,
    encoded: list[bytes] | None = None,
) -> Path:
    """Write ``path`` (.obj) with ``<stem>.mtl`` and the texture(s) next to it.

    Parameters
    ----------
    textured : TexturedMesh
        ``vertices`` (M, 3), ``faces`` (F, 3), ``uv`` (M, 2) bottom-left origin, ``texture``
        (S, S, 3) uint8 (pages stacked vertically when ``pages`` > 1), optionally ``normals``.
    path : path-like
        Destination ``.obj``.
    png_compression : int, default 1
        zlib level of a PNG (0-9; 1 is fast and close in size).
    png : bytes, optional
        Already encoded single-page PNG texture (:func:`encode_png`).
    texture_format : {"png", "jpg", "webp"}, default "png"
        ``<stem>.png`` (``<stem>_<page>.png`` for several pages), or JPEG / WebP.
    quality : int, default 90
        JPEG / WebP quality.
    transform : (3, 3) float, optional
        Rotation applied to positions and normals.
    encoded : list of bytes, or a callable returning it, optional
        Already encoded textures, one per page, in ``texture_format`` (a callable is called once the
        OBJ's text is written: the textures may be encoded meanwhile).

    Returns
    -------
    pathlib.Path
        The OBJ path (written after its textures and material).
    """
    _check(textured)
    fmt = _check_format(texture_format, quality)
    path = Path(path)
    stem = path.stem
    if png is not None and encoded is None and fmt == "png":
        encoded = [png]
    n_pages = len(encoded) if isinstance(encoded, (list, tuple)) else int(getattr(textured, "pages", 1))
    names = texture_file_names(stem, fmt, n_pages)
    mtl_name = f"{stem}.mtl"
    verts, normals = _geometry(textured, transform)
    head = f"# o3d_seqcc textured mesh\nmtllib {mtl_name}\n".encode("ascii")
    with atomic_path(path) as tmp:  # the text first (while the textures may still be encoded), renamed last
        with open(tmp, "wb") as fh:
            for b in itertools.chain([head], obj_lines(verts, _page_uv(textured), normals,
                                                       np.asarray(textured.faces, dtype=np.int64),
                                                       _face_page(textured), len(names), digits=_digits(verts))):
                fh.write(b)
        images = _encoded_pages(textured, fmt, quality, png_compression, encoded)
        for name, data in zip(names, images):
            atomic_write_bytes(path.with_name(name), data)
        mtl = "# o3d_seqcc texture atlas\n" + "".join(
            f"newmtl material_{p}\n"
            "Ka 1.000000 1.000000 1.000000\nKd 1.000000 1.000000 1.000000\nKs 0.000000 0.000000 0.000000\n"
            f"d 1.0\nillum 1\nmap_Kd {name}\n" for p, name in enumerate(names))
        atomic_write_bytes(path.with_name(mtl_name), mtl.encode("utf-8"))
    logger.info("wrote %s (+ %s, %s)", path, mtl_name, ", ".join(names))
    return path


def _pad4(b: bytes, fill: bytes = b"\x00") -> bytes:
    return b + fill * ((-len(b)) % 4)


def glb_bytes(
    textured: Any, *, unlit: bool = False, png_compression: int = 1, png: bytes | None = None,
    texture_format: str = "png", quality: int = 90, transform: np.ndarray | None = None,
    encoded: list[bytes] | None = None,
) -> bytes:
    """The GLB file content of a textured mesh (see :func:`export_glb`)."""
    return b"".join(_glb_parts(textured, unlit=unlit, png_compression=png_compression, png=png,
                               texture_format=texture_format, quality=quality, transform=transform, encoded=encoded))


def _glb_parts(
    textured: Any, *, unlit: bool, png_compression: int, png: bytes | None, texture_format: str, quality: int,
    transform: np.ndarray | None, encoded: list[bytes] | None,
) -> list[bytes]:
    """The GLB file as consecutive parts (the textures' bytes among them as given, not copied)."""
    _check(textured)
    fmt = _check_format(texture_format, quality)
    if png is not None and encoded is None and fmt == "png":
        encoded = [png]
    images_data = _encoded_pages(textured, fmt, quality, png_compression, encoded)
    verts, normals = _geometry(textured, transform)
    shift = float32_offset(verts)  # float32 positions: relative to the node's translation when far away
    pos = np.ascontiguousarray(verts - shift, dtype=np.float32)
    nrm = np.ascontiguousarray(normals, dtype=np.float32)
    # float32 rounding can leave |n| a hair off 1; renormalise in float32
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    puv = _page_uv(textured)
    uv = np.ascontiguousarray(np.stack([puv[:, 0], 1.0 - puv[:, 1]], axis=1), dtype=np.float32)
    faces = np.asarray(textured.faces)
    face_page = _face_page(textured)
    blobs: list[bytes] = []
    views: list[dict] = []
    offset = 0

    def add_view(data: bytes, target: int | None) -> int:
        nonlocal offset
        view = {"buffer": 0, "byteOffset": offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        views.append(view)
        blobs.extend((data, b"\x00" * ((-len(data)) % 4)))
        offset += len(data) + (-len(data)) % 4
        return len(views) - 1

    n = len(pos)
    accessors: list[dict] = [
        {"bufferView": add_view(pos.tobytes(), 34962), "componentType": 5126, "count": n, "type": "VEC3",
         "min": pos.min(axis=0).astype(float).tolist(), "max": pos.max(axis=0).astype(float).tolist()},
        {"bufferView": add_view(nrm.tobytes(), 34962), "componentType": 5126, "count": n, "type": "VEC3"},
        {"bufferView": add_view(uv.tobytes(), 34962), "componentType": 5126, "count": n, "type": "VEC2"},
    ]
    mime = TEXTURE_FORMATS[fmt][1]
    primitives, materials, textures, images = [], [], [], []
    for p, data in enumerate(images_data):
        idx = np.ascontiguousarray(faces[face_page == p], dtype=np.uint32).reshape(-1)
        if idx.size == 0:
            continue
        accessors.append({"bufferView": add_view(idx.tobytes(), 34963), "componentType": 5125,
                          "count": int(idx.size), "type": "SCALAR"})
        images.append({"bufferView": add_view(data, None), "mimeType": mime})
        if fmt == "webp":
            textures.append({"sampler": 0, "extensions": {"EXT_texture_webp": {"source": len(images) - 1}}})
        else:
            textures.append({"sampler": 0, "source": len(images) - 1})
        material: dict[str, Any] = {
            "name": "atlas" if len(images_data) == 1 else f"atlas_{p}",
            "pbrMetallicRoughness": {"baseColorTexture": {"index": len(textures) - 1}, "metallicFactor": 0.0,
                                     "roughnessFactor": 1.0},
            "doubleSided": False,
        }
        if unlit:
            material["extensions"] = {"KHR_materials_unlit": {}}
        materials.append(material)
        primitives.append({"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": len(accessors) - 1,
                           "material": len(materials) - 1, "mode": 4})
    gltf: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": "o3d_seqcc"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "textured_mesh",
                   **({"translation": shift.tolist()} if shift.any() else {})}],
        "meshes": [{"name": "textured_mesh", "primitives": primitives}],
        "materials": materials,
        "textures": textures,
        "samplers": [{"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071}],
        "images": images,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": offset}],
    }
    used = (["KHR_materials_unlit"] if unlit else []) + (["EXT_texture_webp"] if fmt == "webp" else [])
    if used:
        gltf["extensionsUsed"] = used
    if fmt == "webp":
        gltf["extensionsRequired"] = ["EXT_texture_webp"]
    js = _pad4(json.dumps(gltf, separators=(",", ":")).encode("utf-8"), b" ")
    total = 12 + 8 + len(js) + 8 + offset
    return [struct.pack("<4sII", b"glTF", 2, total), struct.pack("<I4s", len(js), b"JSON"), js,
            struct.pack("<I4s", offset, b"BIN\x00"), *blobs]


def export_glb(
    textured: Any, path: str | os.PathLike, *, unlit: bool = False, png_compression: int = 1, png: bytes | None = None,
    texture_format: str = "png", quality: int = 90, transform: np.ndarray | None = None,
    encoded: list[bytes] | None = None,
) -> Path:
    """Write a glTF 2.0 binary (.glb) with the atlas embedded as ``baseColorTexture``.

    Parameters
    ----------
    textured : TexturedMesh
    path : path-like
        Destination ``.glb``.
    unlit : bool, default False
        Add ``KHR_materials_unlit`` (viewers then show the photo colours without shading);
        the material is otherwise metallic 0 / roughness 1.
    png_compression : int, default 1
    png : bytes, optional
        Already encoded single-page PNG texture (:func:`encode_png`).
    texture_format : {"png", "jpg", "webp"}, default "png"
        WebP is embedded through ``EXT_texture_webp`` (listed as required).
    quality : int, default 90
        JPEG / WebP quality.
    transform : (3, 3) float, optional
        Rotation applied to positions and normals (glTF is Y-up:
        :func:`o3d_seqcc.geometry.orientation.up_axis_transform`).
    encoded : list of bytes, optional
        Already encoded textures, one per page, in ``texture_format``.

    Returns
    -------
    pathlib.Path
    """
    path = Path(path)
    parts = _glb_parts(textured, unlit=unlit, png_compression=png_compression, png=png, texture_format=texture_format,
                       quality=quality, transform=transform, encoded=encoded)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:  # part by part: the textures' bytes are not copied
        for b in parts:
            fh.write(b)
    logger.info("wrote %s", path)
    return path


def _ply_vertices(textured: Any, colours: np.ndarray | None, transform: np.ndarray | None = None, *,
                  offset: np.ndarray | None = None) -> tuple[str, bytes]:
    """PLY header lines and binary block of the vertices: x y z nx ny nz [red green blue] (float32, uint8;
    x y z double when float32 would not hold them, :func:`float32_offset`), minus ``offset``."""
    verts, n = _geometry(textured, transform)
    if offset is not None:
        verts = verts - np.asarray(offset, dtype=np.float64)
    pos = "<f8" if float32_offset(verts).any() else "<f4"
    fields = [(k, pos) for k in ("x", "y", "z")] + [(k, "<f4") for k in ("nx", "ny", "nz")]
    if colours is not None:
        fields += [(k, "u1") for k in ("red", "green", "blue")]
    va = np.empty(len(verts), dtype=np.dtype(fields))
    for i, k in enumerate("xyz"):
        va[k] = verts[:, i]
        va["n" + k] = n[:, i]
    if colours is not None:
        c8 = np.clip(np.rint(colours), 0, 255).astype(np.uint8)
        va["red"], va["green"], va["blue"] = c8[:, 0], c8[:, 1], c8[:, 2]
    header = f"element vertex {len(va)}\n" + "".join(
        f"property {_PLY_TYPES[t]} {k}\n" for k, t in fields)
    return header, va.tobytes()


_PLY_TYPES = {"<f4": "float", "<f8": "double", "u1": "uchar"}


def export_ply(textured: Any, path: str | os.PathLike, *, transform: np.ndarray | None = None) -> Path:
    """Write a binary PLY with per-vertex colours sampled from the atlas (bilinear).

    Vertices are the textured mesh's (duplicated along chart borders), so colours stay exact at
    every vertex; detail inside a face is lost (vertex colours are interpolated). ``transform``
    (3 x 3) rotates positions and normals.
    """
    _check(textured)
    path = Path(path)
    col = sample_bilinear(textured.texture, *textured.texel_xy().T)
    vheader, vblock = _ply_vertices(textured, col, transform)
    fdt = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
    fa = np.empty(len(textured.faces), dtype=fdt)
    fa["n"] = 3
    fa["i"] = textured.faces
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment o3d_seqcc vertex colours from the texture atlas\n"
        f"{vheader}element face {len(fa)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    atomic_write_bytes(path, header.encode("ascii") + vblock + fa.tobytes())
    logger.info("wrote %s", path)
    return path


def export_meshlab_ply(
    textured: Any,
    path: str | os.PathLike,
    *,
    texture: str | os.PathLike | list | None = None,
    png_compression: int = 1,
    png: bytes | None = None,
    offset: np.ndarray | None = None,
) -> Path:
    """Write MeshLab's own textured PLY: per-face texture coordinates and ``TextureFile`` comments.

    This is the layout MeshLab writes when it saves a textured mesh as PLY (``element face`` with
    ``vertex_indices`` and a ``texcoord`` list of 6 floats per face, the texture named in a
    ``comment TextureFile`` header line; with several atlas pages one such line per page and an
    ``int texnumber`` per face), and the textured format every MeshLab version reads: MeshLab
    2020.09, the version in Debian 12 and Ubuntu 22.04-24.04, aborts on any OBJ file (an
    assertion in its OBJ importer, Debian bug 1054006). Texture coordinates keep the OBJ
    convention (origin bottom-left, v up), as MeshLab's. The mesh stays in the scene's frame (no
    up-axis transform: a MeshLab project's rasters must keep matching it).

    Parameters
    ----------
    textured : TexturedMesh
        ``vertices`` (M, 3), ``faces`` (F, 3), ``uv`` (M, 2), ``texture`` (S, S, 3) uint8
        (pages stacked vertically when ``pages`` > 1).
    path : path-like
        Destination ``.ply``.
    texture : path-like or list of path-like, optional
        Existing image file(s) holding the texture (one per page, e.g. the OBJ's) to refer to;
        by default ``<stem>.png`` (``<stem>_<page>.png``) is written next to ``path``.
    png_compression : int, default 1
    png : bytes, optional
        Already encoded single-page PNG texture (:func:`encode_png`), when ``texture`` is not given.
    offset : (3,) float, optional
        Subtracted from the positions (MeshLab holds them in float32: a project far from the
        origin places the layer with a matrix that adds it back).

    Returns
    -------
    pathlib.Path
        The PLY path.
    """
    _check(textured)
    path = Path(path)
    pages = int(getattr(textured, "pages", 1))
    if texture is None:
        names = texture_file_names(path.stem, "png", pages)
        data = [png] if png is not None and pages == 1 else _encoded_pages(textured, "png", 90, png_compression, None)
        files = [path.with_name(n) for n in names]
        for f, b in zip(files, data):
            atomic_write_bytes(f, b)
    else:
        files = [Path(t) for t in (texture if isinstance(texture, (list, tuple)) else [texture])]
        if len(files) != pages:
            raise InputError(f"texture: {len(files)} file(s) given for {pages} atlas page(s)")
        missing = [str(f) for f in files if not f.is_file()]
        if missing:
            raise InputError(f"texture: {missing[0]} does not exist; write the texture first or pass texture=None")
    tex_names = [Path(os.path.relpath(f.resolve(), path.parent.resolve())).as_posix() for f in files]
    if any(c in n for n in tex_names for c in "\r\n"):
        raise InputError(f"texture: the file names {tex_names!r} cannot go into a PLY header")
    vheader, vblock = _ply_vertices(textured, None, offset=offset)
    fields = [("n", "u1"), ("i", "<i4", (3,)), ("m", "u1"), ("t", "<f4", (6,))]
    if pages > 1:
        fields.append(("k", "<i4"))
    fa = np.empty(len(textured.faces), dtype=np.dtype(fields))
    fa["n"], fa["m"] = 3, 6
    fa["i"] = textured.faces
    fa["t"] = _page_uv(textured)[textured.faces].reshape(-1, 6)
    if pages > 1:
        fa["k"] = _face_page(textured)
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment o3d_seqcc textured mesh\n"
        + "".join(f"comment TextureFile {n}\n" for n in tex_names)
        + f"{vheader}element face {len(fa)}\nproperty list uchar int vertex_indices\n"
        "property list uchar float texcoord\n" + ("property int texnumber\n" if pages > 1 else "") + "end_header\n"
    )
    atomic_write_bytes(path, header.encode("utf-8") + vblock + fa.tobytes())
    logger.info("wrote %s (texture %s)", path, ", ".join(tex_names))
    return path


_WRITERS = {"glb": (".glb", export_glb), "obj": (".obj", export_obj), "ply": ("_colors.ply", export_ply)}
#: format -> what follows the stem in the name of the file :func:`export_textured_mesh` writes
FILE_SUFFIXES = {f: suffix for f, (suffix, _) in _WRITERS.items()}


def export_textured_mesh(
    textured: Any,
    out_dir: str | os.PathLike,
    *,
    formats: Iterable[str] = ("glb", "obj"),
    stem: str = "mesh",
    unlit: bool = False,
    texture_format: str = "png",
    quality: int = 90,
    transform: np.ndarray | None = None,
) -> dict[str, Path]:
    """Write ``out_dir/<stem>.glb``, ``<stem>.obj`` (+ .mtl, textures), ``<stem>_colors.ply`` as asked.

    The textures are encoded once for GLB and OBJ, on a thread, while the OBJ's text is written.

    Parameters
    ----------
    formats : iterable of {"glb", "obj", "ply"}, default ("glb", "obj")
    stem : str, default "mesh"
    unlit : bool, default False
        GLB material with ``KHR_materials_unlit``.
    texture_format : {"png", "jpg", "webp"}, default "png"
    quality : int, default 90
        JPEG / WebP quality.
    transform : (3, 3) float, optional
        Rotation applied to the positions and normals of every file (e.g. to make the scene
        Y-up: :func:`o3d_seqcc.geometry.orientation.up_axis_transform`).

    Returns
    -------
    dict
        Format -> written path.
    """
    fmts = [f.strip().lower() for f in formats if f.strip()]
    bad = [f for f in fmts if f not in _WRITERS]
    if bad or not fmts:
        raise InputError(f"unknown export format(s) {bad or fmts}; valid: {', '.join(FORMATS)}")
    fmt = _check_format(texture_format, quality)
    out_dir = Path(out_dir)
    out: dict[str, Path] = dict.fromkeys(fmts)
    # the textures are encoded on a thread (OpenCV releases the interpreter) while the OBJ's text is formatted and
    # written; the GLB waits for them
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="o3d_seqcc-texture") if {"glb", "obj"} & set(fmts) \
        else None
    try:
        encoded = None if pool is None else pool.submit(_encoded_pages, textured, fmt, quality, 1, None).result
        for f in sorted(out, key=lambda f: f != "obj"):
            suffix, fn = _WRITERS[f]
            kw: dict[str, Any] = {"transform": transform}
            if f in ("glb", "obj"):
                kw.update(encoded=encoded, texture_format=fmt, quality=quality)
            if f == "glb" and unlit:
                kw["unlit"] = True
            out[f] = fn(textured, out_dir / f"{stem}{suffix}", **kw)
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
    return out
