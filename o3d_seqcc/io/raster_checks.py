"""What every raster file (photo, depth map, mask) passes before it is decoded.

The pixel budget (:data:`MAX_IMAGE_PIXELS`, ``--max-image-pixels``) is checked on the size the
header declares, and the file's size on disk against what an image within the budget can need,
before a byte is decoded (:func:`over_budget`, :func:`read_bounded`); a JPEG's main image must end
with its end-of-image marker after its first scan (an EXIF thumbnail's marker does not count), a
PNG's chunks must reach IEND (:func:`check_complete`); Pillow reads headers with its own limit off
(:func:`pillow_headers`: ours is the one that counts).
"""

from __future__ import annotations

import logging
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO, Iterator

import numpy as np

from ..errors import InputError
from . import headers
from .regular_files import file_size, open_regular

__all__ = ["MAX_IMAGE_PIXELS", "check_complete", "over_budget", "pillow_headers", "read_bounded",
           "set_max_image_pixels"]

logger = logging.getLogger(__name__)

#: images with more pixels than this are refused before they are decoded (a decompression bomb, or
#: a photo far larger than texturing needs); change it with :func:`set_max_image_pixels`
MAX_IMAGE_PIXELS = 100_000_000
_pillow_lock = threading.Lock()


def set_max_image_pixels(n: int) -> int:
    """Set the pixel budget of :func:`~o3d_seqcc.io.images.check_image_file` (and of every image, depth map and
    mask read); returns the previous one."""
    global MAX_IMAGE_PIXELS
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise InputError(f"max_image_pixels must be a positive integer, got {n!r}")
    old, MAX_IMAGE_PIXELS = MAX_IMAGE_PIXELS, int(n)
    return old


def _max_file_bytes() -> int:
    """Largest image / depth file read into memory: an uncompressed 16-bit RGBA image at the pixel budget, plus slack."""
    return 8 * MAX_IMAGE_PIXELS + 2**26


def read_bounded(path: Path, what: str) -> bytes:
    """The bytes of a regular file, refused when empty or larger than any image within the pixel budget."""
    with open_regular(path, what) as f:
        size = file_size(f)
        if size == 0:
            raise InputError(f"{what} {path} is an empty file (0 bytes); copy or export it again")
        if size > _max_file_bytes():
            raise InputError(f"{what} {path} is {size / 2**20:.0f} MB, more than any image within the pixel budget "
                             f"({_pixels(MAX_IMAGE_PIXELS)}) needs; downscale it, or raise --max-image-pixels")
        return f.read()


def _pixels(n: int) -> str:
    return f"{n / 1e6:.0f} Mpx" if n >= 10**6 else f"{n} pixels"


def over_budget(path: Path, what: str, w: int, h: int) -> None:
    """Refuse a ``w`` x ``h`` raster over :data:`MAX_IMAGE_PIXELS` (from its header, before decoding)."""
    if w * h > MAX_IMAGE_PIXELS:
        raise InputError(
            f"{what} {path} is {w}x{h} = {_pixels(w * h)}, over the limit of {_pixels(MAX_IMAGE_PIXELS)} "
            "(a decompression bomb, or far more than texturing needs); downscale it, or raise the limit with "
            "--max-image-pixels"
        )


def check_complete(path: Path, f: BinaryIO, size: int, *, what: str, full: bool) -> None:
    """Refuse JPEG / PNG files cut short: decoders fill the rest with grey."""
    f.seek(0)
    head = f.read(8)
    if head.startswith(b"\xff\xd8"):
        ok, kind = headers.jpeg_complete(f, size, tail=None if full else 65536), "JPEG end-of-image marker"
    elif head.startswith(b"\x89PNG"):
        ok, kind = headers.png_complete(f, size), "PNG IEND chunk"
    else:
        return
    if not ok:
        raise InputError(f"{what} {path} is truncated (no {kind}: the file was cut short, e.g. by an interrupted "
                         "copy or download); copy or export it again")


@contextmanager
def pillow_headers() -> Iterator[None]:
    """Pillow's own pixel limit off while a header is read (ours is checked after), one thread at a time."""
    from PIL import Image

    with _pillow_lock:
        limit, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
        try:
            yield
        finally:
            Image.MAX_IMAGE_PIXELS = limit
