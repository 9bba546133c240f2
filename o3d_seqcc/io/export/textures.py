"""The exports' textures: the image formats, the encoder, the atlas pages and their file names.

An atlas of several pages (``TexturedMesh.pages``) is one (pages * S, S, 3) uint8 array, the pages
stacked vertically; each page is encoded on its own, as PNG (lossless), JPEG or WebP (``quality``),
by OpenCV. Every writer of the package (OBJ, GLB, MeshLab's PLY) takes its textures from here.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ...errors import InputError

__all__ = ["TEXTURE_FORMATS", "encode_png", "encode_texture", "texture_file_names"]

#: texture image formats: name -> (file extension, MIME type)
TEXTURE_FORMATS = {"png": ("png", "image/png"), "jpg": ("jpg", "image/jpeg"), "webp": ("webp", "image/webp")}


def _check_format(texture_format: str, quality: int) -> str:
    """The canonical name of ``texture_format`` ("jpeg" -> "jpg"); raises InputError on an unknown name or a
    ``quality`` outside 1..100."""
    fmt = "jpg" if str(texture_format).lower() == "jpeg" else str(texture_format).lower()
    if fmt not in TEXTURE_FORMATS:
        raise InputError(f"unknown texture format {texture_format!r}; valid: {', '.join(TEXTURE_FORMATS)}")
    if isinstance(quality, bool) or int(quality) != quality or not 1 <= int(quality) <= 100:
        raise InputError(f"texture quality must be an integer in 1..100, got {quality!r}")
    return fmt


def encode_texture(image: np.ndarray, texture_format: str = "png", *, quality: int = 90,
                   png_compression: int = 1) -> bytes:
    """Bytes of an (H, W, 3) uint8 RGB image as PNG, JPEG or WebP: the exports' one image encoder (OpenCV's).

    Parameters
    ----------
    image : (H, W, 3) uint8
        RGB (OpenCV is given it as BGR).
    texture_format : {"png", "jpg", "webp"}
        "jpeg" is "jpg"; anything else raises InputError.
    quality : int, default 90
        JPEG / WebP quality (1-100); PNG is lossless.
    png_compression : int, default 1
        zlib level of a PNG (0-9).

    Returns
    -------
    bytes
        The encoded file.
    """
    import cv2

    fmt = _check_format(texture_format, quality)
    if fmt == "png":
        flag, value = cv2.IMWRITE_PNG_COMPRESSION, png_compression
    else:
        flag, value = (cv2.IMWRITE_JPEG_QUALITY if fmt == "jpg" else cv2.IMWRITE_WEBP_QUALITY), quality
    ok, buf = cv2.imencode(f".{fmt}", np.ascontiguousarray(image[..., ::-1]), [flag, int(value)])
    if not ok:  # pragma: no cover
        raise OSError(f"OpenCV could not encode the texture as {'PNG' if fmt == 'png' else fmt}")
    return buf.tobytes()


def encode_png(image: np.ndarray, *, compression: int = 1) -> bytes:
    """PNG bytes of an (H, W, 3) uint8 RGB image (:func:`encode_texture`; ``compression`` 0-9)."""
    return encode_texture(image, "png", png_compression=compression)


def _given_pages(encoded: list[bytes] | Callable[[], list[bytes]] | None, png: bytes | None,
                 texture_format: str) -> list[bytes] | Callable[[], list[bytes]] | None:
    """The already encoded pages a writer was given: ``encoded``, else ``[png]`` for a PNG texture, else None."""
    if png is not None and encoded is None and texture_format == "png":
        return [png]
    return encoded


def _encoded_pages(textured: Any, texture_format: str, quality: int, png_compression: int,
                   encoded: list[bytes] | Callable[[], list[bytes]] | None) -> list[bytes]:
    """The atlas pages' files: ``encoded`` (a list, or a callable waiting for another thread's), else every page of
    ``textured.texture`` through :func:`encode_texture`."""
    if encoded is not None:  # given, or being encoded on another thread (a callable waiting for it)
        return list(encoded() if callable(encoded) else encoded)
    return [encode_texture(p, texture_format, quality=quality, png_compression=png_compression)
            for p in _pages(textured)]


def _pages(textured: Any) -> list[np.ndarray]:
    """The (S, S, 3) uint8 pages of ``textured.texture`` ((pages * S, S, 3), stacked vertically), as views."""
    tex = textured.texture
    n = int(getattr(textured, "pages", 1))
    h = tex.shape[0] // n
    return [tex[p * h:(p + 1) * h] for p in range(n)]


def texture_file_names(stem: str, texture_format: str, pages: int) -> list[str]:
    """The texture files :func:`~o3d_seqcc.io.export.obj.export_obj` writes next to ``<stem>.obj``: ``<stem>.png``,
    or ``<stem>_<page>.png``."""
    ext = TEXTURE_FORMATS[_check_format(texture_format, 90)][0]
    return [f"{stem}.{ext}"] if pages == 1 else [f"{stem}_{p}.{ext}" for p in range(pages)]
