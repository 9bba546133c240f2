"""Open3D RGB-D folders (the layout of ``open3d.data.SampleFountainRGBDImages``).

::

    root/image/*.jpg|png      colour images, paired with the poses in sorted order
    root/depth/*.png          optional depth maps (uint16, ``depth_scale`` units per metre)
    root/scene/key.log        camera-to-world 4x4 poses, blocks of a header line + 4 rows

The intrinsic is not in the files: PrimeSense (fx = fy = 525, cx = 319.5, cy = 239.5) unless
given. The mesh is not part of the layout and must be passed.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..scene import PRIMESENSE_INTRINSIC, Scene, View
from .files import check_image_file

__all__ = ["IMAGE_EXTENSIONS", "detect", "load", "read_log_trajectory"]

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
        if not np.all(np.isfinite(pose)):
            raise InputError(f"{path}: pose {b // 5} contains NaN/inf")
        if abs(np.linalg.det(pose[:3, :3])) < 1e-9:
            raise InputError(f"{path}: pose {b // 5} is singular (its rotation has determinant 0); fix the trajectory")
        poses.append(pose)
    return poses


def _list_images(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS and not p.name.startswith("."))


def load(
    root: Path,
    *,
    mesh: str | os.PathLike | None = None,
    intrinsic: np.ndarray | None = None,
    depth_scale: float = 1000.0,
) -> Scene:
    """Load an Open3D RGB-D folder.

    Parameters
    ----------
    root : pathlib.Path
        The folder.
    mesh : path-like
        Mesh file, absolute or relative to ``root`` (required).
    intrinsic : (3, 3) array, optional
        Defaults to :data:`~o3d_seqcc.scene.PRIMESENSE_INTRINSIC`.
    depth_scale : float, default 1000.0

    Raises
    ------
    InputError
        No mesh given, counts of images / depth maps / poses that differ, bad poses.
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
    K = PRIMESENSE_INTRINSIC if intrinsic is None else np.asarray(intrinsic, dtype=np.float64)
    mesh_path = Path(mesh)
    if not mesh_path.is_absolute() and not mesh_path.exists():
        mesh_path = root / mesh_path
    w, h, _ = check_image_file(images[0])  # the file layer: regular files only, pixel budget, header only
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
