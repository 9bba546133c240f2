"""COLMAP sparse models, text (``cameras.txt``, ``images.txt``) or binary (``cameras.bin``, ``images.bin``).

Pinhole cameras (PINHOLE, SIMPLE_PINHOLE) are read as they are; distorted ones are undistorted
on the fly (:mod:`o3d_seqcc.geometry.distortion`): SIMPLE_RADIAL, RADIAL, OPENCV and FULL_OPENCV as
OpenCV's model, OPENCV_FISHEYE, SIMPLE_RADIAL_FISHEYE and RADIAL_FISHEYE as OpenCV's fisheye
model; the view's camera is then the pinhole :meth:`~o3d_seqcc.geometry.distortion.Distortion.pinhole`
of the same size. FOV and THIN_PRISM_FISHEYE cameras are refused (``colmap
image_undistorter`` makes PINHOLE ones). COLMAP's pixel convention (the centre of the top-left pixel at 0.5) is converted to ours (pixel
centres at integers): cx, cy are shifted by -0.5. COLMAP's ``images`` hold world-to-camera
poses (quaternion ``qw qx qy qz`` and translation) in OpenCV axes, like our extrinsics.

The binary layout (little-endian) is COLMAP's ``read_write_model.py``: ``cameras.bin`` = uint64
count, then per camera int32 id, int32 model id, uint64 width, uint64 height, float64 params;
``images.bin`` = uint64 count, then per image int32 id, 4 float64 quaternion, 3 float64
translation, int32 camera id, a NUL-terminated name, uint64 number of 2-D points and 24 bytes
per point (x, y float64, point3D id int64).
"""

from __future__ import annotations

import os
import struct
from pathlib import Path
from typing import Iterable

import numpy as np

from ..geometry.distortion import Distortion
from .._shared.numbers import parse_number
from ..errors import InputError
from ..scene import Scene, View

__all__ = ["CAMERA_MODELS", "detect", "load", "qvec_to_rotmat"]

#: COLMAP camera model id -> (name, number of parameters)
CAMERA_MODELS: dict[int, tuple[str, int]] = {
    0: ("SIMPLE_PINHOLE", 3), 1: ("PINHOLE", 4), 2: ("SIMPLE_RADIAL", 4), 3: ("RADIAL", 5), 4: ("OPENCV", 8),
    5: ("OPENCV_FISHEYE", 8), 6: ("FULL_OPENCV", 12), 7: ("FOV", 5), 8: ("SIMPLE_RADIAL_FISHEYE", 4),
    9: ("RADIAL_FISHEYE", 5), 10: ("THIN_PRISM_FISHEYE", 12),
}
_N_PARAMS = {name: n for name, n in CAMERA_MODELS.values()}
_MAX_COUNT = 10_000_000


def detect(path: Path) -> Path | None:
    """``path`` when it holds a COLMAP text or binary model, else None."""
    if not path.is_dir():
        return None
    for names in (("cameras.txt", "images.txt"), ("cameras.bin", "images.bin")):
        if all((path / n).is_file() for n in names):
            return path
    return None


def qvec_to_rotmat(q: Iterable[float]) -> np.ndarray:
    """(3, 3) rotation matrix of a quaternion ``(w, x, y, z)`` (normalised first)."""
    q = np.asarray(list(q), dtype=np.float64)
    norm = np.linalg.norm(q)
    if not np.isfinite(norm) or norm < 1e-12:
        raise InputError(f"quaternion {q.tolist()} is zero or not finite")
    w, x, y, z = q / norm
    return np.array(
        [
            [1 - 2 * y * y - 2 * z * z, 2 * x * y - 2 * w * z, 2 * x * z + 2 * w * y],
            [2 * x * y + 2 * w * z, 1 - 2 * x * x - 2 * z * z, 2 * y * z - 2 * w * x],
            [2 * x * z - 2 * w * y, 2 * y * z + 2 * w * x, 1 - 2 * x * x - 2 * y * y],
        ]
    )


#: COLMAP model -> (our distortion model, the coefficients of OpenCV's order from COLMAP's parameters)
_DISTORTION = {
    "SIMPLE_RADIAL": ("opencv", lambda p: [p[3], 0.0, 0.0, 0.0]),
    "RADIAL": ("opencv", lambda p: [p[3], p[4], 0.0, 0.0]),
    "OPENCV": ("opencv", lambda p: p[4:8]),
    "FULL_OPENCV": ("opencv", lambda p: p[4:12]),
    "OPENCV_FISHEYE": ("fisheye", lambda p: p[4:8]),
    "SIMPLE_RADIAL_FISHEYE": ("fisheye", lambda p: [p[3], 0.0, 0.0, 0.0]),
    "RADIAL_FISHEYE": ("fisheye", lambda p: [p[3], p[4], 0.0, 0.0]),
}
_ONE_FOCAL = ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL", "SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE")


def _intrinsic(model: str, params: list[float], where: str, width: int = 0,
               height: int = 0) -> tuple[np.ndarray, Distortion | None]:
    """Our (3, 3) pinhole intrinsic of a COLMAP camera, and its distortion (None for a pinhole one)."""
    if model not in _N_PARAMS:
        raise InputError(f"{where}: unknown camera model {model!r}; valid: {', '.join(_N_PARAMS)}")
    if len(params) != _N_PARAMS[model]:
        raise InputError(f"{where}: model {model} needs {_N_PARAMS[model]} parameters, got {len(params)}")
    if not all(np.isfinite(params)):
        raise InputError(f"{where}: camera parameters are not finite")
    if model not in ("PINHOLE", "SIMPLE_PINHOLE") and model not in _DISTORTION:
        raise InputError(
            f"{where}: camera model {model} is not supported; undistort the images first "
            "(`colmap image_undistorter`) to get PINHOLE cameras"
        )
    if model in _ONE_FOCAL:
        fx = fy = params[0]
        cx, cy = params[1:3]
    else:
        fx, fy, cx, cy = params[:4]
    K = np.array([[fx, 0.0, cx - 0.5], [0.0, fy, cy - 0.5], [0.0, 0.0, 1.0]])
    if model not in _DISTORTION or not any(params[3 if model in _ONE_FOCAL else 4:]):
        return K, None
    kind, coeffs = _DISTORTION[model]
    if width <= 0 or height <= 0:
        raise InputError(f"{where}: image size {width}x{height} must be positive")
    try:
        dist = Distortion(kind, coeffs(params), K)
        return dist.pinhole(width, height), dist
    except InputError as e:
        raise InputError(f"{where}: {e}") from None


# --------------------------------------------------------------------------------------------
# text


def _read_text(path: Path) -> list[str]:
    try:
        return [ln for ln in path.read_text(encoding="utf-8").splitlines() if not ln.startswith("#")]
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file; is it a binary model? (use cameras.bin / images.bin)") from None


def _text_cameras(path: Path) -> dict[int, tuple[int, int, np.ndarray, Distortion | None]]:
    cams: dict[int, tuple[int, int, np.ndarray, Distortion | None]] = {}
    for ln in _read_text(path):
        tok = ln.split()
        if not tok:
            continue
        where = f"{path}: camera line {ln[:60]!r}"
        if len(tok) < 5:
            raise InputError(f"{where}: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS...")
        try:
            cid, w, h = int(tok[0]), int(tok[2]), int(tok[3])
        except ValueError:
            raise InputError(f"{where}: id, width and height must be integers") from None
        params = [parse_number(x, f"{where}: parameter {i}") for i, x in enumerate(tok[4:])]
        cams[cid] = (w, h, *_intrinsic(tok[1], params, where, w, h))
    return cams


def _text_images(path: Path) -> list[tuple[list[float], list[float], int, str]]:
    lines = _read_text(path)
    out = []
    for k in range(0, len(lines), 2):  # every image has a pose line and a points line (possibly empty)
        if not lines[k].strip():
            continue
        tok = lines[k].split()
        if len(tok) < 10:
            raise InputError(f"{path}: malformed image line {lines[k][:80]!r} "
                             "(expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME)")
        where = f"{path}: image line {lines[k][:80]!r}"
        try:
            cid = int(tok[8])
        except ValueError:
            raise InputError(f"{where}: CAMERA_ID {tok[8][:40]!r} is not an integer") from None
        q = [parse_number(x, f"{where}: {n}") for x, n in zip(tok[1:5], ("QW", "QX", "QY", "QZ"))]
        t = [parse_number(x, f"{where}: {n}") for x, n in zip(tok[5:8], ("TX", "TY", "TZ"))]
        out.append((q, t, cid, " ".join(tok[9:])))
    return out


# --------------------------------------------------------------------------------------------
# binary


class _Reader:
    def __init__(self, path: Path) -> None:
        self.path, self.data, self.pos = path, path.read_bytes(), 0

    def take(self, fmt: str) -> tuple:
        n = struct.calcsize(fmt)
        if self.pos + n > len(self.data):
            raise InputError(f"{self.path}: truncated binary model (needs {n} more bytes at offset {self.pos})")
        out = struct.unpack_from(fmt, self.data, self.pos)
        self.pos += n
        return out

    def count(self, what: str) -> int:
        (n,) = self.take("<Q")
        if n > _MAX_COUNT:
            raise InputError(f"{self.path}: implausible number of {what} ({n}); the file is corrupt")
        return n

    def cstring(self) -> str:
        end = self.data.find(b"\x00", self.pos)
        if end < 0:
            raise InputError(f"{self.path}: truncated binary model (unterminated image name)")
        raw, self.pos = self.data[self.pos:end], end + 1
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError:
            raise InputError(f"{self.path}: image name at offset {self.pos} is not UTF-8") from None


def _bin_cameras(path: Path) -> dict[int, tuple[int, int, np.ndarray, Distortion | None]]:
    r = _Reader(path)
    cams = {}
    for _ in range(r.count("cameras")):
        cid, model_id, w, h = r.take("<iiQQ")
        if model_id not in CAMERA_MODELS:
            raise InputError(f"{path}: camera {cid} has unknown model id {model_id}")
        name, n = CAMERA_MODELS[model_id]
        params = list(r.take(f"<{n}d"))
        if w > 2**31 or h > 2**31:
            raise InputError(f"{path}: camera {cid} has an implausible size {w}x{h}")
        cams[cid] = (int(w), int(h), *_intrinsic(name, params, f"{path}: camera {cid}", int(w), int(h)))
    return cams


def _bin_images(path: Path) -> list[tuple[list[float], list[float], int, str]]:
    r = _Reader(path)
    out = []
    for _ in range(r.count("images")):
        _image_id, qw, qx, qy, qz, tx, ty, tz, cid = r.take("<i7di")
        name = r.cstring()
        n_pts = r.count("2-D points")
        if r.pos + 24 * n_pts > len(r.data):
            raise InputError(f"{path}: truncated binary model (points of image {name!r})")
        r.pos += 24 * n_pts
        out.append(([qw, qx, qy, qz], [tx, ty, tz], cid, name))
    return out


# --------------------------------------------------------------------------------------------


def load(
    model_dir: Path,
    *,
    mesh: str | os.PathLike | None = None,
    image_dir: str | os.PathLike | None = None,
) -> Scene:
    """Load a COLMAP model (text preferred when both are present).

    Parameters
    ----------
    model_dir : pathlib.Path
        Folder with ``cameras.txt`` + ``images.txt`` or ``cameras.bin`` + ``images.bin``.
    mesh : path-like
        Mesh file, absolute or relative to ``model_dir`` (required).
    image_dir : path-like, optional
        Folder of the images; default ``images/`` next to the model or in its parent folders.

    Raises
    ------
    InputError
        No mesh, missing or malformed model files, unsupported camera models, unknown camera ids.
    """
    if mesh is None:
        raise InputError(f"{model_dir} is a COLMAP model: pass the mesh explicitly (mesh=... / --mesh)")
    text = (model_dir / "cameras.txt").is_file() and (model_dir / "images.txt").is_file()
    if text:
        cams, images, imgs_file = _text_cameras(model_dir / "cameras.txt"), _text_images(model_dir / "images.txt"), "images.txt"
    else:
        cams, images, imgs_file = _bin_cameras(model_dir / "cameras.bin"), _bin_images(model_dir / "images.bin"), "images.bin"
    if image_dir is None:
        cands = [model_dir / "images", model_dir.parent / "images", model_dir.parent.parent / "images"]
        image_dir = next((c for c in cands if c.is_dir()), model_dir)
    image_dir = Path(image_dir)
    views = []
    for q, t, cid, name in images:
        where = f"{model_dir / imgs_file}: image {name!r:.80}"
        if cid not in cams:
            raise InputError(f"{where} refers to camera {cid}, which the model's cameras do not define")
        if not name or "\x00" in name:
            raise InputError(f"{where}: empty image name")
        w, h, K, dist = cams[cid]
        ext = np.eye(4)
        ext[:3, :3] = qvec_to_rotmat(q)
        ext[:3, 3] = t
        try:
            views.append(View(name=Path(name).stem, image=image_dir / name, intrinsic=K, extrinsic=ext, width=w, height=h,
                              distortion=dist))
        except InputError as e:
            raise InputError(f"{where}: {e}") from None
    if not views:
        raise InputError(f"{model_dir / imgs_file}: the model has no registered images")
    mesh_path = Path(mesh)
    if not mesh_path.is_absolute() and not mesh_path.exists():
        mesh_path = model_dir / mesh_path
    return Scene(mesh=mesh_path, views=tuple(views))
