"""Texture memory: what an engine holds for the atlas pages (issue 35).

A game engine or a web viewer uploads every page whole, whatever share of it the triangles use,
usually with its full mip chain. :func:`gpu_bytes` is the memory of one page at RGBA8 (4 bytes a
texel: GPUs have no 3-byte format) with every mip level down to 1 x 1, each level's sides halved
and rounded down, never below 1 (OpenGL / Vulkan / WebGL's rule); :func:`texture_memory` is the
per-page record that ``report.json``'s ``atlas.texture_memory``, the report and the CLI summary
show.
"""

from __future__ import annotations

import numpy as np

__all__ = ["gpu_bytes", "texture_memory"]

#: bytes per texel of the format the memory is counted in (RGBA8)
RGBA8 = 4


def gpu_bytes(width: int, height: int, *, bytes_per_texel: int = RGBA8, mipmaps: bool = True) -> int:
    """Bytes of a ``width`` x ``height`` texture on a GPU.

    Parameters
    ----------
    width, height : int
        The page in texels (>= 1).
    bytes_per_texel : int, default 4
        RGBA8.
    mipmaps : bool, default True
        With the full mip chain (about 4/3 of the base level).

    Returns
    -------
    int
    """
    w, h, total = int(width), int(height), 0
    if w < 1 or h < 1:
        raise ValueError(f"a texture needs sides >= 1, got {w}x{h}")
    while True:
        total += w * h * int(bytes_per_texel)
        if not mipmaps or (w == 1 and h == 1):
            return total
        w, h = max(1, w // 2), max(1, h // 2)


def texture_memory(width: int, height: int, coverage: np.ndarray) -> dict:
    """The texture-memory record of an atlas of pages of ``width`` x ``height`` texels.

    Parameters
    ----------
    width, height : int
        Every page's size in texels.
    coverage : (P,) float
        Each page's share of texels inside a triangle (0..1).

    Returns
    -------
    dict
        ``pages``: per page ``width``, ``height``, ``coverage``, ``gpu_bytes`` (RGBA8 with mipmaps) and
        ``gpu_bytes_base`` (without); ``gpu_bytes`` and ``gpu_bytes_base``: their totals; ``format``.
    """
    full, base = gpu_bytes(width, height), gpu_bytes(width, height, mipmaps=False)
    pages = [{"width": int(width), "height": int(height), "coverage": round(float(c), 4), "gpu_bytes": full,
              "gpu_bytes_base": base} for c in np.asarray(coverage, dtype=np.float64).reshape(-1)]
    return {"format": "RGBA8 with the full mip chain", "pages": pages, "gpu_bytes": full * len(pages),
            "gpu_bytes_base": base * len(pages)}
