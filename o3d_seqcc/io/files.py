"""The one file layer: every image, depth map, mesh and point cloud is read through it; writes are atomic.

Reading (:func:`read_image`, :func:`check_image_file`, :func:`read_depth`,
:func:`~o3d_seqcc.io.mesh_files.read_mesh`, :func:`~o3d_seqcc.io.mesh_files.read_point_cloud`) follows the same steps for every file, before any decoder sees it:

1. **regular files only** (:func:`open_regular`): a FIFO, a device, a socket or a folder is an error naming
   it, found without blocking (opened non-blocking and checked with ``fstat``: a named pipe never hangs a run);
2. **any path bytes**: files are read through their descriptor (OpenCV decodes from memory, ``cv2.imdecode``;
   Open3D gets an ASCII alias of the open file), so a folder name that is not UTF-8 works as in the shell;
3. **budgets from the header, before decoding**: images and depth maps have at most
   :data:`MAX_IMAGE_PIXELS` pixels (``--max-image-pixels``); a PLY / OFF / STL header may not
   declare more elements than its file can hold (:mod:`o3d_seqcc.io.headers`);
4. **complete files**: a JPEG's main image must end with its end-of-image marker after its first
   scan (an EXIF thumbnail's marker does not count), a PNG's chunks must reach IEND;
5. **sane values**: mesh vertices finite and within :data:`MAX_COORDINATE`; point-cloud points that are not
   are dropped with a warning; depth that is not finite is "missing".

Images are RGB (never BGR) arrays (H, W, 3) uint8 or uint16, the pixels as stored: EXIF orientation
is not applied (cameras are registered on the stored pixels), a photo whose tag asks for it is warned about.
"""

from __future__ import annotations

import io
import json
import logging
import os
import stat
import struct
import tempfile
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Any, BinaryIO, Iterator

import cv2
import numpy as np

from ..errors import InputError, warn
from . import headers

__all__ = ["IMAGE_SUFFIXES", "MAX_COORDINATE", "MAX_IMAGE_PIXELS", "atomic_path", "atomic_write_bytes",
           "check_depth_file", "check_image_file", "default_mode", "encode_image", "find_file", "image_dtype",
           "join_path", "open_regular", "parse_json", "read_depth", "read_image", "read_json", "read_view_images",
           "set_max_image_pixels", "to_jsonable", "write_image", "write_json"]

logger = logging.getLogger(__name__)


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
#: mesh vertices and point-cloud points beyond +-this (in the scene's units) are not a scan: a corrupt
#: value (1e300), or the wrong units; every computation on them would overflow or lose all precision
MAX_COORDINATE = 1e12

_GREY_MODES = ("L", "I;16", "I;16B", "I;16L", "I", "F", "1", "LA")
_ALPHA_MODES = ("RGBA", "RGBa", "LA", "PA")
#: EXIF orientation values (tag 0x0112) and what a viewer would do to the stored pixels
_ORIENTATIONS = {2: "mirror left-right", 3: "rotate 180", 4: "mirror top-bottom", 5: "transpose",
                 6: "rotate 90 clockwise", 7: "transverse", 8: "rotate 90 counter-clockwise"}
_warned: set = set()
_warned_lock, _pillow_lock = threading.Lock(), threading.Lock()


def set_max_image_pixels(n: int) -> int:
    """Set the pixel budget of :func:`check_image_file` (and every image read); returns the previous one."""
    global MAX_IMAGE_PIXELS
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise InputError(f"max_image_pixels must be a positive integer, got {n!r}")
    old, MAX_IMAGE_PIXELS = MAX_IMAGE_PIXELS, int(n)
    return old


def _kind(mode: int) -> str:
    kinds = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
             (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a folder"))
    return next((name for test, name in kinds if test(mode)), "not a regular file")


def open_regular(path: str | os.PathLike, what: str = "file") -> BinaryIO:
    """Open ``path`` for reading in binary mode, refusing anything but a regular file, without blocking.

    Parameters
    ----------
    path : path-like
        Any path (bytes that are not UTF-8 included).
    what : str
        What the file is, for messages ("image", "depth map", "mesh", ...).

    Returns
    -------
    file object
        Opened ``rb``; close it (``with open_regular(p) as f: ...``).

    Raises
    ------
    InputError
        Missing, unreadable, or a FIFO / device / socket / folder (found with ``fstat`` on a
        descriptor opened non-blocking: a named pipe with no writer is refused at once).
    """
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise InputError(f"{what} not found: {path} (check the path)") from None
    except PermissionError:
        raise InputError(f"cannot read {what} {path}: permission denied (fix its permissions)") from None
    except OSError as e:
        raise InputError(f"cannot open {what} {path}: {e.strerror}; give a regular file") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputError(f"{what} {path} is {_kind(st.st_mode)}, not a regular file; give the {what} file itself")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def _size(f: BinaryIO) -> int:
    return os.fstat(f.fileno()).st_size


def _max_file_bytes() -> int:
    """Largest image / depth file read into memory: an uncompressed 16-bit RGBA image at the pixel budget, plus slack."""
    return 8 * MAX_IMAGE_PIXELS + 2**26


def _read_all(path: Path, what: str) -> bytes:
    with open_regular(path, what) as f:
        size = _size(f)
        if size == 0:
            raise InputError(f"{what} {path} is an empty file (0 bytes); copy or export it again")
        if size > _max_file_bytes():
            raise InputError(f"{what} {path} is {size / 2**20:.0f} MB, more than any image within the pixel budget "
                             f"({_pixels(MAX_IMAGE_PIXELS)}) needs; downscale it, or raise --max-image-pixels")
        return f.read()


def _pixels(n: int) -> str:
    return f"{n / 1e6:.0f} Mpx" if n >= 10**6 else f"{n} pixels"


def over_budget(path: Path, what: str, w: int, h: int) -> None:
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


def _image_header(path: Path, f: BinaryIO, size: int, *, what: str = "image", full: bool = False) -> tuple[int, int, str]:
    """(width, height, Pillow mode) of an image file from its header; budget and completeness checked."""
    import warnings

    from PIL import Image, UnidentifiedImageError

    if size == 0:
        raise InputError(f"{what} {path} is an empty file (0 bytes); copy or export it again")
    try:
        with warnings.catch_warnings(), _pillow_headers():
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


@contextmanager
def _pillow_headers() -> Iterator[None]:
    """Pillow's own pixel limit off while a header is read (ours is checked after), one thread at a time."""
    from PIL import Image

    with _pillow_lock:
        limit, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
        try:
            yield
        finally:
            Image.MAX_IMAGE_PIXELS = limit


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
        Missing, not a regular file, unreadable, more than :data:`MAX_IMAGE_PIXELS` pixels
        (before decoding: a decompression bomb is never decoded), truncated JPEG / PNG (the main
        image's end marker is looked for in the last 64 KB), grey-scale, alpha channel.
    """
    path = Path(path)
    with open_regular(path, "image") as f:
        w, h, mode = _image_header(path, f, _size(f))
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
        Missing or not a regular file, unreadable, too large (:data:`MAX_IMAGE_PIXELS`) or
        truncated (the main image's end marker, wherever it is), grey-scale image, image with an
        alpha channel, or an unsupported bit depth; the message names the file and the fix.
    """
    path = Path(path)
    data = _read_all(path, "image")
    _check_colour(path, _image_header(path, io.BytesIO(data), len(data), full=True)[2])
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


def _depth_header(path: Path, f: BinaryIO, shape: tuple[int, int] | None) -> None:
    """The depth map's size from its header (PNG / TIFF / EXR), checked against the budget and ``shape``."""
    from PIL import Image, UnidentifiedImageError

    f.seek(0)
    size = headers.exr_size(f.read(65536))
    if size is None:
        try:
            with _pillow_headers():
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
        size = _size(f)
        if size == 0:
            raise InputError(f"depth map {path} is an empty file (0 bytes); copy or export it again")
        _depth_header(path, f, shape)
        check_complete(path, f, size, what="depth map", full=False)


def read_depth(path: str | os.PathLike, depth_scale: float, *, shape: tuple[int, int] | None = None,
               stored: bool = False) -> np.ndarray:
    """Read a depth map and convert it to metres.

    Parameters
    ----------
    path : path-like
        Single-channel 16-bit PNG (or 32-bit float TIFF/EXR) depth image; any path bytes.
    depth_scale : float
        Units per metre (1000 for millimetres).
    shape : (int, int), optional
        Expected (height, width); a mismatch raises (before decoding).
    stored : bool, default False
        Return the map as stored (uint16 counts, float32, float64 or int32), not converted.

    Returns
    -------
    numpy.ndarray
        (H, W) float64 depth in metres, 0 where missing (and where not finite or beyond
        :data:`~o3d_seqcc.io.MAX_COORDINATE`).

    Raises
    ------
    InputError
        Missing or not a regular file, a header declaring more pixels than the budget (:data:`MAX_IMAGE_PIXELS`,
        before decoding), truncated PNG, wrong size, channels or dtype.
    """
    path = Path(path)
    try:
        data = _read_all(path, "depth map")
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
    if stored:
        return d
    out = d.astype(np.float64) / float(depth_scale)
    out[~np.isfinite(out) | (out < 0) | (out > MAX_COORDINATE)] = 0.0
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


def join_path(root: str | os.PathLike, rel: str) -> Path:
    """``root / rel`` normalised, with ``..`` resolved as the operating system does.

    ``os.path.normpath`` drops ``x/..`` by text; when ``root`` lies under a symbolic link that
    is wrong (``link/../a`` is ``a`` beside the link's *target*). A relative path with ``..``
    under a linked folder is therefore joined to the folder's real path, so a project or
    manifest written in an output folder reached through a link loads through that link.
    """
    rel_parts = Path(rel).parts
    if ".." in rel_parts and not Path(rel).is_absolute():
        real = os.path.realpath(root)
        if real != os.path.abspath(root):
            return Path(os.path.normpath(os.path.join(real, rel)))
    return Path(os.path.normpath(Path(root) / rel))


def parse_json(text: str, where: str | os.PathLike) -> Any:
    """``json.loads`` that refuses duplicate keys (which would silently keep the last one).

    Raises
    ------
    InputError
        Not valid JSON, or an object with the same key twice (named, with ``where``).
    """
    def pairs(items: list) -> dict:
        out: dict = {}
        for k, v in items:
            if k in out:
                raise InputError(f"{where}: the key {k!r} appears twice in one JSON object (only one value can "
                                 "count); remove the duplicate")
            out[k] = v
        return out

    try:
        return json.loads(text, object_pairs_hook=pairs)
    except (json.JSONDecodeError, RecursionError) as e:
        raise InputError(f"{where}: not valid JSON ({e})") from None


def read_json(path: str | os.PathLike, what: str = "JSON file") -> Any:
    """Read a UTF-8 JSON file (regular files only; duplicate keys refused, see :func:`parse_json`)."""
    path = Path(path)
    with open_regular(path, what) as f:
        raw = f.read()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start}); save it as UTF-8") from None
    return parse_json(text, path)
