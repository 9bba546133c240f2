"""Photos: checked from their header, read as RGB, encoded and written atomically.

Images are RGB (never BGR) arrays (H, W, 3) uint8 or uint16, the pixels as stored: EXIF orientation
is not applied (cameras are registered on the stored pixels), a photo whose tag asks for it is warned about.
Every photo is opened as a regular file (:func:`~o3d_seqcc.io.regular_files.open_regular`) and passes the
raster checks (:mod:`o3d_seqcc.io.raster_checks`: pixel budget and completeness) before it is decoded;
OpenCV decodes it from memory (``cv2.imdecode``), so any path bytes work.
"""

from __future__ import annotations

import io
import logging
import os
import struct
import threading
from pathlib import Path
from typing import Any, BinaryIO

import cv2
import numpy as np

from ..errors import InputError, warn
from . import headers
from .atomic import atomic_write_bytes
from .raster_checks import check_complete, over_budget, pillow_headers, read_bounded
from .regular_files import file_size, open_regular

__all__ = ["IMAGE_SUFFIXES", "check_image_file", "encode_image", "image_dtype", "image_header", "read_image",
           "read_view_images", "write_image"]

logger = logging.getLogger(__name__)

_GREY_MODES = ("L", "I;16", "I;16B", "I;16L", "I", "F", "1", "LA")
_ALPHA_MODES = ("RGBA", "RGBa", "LA", "PA")
#: EXIF orientation values (tag 0x0112) and what a viewer would do to the stored pixels
_ORIENTATIONS = {2: "mirror left-right", 3: "rotate 180", 4: "mirror top-bottom", 5: "transpose",
                 6: "rotate 90 clockwise", 7: "transverse", 8: "rotate 90 counter-clockwise"}
_warned: set = set()
_warned_lock = threading.Lock()


def _warn_orientation(path: Path, im: Any, f: BinaryIO) -> None:
    from PIL import Image

    try:  # Pillow's getexif decodes a PNG to find an eXIf chunk after the pixels; the chunk headers tell at once
        if im.format == "PNG" and not {"exif", "Raw profile type exif"} & set(im.info):
            (exif := Image.Exif()).load(headers.png_exif(f) or b"")
        else:
            exif = im.getexif()
        value = int(exif.get(0x0112, 1))
    except Exception:  # a broken EXIF block is not our business: the pixels decode without it
        return
    if value not in _ORIENTATIONS:
        return
    try:
        st = os.stat(path)
        key = (os.fspath(path), st.st_mtime_ns, st.st_size)
    except OSError:
        key = (os.fspath(path),)
    with _warned_lock:
        if key in _warned:
            return
        _warned.add(key)
    warn(f"image {path} has EXIF orientation {value} ({_ORIENTATIONS[value]}), which is not applied: its pixels are "
         "used as stored, as the camera registration (COLMAP, MeshLab, OpenCV) reads them; if the scene was "
         "registered on the rotated photo, save it with the rotation applied (e.g. `exiftran -ai`, `mogrify "
         "-auto-orient`)")


def image_header(path: Path, f: BinaryIO, size: int, *, what: str = "image", full: bool = False) -> tuple[int, int, str]:
    """(width, height, Pillow mode) of an image file from its header; budget and completeness checked."""
    import warnings

    from PIL import Image, UnidentifiedImageError

    if size == 0:
        raise InputError(f"{what} {path} is an empty file (0 bytes); copy or export it again")
    try:
        with warnings.catch_warnings(), pillow_headers():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            f.seek(0)
            with Image.open(f) as im:
                (w, h), mode = im.size, im.mode
                if what == "image":
                    _warn_orientation(path, im, f)
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError, struct.error) as e:
        raise InputError(f"cannot read {what} {path}: {e}; re-save it as PNG or JPEG") from None
    over_budget(path, what, w, h)
    check_complete(path, f, size, what=what, full=full)
    return int(w), int(h), str(mode)


def _check_colour(path: Path, mode: str) -> None:
    if mode in _GREY_MODES:
        kind = "grey-scale with alpha" if "A" in mode else "grey-scale"
        raise InputError(f"image {path} is {kind}; colour correction needs RGB images "
                         "(convert it, e.g. cv2.cvtColor(img, cv2.COLOR_GRAY2RGB), and save as RGB)")
    if mode in _ALPHA_MODES:
        raise InputError(f"image {path} has an alpha channel; save it as 3-channel RGB "
                         "(e.g. `convert in.png -alpha off out.png` or drop the 4th channel with numpy)")


def check_image_file(path: str | os.PathLike) -> tuple[int, int, str]:
    """Check an image file from its header, without decoding it.

    Returns
    -------
    (width, height, mode)
        Pillow's mode (``"RGB"``, ``"I;16"``, ...).

    Raises
    ------
    InputError
        Missing, not a regular file, unreadable, more than :data:`~o3d_seqcc.io.raster_checks.MAX_IMAGE_PIXELS` pixels
        (before decoding: a decompression bomb is never decoded), truncated JPEG / PNG (the main
        image's end marker is looked for in the last 64 KB), grey-scale, alpha channel.
    """
    path = Path(path)
    with open_regular(path, "image") as f:
        w, h, mode = image_header(path, f, file_size(f))
    _check_colour(path, mode)
    return w, h, mode


def read_image(path: str | os.PathLike, *, allow_16bit: bool = True) -> np.ndarray:
    """Read an RGB image.

    Parameters
    ----------
    path : path-like
        PNG, JPEG, TIFF, ... anything OpenCV decodes; any path bytes.
    allow_16bit : bool, default True
        Accept 16-bit images (returned as uint16). When False a 16-bit file raises.

    Returns
    -------
    numpy.ndarray
        (H, W, 3) uint8 or uint16, RGB order, the pixels as stored (EXIF orientation not applied).

    Raises
    ------
    InputError
        Missing or not a regular file, unreadable, too large (:data:`~o3d_seqcc.io.raster_checks.MAX_IMAGE_PIXELS`) or
        truncated (the main image's end marker, wherever it is), grey-scale image, image with an
        alpha channel, or an unsupported bit depth; the message names the file and the fix.
    """
    path = Path(path)
    data = read_bounded(path, "image")
    _check_colour(path, image_header(path, io.BytesIO(data), len(data), full=True)[2])
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(f"cannot read image {path}: not an image OpenCV can decode (re-save it as PNG or JPEG)")
    if img.ndim == 2 or (img.ndim == 3 and img.shape[2] == 1):
        raise InputError(
            f"image {path} is grey-scale; colour correction needs RGB images "
            "(convert it, e.g. cv2.cvtColor(img, cv2.COLOR_GRAY2RGB), and save as RGB)"
        )
    if img.shape[2] == 4:
        raise InputError(
            f"image {path} has an alpha channel; save it as 3-channel RGB "
            "(e.g. `convert in.png -alpha off out.png` or drop the 4th channel with numpy)"
        )
    if img.shape[2] != 3:
        raise InputError(f"image {path} has {img.shape[2]} channels; expected 3 (RGB)")
    if img.dtype == np.uint16:
        if not allow_16bit:
            raise InputError(f"image {path} is 16-bit; this operation needs 8-bit images (convert with img >> 8)")
    elif img.dtype != np.uint8:
        raise InputError(f"image {path} has dtype {img.dtype}; only 8-bit and 16-bit images are supported")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def encode_image(image: np.ndarray, suffix: str = ".png", *, quality: int | None = None) -> bytes:
    """Encode an (H, W, 3) RGB uint8/uint16 image in memory (format from ``suffix``: ``.png``, ``.jpg``).

    ``quality``: JPEG quality 0-100 (OpenCV's default 95 when None). Deterministic: the same
    pixels give the same bytes.
    """
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"encode_image expects (H, W, 3) uint8/uint16, got {image.shape} {image.dtype}")
    params = [] if quality is None else [int(cv2.IMWRITE_JPEG_QUALITY), int(quality)]
    ok, buf = cv2.imencode(suffix, cv2.cvtColor(image, cv2.COLOR_RGB2BGR), params)
    if not ok:
        raise OSError(f"OpenCV could not encode a {suffix} image")
    return buf.tobytes()


def write_image(path: str | os.PathLike, image: np.ndarray) -> Path:
    """Write an (H, W, 3) RGB uint8/uint16 image atomically (format from the suffix, PNG advised)."""
    path = Path(path)
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"write_image expects (H, W, 3) uint8/uint16, got {image.shape} {image.dtype}")
    try:
        data = encode_image(image, path.suffix or ".png")
    except OSError:
        raise OSError(f"OpenCV could not encode {path}") from None
    return atomic_write_bytes(path, data)


def image_dtype(path: str | os.PathLike) -> np.dtype:
    """The dtype :func:`read_image` returns for a file (uint8 or uint16), from its header when it can.

    PNG (IHDR bit depth) and JPEG (start-of-frame precision) are read from their first bytes;
    other formats are decoded.
    """
    path = Path(path)
    with open_regular(path, "image") as f:
        head = f.read(65536)
    if head.startswith(b"\x89PNG\r\n\x1a\n") and head[12:16] == b"IHDR" and len(head) > 24:
        return np.dtype(np.uint16 if head[24] == 16 else np.uint8)
    if head.startswith(b"\xff\xd8"):
        bits = headers.jpeg_precision(head)
        if bits == 8:
            return np.dtype(np.uint8)
    return read_image(path).dtype


#: image file suffixes tried by :func:`read_view_images`
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff")


def read_view_images(scene: Any, folder: str | os.PathLike) -> list[np.ndarray]:
    """One image per view of ``scene`` from ``folder``, named after the views (``<name>.png``, ``.jpg``, ...)
    or like the view's own image file.

    Returns
    -------
    list of (H, W, 3) uint8 / uint16 arrays

    Raises
    ------
    InputError
        Not a folder, a view without an image, an image of the wrong size.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"--images {folder} is not a folder")
    out = []
    for v in scene.views:
        cands = [folder / f"{v.name}{s}" for s in IMAGE_SUFFIXES] + [folder / v.image.name]
        p = next((c for c in cands if c.is_file()), None)
        if p is None:
            raise InputError(f"--images {folder}: no image for view {v.name!r} (expected {v.name}.png or {v.image.name})")
        img = read_image(p)
        if img.shape[:2] != (v.height, v.width):
            raise InputError(f"{p} is {img.shape[1]}x{img.shape[0]} but view {v.name!r} is {v.width}x{v.height}")
        out.append(img)
    return out
