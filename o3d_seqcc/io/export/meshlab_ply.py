"""MeshLab's own textured PLY: per-face texture coordinates and ``TextureFile`` comments.

MeshLab projects (:mod:`o3d_seqcc.io.meshlab`, written by :mod:`o3d_seqcc.run_folder`) get their textured
mesh in this layout; the vertex block is :mod:`o3d_seqcc.io.export.ply`'s, positions optionally minus an
``offset`` the project's layer matrix adds back.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError
from ..atomic import atomic_write_bytes
from .common import _check, _face_page, _page_uv
from .ply import _ply_vertices
from .textures import _encoded_pages, _given_pages, texture_file_names

__all__ = ["export_meshlab_ply"]

logger = logging.getLogger(__name__)


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
        data = _encoded_pages(textured, "png", 90, png_compression, _given_pages(None, png if pages == 1 else None, "png"))
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
