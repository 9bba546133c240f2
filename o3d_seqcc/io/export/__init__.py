"""Export of a :class:`~o3d_seqcc.texturing.TexturedMesh`: OBJ + MTL + textures, glTF 2.0 binary (GLB), PLY.

One module per format, behind the table of :func:`export_textured_mesh` (``_WRITERS``):

- :mod:`~o3d_seqcc.io.export.obj`: OBJ + MTL + textures (its text: :mod:`~o3d_seqcc.io.export.obj_text`);
- :mod:`~o3d_seqcc.io.export.glb`: glTF 2.0 binary;
- :mod:`~o3d_seqcc.io.export.ply`: binary PLY with vertex colours;
- :mod:`~o3d_seqcc.io.export.meshlab_ply`: MeshLab projects' textured PLY in MeshLab's own layout
  (:func:`export_meshlab_ply`);
- :mod:`~o3d_seqcc.io.export.textures`: the texture formats and their one encoder, shared by all of them;
- :mod:`~o3d_seqcc.io.export.common`: the mesh checks, positions and normals every writer uses.

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

The GLB's layout (primitives, materials, padding; Khronos glTF-Validator clean) is described in
:mod:`~o3d_seqcc.io.export.glb`.
"""

from __future__ import annotations

import os
from pathlib import Path
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Iterable

import numpy as np

from ...errors import InputError
from ...geometry.meshops import float32_offset
from ...geometry.orientation import UP_AXES
from .glb import export_glb, glb_bytes as glb_bytes  # the report's viewer embeds a GLB
from .meshlab_ply import export_meshlab_ply
from .obj import export_obj
from .ply import export_ply
from .textures import TEXTURE_FORMATS, _check_format, _encoded_pages, encode_png, encode_texture, texture_file_names

__all__ = [
    "DEFAULT_FORMATS", "EXPORT_UP_AXES", "FILE_SUFFIXES", "FORMATS", "TEXTURE_FORMATS", "check_export_options", "encode_png", "encode_texture",
    "export_glb", "export_meshlab_ply", "export_obj", "export_ply", "export_textured_mesh", "float32_offset",
    "parse_formats", "texture_file_names",
]

#: formats known to :func:`export_textured_mesh`
FORMATS = ("glb", "obj", "ply")
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
    fmt = _check_format(texture_format, 90)  # the format's name; the quality's message names jpeg_quality
    if isinstance(jpeg_quality, bool) or int(jpeg_quality) != jpeg_quality or not 1 <= int(jpeg_quality) <= 100:
        raise InputError(f"jpeg_quality must be an integer in 1..100, got {jpeg_quality!r}")
    return fmt


#: format -> (what follows the stem in its file name, the writer)
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
