"""Bundler v0.3 reconstructions: ``bundle.out`` and the ``list.txt`` of its images.

The format is snavely/bundler_sfm's ``README.md`` ("Output format")::

    # Bundle file v0.3
    <num_cameras> <num_points>
    per camera:   <f> <k1> <k2>          focal length in pixels, radial distortion
                  <R>                    3 lines: the rotation, row by row
                  <t>                    1 line: the translation
    per point:    position, colour, view list    (not read: the points are not needed)

``list.txt`` names the images, one per line, in the order of the cameras, optionally followed
by ``0 <focal>`` (the EXIF focal estimate); the path ends at the first blank, as Bundler's
``ReadListFile`` cuts it (``src/RadialUndistort.cpp``). Paths are relative to the folder of
``list.txt``, which is looked for beside ``bundle.out`` and in its parent (Bundler writes
``bundle/bundle.out`` beside the ``list.txt`` it was run on); ``image_dir=`` looks the images up
by file name instead.

A camera projects ``X`` as ``P = R X + t``, ``p = -P / P.z``, ``p' = f r(p) p`` with ``r(p) = 1 +
k1 |p|^2 + k2 |p|^4``: pixels from the image centre, x right, y up, the camera looking down -z
(OpenGL axes). In OpenCV axes ``(x, y, z) = (P.x, -P.y, -P.z)``, so the extrinsic is
``diag(1, -1, -1) [R | t]``, ``p = (x / z, -y / z)`` and the pixel, y down, is ``f r (x / z, y /
z)`` from the centre: OpenCV's model with ``(k1, k2, p1, p2) = (k1, k2, 0, 0)`` on focal-
normalised coordinates, in the same direction (the ideal point distorted; RadialUndistort
samples the photo at ``r`` times the undistorted point). The centre is ``((w - 1) / 2, (h - 1) /
2)`` with pixel centres at integers, ours: Bundler's ``ImageData::LoadKeys`` flips the keys' y
(``h - 1 - y``) and subtracts ``0.5 (w - 1)``, ``0.5 (h - 1)``, and ``Bundle2PMVS`` writes ``K =
[[-f, 0, 0.5 w - 0.5], [0, f, 0.5 h - 0.5]]``. The image size is read from the image header.
Distorted cameras are undistorted on the fly (:mod:`o3d_seqcc.geometry.distortion`); the view's
camera is :meth:`~o3d_seqcc.geometry.distortion.Distortion.pinhole`.

Cameras with ``f = 0`` (not reconstructed: Bundler writes zeros) are skipped with one warning.
MeshLab's Bundler import reads the same pair (``vcglib`` ``wrap/io_trimesh/import_out.h``), so any
``*.out`` whose first line is the header is taken. Other versions are refused. The file holds
no mesh: ``mesh=`` is required.
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path
from typing import BinaryIO, Iterator

import numpy as np

from .._shared.numbers import parse_number
from ..errors import InputError
from ..geometry.distortion import Distortion
from ..scene import Scene, View
from .paths import join_path
from .regular_files import open_regular
from .missing import MissingImage, check_photo, missing_images

__all__ = ["HEADER", "detect", "find_list", "load"]

logger = logging.getLogger(__name__)

#: the first line of a Bundler v0.3 file
HEADER = "# Bundle file v0.3"
_FLIP = np.diag([1.0, -1.0, -1.0])
_MAX_LINE = 1 << 16
_MAX_CAMERAS = 1_000_000
_MAX_POINTS = 2_000_000_000


def _first_line(path: Path) -> str:
    try:
        with path.open("rb") as fh:
            return fh.readline(256).decode("utf-8", "replace").strip()
    except OSError:
        return ""


def detect(path: Path) -> Path | None:
    """``bundle.out``, any ``*.out`` starting with a Bundler header, or a folder holding ``bundle[/]bundle.out``."""
    if path.is_dir():
        return next((p for p in (path / "bundle.out", path / "bundle" / "bundle.out") if p.is_file()), None)
    if not path.is_file():
        return None
    if path.name == "bundle.out":
        return path
    if path.suffix.lower() == ".out" and _first_line(path).startswith("# Bundle file v"):
        return path
    return None


def find_list(bundle: Path) -> Path | None:
    """The ``list.txt`` of ``bundle``: beside it, else in its parent folder."""
    return next((p for p in (bundle.parent / "list.txt", bundle.parent.parent / "list.txt") if p.is_file()), None)


def _lines(fh: BinaryIO, path: Path) -> Iterator[tuple[int, list[str]]]:
    """(1-based line number, tokens) of the non-blank lines."""
    n = 0
    while True:
        raw = fh.readline(_MAX_LINE + 1)
        if not raw:
            return
        n += 1
        if len(raw) > _MAX_LINE and not raw.endswith(b"\n"):
            raise InputError(f"{path}: line {n} is longer than {_MAX_LINE // 1024} KB; not a Bundler file")
        try:
            toks = raw.decode("utf-8").split()
        except UnicodeDecodeError:
            raise InputError(f"{path}: line {n} is not UTF-8 text; not a Bundler file") from None
        if toks:
            yield n, toks


def _numbers(item: tuple[int, list[str]] | None, path: Path, what: str, count: int = 3) -> tuple[list[float], int]:
    if item is None:
        raise InputError(f"{path}: the file ends before {what}; it is truncated (write it again)")
    line, toks = item
    where = f"{path}: line {line}"
    if len(toks) != count:
        raise InputError(f"{where}: {what} needs {count} numbers, got {len(toks)} ({' '.join(toks)[:60]!r})")
    return [parse_number(t, f"{where}: {what}") for t in toks], line


def _read_bundle(path: Path) -> tuple[list[dict], int]:
    """The cameras of a bundle file (points are not read) and its number of points."""
    with open_regular(path, "Bundler file") as fh:
        lines = _lines(fh, path)
        head = next(lines, None)
        text = " ".join(head[1]) if head else ""
        if head is None or head[0] != 1 or not text.startswith("# Bundle file"):
            raise InputError(f"{path}: line 1: not a Bundler file (expected the header {HEADER!r})")
        if text != HEADER:
            raise InputError(f"{path}: line 1: {text[:40]!r}: only Bundler v0.3 files are read ({HEADER!r}); write "
                             "the reconstruction as v0.3")
        counts = next(lines, None)
        if counts is None or len(counts[1]) != 2 or not all(t.isascii() and t.isdigit() for t in counts[1]):
            where = f"line {counts[0]}" if counts else "the end of the file"
            raise InputError(f"{path}: {where}: expected '<num_cameras> <num_points>' (two non-negative integers)")
        n_cams, n_points = (int(t) for t in counts[1])
        if n_cams > _MAX_CAMERAS or n_points > _MAX_POINTS:
            raise InputError(f"{path}: line {counts[0]}: implausible counts {n_cams} cameras, {n_points} points; "
                             "the file is corrupt")
        cams = []
        for i in range(n_cams):
            what = f"camera {i}"
            (f, k1, k2), line = _numbers(next(lines, None), path, f"{what}'s '<f> <k1> <k2>'")
            R = []
            for r in range(3):
                row, row_line = _numbers(next(lines, None), path, f"{what}'s rotation row {r + 1}")
                if max(map(abs, row)) > 1.001:
                    raise InputError(f"{path}: line {row_line}: {what}'s rotation row {r + 1}: the entries of a "
                                     f"rotation lie in [-1, 1], got {max(map(abs, row)):.6g}")
                R.append(row)
            t, t_line = _numbers(next(lines, None), path, f"{what}'s translation")
            if max(map(abs, t)) > 1e12:
                raise InputError(f"{path}: line {t_line}: {what}'s translation {t} is implausible")
            where = f"{path}: line {line}: {what}"
            if f < 0:
                raise InputError(f"{where}: negative focal length {f}; Bundler's focal lengths are > 0 (0: not "
                                 "reconstructed)")
            if f > 1e7 or abs(k1) > 1e6 or abs(k2) > 1e6:
                raise InputError(f"{where}: implausible focal length or distortion ({f}, {k1}, {k2})")
            cams.append({"f": f, "k": (k1, k2), "R": np.array(R), "t": np.array(t), "line": line})
    return cams, n_points


def _read_list(path: Path) -> list[tuple[str, int]]:
    """(image path, 1-based line) per line of ``list.txt``; trailing blank lines dropped."""
    with open_regular(path, "image list") as fh:
        raw = fh.read(64 * 2**20 + 1)
    if len(raw) > 64 * 2**20:
        raise InputError(f"{path}: more than 64 MB; not a Bundler image list")
    try:
        lines = [ln.rstrip("\r") for ln in raw.decode("utf-8").split("\n")]
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file; not a Bundler image list") from None
    while lines and not lines[-1].strip():
        lines.pop()
    out = []
    for i, ln in enumerate(lines, 1):
        toks = ln.split()
        ok = len(toks) == 1 or len(toks) == 3 and _is_number(toks[1]) and _is_number(toks[2])
        if not ok or "\x00" in toks[0] or len(toks[0]) > 4096:
            raise InputError(f"{path}: line {i}: expected an image path, optionally followed by '0 <focal>', got "
                             f"{ln[:60]!r} (a path ends at its first blank, as Bundler reads it)")
        out.append((toks[0].replace("\\", "/"), i))
    return out


def _is_number(tok: str) -> bool:
    try:
        return math.isfinite(float(tok))
    except ValueError:
        return False


def _intrinsic(f: float, k: tuple[float, float], w: int, h: int) -> tuple[np.ndarray, Distortion | None]:
    K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
    if k == (0.0, 0.0):
        return K, None
    dist = Distortion("opencv", (k[0], k[1], 0.0, 0.0), K)
    return dist.pinhole(w, h), dist


def load(path: Path, *, mesh: str | os.PathLike | None = None, image_dir: str | os.PathLike | None = None) -> Scene:
    """Load a Bundler v0.3 reconstruction.

    Parameters
    ----------
    path : pathlib.Path
        ``bundle.out`` (or another ``*.out`` with the header); its ``list.txt`` beside it or in
        its parent folder.
    mesh : path-like
        Mesh file, absolute or relative to the folder of ``bundle.out`` (required).
    image_dir : path-like, optional
        Folder to look the images up in by file name, instead of the paths of ``list.txt``.

    Raises
    ------
    InputError
        No mesh, no ``list.txt``, malformed files (file and line named), counts that differ,
        missing or unreadable images (a :class:`~o3d_seqcc.errors.MissingImagesError` listing
        them all, with their ``list.txt`` lines), no reconstructed camera.
    """
    if mesh is None:
        raise InputError(f"{path} is a Bundler file, which holds no mesh: pass the mesh explicitly (mesh=... / --mesh)")
    cams, n_points = _read_bundle(path)
    lst = find_list(path)
    if lst is None:
        raise InputError(f"{path}: no list.txt (the image list Bundler ran on) beside it or in {path.parent.parent}; "
                         "put it there")
    images = _read_list(lst)
    if len(images) != len(cams):
        raise InputError(f"{path} has {len(cams)} cameras but {lst} lists {len(images)} images; give the list the "
                         "reconstruction was made from (one line per camera, in order)")
    img_root = None if image_dir is None else Path(image_dir)
    if img_root is not None and not img_root.is_dir():
        raise InputError(f"image_dir {img_root} is not a folder")
    views, names, skipped, missing = [], set(), [], []
    for i, (cam, (name, line)) in enumerate(zip(cams, images)):
        if cam["f"] == 0:
            skipped.append(name)
            continue
        rel = Path(name)
        file = img_root / rel.name if img_root is not None else rel if rel.is_absolute() else join_path(lst.parent, name)
        view_name = file.stem if file.stem not in names else f"{file.stem}_{i}"
        names.add(view_name)
        size = check_photo(view_name, file, where=f"{lst}: line {line}")  # missing or unreadable: listed below
        if isinstance(size, MissingImage):
            missing.append(size)
            continue
        w, h = size
        where = f"{path}: line {cam['line']}: camera {i} ({name!r:.80})"
        ext = np.eye(4)
        ext[:3, :3] = _FLIP @ cam["R"]
        ext[:3, 3] = _FLIP @ cam["t"]
        try:
            K, dist = _intrinsic(cam["f"], cam["k"], w, h)
            views.append(View(name=view_name, image=file, intrinsic=K, extrinsic=ext, width=w, height=h,
                              distortion=dist))
        except InputError as e:
            raise InputError(f"{where}: {e}") from None
    if skipped:
        logger.warning("%s: %d camera(s) have focal length 0 (not reconstructed) and are skipped: %s", path,
                       len(skipped), ", ".join(skipped[:5]) + (" ..." if len(skipped) > 5 else ""))
    mesh_path = Path(mesh)
    if not mesh_path.is_absolute() and not mesh_path.exists():
        mesh_path = path.parent / mesh_path
    if missing:
        hint = "" if img_root is not None else "pass image_dir= (--image-dir DIR) if the images are elsewhere"
        raise missing_images(missing, total=len(views) + len(missing), where=str(path), hint=hint,
                             scene=Scene(mesh=mesh_path, views=tuple(views)) if views else None)
    if not views:
        raise InputError(f"{path}: no reconstructed camera (every focal length is 0)")
    logger.info("%s: Bundler v0.3, %d of %d cameras reconstructed, %d points (not read), images from %s", path,
                len(views), len(cams), n_points, lst)
    return Scene(mesh=mesh_path, views=tuple(views))
