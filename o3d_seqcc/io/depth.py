"""Depth maps: checked from their header, read as stored, converted to metres.

A depth map is a single-channel 16-bit PNG (counts, ``depth_scale`` units per metre) or a 32-bit
float TIFF / EXR. It is opened as a regular file and passes the raster checks
(:mod:`o3d_seqcc.io.raster_checks`: pixel budget and completeness) before it is decoded.
:func:`read_stored_depth` gives the values as stored, :func:`read_depth` in metres; both go
through :func:`depth_in_metres`, the one conversion (also used on the counts a 16-bit map is kept
as, :class:`~o3d_seqcc.visibility.depthmaps.DepthImage`).
"""

from __future__ import annotations

import io
import logging
import os
import struct
from pathlib import Path
from typing import BinaryIO

import cv2
import numpy as np

from ..errors import InputError
from . import headers
from .mesh_files import MAX_COORDINATE
from .raster_checks import check_complete, over_budget, pillow_headers, read_bounded
from .regular_files import file_size, open_regular

__all__ = ["check_depth_file", "depth_in_metres", "read_depth", "read_stored_depth"]

logger = logging.getLogger(__name__)


def _depth_header(path: Path, f: BinaryIO, shape: tuple[int, int] | None) -> None:
    """The depth map's size from its header (PNG / TIFF / EXR), checked against the budget and ``shape``."""
    from PIL import Image, UnidentifiedImageError

    f.seek(0)
    size = headers.exr_size(f.read(65536))
    if size is None:
        try:
            with pillow_headers():
                f.seek(0)
                with Image.open(f) as im:
                    size = im.size
        except (UnidentifiedImageError, OSError, ValueError, SyntaxError, struct.error):
            raise InputError(f"cannot read depth map {path} (expected a single-channel 16-bit PNG, or a float TIFF / "
                             "EXR)") from None
    w, h = size
    over_budget(path, "depth map", w, h)
    if shape is not None and (h, w) != tuple(shape):
        raise InputError(f"depth map {path} is {w}x{h} but the view is {shape[1]}x{shape[0]}; "
                         "register/resize the depth map to the colour image")


def check_depth_file(path: str | os.PathLike, *, shape: tuple[int, int] | None = None) -> None:
    """Check a depth map from its header, without decoding it (what :func:`read_depth` checks first).

    Raises
    ------
    InputError
        Missing, not a regular file, unreadable header, over the pixel budget, not ``shape``
        ((height, width)), truncated PNG.
    """
    path = Path(path)
    with open_regular(path, "depth map") as f:
        size = file_size(f)
        if size == 0:
            raise InputError(f"depth map {path} is an empty file (0 bytes); copy or export it again")
        _depth_header(path, f, shape)
        check_complete(path, f, size, what="depth map", full=False)


def read_stored_depth(path: str | os.PathLike, *, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Read a depth map as stored, not converted (:func:`read_depth` gives it in metres).

    Parameters
    ----------
    path : path-like
        Single-channel 16-bit PNG (or 32-bit float TIFF/EXR) depth image; any path bytes.
    shape : (int, int), optional
        Expected (height, width); a mismatch raises (before decoding).

    Returns
    -------
    numpy.ndarray
        (H, W) as stored: uint16 counts, float32, float64 or int32.

    Raises
    ------
    InputError
        Missing or not a regular file, a header declaring more pixels than the budget
        (:data:`~o3d_seqcc.io.raster_checks.MAX_IMAGE_PIXELS`, before decoding), truncated PNG, wrong
        size, channels or dtype.
    """
    path = Path(path)
    try:
        data = read_bounded(path, "depth map")
    except InputError as e:
        if "not found" in str(e):
            raise InputError(f"depth map not found: {path} (check the 'depth' entry of the view)") from None
        raise
    _depth_header(path, io.BytesIO(data), shape)
    check_complete(path, io.BytesIO(data), len(data), what="depth map", full=True)
    d = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH)
    if d is None:
        raise InputError(f"cannot read depth map {path} (expected a single-channel 16-bit PNG)")
    if d.ndim != 2:
        raise InputError(f"depth map {path} has {d.shape[2]} channels; expected a single-channel depth image")
    if d.dtype not in (np.uint16, np.float32, np.float64, np.int32):
        raise InputError(f"depth map {path} has dtype {d.dtype}; expected uint16 (scaled by depth_scale) or float32")
    if shape is not None and d.shape != tuple(shape):
        raise InputError(f"depth map {path} is {d.shape[1]}x{d.shape[0]} but the view is {shape[1]}x{shape[0]}; "
                         "register/resize the depth map to the colour image")
    return d


def depth_in_metres(stored: np.ndarray, depth_scale: float) -> np.ndarray:
    """Depth values as stored, in metres: divided by ``depth_scale``, 0 where missing.

    Parameters
    ----------
    stored : numpy.ndarray
        Any shape: uint16 counts, float32, float64 or int32 (:func:`read_stored_depth`).
    depth_scale : float
        Units per metre (1000 for millimetres).

    Returns
    -------
    numpy.ndarray
        float64, the shape of ``stored``: ``stored / depth_scale``, 0 where not finite, negative or beyond
        :data:`~o3d_seqcc.io.mesh_files.MAX_COORDINATE`.
    """
    out = np.asarray(stored).astype(np.float64) / float(depth_scale)
    out[~np.isfinite(out) | (out < 0) | (out > MAX_COORDINATE)] = 0.0
    return out


def read_depth(path: str | os.PathLike, depth_scale: float, *, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Read a depth map and convert it to metres (:func:`read_stored_depth`, then :func:`depth_in_metres`).

    Parameters
    ----------
    path : path-like
        Single-channel 16-bit PNG (or 32-bit float TIFF/EXR) depth image; any path bytes.
    depth_scale : float
        Units per metre (1000 for millimetres).
    shape : (int, int), optional
        Expected (height, width); a mismatch raises (before decoding).

    Returns
    -------
    numpy.ndarray
        (H, W) float64 depth in metres, 0 where missing (and where not finite or beyond
        :data:`~o3d_seqcc.io.mesh_files.MAX_COORDINATE`).

    Raises
    ------
    InputError
        As :func:`read_stored_depth`: missing or not a regular file, over the pixel budget, truncated PNG,
        wrong size, channels or dtype.
    """
    return depth_in_metres(read_stored_depth(path, shape=shape), depth_scale)
