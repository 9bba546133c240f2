"""The parts of a run's folder beside its mesh: the photos, written in parallel, and the MeshLab project.

Used by :mod:`o3d_seqcc.run_folder.write` (and the MeshLab filters' folder) inside the output folder
transaction (:func:`o3d_seqcc.io.output.output_folder`).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, warn
from .._shared.parallel import current as current_executor
from ..scene import Scene
from ..io.atomic import atomic_path, atomic_write_bytes
from ..io.images import encode_image
from ..io.meshlab import MeshLayer, save_mlp
from .layout import MESHLAB_PROJECT

__all__ = ["meshlab_project", "scene_paths", "with_mesh_file", "write_images"]

logger = logging.getLogger(__name__)


def _encode_view(i: int, images) -> bytes:
    return encode_image(np.asarray(images[i]), ".png")


def write_images(folder: Path, views, images) -> list[Path]:
    """``folder/<view>.png`` for every view: encoded by one task per view (threads or Dask workers,
    results streamed back in view order), written here atomically.

    Parameters
    ----------
    folder : pathlib.Path
        An existing folder (inside the output's staging folder).
    views : sequence of View
        Give the file names.
    images : sequence of (H, W, 3) uint8 / uint16 arrays, or an ImageSequence
        One per view.

    Returns
    -------
    list of pathlib.Path
    """
    ex = current_executor()
    shared = ex.share(images)
    return [atomic_write_bytes(folder / f"{v.name}.png", data)
            for v, data in zip(views, ex.imap(_encode_view, range(len(views)), shared, desc="write images",
                                              unit="image"))]


def scene_paths(scene: Scene) -> dict[str, Any]:
    """Absolute paths of the scene and its mesh files (what ``o3d-seqcc report`` reloads), when on disk,
    and the options it was loaded with (``scene_options``)."""
    out = {}
    if scene.source is not None:
        out["scene_path"] = str(Path(scene.source).resolve())
    if isinstance(scene.mesh, Path):
        out["mesh"] = str(scene.mesh.resolve())
    if scene.options:
        out["scene_options"] = dict(scene.options)  # how load_scene read it (image_dir, extrinsic, ...)
    return out


def meshlab_project(scene: Scene, folder: Path, *, mesh: Path | None, images: list | None,
                    offset: np.ndarray | None = None) -> Path | None:
    """``folder/project.mlp``: the mesh layer and the rasters, so MeshLab opens the result as it opened the input.

    ``images`` default to the scene's own; a camera MeshLab cannot represent (skew), or a path a
    project cannot hold (file names that are not UTF-8: the project is UTF-8 XML), leaves the
    project out, with a warning. ``offset`` (3,): the layer's file holds the mesh minus it, and
    the layer's placement matrix adds it back.
    """
    try:
        if offset is not None and np.any(offset) and mesh is not None:
            T = np.eye(4)
            T[:3, 3] = offset
            return save_mlp(scene, folder / MESHLAB_PROJECT, layers=[MeshLayer(Path(mesh), matrix=T)], images=images)
        return save_mlp(scene, folder / MESHLAB_PROJECT, mesh=mesh, images=images)
    except InputError as e:
        warn(f"no MeshLab project written: {e}")
    except UnicodeEncodeError:
        shown = next((str(p) for p in scene.input_paths() if not _utf8(p)), "a path")
        warn(f"no MeshLab project written: {shown.encode('utf-8', 'backslashreplace').decode()} is not a UTF-8 "
             "name, which a MeshLab project (UTF-8 XML) cannot hold; rename the folder to open the result in MeshLab")
    return None


def _utf8(p) -> bool:
    try:
        str(p).encode("utf-8")
        return True
    except UnicodeEncodeError:
        return False


def with_mesh_file(scene: Scene, path: Path) -> Scene:
    """``scene`` itself when its mesh is a file; else a copy whose mesh (in memory, as the Open3D front door
    builds it) is written to ``path`` as a PLY file (atomically), so that a manifest can name it."""
    if isinstance(scene.mesh, Path):
        return scene
    import open3d as o3d

    with atomic_path(path) as tmp:
        if not o3d.io.write_triangle_mesh(str(tmp), scene.mesh.to_open3d(), write_ascii=False):
            raise OSError(f"Open3D could not write {path}")
    return Scene(path, scene.views, source=scene.source)
