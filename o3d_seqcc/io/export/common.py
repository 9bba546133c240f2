"""What every writer reads of a textured mesh: its checks, positions and normals, per-page UVs and faces.

The writers take any object with the attributes of a :class:`~o3d_seqcc.texturing.TexturedMesh`
(``vertices``, ``faces``, ``uv``, ``texture``, optionally ``normals``, ``pages``, ``face_page()``,
``page_uv()``); :func:`_check` rejects an inconsistent one with an InputError before any file is written.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import InputError
from ...geometry.meshops import vertex_normals

__all__: list[str] = []


def _check(textured: Any) -> None:
    """Raise InputError unless ``textured`` holds a mesh the writers can write (shapes, indices, texture, pages)."""
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


def _face_page(textured: Any) -> np.ndarray:
    """(F,) int: the atlas page of each face (all 0 for a mesh without ``face_page``)."""
    fp = getattr(textured, "face_page", None)
    return fp() if callable(fp) else np.zeros(len(textured.faces), dtype=np.int64)


def _page_uv(textured: Any) -> np.ndarray:
    """(M, 2) float64: each vertex's UV within its own page (``uv`` for a mesh without ``page_uv``)."""
    pu = getattr(textured, "page_uv", None)
    return np.asarray(pu() if callable(pu) else textured.uv, dtype=np.float64)


def _normals(textured: Any) -> np.ndarray:
    """(M, 3) unit normals: the mesh's where usable, else area-weighted face normals."""
    return vertex_normals(textured.vertices, textured.faces, getattr(textured, "normals", None))


def _geometry(textured: Any, transform: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) float64 positions and (M, 3) unit normals with ``transform`` (a 3 x 3 rotation, or None) applied."""
    v = np.asarray(textured.vertices, dtype=np.float64)
    n = _normals(textured)
    if transform is not None:
        R = np.asarray(transform, dtype=np.float64)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise InputError(f"export: transform must be a 3 x 3 rotation, got {R.tolist()}")
        v, n = v @ R.T, n @ R.T
    return v, n
