"""Open3D RGB-D folders (the layout of ``open3d.data.SampleFountainRGBDImages``).

::

    root/image/*.jpg|png      colour images, paired with the poses in sorted order
    root/depth/*.png          optional depth maps (uint16, ``depth_scale`` units per metre)
    root/scene/key.log        camera-to-world 4x4 poses, blocks of a header line + 4 rows

The intrinsic is not in the files: PrimeSense (fx = fy = 525, cx = 319.5, cy = 239.5, for
640x480 images) unless given, as a matrix or a file (:func:`read_intrinsic`: Open3D's
``PinholeCameraIntrinsic`` JSON); images of another size need it. The mesh is not part of the
layout and must be passed.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from .._shared.numbers import check_numbers
from ..errors import InputError
from ..scene import PRIMESENSE_INTRINSIC, Scene, View
from .missing import MissingImage, check_photo, missing_images

__all__ = ["IMAGE_EXTENSIONS", "detect", "load", "read_intrinsic", "read_log_trajectory"]

IMAGE_EXTENSIONS = frozenset({".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp"})


def detect(path: Path) -> Path | None:
    """``path`` when it is an RGB-D folder (``image/`` and ``scene/key.log``), else None."""
    return path if path.is_dir() and (path / "scene" / "key.log").is_file() and (path / "image").is_dir() else None


def read_log_trajectory(path: str | os.PathLike) -> list[np.ndarray]:
    """Read a ``.log`` trajectory: a list of camera-to-world (4, 4) float64 poses.

    Raises
    ------
    InputError
        Not text, blocks not of 5 lines, non-numeric or non-finite entries, singular poses.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text .log trajectory (not UTF-8)") from None
    rows = [ln.split() for ln in text.splitlines() if ln.strip()]
    if len(rows) % 5:
        raise InputError(f"{path}: a .log trajectory has blocks of 5 lines (header + 4x4 matrix); got {len(rows)} lines")
    poses = []
    for b in range(0, len(rows), 5):
        block = rows[b + 1 : b + 5]
        if any(len(r) != 4 for r in block):
            raise InputError(f"{path}: block {b // 5} does not hold a 4x4 matrix (4 rows of 4 numbers)")
        try:
            pose = np.array([[float(x) for x in r] for r in block], dtype=np.float64)
        except ValueError:
            raise InputError(f"{path}: block {b // 5} does not hold a 4x4 numeric matrix") from None
        check_numbers(pose, f"{path}: pose {b // 5}", fix="fix the trajectory")
        if abs(np.linalg.det(pose[:3, :3])) < 1e-9:
            raise InputError(f"{path}: pose {b // 5} is singular (its rotation has determinant 0); fix the trajectory")
        poses.append(pose)
    return poses


def read_intrinsic(path: str | os.PathLike) -> tuple[np.ndarray, tuple[int, int] | None]:
    """Read a pinhole intrinsic file: Open3D's ``PinholeCameraIntrinsic`` JSON, or a 3x3 text matrix.

    The JSON is what ``open3d.io.write_pinhole_camera_intrinsic`` writes: ``width``, ``height``
    and ``intrinsic_matrix``, nine numbers in column-major order; a ``PinholeCameraParameters``
    JSON (its ``intrinsic`` member) is read too. Pixel centres are at integer coordinates, as ours.

    Returns
    -------
    intrinsic : (3, 3) float64
    size : (width, height) or None
        The image size the file states (None for a text matrix).

    Raises
    ------
    InputError
        Missing or malformed file.
    """
    path = Path(path)
    where = f"intrinsic file {path}"
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"{where}: cannot read it ({getattr(e, 'strerror', None) or e}); give Open3D's "
                         "PinholeCameraIntrinsic JSON or a 3x3 text matrix") from None
    if path.suffix.lower() == ".json" or text.lstrip().startswith("{"):
        try:
            data = json.loads(text)
        except (json.JSONDecodeError, RecursionError) as e:
            raise InputError(f"{where}: not valid JSON ({e})") from None
        if isinstance(data, dict) and isinstance(data.get("intrinsic"), dict):
            data = data["intrinsic"]
        try:
            m = np.asarray(data["intrinsic_matrix"], dtype=np.float64)
            w, h = int(data["width"]), int(data["height"])
            if m.shape != (9,) or isinstance(data["width"], bool) or w != data["width"] or h != data["height"]:
                raise ValueError
        except (TypeError, KeyError, ValueError):
            raise InputError(f"{where}: expected Open3D's PinholeCameraIntrinsic JSON: 'width', 'height' (integers) "
                             "and 'intrinsic_matrix' (9 numbers, column-major)") from None
        return m.reshape(3, 3).T.copy(), (w, h)
    try:
        K = np.loadtxt(path.open(encoding="utf-8"), dtype=np.float64, ndmin=2)
    except ValueError:
        K = None
    if K is None or K.shape != (3, 3):
        raise InputError(f"{where}: expected Open3D's PinholeCameraIntrinsic JSON or a 3x3 text matrix")
    return K, None


def _check_intrinsic_size(K: np.ndarray, size: tuple[int, int] | None, w: int, h: int, given: object,
                          root: Path) -> None:
    """An RGB-D folder's intrinsic must be for its images' size (the default is for 640x480)."""
    if given is None and (w, h) != (640, 480):
        scaled = ""
        if w * 480 == h * 640:  # the PrimeSense camera at another resolution: its intrinsic scaled
            k = w / 640.0
            scaled = (f" (PrimeSense's scaled to {w}x{h}: fx = fy = {525 * k:g}, cx = {320 * k - 0.5:g}, "
                      f"cy = {240 * k - 0.5:g})")
        raise InputError(
            f"{root}: image/ holds {w}x{h} images, but no intrinsic was given and the default (PrimeSense: fx = fy "
            f"= 525, cx = 319.5, cy = 239.5) is for 640x480 images; give the colour camera's intrinsic{scaled}: "
            "intrinsic=FILE (--intrinsic FILE), Open3D's PinholeCameraIntrinsic JSON as "
            "open3d.io.write_pinhole_camera_intrinsic writes it")
    where = f"intrinsic {given}" if isinstance(given, (str, os.PathLike)) else "the intrinsic given"
    if size is not None and tuple(size) != (w, h):
        raise InputError(f"{root}: {where} is for {size[0]}x{size[1]} images but image/ holds {w}x{h} images; give "
                         "the intrinsic of these images (scale fx, fy, cx + 0.5, cy + 0.5 with the size)")
    if not (-0.5 <= K[0, 2] <= w - 0.5 and -0.5 <= K[1, 2] <= h - 0.5):
        raise InputError(f"{root}: {where} puts the principal point at ({K[0, 2]:g}, {K[1, 2]:g}), outside the "
                         f"{w}x{h} images of image/: it is for another image size; give the intrinsic of these images")


def _list_images(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS and not p.name.startswith("."))


def load(
    root: Path,
    *,
    mesh: str | os.PathLike | None = None,
    intrinsic: np.ndarray | None = None,
    depth_scale: float = View.depth_scale,
) -> Scene:
    """Load an Open3D RGB-D folder.

    Parameters
    ----------
    root : pathlib.Path
        The folder.
    mesh : path-like
        Mesh file, absolute or relative to ``root`` (required).
    intrinsic : (3, 3) array or path-like, optional
        The colour camera's pinhole matrix, or a file holding it (:func:`read_intrinsic`);
        default :data:`~o3d_seqcc.scene.PRIMESENSE_INTRINSIC`, for 640x480 images only.
    depth_scale : float, default :attr:`View.depth_scale <o3d_seqcc.scene.View>` (1000.0)

    Raises
    ------
    InputError
        No mesh given, counts of images / depth maps / poses that differ, bad poses, an
        intrinsic for another image size (the default one included).
    """
    if mesh is None:
        cands = sorted((root / "scene").glob("*.ply"))
        raise InputError(
            f"{root} is an Open3D RGB-D folder: pass the mesh explicitly (mesh=... / --mesh), "
            f"e.g. one of {[c.name for c in cands]}"
        )
    img_dir, depth_dir, log = root / "image", root / "depth", root / "scene" / "key.log"
    images = _list_images(img_dir)
    if not images:
        raise InputError(f"{root}: image/ holds no images ({', '.join(sorted(IMAGE_EXTENSIONS))})")
    depths = _list_images(depth_dir) if depth_dir.is_dir() else []
    poses = read_log_trajectory(log)
    if len(images) != len(poses):
        raise InputError(f"{root}: {len(images)} images in image/ but {len(poses)} poses in scene/key.log")
    if depths and len(depths) != len(images):
        raise InputError(f"{root}: {len(images)} images but {len(depths)} depth maps; they are paired in sorted order")
    size = None
    if intrinsic is None:
        K = PRIMESENSE_INTRINSIC
    elif isinstance(intrinsic, (str, os.PathLike)):
        K, size = read_intrinsic(intrinsic)
    else:
        K = np.asarray(intrinsic, dtype=np.float64)
    mesh_path = Path(mesh)
    if not mesh_path.is_absolute() and not mesh_path.exists():
        mesh_path = root / mesh_path
    w, h = _first_size(images, root)  # the file layer: regular files only, pixel budget, header only
    if np.shape(K) == (3, 3):
        _check_intrinsic_size(K, size, w, h, intrinsic, root)
    views = []
    for i, (img, pose) in enumerate(zip(images, poses)):
        ext = np.linalg.inv(pose)
        ext[3] = [0.0, 0.0, 0.0, 1.0]
        try:
            views.append(View(name=img.stem, image=img, intrinsic=K, extrinsic=ext, width=w, height=h,
                              depth=depths[i] if depths else None, depth_scale=depth_scale))
        except InputError as e:
            raise InputError(f"{log}: pose {i}: {e}") from None
    return Scene(mesh=mesh_path, views=tuple(views))


def _first_size(images: list[Path], root: Path) -> tuple[int, int]:
    """The size of the first readable image (every image is checked by ``Scene.validate``); none readable: one
    error listing them all."""
    unreadable = []
    for img in images:
        size = check_photo(img.stem, img)
        if not isinstance(size, MissingImage):
            return size
        unreadable.append(size)
    raise missing_images(unreadable, total=len(images), where=str(root))
