"""Meshroom / AliceVision SfM data in JSON (``cameras.sfm``, ``*.json`` written by ConvertSfMFormat).

::

    {"version": ["1", "2", "4"],
     "views": [{"viewId": "1", "poseId": "1", "intrinsicId": "7", "path": "/data/IMG_1.JPG",
                "width": "4000", "height": "3000"}, ...],
     "intrinsics": [{"intrinsicId": "7", "width": "4000", "height": "3000", "type": "pinhole",
                     "sensorWidth": "6.17", "focalLength": "4.0" | "pxFocalLength": ["3200", "3200"],
                     "principalPoint": ["0", "0"], "distortionParams": []}, ...],
     "poses": [{"poseId": "1", "pose": {"transform": {"rotation": [9 values], "center": [3 values]}}}]}

Numbers are usually strings (boost property trees). AliceVision's ``Pose3`` maps a world point
``X`` to the camera as ``R (X - C)`` in OpenCV axes; ``rotation`` holds ``R``'s nine entries in
Eigen's storage order (column-major), so read row by row it is ``R^T``, the camera-to-world
rotation. The extrinsic is ``[R | -R C]``.

Intrinsics: ``pxFocalLength`` (one value or fx, fy) in pixels when present, otherwise
``focalLength`` (mm) x width / ``sensorWidth`` (mm), times ``pixelRatio`` for fy when given.
The principal point is relative to the image centre from file version 1.2.1 on (absolute
before); AliceVision's pixel centres are at integers, as ours. Distortion (``type`` or
``distortionType`` radial1 / radialk1, radial3 / radialk3, brown, fisheye4, on focal-normalised
coordinates as AliceVision's ``addDistortion``) is removed on the fly
(:mod:`o3d_seqcc.geometry.distortion`); other distorted types are refused (undistort the images first,
e.g. with Meshroom's PrepareDenseScene).
Views without a pose (not reconstructed) are skipped, with a warning.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..geometry.distortion import Distortion
from .._shared.numbers import check_numbers
from ..errors import InputError
from ..scene import Scene, View
from .paths import find_file
from .masks import attach_masks

__all__ = ["detect", "load"]

logger = logging.getLogger(__name__)


def detect(path: Path) -> Path | None:
    """The SfM JSON to read for ``path`` (a ``.sfm`` file, or a folder holding ``cameras.sfm``), or None."""
    return find_file(path, name="cameras.sfm", suffix=".sfm")


def _num(d: dict, key: str, where: str, n: int | None = None) -> Any:
    """A number (or ``n`` numbers) of ``d[key]``, given as numbers or strings."""
    if key not in d:
        raise InputError(f"{where}: missing {key!r}")
    v = d[key]
    try:
        if n is None:
            if isinstance(v, (list, dict, bool)) or v is None:
                raise ValueError
            return float(check_numbers(float(v), f"{where}: {key!r}", fix="fix or re-export cameras.sfm"))
        if not isinstance(v, list) or len(v) != n:
            raise ValueError
        vals = np.array([float(x) for x in v], dtype=np.float64)
    except (TypeError, ValueError):
        shape = "a number" if n is None else f"a list of {n} numbers"
        raise InputError(f"{where}: {key!r} must be {shape}, got {v!r:.80}") from None
    return check_numbers(vals, f"{where}: {key!r}", fix="fix or re-export cameras.sfm")


def _version(data: dict) -> tuple[int, ...]:
    v = data.get("version", ["1", "0", "0"])
    try:
        return tuple(int(x) for x in v)
    except (TypeError, ValueError):
        return (1, 0, 0)


#: AliceVision distortion types -> (our model, OpenCV-ordered coefficients from AliceVision's parameters)
_DISTORTION = {
    "radial1": ("opencv", lambda k: [k[0], 0.0, 0.0, 0.0]),
    "radial3": ("opencv", lambda k: [k[0], k[1], 0.0, 0.0, k[2]]),
    "brown": ("opencv", lambda k: [k[0], k[1], k[3], k[4], k[2]]),  # k1 k2 k3 t1 t2 -> k1 k2 p1 p2 k3
    "fisheye4": ("fisheye", lambda k: list(k[:4])),
}
_DISTORTION["radialk1"], _DISTORTION["radialk3"] = _DISTORTION["radial1"], _DISTORTION["radial3"]
_N_COEFFS = {"radial1": 1, "radialk1": 1, "radial3": 3, "radialk3": 3, "brown": 5, "fisheye4": 4}


def _intrinsic(d: dict, where: str, version: tuple[int, ...]) -> tuple[int, int, np.ndarray, Distortion | None]:
    w, h = int(_num(d, "width", where)), int(_num(d, "height", where))
    kind = str(d.get("distortionType") or d.get("type", "pinhole"))
    dist = d.get("distortionParams") or []
    try:
        dist_vals = [float(x) for x in dist] if isinstance(dist, list) else [float("nan")]
    except (TypeError, ValueError):
        dist_vals = [float("nan")]
    if not all(np.isfinite(dist_vals)):
        raise InputError(f"{where}: distortionParams {dist!r:.60} must be a list of numbers")
    distorted = any(x != 0 for x in dist_vals)
    if distorted and (kind not in _DISTORTION or len(dist_vals) != _N_COEFFS[kind]):
        raise InputError(f"{where}: camera type {kind!r} with distortion {dist!r:.60} is not supported (radial1, "
                         "radial3, brown and fisheye4 are); undistort the images first (Meshroom's PrepareDenseScene "
                         "writes undistorted images and cameras)")
    if "pxFocalLength" in d:
        v = d["pxFocalLength"]
        f = _num(d, "pxFocalLength", where, 2) if isinstance(v, list) else np.array([_num(d, "pxFocalLength", where)] * 2)
        fx, fy = float(f[0]), float(f[1])
    else:
        focal, sensor = _num(d, "focalLength", where), _num(d, "sensorWidth", where)
        if sensor <= 0:
            raise InputError(f"{where}: sensorWidth must be > 0, got {sensor}")
        fx = focal * w / sensor
        fy = fx * (_num(d, "pixelRatio", where) if "pixelRatio" in d else 1.0)
    centre = np.array([w / 2.0, h / 2.0])  # AliceVision's image centre (IntrinsicScaleOffset)
    if "principalPoint" not in d:
        pp = centre
    else:
        pp = _num(d, "principalPoint", where, 2)
        if version >= (1, 2, 1):  # an offset from the centre since file version 1.2.1
            pp = pp + centre
    K = np.array([[fx, 0.0, pp[0]], [0.0, fy, pp[1]], [0.0, 0.0, 1.0]])
    if not distorted:
        return w, h, K, None
    model, coeffs = _DISTORTION[kind]
    try:
        lens = Distortion(model, coeffs(dist_vals), K)
        return w, h, lens.pinhole(w, h), lens
    except InputError as e:
        raise InputError(f"{where}: {e}") from None


def load(path: Path, *, mesh: str | os.PathLike | None = None, image_dir: str | os.PathLike | None = None,
         masks: str | os.PathLike | None = None) -> Scene:
    """Load a Meshroom / AliceVision SfM JSON file.

    Parameters
    ----------
    path : pathlib.Path
        ``cameras.sfm`` (or any SfM JSON).
    mesh : path-like
        Mesh file (required; Meshroom writes it elsewhere, e.g. ``Texturing/texturedMesh.obj``).
    image_dir : path-like, optional
        Folder to look the images up in by file name, instead of the paths in the file (e.g. the
        undistorted images of PrepareDenseScene, named ``<viewId>.exr``/``.png``: tried too).
    masks : path-like, optional
        AliceVision's masks folder (``--masksFolder``): ``<viewId>.png``, else the image's name
        with the mask's suffix, as ``tryLoadMask`` (``aliceVision/image/io.cpp``) looks them up
        (:func:`o3d_seqcc.io.masks.attach_masks`); 0 = masked out, of the original photos.

    Raises
    ------
    InputError
        No mesh, invalid JSON, missing keys, distorted cameras, no posed view.
    """
    if mesh is None:
        raise InputError(f"{path} is Meshroom SfM data: pass the mesh explicitly (mesh=... / --mesh)")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as e:
        raise InputError(f"{path}: not a valid SfM JSON file ({e})") from None
    if not isinstance(data, dict) or not isinstance(data.get("views"), list):
        raise InputError(f"{path}: expected an object with 'views', 'intrinsics' and 'poses' lists")
    version = _version(data)
    intr = {}
    for i, d in enumerate(data.get("intrinsics") or []):
        where = f"{path}: intrinsics[{i}]"
        if not isinstance(d, dict) or "intrinsicId" not in d:
            raise InputError(f"{where} must be an object with an 'intrinsicId'")
        intr[str(d["intrinsicId"])] = (d, where)
    poses = {}
    for i, d in enumerate(data.get("poses") or []):
        where = f"{path}: poses[{i}]"
        try:
            tr = d["pose"]["transform"]
            pid = str(d["poseId"])
        except (TypeError, KeyError):
            raise InputError(f"{where} must be {{'poseId': ..., 'pose': {{'transform': {{'rotation', 'center'}}}}}}") from None
        if not isinstance(tr, dict):
            raise InputError(f"{where}: 'transform' must be an object")
        R = _num(tr, "rotation", where, 9).reshape(3, 3).T  # column-major storage of world-to-camera R
        C = _num(tr, "center", where, 3)
        poses[pid] = (R, C, where)
    views, skipped, ids = [], [], {}
    img_root = None if image_dir is None else Path(image_dir)
    for i, d in enumerate(data["views"]):
        where = f"{path}: views[{i}]"
        if not isinstance(d, dict) or not isinstance(d.get("path"), str):
            raise InputError(f"{where} must be an object with a 'path' string")
        pid, iid = str(d.get("poseId", "")), str(d.get("intrinsicId", ""))
        src = Path(d["path"])
        if pid not in poses:
            skipped.append(src.name)
            continue
        if iid not in intr:
            raise InputError(f"{where} refers to intrinsic {iid!r}, which 'intrinsics' does not define")
        w, h, K, lens = _intrinsic(*intr[iid], version)
        R, C, pwhere = poses[pid]
        ext = np.eye(4)
        ext[:3, :3] = R
        ext[:3, 3] = -R @ C
        img = src if src.is_absolute() else path.parent / src
        if img_root is not None:
            cands = [img_root / src.name] + [img_root / f"{d.get('viewId')}{s}" for s in (".png", ".jpg", ".exr", ".tif")]
            img = next((c for c in cands if c.is_file()), img_root / src.name)
        try:
            views.append(View(name=src.stem, image=img, intrinsic=K, extrinsic=ext, width=w, height=h, distortion=lens))
            ids[src.stem] = [str(d["viewId"])] if "viewId" in d else []
        except InputError as e:
            raise InputError(f"{where} ({pwhere}): {e}") from None
    if skipped:
        logger.warning("%s: %d view(s) have no pose (not reconstructed) and are skipped: %s", path, len(skipped),
                       ", ".join(skipped[:5]) + (" ..." if len(skipped) > 5 else ""))
    if not views:
        raise InputError(f"{path}: no view has a pose; run the structure-from-motion step first")
    mesh_path = Path(mesh)
    if not mesh_path.is_absolute() and not mesh_path.exists():
        mesh_path = path.parent / mesh_path
    return Scene(mesh=mesh_path, views=attach_masks(views, masks, extra=ids) if masks is not None else tuple(views))
