"""OBJ + MTL + textures: ``<stem>.obj``, ``<stem>.mtl`` and one texture file per atlas page.

The OBJ keeps ``TexturedMesh.uv``'s convention (origin bottom-left, v up), so ``vt = (u, v)``; an
atlas of several pages is one ``material_<page>`` and one ``usemtl`` per page. Positions are
written with as many digits as they need (:func:`_digits`: far from the origin, geo-referenced
scans keep full precision). The text is formatted by numpy in chunks
(:func:`o3d_seqcc.io.export.obj_text.obj_lines`); the textures and the material are written before
the ``.obj`` that refers to them, every file atomically.
"""

from __future__ import annotations

import itertools
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import atomic_path, atomic_write_bytes
from .common import _check, _face_page, _geometry, _page_uv
from .obj_text import obj_lines
from .textures import _check_format, _encoded_pages, _given_pages, texture_file_names

__all__ = ["export_obj"]

logger = logging.getLogger(__name__)


def _digits(verts: np.ndarray) -> int:
    """Significant digits an OBJ needs for these positions: 9 near the origin, more far from it (up to 17)."""
    if not len(verts):
        return 9
    size = float(np.max(np.ptp(verts, axis=0)))
    far = float(np.max(np.abs(verts)))
    return int(min(17, 9 + max(0, int(np.ceil(np.log10(max(far / max(size, 1e-12), 1.0)))))))


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
    encoded = _given_pages(encoded, png, fmt)
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
