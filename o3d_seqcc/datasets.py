"""Real datasets.

``fountain`` is the "Fountain" key-frame set of Zhou & Koltun (SIGGRAPH 2014), distributed by
Open3D as ``open3d.data.SampleFountainRGBDImages``: 33 RGB-D key frames (640x480, PrimeSense
intrinsics) with camera-to-world poses in ``scene/key.log``.
"""

from __future__ import annotations

import logging
import os
import re
from pathlib import Path

import numpy as np

from .errors import InputError
from .io import rgbd_folder
from .scene import Scene

__all__ = ["DatasetUnavailable", "fountain"]

logger = logging.getLogger(__name__)

#: environment variable naming a local copy of the Fountain set (used when ``root`` is not given)
FOUNTAIN_ENV = "O3D_SEQCC_FOUNTAIN"


class DatasetUnavailable(InputError):
    """A built-in data set could not be had (offline, no local copy): the message says how to give a copy.

    ``str(e)`` is in Python words (``fountain(root=DIR)``); :meth:`cli_message` says the same
    for the command line (``--data-root DIR``). Both name the environment variable.
    """

    def __init__(self, reason: str, *, python: str = "fountain(root=DIR)", option: str = "--data-root DIR") -> None:
        self.reason, self.python, self.option = reason, python, option
        super().__init__(self._text(f"pass it as {python}"))

    def _text(self, how: str) -> str:
        return (f"could not download Open3D's SampleFountainRGBDImages (offline?): {self.reason}; put a copy of the "
                f"set (image/, depth/, scene/key.log, a mesh in scene/) in a folder DIR and {how}, or set the "
                f"environment variable {FOUNTAIN_ENV}=DIR, or let Open3D download it into ~/open3d_data once online")

    def cli_message(self, option: str | None = None) -> str:
        """The message in command-line words: give the copy with ``option`` (default ``--data-root DIR``)."""
        return self._text(f"give it with {option or self.option}")

    def for_python(self, python: str) -> "DatasetUnavailable":
        """The same error naming another Python entry point (e.g. ``run_demo(..., data_root=DIR)``)."""
        return DatasetUnavailable(self.reason, python=python, option=self.option)


#: meshes looked for, in order, in ``root/scene`` when ``mesh`` is not given
FOUNTAIN_MESHES = ("mesh_decimated_uv_blender.ply", "integrated.ply", "tsdf_mesh.ply")


def fountain(
    root: str | os.PathLike | None = None,
    *,
    mesh: str | os.PathLike | None = None,
    intrinsic: np.ndarray | None = None,
) -> Scene:
    """The Fountain RGB-D key frames as a :class:`~o3d_seqcc.scene.Scene`.

    Parameters
    ----------
    root : path-like, optional
        A folder in the ``SampleFountainRGBDImages`` layout (``image/``, ``depth/``,
        ``scene/key.log``). When omitted: the folder named by the environment variable
        ``O3D_SEQCC_FOUNTAIN`` if set, else Open3D's own copy (``open3d.data`` downloads it on
        first use, which needs internet access; offline, :class:`DatasetUnavailable`).
    mesh : path-like, optional
        Mesh file, absolute or relative to ``root``; default: the first of
        :data:`FOUNTAIN_MESHES` found in ``root/scene``.
    intrinsic : (3, 3) array, optional
        Default: PrimeSense (fx = fy = 525, cx = 319.5, cy = 239.5).

    Returns
    -------
    Scene
        33 views named after their image files, with depth maps (depth_scale 1000).
    """
    if root is None and os.environ.get(FOUNTAIN_ENV):
        root = os.environ[FOUNTAIN_ENV]
    if root is None:
        import open3d as o3d

        try:
            data = o3d.data.SampleFountainRGBDImages()
        except Exception as e:  # network failures surface as RuntimeError in Open3D
            text = re.sub(r"\x1b\[[0-9;]*m", "", str(e))
            reason = text.split(":")[-1].strip() or type(e).__name__
            raise DatasetUnavailable(reason[:120]) from None
        root = Path(data.extract_dir if hasattr(data, "extract_dir") else Path(data.color_paths[0]).parents[1])
        if mesh is None and hasattr(data, "reconstruction_path"):
            mesh = data.reconstruction_path
    root = Path(root)
    if not root.is_dir():
        raise InputError(f"fountain dataset folder not found: {root}")
    if mesh is None:
        found = [root / "scene" / m for m in FOUNTAIN_MESHES if (root / "scene" / m).is_file()]
        if not found:
            raise InputError(f"{root}/scene holds none of {FOUNTAIN_MESHES}; pass mesh=")
        mesh = found[0]
    if rgbd_folder.detect(root) is None:
        raise InputError(f"{root}: not an Open3D RGB-D folder (needs image/ and scene/key.log)")
    scene = rgbd_folder.load(root, mesh=mesh, intrinsic=intrinsic)
    scene = Scene(scene.mesh, scene.views, source=root)
    scene.validate()
    logger.info("fountain: %d views, mesh %s", len(scene.views), scene.mesh)
    return scene
