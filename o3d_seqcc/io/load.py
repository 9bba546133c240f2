"""Scene loading and saving, dispatched on a table of formats (trimesh's ``exchange`` style).

:data:`SCENE_FORMATS` maps a format name to its module's ``detect(path) -> path | None`` and
``load(path, *, mesh=None, **options) -> Scene``; :func:`load_scene` tries them in order (or
uses the one named by ``format=``) and passes only the options the chosen loader takes.
"""

from __future__ import annotations

import inspect
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import InputError
from ..scene import Scene, View
from . import colmap, meshlab, meshroom, rgbd_folder, scene_json
from .files import find_file

__all__ = ["SCENE_FORMATS", "SceneFormat", "load_scene", "save_scene"]


@dataclass(frozen=True)
class SceneFormat:
    """One scene format of the table.

    Attributes
    ----------
    name : str
    description : str
        What the path looks like (listed in error messages).
    detect : callable
        ``detect(path) -> path to read | None``.
    load : callable
        ``load(path, *, mesh=None, ...) -> Scene``.
    """

    name: str
    description: str
    detect: Callable[[Path], Path | None]
    load: Callable[..., Scene]


def _detect_mlp(path: Path) -> Path | None:
    return None if path.is_dir() else find_file(path, name="", suffix=".mlp")


#: The scene formats, in detection order.
SCENE_FORMATS: dict[str, SceneFormat] = {
    f.name: f
    for f in (
        SceneFormat("scene.json", "a scene.json manifest or its folder", scene_json.detect, scene_json.load),
        SceneFormat("meshlab", "a MeshLab project (.mlp)", _detect_mlp, meshlab.load_mlp),
        SceneFormat("meshroom", "Meshroom/AliceVision SfM data (cameras.sfm or its folder)", meshroom.detect, meshroom.load),
        SceneFormat("rgbd-folder", "an Open3D RGB-D folder (image/, depth/, scene/key.log)", rgbd_folder.detect,
                    rgbd_folder.load),
        SceneFormat("colmap", "a COLMAP model folder (cameras/images .txt or .bin)", colmap.detect, colmap.load),
    )
}


def load_scene(
    path: str | os.PathLike,
    *,
    mesh: str | os.PathLike | None = None,
    format: str = "auto",
    intrinsic: np.ndarray | None = None,
    image_dir: str | os.PathLike | None = None,
    depth_dir: str | os.PathLike | None = None,
    depth_scale: float = 1000.0,
    validate: bool = True,
) -> Scene:
    """Load a scene, detecting its format.

    Parameters
    ----------
    path : path-like
        A ``scene.json`` manifest (or its folder), a MeshLab project (``.mlp``), Meshroom's
        ``cameras.sfm`` (or its folder), an Open3D RGB-D folder or a COLMAP model folder (text
        or binary); see :data:`SCENE_FORMATS`.
    mesh : path-like, optional
        Mesh file; required for RGB-D folders, COLMAP and Meshroom, overrides the others'.
    format : str, default "auto"
        A name of :data:`SCENE_FORMATS` to skip detection.
    intrinsic : (3, 3) array, optional
        RGB-D folders only; default PrimeSense (fx = fy = 525, cx = 319.5, cy = 239.5).
    image_dir : path-like, optional
        COLMAP and Meshroom only: folder of the images.
    depth_dir : path-like, optional
        Folder of depth maps registered to the images, for the views that have none (MeshLab
        projects, COLMAP and Meshroom models carry no depth): ``<view name>.png`` or the image's
        file name with a depth extension (``.png``, ``.tif``, ``.tiff``, ``.exr``).
    depth_scale : float, default 1000.0
        Units per metre of the depth maps of ``depth_dir`` (1000: millimetres).
    validate : bool, default True
        Check files, image headers (size, grey, alpha) and the mesh now rather than later.

    Returns
    -------
    Scene
        Images are not read (lazy); use ``View.load_image``.

    Raises
    ------
    InputError
        Unknown layout (the message lists the formats), an option the format does not take,
        missing files, malformed cameras, duplicate names, ...
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"scene not found: {p}")
    if format == "auto":
        found = next(((f, hit) for f in SCENE_FORMATS.values() if (hit := f.detect(p)) is not None), None)
        if found is None:
            raise InputError(
                f"{p}: unknown scene layout; expected "
                + "; ".join(f"{f.description}" for f in SCENE_FORMATS.values())
            )
    else:
        if format not in SCENE_FORMATS:
            raise InputError(f"unknown scene format {format!r}; valid: 'auto', {', '.join(map(repr, SCENE_FORMATS))}")
        fmt = SCENE_FORMATS[format]
        hit = fmt.detect(p)
        if hit is None:
            raise InputError(f"{p} is not {fmt.description}")
        found = (fmt, hit)
    fmt, target = found
    if mesh is not None:
        _check_mesh_path(Path(mesh), target)
    options: dict[str, Any] = {"mesh": mesh}
    accepted = inspect.signature(fmt.load).parameters
    for name, value in (("intrinsic", intrinsic), ("image_dir", image_dir)):
        if value is None:
            continue
        if name not in accepted:
            raise InputError(f"{name}= does not apply to {fmt.description} ({p}); drop it")
        options[name] = value
    scene = fmt.load(target, **options)
    views = scene.views if depth_dir is None else _with_depth(scene.views, Path(depth_dir), depth_scale)
    scene = Scene(scene.mesh, views, source=target)
    if validate:
        scene.validate()
    return scene


def _check_mesh_path(mesh: Path, target: Path) -> None:
    """A mesh given by the user must exist as typed: from the current folder, or from the scene's folder."""
    folder = target if target.is_dir() else target.parent
    if mesh.is_file() or (not mesh.is_absolute() and (folder / mesh).is_file()):
        return
    where = ("" if mesh.is_absolute() else
             f" (a relative path is looked for from the current folder {Path.cwd()} and from the scene's folder {folder})")
    what = "is a folder, not a mesh file" if mesh.is_dir() else "not found"
    raise InputError(f"mesh {mesh} {what}{where}; give the path of the mesh file")


def _with_depth(views: tuple[View, ...], folder: Path, depth_scale: float) -> tuple[View, ...]:
    """The views with a depth map from ``folder`` where they have none (named after the view or its image)."""
    if not folder.is_dir():
        raise InputError(f"depth_dir {folder} is not a folder")
    out = []
    for v in views:
        if v.depth is not None:
            out.append(v)
            continue
        stems = [v.name] + ([v.image.stem] if v.image is not None else [])
        cands = [folder / f"{s}{ext}" for s in stems for ext in (".png", ".tif", ".tiff", ".exr")]
        found = next((c for c in cands if c.is_file()), None)
        if found is None:
            raise InputError(f"depth_dir {folder}: no depth map for view {v.name!r} (expected {v.name}.png)")
        out.append(replace(v, depth=found, depth_scale=depth_scale))
    return tuple(out)


def save_scene(scene: Scene, path: str | os.PathLike) -> Path:
    """Write ``scene`` as a ``scene.json`` manifest (format ``o3d_seqcc.scene/1``), atomically.

    Paths are stored relative to the manifest's folder as given (symbolic links are not
    followed). ``load_scene(save_scene(s, p)) == s`` exactly.

    Returns
    -------
    pathlib.Path
        The manifest path.
    """
    return scene_json.save(scene, path)
