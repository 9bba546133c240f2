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
    "atomic_path",
    "atomic_write_bytes",
    "default_mode",
    "find_file",
    "to_jsonable",
    "read_depth",
    "read_image",
    "read_view_images",
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
        Missing or unreadable file, grey-scale image, image with an alpha channel, or an
        unsupported bit depth; the message names the file and the fix.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"image not found: {path} (check the path in the scene file)")
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


def write_image(path: str | os.PathLike, image: np.ndarray) -> Path:
    """Write an (H, W, 3) RGB uint8/uint16 image atomically (format from the suffix, PNG advised)."""
    path = Path(path)
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"write_image expects (H, W, 3) uint8/uint16, got {image.shape} {image.dtype}")
    ok, buf = cv2.imencode(path.suffix or ".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    if not ok:
        raise OSError(f"OpenCV could not encode {path}")
    return atomic_write_bytes(path, buf.tobytes())


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
