"""Export of a :class:`~o3d_seqcc.texturing.TexturedMesh`: OBJ + MTL + PNG, glTF 2.0 binary (GLB), PLY.

MeshLab projects get a textured PLY in MeshLab's own layout (:func:`export_meshlab_ply`).

UV conventions. ``TexturedMesh.uv`` has its origin at the bottom-left corner of the atlas with
v up (the OBJ convention, see :mod:`o3d_seqcc.texturing.textured_mesh`).

- OBJ/MTL: the same convention, so ``vt = (u, v)``.
- glTF 2.0: origin top-left (the first pixel of the image), so ``TEXCOORD_0 = (u, 1 - v)``.

Every file is written atomically (temporary file in the destination folder, then rename), and
for OBJ the texture and material are written before the ``.obj`` that refers to them.

The GLB holds one mesh with one primitive (POSITION, NORMAL, TEXCOORD_0, uint32 indices), one
material (``baseColorTexture`` = the embedded PNG, ``metallicFactor`` 0, ``roughnessFactor`` 1,
optionally ``KHR_materials_unlit``), a sampler with linear mip-mapped filtering and
clamp-to-edge wrapping; every bufferView starts on a 4-byte boundary and both chunks are padded
as the specification requires (JSON with spaces, BIN with zeros). It passes the Khronos
glTF-Validator without errors (see ``tests/test_export.py``).
"""

from __future__ import annotations

import json
import logging
import os
import struct
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from .errors import InputError
from .imageops import sample_bilinear
from .io.files import atomic_write_bytes
from .meshops import vertex_normals

__all__ = [
    "FORMATS", "encode_png", "export_glb", "export_meshlab_ply", "export_obj", "export_ply", "export_textured_mesh",
]

logger = logging.getLogger(__name__)

#: formats known to :func:`export_textured_mesh`
FORMATS = ("glb", "obj", "ply")


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


def encode_png(image: np.ndarray, *, compression: int = 1) -> bytes:
    """PNG bytes of an (H, W, 3) uint8 RGB image (OpenCV encoder; ``compression`` 0-9)."""
    import cv2

    ok, buf = cv2.imencode(".png", np.ascontiguousarray(image[..., ::-1]), [cv2.IMWRITE_PNG_COMPRESSION, int(compression)])
    if not ok:  # pragma: no cover
        raise OSError("OpenCV could not encode the texture as PNG")
    return buf.tobytes()


def _normals(textured: Any) -> np.ndarray:
    """(M, 3) unit normals: the mesh's where usable, else area-weighted face normals."""
    return vertex_normals(textured.vertices, textured.faces, getattr(textured, "normals", None))


def _fmt_rows(prefix: str, a: np.ndarray, fmt: str) -> str:
    if len(a) == 0:
        return ""
    row = prefix + " " + " ".join([fmt] * a.shape[1]) + "\n"
    return (row * len(a)) % tuple(a.ravel().tolist())


def export_obj(textured: Any, path: str | os.PathLike, *, png_compression: int = 1, png: bytes | None = None) -> Path:
    """Write ``path`` (.obj) with ``<stem>.mtl`` and ``<stem>.png`` next to it.

    Parameters
    ----------
    textured : TexturedMesh
        ``vertices`` (M, 3), ``faces`` (F, 3), ``uv`` (M, 2) bottom-left origin, ``texture``
        (S, S, 3) uint8, optionally ``normals`` (M, 3).
    path : path-like
        Destination ``.obj``.
    png_compression : int, default 1
        zlib level of the PNG (0-9; 1 is fast and close in size).
    png : bytes, optional
        Already encoded texture (:func:`encode_png`), to encode it once for several formats.

    Returns
    -------
    pathlib.Path
        The OBJ path.
    """
    _check(textured)
    path = Path(path)
    stem = path.stem
    png_name, mtl_name = f"{stem}.png", f"{stem}.mtl"
    if png is None:
        png = encode_png(textured.texture, compression=png_compression)
    atomic_write_bytes(path.with_name(png_name), png)
    mtl = (
        "# o3d_seqcc texture atlas\n"
        "newmtl material_0\n"
        "Ka 1.000000 1.000000 1.000000\nKd 1.000000 1.000000 1.000000\nKs 0.000000 0.000000 0.000000\n"
        f"d 1.0\nillum 1\nmap_Kd {png_name}\n"
    )
    atomic_write_bytes(path.with_name(mtl_name), mtl.encode("utf-8"))
    vt = np.asarray(textured.uv, dtype=np.float64)
    f1 = np.asarray(textured.faces, dtype=np.int64) + 1
    fidx = np.repeat(f1, 3, axis=1)  # a/a/a b/b/b c/c/c
    parts = [
        "# o3d_seqcc textured mesh\n",
        f"mtllib {mtl_name}\n",
        _fmt_rows("v", np.asarray(textured.vertices, dtype=np.float64), "%.9g"),
        _fmt_rows("vt", vt, "%.7f"),
        _fmt_rows("vn", _normals(textured), "%.5f"),
        "usemtl material_0\n",
        (("f" + " %d/%d/%d" * 3 + "\n") * len(fidx)) % tuple(fidx.ravel().tolist()),
    ]
    atomic_write_bytes(path, "".join(parts).encode("ascii"))
    logger.info("wrote %s (+ %s, %s)", path, mtl_name, png_name)
    return path


def _pad4(b: bytes, fill: bytes = b"\x00") -> bytes:
    return b + fill * ((-len(b)) % 4)


def glb_bytes(textured: Any, *, unlit: bool = False, png_compression: int = 1, png: bytes | None = None) -> bytes:
    """The GLB file content of a textured mesh (see :func:`export_glb`)."""
    _check(textured)
    pos = np.ascontiguousarray(textured.vertices, dtype=np.float32)
    nrm = np.ascontiguousarray(_normals(textured), dtype=np.float32)
    # float32 rounding can leave |n| a hair off 1; renormalise in float32
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    uv = np.ascontiguousarray(np.stack([textured.uv[:, 0], 1.0 - textured.uv[:, 1]], axis=1), dtype=np.float32)
    idx = np.ascontiguousarray(textured.faces, dtype=np.uint32).reshape(-1)
    if png is None:
        png = encode_png(textured.texture, compression=png_compression)
    blobs: list[bytes] = []
    views: list[dict] = []
    offset = 0

    def add_view(data: bytes, target: int | None) -> int:
        nonlocal offset
        view = {"buffer": 0, "byteOffset": offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        views.append(view)
        padded = _pad4(data)
        blobs.append(padded)
        offset += len(padded)
        return len(views) - 1

    v_pos = add_view(pos.tobytes(), 34962)
    v_nrm = add_view(nrm.tobytes(), 34962)
    v_uv = add_view(uv.tobytes(), 34962)
    v_idx = add_view(idx.tobytes(), 34963)
    v_png = add_view(png, None)
    n = len(pos)
    accessors = [
        {"bufferView": v_pos, "componentType": 5126, "count": n, "type": "VEC3",
         "min": pos.min(axis=0).astype(float).tolist(), "max": pos.max(axis=0).astype(float).tolist()},
        {"bufferView": v_nrm, "componentType": 5126, "count": n, "type": "VEC3"},
        {"bufferView": v_uv, "componentType": 5126, "count": n, "type": "VEC2"},
        {"bufferView": v_idx, "componentType": 5125, "count": int(idx.size), "type": "SCALAR"},
    ]
    material: dict[str, Any] = {
        "name": "atlas",
        "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "doubleSided": False,
    }
    gltf: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": "o3d_seqcc"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "textured_mesh"}],
        "meshes": [{"name": "textured_mesh", "primitives": [
            {"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3, "material": 0, "mode": 4}
        ]}],
        "materials": [material],
        "textures": [{"sampler": 0, "source": 0}],
        "samplers": [{"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071}],
        "images": [{"bufferView": v_png, "mimeType": "image/png"}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": offset}],
    }
    if unlit:
        material["extensions"] = {"KHR_materials_unlit": {}}
        gltf["extensionsUsed"] = ["KHR_materials_unlit"]
    js = _pad4(json.dumps(gltf, separators=(",", ":")).encode("utf-8"), b" ")
    binc = b"".join(blobs)
    total = 12 + 8 + len(js) + 8 + len(binc)
    out = bytearray()
    out += struct.pack("<4sII", b"glTF", 2, total)
    out += struct.pack("<I4s", len(js), b"JSON") + js
    out += struct.pack("<I4s", len(binc), b"BIN\x00") + binc
    return bytes(out)


def export_glb(
    textured: Any, path: str | os.PathLike, *, unlit: bool = False, png_compression: int = 1, png: bytes | None = None
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
        Already encoded texture (:func:`encode_png`).

    Returns
    -------
    pathlib.Path
    """
    path = Path(path)
    atomic_write_bytes(path, glb_bytes(textured, unlit=unlit, png_compression=png_compression, png=png))
    logger.info("wrote %s", path)
    return path


def _ply_vertices(textured: Any, colours: np.ndarray | None) -> tuple[str, bytes]:
    """PLY header lines and binary block of the vertices: x y z nx ny nz [red green blue] (float32, uint8)."""
    n = _normals(textured)
    fields = [(k, "<f4") for k in ("x", "y", "z", "nx", "ny", "nz")]
    if colours is not None:
        fields += [(k, "u1") for k in ("red", "green", "blue")]
    va = np.empty(len(textured.vertices), dtype=np.dtype(fields))
    for i, k in enumerate("xyz"):
        va[k] = textured.vertices[:, i]
        va["n" + k] = n[:, i]
    if colours is not None:
        c8 = np.clip(np.rint(colours), 0, 255).astype(np.uint8)
        va["red"], va["green"], va["blue"] = c8[:, 0], c8[:, 1], c8[:, 2]
    header = f"element vertex {len(va)}\n" + "".join(
        f"property {'float' if t == '<f4' else 'uchar'} {k}\n" for k, t in fields)
    return header, va.tobytes()


def export_ply(textured: Any, path: str | os.PathLike) -> Path:
    """Write a binary PLY with per-vertex colours sampled from the atlas (bilinear).

    Vertices are the textured mesh's (duplicated along chart borders), so colours stay exact at
    every vertex; detail inside a face is lost (vertex colours are interpolated).
    """
    _check(textured)
    path = Path(path)
    col = sample_bilinear(textured.texture, *textured.texel_xy().T)
    vheader, vblock = _ply_vertices(textured, col)
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
    texture: str | os.PathLike | None = None,
    png_compression: int = 1,
    png: bytes | None = None,
) -> Path:
    """Write MeshLab's own textured PLY: per-face texture coordinates and a ``TextureFile`` comment.

    This is the layout MeshLab writes when it saves a textured mesh as PLY (``element face`` with
    ``vertex_indices`` and a ``texcoord`` list of 6 floats per face, the texture named in a
    ``comment TextureFile`` header line), and the textured format every MeshLab version reads:
    MeshLab 2020.09, the version in Debian 12 and Ubuntu 22.04-24.04, aborts on any OBJ file
    (an assertion in its OBJ importer, Debian bug 1054006). Texture coordinates keep the OBJ
    convention (origin bottom-left, v up), as MeshLab's.

    Parameters
    ----------
    textured : TexturedMesh
        ``vertices`` (M, 3), ``faces`` (F, 3), ``uv`` (M, 2), ``texture`` (S, S, 3) uint8.
    path : path-like
        Destination ``.ply``.
    texture : path-like, optional
        An existing image file holding ``textured.texture`` (e.g. the OBJ's PNG) to refer to;
        by default ``<stem>.png`` is written next to ``path``.
    png_compression : int, default 1
    png : bytes, optional
        Already encoded texture (:func:`encode_png`), when ``texture`` is not given.

    Returns
    -------
    pathlib.Path
        The PLY path.
    """
    _check(textured)
    path = Path(path)
    if texture is None:
        texture = path.with_suffix(".png")
        atomic_write_bytes(texture, png if png is not None else encode_png(textured.texture, compression=png_compression))
    elif not Path(texture).is_file():
        raise InputError(f"texture: {texture} does not exist; write the texture first or pass texture=None")
    tex_name = Path(os.path.relpath(Path(texture).resolve(), path.parent.resolve())).as_posix()
    if any(c in tex_name for c in "\r\n"):
        raise InputError(f"texture: the file name {tex_name!r} cannot go into a PLY header")
    vheader, vblock = _ply_vertices(textured, None)
    fdt = np.dtype([("n", "u1"), ("i", "<i4", (3,)), ("m", "u1"), ("t", "<f4", (6,))])
    fa = np.empty(len(textured.faces), dtype=fdt)
    fa["n"], fa["m"] = 3, 6
    fa["i"] = textured.faces
    fa["t"] = np.asarray(textured.uv, dtype=np.float64)[textured.faces].reshape(-1, 6)
    header = (
        f"ply\nformat binary_little_endian 1.0\ncomment o3d_seqcc textured mesh\ncomment TextureFile {tex_name}\n"
        f"{vheader}element face {len(fa)}\nproperty list uchar int vertex_indices\n"
        "property list uchar float texcoord\nend_header\n"
    )
    atomic_write_bytes(path, header.encode("utf-8") + vblock + fa.tobytes())
    logger.info("wrote %s (texture %s)", path, tex_name)
    return path


_WRITERS = {"glb": ("mesh.glb", export_glb), "obj": ("mesh.obj", export_obj), "ply": ("mesh_colors.ply", export_ply)}


def export_textured_mesh(
    textured: Any,
    out_dir: str | os.PathLike,
    *,
    formats: Iterable[str] = ("glb", "obj"),
    stem: str = "mesh",
    unlit: bool = False,
) -> dict[str, Path]:
    """Write ``out_dir/<stem>.glb``, ``<stem>.obj`` (+ .mtl, .png), ``<stem>_colors.ply`` as asked.

    The PNG is encoded once for GLB and OBJ.

    Parameters
    ----------
    formats : iterable of {"glb", "obj", "ply"}, default ("glb", "obj")
    stem : str, default "mesh"
    unlit : bool, default False
        GLB material with ``KHR_materials_unlit``.

    Returns
    -------
    dict
        Format -> written path.
    """
    fmts = [f.strip().lower() for f in formats if f.strip()]
    bad = [f for f in fmts if f not in _WRITERS]
    if bad or not fmts:
        raise InputError(f"unknown export format(s) {bad or fmts}; valid: {', '.join(FORMATS)}")
    out_dir = Path(out_dir)
    out: dict[str, Path] = {}
    png = encode_png(textured.texture) if {"glb", "obj"} & set(fmts) else None
    for f in dict.fromkeys(fmts):
        name, fn = _WRITERS[f]
        kw: dict[str, Any] = {"png": png} if f in ("glb", "obj") else {}
        if f == "glb" and unlit:
            kw["unlit"] = True
        out[f] = fn(textured, out_dir / name.replace("mesh", stem, 1), **kw)
    return out
