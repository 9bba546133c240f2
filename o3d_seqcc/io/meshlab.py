"""MeshLab projects (``.mlp``): write a :class:`~o3d_seqcc.scene.Scene` as mesh + rasters, read one back.

A MeshLab project lists meshes (``MeshGroup/MLMesh`` with a 4x4 placement matrix) and
registered rasters (``RasterGroup/MLRaster``), each with a ``VCGCamera`` element and an image
(``Plane``). This module converts between VCG cameras and our cameras (OpenCV axes,
world-to-camera extrinsic, pixel centres at integers).

Camera convention (vcglib ``Shot``): the camera looks down its -z axis with the image y axis
up; ``RotationMatrix`` is the 4x4 world-to-camera rotation (row-major) and
``TranslationVector`` is minus the camera centre (plus a trailing 1). Hence::

    R_opencv = diag(1, -1, -1) @ R_meshlab        C = -TranslationVector[:3]
    fx = FocalMm / PixelSizeMm.x                  fy = FocalMm / PixelSizeMm.y
    cx = CenterPx.x - sx                          cy = height - (CenterPx.y - sy)

with a half-pixel shift ``(sx, sy) = CENTER_SHIFT = (0.5, -0.5)``: a world point that lands at
pixel ``(x, y)`` in ours (pixel centres at integers, y down) lands at viewport coordinates
``(x + 0.5, height - y - 0.5)`` in MeshLab (y up, pixel *corners* at integers; see
:func:`project_meshlab`). A 640 x 480 camera with cx, cy = 319.5, 239.5 has CenterPx = 320 240.

The shift was measured with MeshLab itself (pymeshlab 2025.7.post1): texturing a bumpy plane
with ``compute_texcoord_parametrization_and_texture_from_registered_rasters`` from one raster
and ray-casting the result from the same camera reproduces the photo to 0.03 grey levels (mean
absolute difference) with this shift; with ``(0, 0)`` the render is offset by half a pixel in
x and in y (texture sizes 512 to 2048 alike). Pass ``center_shift=(0, 0)`` for the plain
convention ``cx = CenterPx.x, cy = height - CenterPx.y``.
A non-zero ``LensDistortion`` (its first coefficient: vcglib uses only that one) is removed on
the fly the way MeshLab's ``Camera::Project`` applies it (:mod:`o3d_seqcc.geometry.distortion`, model
``"meshlab"``); the view's camera is then the pinhole of the same size, and a project written
for the original photos gets the photo's camera and ``LensDistortion`` back.
"""

from __future__ import annotations

import logging
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from ..geometry.distortion import Distortion
from .._shared.numbers import check_numbers
from ..errors import InputError
from ..scene import Scene, View
from .atomic import atomic_write_bytes
from .paths import join_path

__all__ = [
    "CENTER_SHIFT",
    "DEFAULT_PIXEL_SIZE_MM",
    "FLIP_YZ",
    "MeshLayer",
    "load_mlp",
    "project_meshlab",
    "save_mlp",
    "vcg_camera_attributes",
    "view_from_vcg_camera",
]

logger = logging.getLogger(__name__)

#: diag(1, -1, -1): OpenCV camera axes (y down, z forward) <-> VCG camera axes (y up, looks down -z).
FLIP_YZ = np.diag([1.0, -1.0, -1.0])
#: Half-pixel shift between our pixel centres and MeshLab's viewport coordinates (measured).
CENTER_SHIFT = (0.5, -0.5)
#: Pixel size written to ``PixelSizeMm`` (only FocalMm / PixelSizeMm matters; MeshLab's usual value).
DEFAULT_PIXEL_SIZE_MM = 0.0369161


def _fmt(values: Sequence[float]) -> str:
    return " ".join(repr(float(x)) for x in values)


@dataclass(frozen=True)
class MeshLayer:
    """A mesh layer of a MeshLab project (``MeshGroup/MLMesh``).

    Attributes
    ----------
    path : pathlib.Path
        Mesh file.
    label : str, default ""
        Layer name shown by MeshLab; default the file name.
    matrix : (4, 4) float64, default identity
        Placement of the layer (``MLMatrix44``): MeshLab shows the mesh at ``matrix @ x``.
    visible : bool, default True
    """

    path: Path
    label: str = ""
    matrix: np.ndarray = field(default_factory=lambda: np.eye(4))
    visible: bool = True


def _matrix_text(m: np.ndarray) -> str:
    """``MLMatrix44`` text: one row a line, shortest exact decimals (the identity reads ``1 0 0 0``)."""
    rows = np.asarray(m, dtype=np.float64).reshape(4, 4)
    return "\n" + "".join("%s \n" % " ".join("%.17g" % x for x in row) for row in rows)


def vcg_camera_attributes(
    view: View,
    *,
    pixel_size_mm: float = DEFAULT_PIXEL_SIZE_MM,
    center_shift: tuple[float, float] = CENTER_SHIFT,
    undistorted: bool = False,
) -> dict[str, str]:
    """The ``VCGCamera`` XML attributes of a view.

    Parameters
    ----------
    view : View
        Camera with zero skew.
    pixel_size_mm : float, default 0.0369161
        Horizontal pixel size written to ``PixelSizeMm`` (the vertical one is scaled by fx / fy).
    center_shift : (float, float), default CENTER_SHIFT = (0.5, -0.5)
        ``CenterPx = (cx + sx, height - cy + sy)``; see the module docstring.
    undistorted : bool, default False
        The raster is the view's undistorted image (the pinhole camera is written); by default
        a view with lens distortion gets its photo's camera and ``LensDistortion`` (MeshLab's
        model only; others raise).

    Returns
    -------
    dict of str
        ``TranslationVector, LensDistortion, ViewportPx, PixelSizeMm, CenterPx, FocalMm,
        RotationMatrix, CameraType``.
    """
    K = view.intrinsic
    lens = "0 0"
    if view.distorted and not undistorted:  # the rasters are the distorted photos: their own camera
        d = view.distortion
        if d.model != "meshlab":
            raise InputError(f"view {view.name!r}: MeshLab cannot hold its {d.model} lens distortion; write the "
                             "undistorted images (save_images=True, --save-images) for a project of pinhole rasters")
        K = d.intrinsic
        lens = _fmt(d.coefficients)
        pixel_size_mm = d.meshlab["pixel_size_mm"][0]
    if K[0, 1] != 0:
        raise InputError(f"view {view.name!r}: MeshLab cameras have no skew; intrinsic[0, 1] = {K[0, 1]}")
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    px = float(pixel_size_mm)
    R_ml = FLIP_YZ @ view.rotation
    M = np.eye(4)
    M[:3, :3] = R_ml
    # camera centre such that R (x - C) == R x + t exactly, even for a slightly non-orthonormal R
    C = -np.linalg.solve(view.rotation, view.translation)
    return {
        "TranslationVector": _fmt([*(-C), 1.0]),
        "LensDistortion": lens,
        "ViewportPx": f"{view.width} {view.height}",
        "PixelSizeMm": _fmt([px, px * fx / fy]),
        "CenterPx": _fmt([cx + center_shift[0], view.height - cy + center_shift[1]]),
        "FocalMm": repr(float(fx * px)),
        "RotationMatrix": _fmt(M.reshape(-1)),
        "CameraType": "0",
    }


def _floats(attrs: dict[str, str], key: str, n: int, where: str) -> np.ndarray:
    if key not in attrs:
        raise InputError(f"{where}: VCGCamera has no {key} attribute")
    try:
        vals = np.array([float(x) for x in attrs[key].split()], dtype=np.float64)
    except ValueError:
        raise InputError(f"{where}: VCGCamera {key}={attrs[key]!r} is not numeric") from None
    if len(vals) < n:
        raise InputError(f"{where}: VCGCamera {key} needs {n} numbers, got {attrs[key]!r}")
    return check_numbers(vals[:n], f"{where}: VCGCamera {key}", fix="fix or re-export the project")


def view_from_vcg_camera(
    attrs: dict[str, str],
    *,
    name: str,
    image: str | os.PathLike,
    center_shift: tuple[float, float] = CENTER_SHIFT,
) -> View:
    """A :class:`View` from ``VCGCamera`` XML attributes (inverse of :func:`vcg_camera_attributes`).

    Raises
    ------
    InputError
        Missing/malformed attributes, orthographic camera.
    """
    where = f"raster {name!r}"
    if attrs.get("CameraType", "0").strip() not in ("0", ""):
        raise InputError(f"{where}: only perspective cameras (CameraType 0) are supported")
    dist = _floats(attrs, "LensDistortion", 2, where) if "LensDistortion" in attrs else np.zeros(2)
    t = _floats(attrs, "TranslationVector", 3, where)
    w, h = (int(round(x)) for x in _floats(attrs, "ViewportPx", 2, where))
    pix = _floats(attrs, "PixelSizeMm", 2, where)
    c = _floats(attrs, "CenterPx", 2, where)
    f = _floats(attrs, "FocalMm", 1, where)[0]
    M = _floats(attrs, "RotationMatrix", 16, where).reshape(4, 4)
    if np.any(pix <= 0) or f <= 0:
        raise InputError(f"{where}: FocalMm and PixelSizeMm must be positive")
    R = FLIP_YZ @ M[:3, :3]
    C = -t
    ext = np.eye(4)
    ext[:3, :3] = R
    ext[:3, 3] = -R @ C
    cx, cy = c[0] - center_shift[0], h - (c[1] - center_shift[1])
    K = np.array([[f / pix[0], 0.0, cx], [0.0, f / pix[1], cy], [0.0, 0.0, 1.0]])
    lens = None
    if dist[0] != 0:  # vcglib's Camera::Project distorts only when k[0] != 0
        try:
            lens = Distortion("meshlab", dist.tolist(), K, meshlab={"pixel_size_mm": pix.tolist(),
                                                                    "center_px": c.tolist(), "viewport_px": [w, h]})
            K = lens.pinhole(w, h)
        except InputError as e:
            raise InputError(f"{where}: {e}") from None
    elif dist[1] != 0:
        logger.info("%s: LensDistortion %s: MeshLab ignores the second coefficient without a first", where, dist)
    return View(name=name, image=Path(image), intrinsic=K, extrinsic=ext, width=w, height=h, distortion=lens)


def project_meshlab(points: np.ndarray, attrs: dict[str, str]) -> np.ndarray:
    """Project world points with a VCG camera the way vcglib's ``Shot::Project`` does.

    World -> camera: ``p_c = RotationMatrix[:3, :3] @ (p + TranslationVector)``; the camera looks
    down -z, so ``x = FocalMm * p_c.x / -p_c.z / PixelSizeMm.x + CenterPx.x`` and likewise y (up).

    Parameters
    ----------
    points : (n, 3) float
    attrs : dict
        ``VCGCamera`` attributes.

    Returns
    -------
    (n, 2) float64
        Viewport pixel coordinates, y up (MeshLab convention).
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    t = _floats(attrs, "TranslationVector", 3, "camera")
    M = _floats(attrs, "RotationMatrix", 16, "camera").reshape(4, 4)[:3, :3]
    pix = _floats(attrs, "PixelSizeMm", 2, "camera")
    c = _floats(attrs, "CenterPx", 2, "camera")
    f = _floats(attrs, "FocalMm", 1, "camera")[0]
    pc = (p + t) @ M.T
    depth = -pc[:, 2]
    return np.stack([f * pc[:, 0] / depth / pix[0] + c[0], f * pc[:, 1] / depth / pix[1] + c[1]], axis=1)


def _rel(p: Path, root: Path) -> str:
    try:
        return Path(os.path.relpath(Path(p).resolve(), root.resolve())).as_posix()
    except ValueError:  # different drive (Windows)
        return Path(p).resolve().as_posix()


def save_mlp(
    scene: Scene,
    path: str | os.PathLike,
    *,
    mesh: str | os.PathLike | None = None,
    images: Sequence[str | os.PathLike] | None = None,
    layers: Sequence[MeshLayer] | None = None,
    pixel_size_mm: float = DEFAULT_PIXEL_SIZE_MM,
    center_shift: tuple[float, float] = CENTER_SHIFT,
) -> Path:
    """Write a MeshLab project with the scene's mesh and one raster per view, atomically.

    Parameters
    ----------
    scene : Scene
    path : path-like
        Output ``.mlp`` file; mesh and image paths are stored relative to its folder.
    mesh : path-like, optional
        Mesh file to reference instead of ``scene.mesh``.
    images : sequence of path-like, optional
        One image per view to reference instead of the views' own (e.g. corrected images), taken
        to be the undistorted images (pinhole cameras are written for them).
    layers : sequence of MeshLayer, optional
        Mesh layers (file, label, placement, visibility) to list instead of the one mesh; the
        cameras stay in world coordinates, as MeshLab keeps them.
    pixel_size_mm : float, default 0.0369161
    center_shift : (float, float), default CENTER_SHIFT
        See :func:`vcg_camera_attributes`.

    Returns
    -------
    pathlib.Path
    """
    path = Path(path)
    root = path.parent
    root.mkdir(parents=True, exist_ok=True)
    if layers is not None and mesh is not None:
        raise InputError("save_mlp: pass either mesh= or layers=, not both")
    if layers is None:
        if mesh is None and not isinstance(scene.mesh, Path):
            raise InputError("the scene's mesh is in memory: give the mesh file of the project (mesh=)")
        layers = [MeshLayer(Path(mesh) if mesh is not None else scene.mesh)]
    if images is not None and len(images) != len(scene.views):
        raise InputError(f"images: {len(images)} given for {len(scene.views)} views; give one image per view")
    if images is None and any(v.image is None for v in scene.views):
        raise InputError("the scene's images are in memory: give the image files of the rasters (images=)")
    proj = ET.Element("MeshLabProject")
    group = ET.SubElement(proj, "MeshGroup")
    for layer in layers:
        path_l = Path(layer.path)
        m = ET.SubElement(group, "MLMesh", label=layer.label or path_l.name, filename=_rel(path_l, root),
                          visible="1" if layer.visible else "0")
        ET.SubElement(m, "MLMatrix44").text = _matrix_text(layer.matrix)
    rasters = ET.SubElement(proj, "RasterGroup")
    for k, v in enumerate(scene.views):
        img = Path(images[k]) if images is not None else v.image
        r = ET.SubElement(rasters, "MLRaster", label=v.name)
        ET.SubElement(r, "VCGCamera", vcg_camera_attributes(v, pixel_size_mm=pixel_size_mm, center_shift=center_shift,
                                                            undistorted=images is not None))
        ET.SubElement(r, "Plane", semantic="1", fileName=_rel(img, root))
    ET.indent(proj, space=" ")
    text = "<!DOCTYPE MeshLabDocument>\n" + ET.tostring(proj, encoding="unicode") + "\n"
    return atomic_write_bytes(path, text.encode("utf-8"))


def load_mlp(
    path: str | os.PathLike,
    *,
    mesh: str | os.PathLike | None = None,
    center_shift: tuple[float, float] = CENTER_SHIFT,
) -> Scene:
    """Read a MeshLab project into a :class:`Scene` (first mesh + every raster).

    A rigid placement matrix (``MLMatrix44``) of the mesh is folded into the cameras (the scene
    keeps the mesh file's own coordinates); a non-rigid one raises.

    Parameters
    ----------
    path : path-like
        ``.mlp`` file.
    mesh : path-like, optional
        Use this mesh instead of the project's first one.
    center_shift : (float, float), default CENTER_SHIFT
        See :func:`vcg_camera_attributes`.

    Returns
    -------
    Scene
        Views named after the raster labels (file stem if the label is empty or duplicate).

    Raises
    ------
    InputError
        Missing file, not a MeshLab project, no raster, unsupported cameras.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"MeshLab project not found: {path}")
    try:
        root_el = ET.fromstring(path.read_text(encoding="utf-8").replace("<!DOCTYPE MeshLabDocument>", ""))
    except ET.ParseError as e:
        raise InputError(f"{path}: not a valid MeshLab project XML ({e})") from None
    if root_el.tag != "MeshLabProject":
        raise InputError(f"{path}: root element is {root_el.tag!r}, expected MeshLabProject")
    root = path.parent
    meshes = root_el.findall("./MeshGroup/MLMesh")
    placement = np.eye(4)
    if mesh is not None:
        mesh_path = Path(mesh)
    else:
        if not meshes:
            raise InputError(f"{path}: the project has no mesh; pass mesh=...")
        if len(meshes) > 1:
            logger.warning("%s: %d meshes in the project, using the first (%s)", path, len(meshes), meshes[0].get("filename"))
        mesh_path = join_path(root, meshes[0].get("filename", ""))
        mat = meshes[0].find("MLMatrix44")
        if mat is not None and mat.text and mat.text.split():
            try:
                placement = np.array([float(x) for x in mat.text.split()], dtype=np.float64).reshape(4, 4)
            except ValueError:
                raise InputError(f"{path}: MLMatrix44 of the mesh is not a 4x4 numeric matrix") from None
            check_numbers(placement, f"{path}: MLMatrix44 of the mesh", fix="fix or re-export the project")
    if not np.allclose(placement, np.eye(4), atol=1e-12):
        R = placement[:3, :3]
        if not (np.allclose(R.T @ R, np.eye(3), atol=1e-6) and np.allclose(placement[3], [0, 0, 0, 1])):
            raise InputError(f"{path}: the mesh placement matrix is not rigid; apply it to the mesh in MeshLab first")
    views: list[View] = []
    names: set[str] = set()
    for i, r in enumerate(root_el.findall("./RasterGroup/MLRaster")):
        cam = r.find("VCGCamera")
        plane = r.find("Plane")
        if cam is None or plane is None or not plane.get("fileName"):
            raise InputError(f"{path}: raster {i} lacks a VCGCamera or an image (Plane fileName)")
        img = join_path(root, plane.get("fileName"))
        name = r.get("label") or img.stem
        if name in names or any(ch in name for ch in '/\\:*?"<>|'):
            name = f"{img.stem}_{i}" if name in names else img.stem
        names.add(name)
        try:
            v = view_from_vcg_camera(dict(cam.attrib), name=name, image=img, center_shift=center_shift)
        except InputError as e:
            raise InputError(f"{path}: {e}") from None
        if not np.allclose(placement, np.eye(4), atol=1e-12):
            # the project shows placement @ x; the scene keeps the file's x
            from dataclasses import replace

            v = replace(v, extrinsic=v.extrinsic @ placement)
        views.append(v)
    if not views:
        raise InputError(f"{path}: the project has no rasters (RasterGroup/MLRaster); add registered images")
    return Scene(mesh=mesh_path, views=tuple(views))
