"""glTF 2.0 binary (GLB): one mesh, the atlas pages embedded as ``baseColorTexture``.

glTF's texture coordinates have their origin at the top-left (the first pixel of the image), so
``TEXCOORD_0 = (u, 1 - v)`` of ``TexturedMesh.uv``'s bottom-left convention. The GLB holds one mesh
with one primitive per page (POSITION, NORMAL, TEXCOORD_0, uint32 indices; the primitives share one
vertex buffer), one material per page (``baseColorTexture`` = the embedded image, ``metallicFactor``
0, ``roughnessFactor`` 1, optionally ``KHR_materials_unlit``), a sampler with linear mip-mapped
filtering and clamp-to-edge wrapping; WebP textures go through the ``EXT_texture_webp`` extension
(required). Positions are float32: far from the origin they are stored relative to the node's
``translation`` (the bounding box's centre, :func:`~o3d_seqcc.geometry.meshops.float32_offset`).
Every bufferView starts on a 4-byte boundary and both chunks are padded as the specification
requires (JSON with spaces, BIN with zeros). It passes the Khronos glTF-Validator without errors or
warnings (see ``tests/io/test_export.py``).
"""

from __future__ import annotations

import json
import logging
import os
import struct
from pathlib import Path
from typing import Any

import numpy as np

from ...geometry.meshops import float32_offset
from ..atomic import atomic_path
from .common import _check, _face_page, _geometry, _page_uv
from .textures import TEXTURE_FORMATS, _check_format, _encoded_pages, _given_pages

__all__ = ["export_glb", "glb_bytes"]

logger = logging.getLogger(__name__)


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
    encoded = _given_pages(encoded, png, fmt)
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

    Examples
    --------
    >>> import tempfile, o3d_seqcc as sc
    >>> room = sc.make_synthetic_scene(tempfile.mkdtemp() + '/room', n_views=3, width=96, height=72, seed=1,
    ...                                seen_only=True)
    >>> tm = sc.pipeline.texture(room.scene, atlas_size=512, seams=False).textured
    >>> path = sc.export_glb(tm, room.root / 'mesh.glb')
    >>> path.read_bytes()[:4]
    b'glTF'
    """
    path = Path(path)
    parts = _glb_parts(textured, unlit=unlit, png_compression=png_compression, png=png, texture_format=texture_format,
                       quality=quality, transform=transform, encoded=encoded)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:  # part by part: the textures' bytes are not copied
        for b in parts:
            fh.write(b)
    logger.info("wrote %s", path)
    return path
