"""The native scene manifest, ``scene.json`` (format ``o3d_seqcc.scene/1``).

::

    {"format": "o3d_seqcc.scene/1",
     "mesh": "mesh.ply",
     "views": [{"name": "v00", "image": "images/v00.png", "width": 640, "height": 480,
                "intrinsic": [[fx,0,cx],[0,fy,cy],[0,0,1]],
                "extrinsic": [[r,r,r,t],[r,r,r,t],[r,r,r,t],[0,0,0,1]],
                "depth": "depth/v00.png", "depth_scale": 1000.0,
                "point_cloud": "scans/s0.ply", "mask": "masks/v00.png", "mask_invert": false,
                "distortion": {"model": "opencv", "coefficients": [k1, k2, p1, p2],
                               "intrinsic": [[fx,0,cx],[0,fy,cy],[0,0,1]]}}]}

Paths are relative to the JSON file. ``depth``, ``depth_scale`` (units per metre, default
1000), ``point_cloud``, ``mask`` (the photo's mask, :mod:`o3d_seqcc.io.masks`: nonzero = kept, 0 =
masked out), ``mask_invert`` (default false: true for the other convention) and ``distortion`` are
optional. ``extrinsic`` is world-to-camera in
OpenCV axes. ``distortion`` (:class:`~o3d_seqcc.geometry.distortion.Distortion`: model, coefficients,
the photo's own intrinsic) says the image is a distorted photo, undistorted when read to the
pinhole camera ``intrinsic``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..geometry.distortion import Distortion
from ..errors import InputError
from ..scene import FORMAT, Scene, View
from .json_files import parse_json, write_json
from .paths import find_file, join_path

__all__ = ["FORMAT", "SCENE_JSON", "detect", "load", "save"]

#: the manifest's file name in a scene's folder (and in the folder ``o3d-seqcc correct`` writes)
SCENE_JSON = "scene.json"

_VIEW_KEYS = ("name", "image", "width", "height", "intrinsic", "extrinsic")
_OPTIONAL_KEYS = ("depth", "depth_scale", "point_cloud", "distortion", "mask", "mask_invert")


def detect(path: Path) -> Path | None:
    """The manifest to read for ``path`` (a ``.json`` file, or a folder holding ``scene.json``), or None."""
    return find_file(path, name=SCENE_JSON, suffix=".json")


def _join(root: Path, rel: object, where: str) -> Path:
    if not isinstance(rel, str) or not rel or "\x00" in rel:
        raise InputError(f"{where} must be a non-empty relative or absolute path string, got {rel!r}")
    return join_path(root, rel)


def _number(d: dict, key: str, where: str) -> float | int:
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InputError(f"{where}: {key!r} must be a number, got {v!r} ({type(v).__name__})")
    return v


def _flag(d: dict, key: str, where: str) -> bool:
    v = d.get(key, False)
    if not isinstance(v, bool):
        raise InputError(f"{where}: {key!r} must be true or false, got {v!r:.60}")
    return v


def _matrix(d: dict, key: str, shape: tuple[int, int], where: str) -> np.ndarray:
    v = d[key]
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != shape:
        raise InputError(f"{where}: {key!r} must be a {shape[0]}x{shape[1]} list of numbers, got {v!r:.80}")
    return a


def load(path: Path, *, mesh: str | os.PathLike | None = None) -> Scene:
    """Read a ``scene.json`` manifest.

    Parameters
    ----------
    path : pathlib.Path
        The manifest.
    mesh : path-like, optional
        Overrides the manifest's mesh.

    Raises
    ------
    InputError
        Unreadable or non-UTF-8 file, invalid JSON, unknown format version, missing or
        malformed keys (named with the view index and the fix).
    """
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start}); save the manifest as UTF-8") from None
    except OSError as e:
        raise InputError(f"{path}: cannot read the manifest ({e.strerror})") from None
    data = parse_json(text, path)  # not valid JSON, or a key twice in one object: an InputError
    if not isinstance(data, dict):
        raise InputError(f"{path}: expected a JSON object with 'format', 'mesh' and 'views'")
    fmt = data.get("format")
    if fmt != FORMAT:
        raise InputError(
            f"{path}: unknown scene format {fmt!r:.60}; this version of o3d_seqcc reads {FORMAT!r} "
            "(upgrade o3d_seqcc or re-export the scene)"
        )
    root = path.parent
    for key in ("mesh", "views"):
        if key not in data:
            raise InputError(f"{path}: missing required key {key!r}")
    if not isinstance(data["views"], list):
        raise InputError(f"{path}: 'views' must be a list")
    views = []
    for i, d in enumerate(data["views"]):
        where = f"{path}: views[{i}]"
        if not isinstance(d, dict):
            raise InputError(f"{where} must be an object")
        missing = [k for k in _VIEW_KEYS if k not in d]
        if missing:
            raise InputError(f"{where} ({str(d.get('name', '?')):.60}) is missing {', '.join(missing)}")
        unknown = set(d) - set(_VIEW_KEYS) - set(_OPTIONAL_KEYS)
        if unknown:
            raise InputError(f"{where} has unknown keys {sorted(map(str, unknown))}")
        if not isinstance(d["name"], str):
            raise InputError(f"{where}: 'name' must be a string, got {d['name']!r:.60}")
        try:
            views.append(
                View(
                    name=d["name"],
                    image=_join(root, d["image"], f"{where}: 'image'"),
                    intrinsic=_matrix(d, "intrinsic", (3, 3), where),
                    extrinsic=_matrix(d, "extrinsic", (4, 4), where),
                    width=_number(d, "width", where),
                    height=_number(d, "height", where),
                    depth=None if d.get("depth") is None else _join(root, d["depth"], f"{where}: 'depth'"),
                    depth_scale=_number(d, "depth_scale", where) if d.get("depth_scale") is not None else 1000.0,
                    point_cloud=None if d.get("point_cloud") is None
                    else _join(root, d["point_cloud"], f"{where}: 'point_cloud'"),
                    distortion=None if d.get("distortion") is None else Distortion.from_dict(d["distortion"]),
                    mask=None if d.get("mask") is None else _join(root, d["mask"], f"{where}: 'mask'"),
                    mask_invert=_flag(d, "mask_invert", where),
                )
            )
        except InputError as e:
            raise InputError(e.args[0] if str(path) in e.args[0] else f"{path}: {e}") from None
    mesh_path = Path(mesh) if mesh is not None else _join(root, data["mesh"], f"{path}: 'mesh'")
    try:
        return Scene(mesh=mesh_path, views=tuple(views))
    except InputError as e:
        raise InputError(f"{path}: {e}") from None


def _rel(p: Path, root: Path) -> str:
    """``p`` relative to ``root`` without resolving symbolic links (paths stay as given)."""
    return Path(os.path.relpath(os.path.abspath(p), os.path.abspath(root))).as_posix()


def save(scene: Scene, path: str | os.PathLike) -> Path:
    """Write ``scene`` as a ``scene.json`` manifest, atomically.

    Paths are stored relative to the manifest's folder (symbolic links are kept, not
    followed). ``load(save(s, p)) == s`` exactly (floats are written with full precision).

    Parameters
    ----------
    scene : Scene
    path : path-like
        Manifest path (conventionally ``.../scene.json``).

    Returns
    -------
    pathlib.Path
        The manifest path.
    """
    path = Path(path)
    if scene.in_memory:
        raise InputError(f"cannot save an in-memory scene as {path}: its mesh or images have no files; write them "
                         "first (o3d_seqcc.io.images.write_image, open3d.io.write_triangle_mesh) and build the scene "
                         "from the files")
    root = path.parent
    root.mkdir(parents=True, exist_ok=True)
    views = []
    for v in scene.views:
        d = {
            "name": v.name,
            "image": _rel(v.image, root),
            "width": v.width,
            "height": v.height,
            "intrinsic": v.intrinsic.tolist(),
            "extrinsic": v.extrinsic.tolist(),
        }
        if v.depth is not None:
            d["depth"] = _rel(v.depth, root)
            d["depth_scale"] = v.depth_scale
        if v.point_cloud is not None:
            d["point_cloud"] = _rel(v.point_cloud, root)
        if v.distortion is not None:
            d["distortion"] = v.distortion.to_dict()
        if v.mask_map is not None:
            raise InputError(f"cannot save view {v.name!r} as {path}: its mask is in memory; write it as an image "
                             "(o3d_seqcc.io.images.write_image) and give its path (View.mask)")
        if v.mask is not None:
            d["mask"] = _rel(v.mask, root)
            if v.mask_invert:
                d["mask_invert"] = True
        views.append(d)
    return write_json(path, {"format": FORMAT, "mesh": _rel(scene.mesh, root), "views": views})
