"""The files of a result beside its mesh: the photos, written in parallel, and the MeshLab project.

Used by :meth:`o3d_seqcc.pipeline.RunResult.save` and :meth:`o3d_seqcc.pipeline.CorrectionRun.save`
inside their output folder transaction (:func:`o3d_seqcc.io.output.output_folder`).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..errors import InputError, warn
from ..parallel import current as current_executor
from ..scene import Scene
from .files import atomic_write_bytes, encode_image
from .meshlab import MeshLayer, save_mlp

__all__ = ["meshlab_project", "scene_paths", "write_images"]

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


def scene_paths(scene: Scene) -> dict[str, str]:
    """Absolute paths of the scene and its mesh files (what ``o3d-seqcc report`` reloads), when on disk."""
    out = {}
    if scene.source is not None:
        out["scene_path"] = str(Path(scene.source).resolve())
    if isinstance(scene.mesh, Path):
        out["mesh"] = str(scene.mesh.resolve())
    return out


def meshlab_project(scene: Scene, folder: Path, *, mesh: Path | None, images: list | None,
                    offset: np.ndarray | None = None) -> Path | None:
    """``folder/project.mlp``: the mesh layer and the rasters, so MeshLab opens the result as it opened the input.

    ``images`` default to the scene's own; a camera MeshLab cannot represent (skew) leaves the
    project out, with a warning. ``offset`` (3,): the layer's file holds the mesh minus it, and
    the layer's placement matrix adds it back.
    """
    try:
        if offset is not None and np.any(offset) and mesh is not None:
            T = np.eye(4)
            T[:3, 3] = offset
            return save_mlp(scene, folder / "project.mlp", layers=[MeshLayer(Path(mesh), matrix=T)], images=images)
        return save_mlp(scene, folder / "project.mlp", mesh=mesh, images=images)
    except InputError as e:
        warn(f"no MeshLab project written: {e}")
        return None
