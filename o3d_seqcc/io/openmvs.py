"""OpenMVS interface files (``scene.mvs``): the cameras, poses and images ``TextureMesh`` reads.

The format is documented by OpenMVS's ``libs/MVS/Interface.h`` (``MVS::Interface``), binary,
little-endian::

    "MVSI", uint32 version, uint32 reserved      (no header at all in version 0)
    platforms: uint64 n, then per platform
        name                                      (string: uint64 length + bytes)
        cameras: uint64 n, then per camera
            name, bandName (version > 3), uint32 width, height (version > 0),
            K (3x3 float64, row-major), R (3x3), C (3 float64): the camera on its platform
        poses: uint64 n, then per pose R (3x3 float64), C (3 float64)
    images: uint64 n, then per image
        name, maskName (version > 4), uint32 platformID, cameraID, poseID, ID (version > 2),
        float32 minDepth, avgDepth, maxDepth + viewScores (version > 6: uint64 n x 24 bytes)
    vertices, normals, colours, lines, ..., transform, OBB   (not read: the points are not needed)

A pose's ``R`` rotates world to camera (OpenCV axes) and ``C`` is the position; a camera mounted
on a platform composes as ``R = R_cam R_pose``, ``C = R_pose^T C_cam + C_pose``, so the
extrinsic is ``[R | -R C]``. ``K``'s integer coordinates are pixel centres, as ours. A camera
with ``width`` and ``height`` (version > 0 and non-zero) has ``K`` in pixels; without, ``K`` is
normalised by ``s = max(width, height)`` of the image (read from its header) the way OpenMVS's
``Camera::ScaleK`` does: ``f = f_n s``, ``c = (c_n + 0.5) s - 0.5``, and a principal point of
(0, 0) means the image centre. Images without a pose (``poseID`` = 2^32 - 1, not calibrated)
are skipped with a warning. Versions 0 to 7 are read.

Image paths are relative to the ``.mvs`` file (absolute ones are kept; ``\\`` read as ``/``),
or looked up by file name in ``image_dir``. An image's ``maskName`` (version > 4; OpenMVS's
segmentation mask, by default ``<image>.mask.png``) is found the same way and becomes the view's
mask (:mod:`o3d_seqcc.io.masks`): pixels equal to 0 are masked out, as ``TextureMesh
--ignore-mask-label 0`` reads it (``ImportIgnoreMask``, ``libs/MVS/DepthMap.cpp``: ``mask !=
label`` is kept); a named mask that is not there is warned about and the photo used whole
(OpenMVS's ``can not load the segmentation mask``). The interface holds no mesh: ``mesh=`` or, as
OpenMVS's ``TextureMesh`` does, the ``.ply`` of the same name beside the file. OpenMVS's own
project files (header ``MVS\\0``, written when a scene holds a mesh) are a different,
undocumented archive and are refused with the way out.
"""

from __future__ import annotations

import logging
import os
import struct
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..errors import InputError
from ..scene import Scene, View
from .missing import MissingImage, check_photo, missing_images

__all__ = ["MAX_VERSION", "NO_ID", "detect", "load"]

logger = logging.getLogger(__name__)

#: the newest interface version read (OpenMVS 2.3's MVSI_PROJECT_VER)
MAX_VERSION = 7
#: OpenMVS's invalid index (an image without a pose)
NO_ID = 2**32 - 1
_MAX_COUNT = 10_000_000
_MAX_STRING = 1 << 16


def detect(path: Path) -> Path | None:
    """``path`` when it is a ``.mvs`` file or starts with the interface header, else None."""
    if not path.is_file():
        return None
    if path.suffix.lower() == ".mvs":
        return path
    try:
        with path.open("rb") as fh:
            return path if fh.read(4) == b"MVSI" else None
    except OSError:
        return None


class _Reader:
    """Reads the little-endian fields of an interface file, checking every length."""

    def __init__(self, fh: BinaryIO, path: Path) -> None:
        self.fh, self.path = fh, path

    def take(self, fmt: str) -> tuple:
        n = struct.calcsize(fmt)
        data = self.fh.read(n)
        if len(data) != n:
            raise InputError(f"{self.path}: truncated OpenMVS interface file (needs {n} more bytes at offset "
                             f"{self.fh.tell()}); write it again")
        return struct.unpack(fmt, data)

    def count(self, what: str) -> int:
        (n,) = self.take("<Q")
        if n > _MAX_COUNT:
            raise InputError(f"{self.path}: implausible number of {what} ({n}); the file is corrupt or not an "
                             "OpenMVS interface file")
        return n

    def string(self, what: str) -> str:
        (n,) = self.take("<Q")
        if n > _MAX_STRING:
            raise InputError(f"{self.path}: implausible {what} length ({n} bytes); the file is corrupt")
        raw = self.fh.read(n)
        if len(raw) != n:
            raise InputError(f"{self.path}: truncated OpenMVS interface file (in a {what})")
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError:
            return raw.decode("latin-1")

    def matrix(self) -> np.ndarray:
        return np.array(self.take("<9d"), dtype=np.float64).reshape(3, 3)

    def point(self) -> np.ndarray:
        return np.array(self.take("<3d"), dtype=np.float64)


def _header(fh: BinaryIO, path: Path) -> int:
    head = fh.read(4)
    if head == b"MVSI":
        rest = fh.read(8)
        if len(rest) != 8:
            raise InputError(f"{path}: truncated OpenMVS interface file (header)")
        version, _reserved = struct.unpack("<II", rest)
        if version > MAX_VERSION:
            raise InputError(f"{path}: OpenMVS interface version {version}; this reader knows versions 0 to "
                             f"{MAX_VERSION} (upgrade o3d_seqcc, or write the file with an older OpenMVS)")
        return version
    if head == b"MVS\0":
        raise InputError(f"{path}: an OpenMVS project archive (written when the scene holds a mesh), not the "
                         "documented interface format; give the interface scene it came from (e.g. scene.mvs or "
                         "scene_dense.mvs, as InterfaceCOLMAP / DensifyPointCloud write it) with the mesh as --mesh "
                         "(e.g. scene_dense_mesh.ply)")
    if path.suffix.lower() != ".mvs":
        raise InputError(f"{path}: not an OpenMVS interface file (no MVSI header)")
    fh.seek(0)
    return 0


def _read(path: Path) -> tuple[int, list, list]:
    """(version, platforms, images) of an interface file; points and the rest are not read."""
    try:
        fh = path.open("rb")
    except OSError as e:
        raise InputError(f"{path}: cannot read the OpenMVS scene ({e.strerror})") from None
    with fh:
        version = _header(fh, path)
        r = _Reader(fh, path)
        platforms = []
        for _ in range(r.count("platforms")):
            name = r.string("platform name")
            cams = []
            for _ in range(r.count("cameras")):
                cam = {"name": r.string("camera name")}
                if version > 3:
                    cam["band"] = r.string("camera band name")
                cam["width"], cam["height"] = r.take("<II") if version > 0 else (0, 0)
                cam["K"], cam["R"], cam["C"] = r.matrix(), r.matrix(), r.point()
                cams.append(cam)
            poses = [(r.matrix(), r.point()) for _ in range(r.count("poses"))]
            platforms.append({"name": name, "cameras": cams, "poses": poses})
        images = []
        for _ in range(r.count("images")):
            img = {"name": r.string("image name")}
            img["mask"] = r.string("mask name") if version > 4 else ""
            img["platform"], img["camera"], img["pose"] = r.take("<III")
            if version > 2:
                r.take("<I")
            if version > 6:
                r.take("<3f")
                n = r.count("view scores")
                if len(fh.read(24 * n)) != 24 * n:
                    raise InputError(f"{path}: truncated OpenMVS interface file (view scores)")
            images.append(img)
    return version, platforms, images


def _intrinsic(cam: dict, size: tuple[int, int], where: str) -> tuple[np.ndarray, int, int]:
    """Our (3, 3) intrinsic and the image size of an interface camera (pixels, or normalised: ``size``, the
    image header's)."""
    K = cam["K"]
    if not np.all(np.isfinite(K)):
        raise InputError(f"{where}: camera K is not finite")
    if cam["width"] > 0 and cam["height"] > 0:
        return K.copy(), int(cam["width"]), int(cam["height"])
    w, h = size  # normalised by max(width, height), as MVS::Camera::ScaleK
    s = float(max(w, h))
    out = np.array([[K[0, 0] * s, K[0, 1] * s, 0.0], [0.0, K[1, 1] * s, 0.0], [0.0, 0.0, 1.0]])
    if K[0, 2] == 0 and K[1, 2] == 0:  # OpenMVS: the image centre
        out[0, 2], out[1, 2] = 0.5 * (w - 1), 0.5 * (h - 1)
    else:
        out[0, 2], out[1, 2] = (K[0, 2] + 0.5) * s - 0.5, (K[1, 2] + 0.5) * s - 0.5
    return out, w, h


def _image_path(name: str, root: Path, image_dir: Path | None) -> Path:
    rel = Path(name.replace("\\", "/"))
    if image_dir is not None:
        return image_dir / rel.name
    return rel if rel.is_absolute() else Path(os.path.normpath(root / rel))


def load(path: Path, *, mesh: str | os.PathLike | None = None, image_dir: str | os.PathLike | None = None) -> Scene:
    """Load an OpenMVS interface file.

    Parameters
    ----------
    path : pathlib.Path
        ``scene.mvs`` (interface versions 0 to 7).
    mesh : path-like, optional
        Mesh file, absolute or relative to the file's folder; default the ``.ply`` of the same
        name beside it (``scene.mvs`` -> ``scene.ply``), as OpenMVS's ``TextureMesh`` does.
    image_dir : path-like, optional
        Folder to look the images up in by file name, instead of the paths in the file.

    Raises
    ------
    InputError
        Truncated or corrupt file, an OpenMVS project archive, a newer version, ids out of
        range, missing or unreadable images (one :class:`~o3d_seqcc.errors.MissingImagesError`
        listing them all), no calibrated image, no mesh.
    """
    version, platforms, images = _read(path)
    root = path.parent
    img_root = None if image_dir is None else Path(image_dir)
    if img_root is not None and not img_root.is_dir():
        raise InputError(f"image_dir {img_root} is not a folder")
    views, names, skipped, missing = [], set(), [], []
    for i, img in enumerate(images):
        where = f"{path}: image {i} ({img['name']!r:.80})"
        if img["pose"] == NO_ID:
            skipped.append(img["name"])
            continue
        if not img["name"]:
            raise InputError(f"{where}: empty image name")
        if img["platform"] >= len(platforms):
            raise InputError(f"{where}: platform {img['platform']} does not exist ({len(platforms)} platforms)")
        plat = platforms[img["platform"]]
        if img["camera"] >= len(plat["cameras"]) or img["pose"] >= len(plat["poses"]):
            raise InputError(f"{where}: camera {img['camera']} or pose {img['pose']} does not exist on platform "
                             f"{img['platform']} ({len(plat['cameras'])} cameras, {len(plat['poses'])} poses)")
        file = _image_path(img["name"], root, img_root)
        name = file.stem if file.stem not in names else f"{file.stem}_{i}"
        names.add(name)
        size = check_photo(name, file, where=where)  # missing or unreadable: listed below
        if isinstance(size, MissingImage):
            missing.append(size)
            continue
        cam = plat["cameras"][img["camera"]]
        Rp, Cp = plat["poses"][img["pose"]]
        R = cam["R"] @ Rp
        C = Rp.T @ cam["C"] + Cp
        K, w, h = _intrinsic(cam, size, where)
        ext = np.eye(4)
        ext[:3, :3] = R
        ext[:3, 3] = -R @ C
        mask = _image_path(img["mask"], root, img_root) if img["mask"] else None
        if mask is not None and not mask.is_file():
            logger.warning("%s: the mask %s is not there: the photo is used whole", where, mask)
            mask = None
        try:
            views.append(View(name=name, image=file, intrinsic=K, extrinsic=ext, width=w, height=h, mask=mask))
        except InputError as e:
            raise InputError(f"{where}: {e}") from None
    if skipped:
        logger.warning("%s: %d image(s) have no pose (not calibrated) and are skipped: %s", path, len(skipped),
                       ", ".join(skipped[:5]) + (" ..." if len(skipped) > 5 else ""))
    if not views and not missing:
        raise InputError(f"{path}: no calibrated image (every image lacks a pose)")
    if mesh is None:
        own = path.with_suffix(".ply")
        if not own.is_file():
            raise InputError(f"{path} is an OpenMVS interface file, which holds no mesh, and {own.name} (the mesh "
                             "TextureMesh would take) is not beside it: pass the mesh (mesh=... / --mesh)")
        mesh_path = own
    else:
        mesh_path = Path(mesh)
        if not mesh_path.is_absolute() and not mesh_path.exists():
            mesh_path = root / mesh_path
    if missing:
        hint = "" if img_root is not None else "pass image_dir= (--image-dir DIR) if the images are elsewhere"
        raise missing_images(missing, total=len(views) + len(missing), where=str(path), hint=hint,
                             scene=Scene(mesh=mesh_path, views=tuple(views)) if views else None)
    logger.info("%s: OpenMVS interface version %d, %d calibrated images, mesh %s", path, version, len(views),
                mesh_path)
    return Scene(mesh=mesh_path, views=tuple(views))
