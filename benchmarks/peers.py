"""Texturing peers for side-by-side comparison (issue 5): MeshLab via pymeshlab, and Open3D.

- :func:`run_meshlab`: MeshLab's ``compute_texcoord_parametrization_and_texture_from_registered_rasters``
  (colour correction on) on a MeshLab project written from the scene. pymeshlab's raster
  filters need an OpenGL context, so the filter runs in a **subprocess** (a crash cannot kill
  the caller) under ``xvfb-run -a -s "-screen 0 1280x1024x24 +extension GLX"`` with
  ``QT_PLUGIN_PATH=/usr/lib/x86_64-linux-gnu/qt5/plugins QT_QPA_PLATFORM=xcb`` (the pymeshlab
  wheel ships no Qt platform plugin). Debian packages: xvfb, xauth, libgl1-mesa-dri,
  libglx-mesa0, libqt5gui5.
- :func:`run_open3d`: Open3D's ``t.geometry.TriangleMesh.compute_uvatlas`` then
  ``project_images_to_albedo`` (which blends all images per texel).

Both filters need an edge-manifold mesh: duplicate vertices are merged and non-manifold edges
removed first (MeshLab: ``meshing_remove_duplicate_vertices``, ``meshing_repair_non_manifold_edges``,
``meshing_repair_non_manifold_vertices``; Open3D: ``remove_duplicated_vertices``,
``remove_non_manifold_edges``). Both write a textured OBJ (+MTL+PNG).
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from o3d_seqcc.errors import InputError
from o3d_seqcc.io.files import write_image, write_json
from o3d_seqcc.io.meshlab import CENTER_SHIFT, save_mlp
from o3d_seqcc.scene import Scene

__all__ = ["PeerResult", "XVFB_ARGS", "meshlab_available", "run_meshlab", "run_open3d"]

logger = logging.getLogger(__name__)

#: Command prefix giving pymeshlab a virtual X display with GLX.
XVFB_ARGS = ("xvfb-run", "-a", "-s", "-screen 0 1280x1024x24 +extension GLX")
#: Environment for pymeshlab's Qt (the wheel ships no platform plugin).
QT_ENV = {"QT_PLUGIN_PATH": "/usr/lib/x86_64-linux-gnu/qt5/plugins", "QT_QPA_PLATFORM": "xcb"}


@dataclass(frozen=True)
class PeerResult:
    """Output of a peer texturing run.

    Attributes
    ----------
    name : str
        ``"meshlab"`` or ``"open3d"``.
    mesh : pathlib.Path
        Textured OBJ (with its MTL and PNG next to it).
    texture : pathlib.Path
        The texture image.
    seconds : float
        Wall time of the texturing itself (MeshLab: the filter; Open3D: uvatlas + albedo).
    total_seconds : float
        Wall time of the whole run (loading, mesh clean-up, writing; MeshLab: the subprocess).
    info : dict
        Details: faces after clean-up, per-step timings, filter parameters.
    """

    name: str
    mesh: Path
    texture: Path
    seconds: float
    total_seconds: float
    info: dict = field(default_factory=dict)


def meshlab_available() -> str | None:
    """None when the MeshLab peer can run here, else the reason it cannot."""
    if shutil.which("xvfb-run") is None:
        return "xvfb-run not found (apt-get install xvfb xauth libgl1-mesa-dri libglx-mesa0 libqt5gui5)"
    try:
        import importlib.util

        if importlib.util.find_spec("pymeshlab") is None:
            return "pymeshlab is not installed"
    except Exception as e:  # pragma: no cover
        return f"pymeshlab cannot be imported: {e}"
    if not Path(QT_ENV["QT_PLUGIN_PATH"], "platforms").is_dir():
        return f"no Qt platform plugins in {QT_ENV['QT_PLUGIN_PATH']} (apt-get install libqt5gui5)"
    return None


def _image_files(scene: Scene, images: Sequence[Any] | None, folder: Path) -> list[Path]:
    """Image files per view: the views' own, given paths, or given arrays written as PNG."""
    if images is None:
        return [v.image for v in scene.views]
    if len(images) != len(scene.views):
        raise InputError(f"images: {len(images)} given for {len(scene.views)} views; give one per view")
    out = []
    for v, img in zip(scene.views, images):
        if isinstance(img, (str, os.PathLike)):
            out.append(Path(img))
        else:
            arr = np.asarray(img)
            if arr.dtype != np.uint8:
                arr = np.clip(np.rint(arr / 257.0), 0, 255).astype(np.uint8) if arr.dtype == np.uint16 else arr
            out.append(write_image(folder / f"{v.name}.png", arr))
    return out


def _prepare_out(out_dir: str | os.PathLike, overwrite: bool) -> Path:
    out = Path(out_dir).resolve()
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise InputError(f"output folder {out} exists and is not empty; pass overwrite=True or another folder")
    out.mkdir(parents=True, exist_ok=True)
    return out


def run_meshlab(
    scene: Scene,
    out_dir: str | os.PathLike,
    *,
    images: Sequence[Any] | None = None,
    texture_size: int = 2048,
    colorcorrection: bool = True,
    texture_gutter: int = 4,
    timeout: float = 1800.0,
    overwrite: bool = False,
    center_shift: tuple[float, float] = CENTER_SHIFT,
) -> PeerResult:
    """Texture the scene's mesh with MeshLab's raster-based filter, in a headless subprocess.

    Parameters
    ----------
    scene : Scene
    out_dir : path-like
        Output folder (``project.mlp``, ``meshlab.obj/.mtl``, ``meshlab_texture.png``).
    images : sequence of path-like or (H, W, 3) uint8 arrays, optional
        One image per view instead of the views' own (e.g. colour-corrected images); arrays
        are written as PNG into ``out_dir/images``.
    texture_size : int, default 2048
        Side of the square texture.
    colorcorrection : bool, default True
        The filter's own colour correction between rasters.
    texture_gutter : int, default 4
        Gutter in texels.
    timeout : float, default 1800
        Seconds before the subprocess is killed.
    overwrite : bool, default False
        Allow a non-empty ``out_dir``.
    center_shift : (float, float), default o3d_seqcc.io.meshlab.CENTER_SHIFT
        Half-pixel convention of the cameras written to the project (see :mod:`o3d_seqcc.io.meshlab`).

    Returns
    -------
    PeerResult

    Raises
    ------
    RuntimeError
        The subprocess failed (its stderr tail is in the message) or xvfb-run is missing.
    """
    reason = meshlab_available()
    if reason:
        raise RuntimeError(f"MeshLab peer unavailable: {reason}")
    out = _prepare_out(out_dir, overwrite)
    t0 = time.perf_counter()
    files = _image_files(scene, images, out / "images")
    mlp = save_mlp(scene, out / "project.mlp", images=files, center_shift=center_shift)
    job = {
        "project": str(mlp),
        "out_mesh": str(out / "meshlab.obj"),
        "texture_name": "meshlab_texture.png",
        "texture_size": int(texture_size),
        "colorcorrection": bool(colorcorrection),
        "texture_gutter": int(texture_gutter),
        "result": str(out / "meshlab_result.json"),
    }
    job_path = write_json(out / "meshlab_job.json", job)
    env = {**os.environ, **QT_ENV}
    cmd = [*XVFB_ARGS, sys.executable, str(Path(__file__).with_name("_meshlab_worker.py")), str(job_path)]
    logger.info("running MeshLab: %s", " ".join(cmd))
    try:
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout, cwd=out)
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"MeshLab texturing timed out after {timeout:.0f} s") from None
    total = time.perf_counter() - t0
    res_path = Path(job["result"])
    if proc.returncode != 0 or not res_path.is_file():
        tail = "\n".join((proc.stderr or "").strip().splitlines()[-15:])
        raise RuntimeError(f"MeshLab texturing failed (exit {proc.returncode}):\n{tail}")
    res = json.loads(res_path.read_text())
    return PeerResult(
        name="meshlab",
        mesh=Path(job["out_mesh"]),
        texture=out / job["texture_name"],
        seconds=float(res["filter_seconds"]),
        total_seconds=total,
        info=res,
    )


def _write_textured_obj(path: Path, vertices: np.ndarray, faces: np.ndarray, corner_uv: np.ndarray, texture: np.ndarray) -> Path:
    """OBJ + MTL + PNG from per-corner UVs (F, 3, 2), OBJ convention (v up)."""
    import trimesh
    from PIL import Image

    F = len(faces)
    key = np.concatenate([faces.reshape(-1, 1).astype(np.float64), corner_uv.reshape(-1, 2)], axis=1)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    v = vertices[uniq[:, 0].astype(np.int64)]
    visual = trimesh.visual.TextureVisuals(uv=uniq[:, 1:], image=Image.fromarray(texture))
    mesh = trimesh.Trimesh(v, inv.reshape(F, 3), visual=visual, process=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh.export(path)
    return path


def run_open3d(
    scene: Scene,
    out_dir: str | os.PathLike,
    *,
    images: Sequence[Any] | None = None,
    texture_size: int = 2048,
    gutter: float = 1.0,
    max_stretch: float = 1.0 / 6.0,
    overwrite: bool = False,
) -> PeerResult:
    """Texture the scene's mesh with Open3D: ``compute_uvatlas`` + ``project_images_to_albedo``.

    Parameters
    ----------
    scene : Scene
    out_dir : path-like
        Output folder (``open3d.obj`` + MTL + PNG).
    images : sequence of path-like or (H, W, 3) uint8 arrays, optional
        One image per view instead of the views' own.
    texture_size : int, default 2048
    gutter, max_stretch : float
        ``compute_uvatlas`` options (Open3D's defaults).
    overwrite : bool, default False

    Returns
    -------
    PeerResult
    """
    import open3d as o3d

    from o3d_seqcc.io.files import read_image

    out = _prepare_out(out_dir, overwrite)
    t0 = time.perf_counter()
    legacy = o3d.io.read_triangle_mesh(str(scene.mesh), enable_post_processing=False)
    n_in = len(legacy.triangles)
    legacy.triangle_uvs = o3d.utility.Vector2dVector()
    legacy.textures = []
    legacy.remove_duplicated_vertices()
    legacy.remove_non_manifold_edges()
    legacy.remove_unreferenced_vertices()
    mesh = o3d.t.geometry.TriangleMesh.from_legacy(legacy)
    if images is None:
        arrays = [v.load_image() for v in scene.views]
    else:
        if len(images) != len(scene.views):
            raise InputError(f"images: {len(images)} given for {len(scene.views)} views")
        arrays = [read_image(p) if isinstance(p, (str, os.PathLike)) else np.asarray(p) for p in images]
    arrays = [a if a.dtype == np.uint8 else np.clip(np.rint(a / 257.0), 0, 255).astype(np.uint8) for a in arrays]
    o3d_images = [o3d.t.geometry.Image(np.ascontiguousarray(a)) for a in arrays]
    Ks = [o3d.core.Tensor(np.asarray(v.intrinsic)) for v in scene.views]
    Es = [o3d.core.Tensor(np.asarray(v.extrinsic)) for v in scene.views]
    t1 = time.perf_counter()
    stretch, n_charts, _ = mesh.compute_uvatlas(size=int(texture_size), gutter=float(gutter), max_stretch=float(max_stretch))
    t2 = time.perf_counter()
    albedo = mesh.project_images_to_albedo(o3d_images, Ks, Es, tex_size=int(texture_size), update_material=True)
    t3 = time.perf_counter()
    tex = np.ascontiguousarray(albedo.as_tensor().numpy()[..., :3])
    if tex.dtype != np.uint8:
        tex = np.clip(np.rint(tex * (255.0 if tex.dtype.kind == "f" else 1.0)), 0, 255).astype(np.uint8)
    obj = _write_textured_obj(
        out / "open3d.obj",
        mesh.vertex.positions.numpy().astype(np.float64),
        mesh.triangle.indices.numpy().astype(np.int64),
        mesh.triangle.texture_uvs.numpy().astype(np.float64),
        tex,
    )
    tex_files = sorted(out.glob("*.png"))
    total = time.perf_counter() - t0
    info = {
        "faces_in": n_in,
        "faces_textured": int(mesh.triangle.indices.shape[0]),
        "uvatlas_seconds": t2 - t1,
        "albedo_seconds": t3 - t2,
        "uvatlas_stretch": float(stretch),
        "uvatlas_charts": int(n_charts),
        "texture_size": int(texture_size),
    }
    write_json(out / "open3d_result.json", info)
    return PeerResult(
        name="open3d",
        mesh=obj,
        texture=tex_files[0] if tex_files else obj,
        seconds=t3 - t1,
        total_seconds=total,
        info=info,
    )
