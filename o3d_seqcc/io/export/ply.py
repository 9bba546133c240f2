"""Binary PLY with per-vertex colours sampled from the atlas, and the vertex block MeshLab's PLY shares.

Positions are ``double`` when float32 would not hold them (far from the origin:
:func:`~o3d_seqcc.geometry.meshops.float32_offset`), else ``float``; normals ``float``, colours
``uchar``. The file is written atomically.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from ...geometry.meshops import float32_offset
from ...imaging.arrays import sample_bilinear
from ..atomic import atomic_write_bytes
from .common import _check, _geometry

__all__ = ["export_ply"]

logger = logging.getLogger(__name__)


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
