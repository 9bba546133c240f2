"""File I/O adapters: images, depth maps, JSON; every write is atomic.

Images are returned as RGB (never BGR) numpy arrays of shape (H, W, 3), dtype uint8 or uint16.
"""

from __future__ import annotations

import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import cv2
import numpy as np

from ..errors import InputError

__all__ = [
    "IMAGE_SUFFIXES",
    "MAX_IMAGE_PIXELS",
    "atomic_path",
    "check_image_file",
    "atomic_write_bytes",
    "default_mode",
    "encode_image",
    "find_file",
    "image_dtype",
    "to_jsonable",
    "read_depth",
    "read_image",
    "read_point_cloud",
    "read_view_images",
    "set_max_image_pixels",
    "write_image",
    "write_json",
]


def default_mode(mode: int = 0o666) -> int:
    """``mode`` masked by the process umask: the permissions a plain ``open``/``mkdir`` would give."""
    mask = os.umask(0)
    os.umask(mask)
    return mode & ~mask


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; it replaces ``path`` only if the block succeeds.

    For writers that need a file name (Open3D, numpy, pymeshlab). The temporary name keeps the
    destination's suffix so format detection by extension works. On error the temporary file is
    removed and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, default_mode())  # mkstemp creates 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then rename).

    Parameters
    ----------
    path : path-like
        Destination. Its parent folder is created if needed.
    data : bytes
        Content.

    Returns
    -------
    pathlib.Path
        The destination path.
    """
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def to_jsonable(o: Any) -> Any:
    """Convert numpy arrays / scalars, paths, tuples and non-string dict keys to JSON types."""
    if isinstance(o, dict):
        return {str(k): to_jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [to_jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    return o


def write_json(path: str | os.PathLike, obj: Any, *, indent: int | None = 1) -> Path:
    """Serialise ``obj`` as JSON and write it atomically; numpy scalars/arrays are converted."""

    text = json.dumps(to_jsonable(obj), indent=indent, allow_nan=False)
    return atomic_write_bytes(path, (text + "\n").encode("utf-8"))


#: images with more pixels than this are refused before they are decoded (a decompression bomb, or
#: a photo far larger than texturing needs); change it with :func:`set_max_image_pixels`
MAX_IMAGE_PIXELS = 100_000_000

_GREY_MODES = ("L", "I;16", "I;16B", "I;16L", "I", "F", "1", "LA")
_ALPHA_MODES = ("RGBA", "RGBa", "LA", "PA")


def set_max_image_pixels(n: int) -> int:
    """Set the pixel budget of :func:`check_image_file` (and every image read); returns the previous one."""
    global MAX_IMAGE_PIXELS
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise InputError(f"max_image_pixels must be a positive integer, got {n!r}")
    old, MAX_IMAGE_PIXELS = MAX_IMAGE_PIXELS, int(n)
    return old


def _check_complete(path: Path, head: bytes) -> None:
    """Refuse JPEG / PNG files cut short (no end-of-image marker / IEND chunk): decoders fill the rest with grey."""
    if head.startswith(b"\xff\xd8"):
        marker, kind = b"\xff\xd9", "JPEG end-of-image marker"
    elif head.startswith(b"\x89PNG"):
        marker, kind = b"IEND", "PNG IEND chunk"
    else:
        return
    size = path.stat().st_size
    with open(path, "rb") as f:
        f.seek(max(0, size - 65536))
        tail = f.read()
    if marker not in tail:
        raise InputError(f"image {path} is truncated (no {kind}: the file was cut short, e.g. by an interrupted "
                         "copy or download); copy or export it again")


def _pixels(n: int) -> str:
    return f"{n / 1e6:.0f} Mpx" if n >= 10**6 else f"{n} pixels"


def check_image_file(path: str | os.PathLike) -> tuple[int, int, str]:
    """Check an image file from its header, without decoding it.

    Returns
    -------
    (width, height, mode)
        Pillow's mode (``"RGB"``, ``"I;16"``, ...).

    Raises
    ------
    InputError
        Missing, unreadable, more than :data:`MAX_IMAGE_PIXELS` pixels (before decoding: a
        decompression bomb is never decoded), truncated JPEG / PNG, grey-scale, alpha channel.
    """
    import warnings

    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    if not path.is_file():
        raise InputError(f"image not found: {path} (check the path in the scene file)")
    pillow_limit = Image.MAX_IMAGE_PIXELS
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            Image.MAX_IMAGE_PIXELS = None  # only the header is read here; our own budget is checked below
            with open(path, "rb") as fh:
                head = fh.read(16)
                fh.seek(0)
                with Image.open(fh) as im:
                    (w, h), mode = im.size, im.mode
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError) as e:
        raise InputError(f"cannot read image {path}: {e}; re-save it as PNG or JPEG") from None
    finally:
        Image.MAX_IMAGE_PIXELS = pillow_limit
    if w * h > MAX_IMAGE_PIXELS:
        raise InputError(
            f"image {path} is {w}x{h} = {_pixels(w * h)}, over the limit of {_pixels(MAX_IMAGE_PIXELS)} "
            "(a decompression bomb, or far more than texturing needs); downscale it, or raise the limit with "
            "--max-image-pixels"
        )
    _check_complete(path, head)
    if mode in _GREY_MODES:
        kind = "grey-scale with alpha" if "A" in mode else "grey-scale"
        raise InputError(f"image {path} is {kind}; colour correction needs RGB images "
                         "(convert it, e.g. cv2.cvtColor(img, cv2.COLOR_GRAY2RGB), and save as RGB)")
    if mode in _ALPHA_MODES:
        raise InputError(f"image {path} has an alpha channel; save it as 3-channel RGB "
                         "(e.g. `convert in.png -alpha off out.png` or drop the 4th channel with numpy)")
    return int(w), int(h), str(mode)


def read_image(path: str | os.PathLike, *, allow_16bit: bool = True) -> np.ndarray:
    """Read an RGB image.

    Parameters
    ----------
    path : path-like
        PNG, JPEG, TIFF, ... anything OpenCV reads.
    allow_16bit : bool, default True
        Accept 16-bit images (returned as uint16). When False a 16-bit file raises.

    Returns
    -------
    numpy.ndarray
        (H, W, 3) uint8 or uint16, RGB order.

    Raises
    ------
    InputError
        Missing, unreadable, too large (:data:`MAX_IMAGE_PIXELS`) or truncated file, grey-scale
        image, image with an alpha channel, or an unsupported bit depth; the message names the
        file and the fix.
    """
    path = Path(path)
    check_image_file(path)
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
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


_JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def _jpeg_precision(head: bytes) -> int | None:
    """Sample precision (bits) from a JPEG's start-of-frame segment, None when not found."""
    i = 2
    while i + 4 <= len(head):
        if head[i] != 0xFF:
            return None
        marker = head[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
            i += 2
            continue
        length = int.from_bytes(head[i + 2:i + 4], "big")
        if marker in _JPEG_SOF:
            return head[i + 4] if i + 4 < len(head) else None
        i += 2 + length
    return None


def image_dtype(path: str | os.PathLike) -> np.dtype:
    """The dtype :func:`read_image` returns for a file (uint8 or uint16), from its header when it can.

    PNG (IHDR bit depth) and JPEG (start-of-frame precision) are read from their first bytes;
    other formats are decoded.
    """
    path = Path(path)
    with open(path, "rb") as f:
        head = f.read(65536)
    if head.startswith(b"\x89PNG\r\n\x1a\n") and head[12:16] == b"IHDR" and len(head) > 24:
        return np.dtype(np.uint16 if head[24] == 16 else np.uint8)
    if head.startswith(b"\xff\xd8"):
        bits = _jpeg_precision(head)
        if bits == 8:
            return np.dtype(np.uint8)
    return read_image(path).dtype


def read_depth(path: str | os.PathLike, depth_scale: float, *, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Read a depth map and convert it to metres.

    Parameters
    ----------
    path : path-like
        Single-channel 16-bit PNG (or 32-bit float TIFF/EXR) depth image.
    depth_scale : float
        Units per metre (1000 for millimetres).
    shape : (int, int), optional
        Expected (height, width); a mismatch raises.

    Returns
    -------
    numpy.ndarray
        (H, W) float64 depth in metres, 0 where missing.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"depth map not found: {path} (check the 'depth' entry of the view)")
    d = cv2.imread(str(path), cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH)
    if d is None:
        raise InputError(f"cannot read depth map {path} (expected a single-channel 16-bit PNG)")
    if d.ndim != 2:
        raise InputError(f"depth map {path} has {d.shape[2]} channels; expected a single-channel depth image")
    if d.dtype not in (np.uint16, np.float32, np.float64, np.int32):
        raise InputError(
            f"depth map {path} has dtype {d.dtype}; expected uint16 (scaled by depth_scale) or float32"
        )
    if shape is not None and d.shape != tuple(shape):
        raise InputError(
            f"depth map {path} is {d.shape[1]}x{d.shape[0]} but the view is {shape[1]}x{shape[0]}; "
            "register/resize the depth map to the colour image"
        )
    out = d.astype(np.float64) / float(depth_scale)
    out[~np.isfinite(out) | (out < 0)] = 0.0
    return out


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


def find_file(path: Path, *, name: str, suffix: str) -> Path | None:
    """``path`` when it is a file ending in ``suffix``, ``path / name`` when ``path`` is a folder holding it, else None.

    The ``detect`` step of the scene formats that are one file (``scene.json``, ``cameras.sfm``).
    """
    path = Path(path)
    if path.is_dir():
        return path / name if (path / name).is_file() else None
    return path if path.is_file() and path.suffix.lower() == suffix else None


def read_point_cloud(path: str | os.PathLike) -> np.ndarray:
    """(M, 3) float64 points of a point-cloud file (PLY, PCD, ...); raises InputError when empty."""
    import open3d as o3d

    if not os.path.isfile(path):
        raise InputError(f"point cloud not found: {path}")
    pc = o3d.io.read_point_cloud(str(path))
    pts = np.asarray(pc.points, dtype=np.float64)
    if len(pts) == 0:
        raise InputError(f"point cloud {path} has no points (unreadable or empty file); give a PLY/PCD with points")
    return pts
