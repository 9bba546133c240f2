"""The Open3D front door: Open3D objects in, Open3D objects out.

Called the way Open3D's own ``TriangleMesh.project_images_to_albedo`` and
``color_map.run_rigid_optimizer`` are::

    import open3d as o3d
    import o3d_seqcc

    traj = o3d.io.read_pinhole_camera_trajectory("scene/key.log")
    images = [o3d.io.read_image(p) for p in image_paths]
    mesh = o3d.io.read_triangle_mesh("mesh.ply")
    corrected = o3d_seqcc.correct_images(mesh, images, traj)          # list of o3d.geometry.Image
    textured = o3d_seqcc.texture_mesh(mesh, images, traj)             # o3d.t.geometry.TriangleMesh
    o3d.visualization.draw(textured)

Accepted inputs (checked before any work; a wrong type or size raises
:class:`~o3d_seqcc.errors.InputError` naming the argument and what it should be):

- ``mesh``: ``o3d.geometry.TriangleMesh`` or ``o3d.t.geometry.TriangleMesh``;
- ``images``: a list of ``o3d.geometry.Image``, ``o3d.t.geometry.Image`` or (H, W, 3) arrays,
  uint8, uint16 or float in [0, 1]; corrected images come back in the type (and dtype) that
  came in;
- ``cameras``: an ``o3d.camera.PinholeCameraTrajectory``, a list of
  ``o3d.camera.PinholeCameraParameters``, or ``(intrinsic_matrices, extrinsic_matrices)`` as
  ``project_images_to_albedo`` takes them ((3, 3) and (4, 4) world-to-camera, arrays or tensors);
- ``depths``: optional, one per image: Open3D depth images (uint16 in ``depth_scale`` units per
  metre, or float metres), ``o3d.geometry.RGBDImage`` (its float depth in metres), point clouds
  (``o3d.geometry.PointCloud`` / ``o3d.t.geometry.PointCloud``, world coordinates), or arrays;
- ``masks``: optional, one per image (or None for an image without one): (H, W) bool / uint8
  arrays or Open3D images of the image's size, or mask files (:mod:`o3d_seqcc.io.masks`);
  nonzero = keep, 0 = masked out (``mask_invert=True``: the other way round). Masked pixels
  colour nothing: not the visibility, the colour mappings, the view selection or the bake.

Everything runs in memory (an in-memory :class:`~o3d_seqcc.scene.Scene`): nothing is written.
The cameras are checked against the mesh first (:func:`~o3d_seqcc.visibility.camera_checks.check_cameras`):
camera-to-world poses given as extrinsics, OpenGL axes or other units than the mesh's raise
:class:`~o3d_seqcc.errors.InputError` naming the fix.
"""

from __future__ import annotations

import logging
from typing import Any, Sequence

import numpy as np

from . import pipeline
from .visibility.camera_checks import check_cameras
from .errors import InputError, warn
from .imaging.arrays import img_as_dtype
from .geometry.meshops import vertex_normals
from .scene import DEPTH_SCALE_RANGE, Mesh, Scene, View
from .settings import CORRECTION_ONLY, RunSettings

__all__ = ["correct_images", "scene_from_open3d", "texture_mesh"]

logger = logging.getLogger(__name__)


def _mesh(mesh: Any) -> Mesh:
    import open3d as o3d

    if isinstance(mesh, o3d.geometry.TriangleMesh):  # copies: the result must not move with the caller's mesh
        v = np.array(mesh.vertices, dtype=np.float64)
        f = np.array(mesh.triangles, dtype=np.int64)
        n = np.array(mesh.vertex_normals, dtype=np.float64) if mesh.has_vertex_normals() else None
        uv = np.array(mesh.triangle_uvs, dtype=np.float64).reshape(-1, 3, 2) if mesh.has_triangle_uvs() else None
    elif isinstance(mesh, o3d.t.geometry.TriangleMesh):
        if "positions" not in mesh.vertex or "indices" not in mesh.triangle:
            raise InputError("mesh: the o3d.t.geometry.TriangleMesh has no vertex positions or triangle indices")
        v = mesh.vertex.positions.numpy().astype(np.float64, copy=True)
        f = mesh.triangle.indices.numpy().astype(np.int64, copy=True)
        n = mesh.vertex.normals.numpy().astype(np.float64, copy=True) if "normals" in mesh.vertex else None
        uv = (mesh.triangle.texture_uvs.numpy().astype(np.float64, copy=True).reshape(-1, 3, 2)
              if "texture_uvs" in mesh.triangle else None)
    else:
        raise InputError(f"mesh must be an o3d.geometry.TriangleMesh or o3d.t.geometry.TriangleMesh, got "
                         f"{type(mesh).__name__}")
    if len(f) == 0 or v.ndim != 2 or v.shape[1] != 3:
        raise InputError(f"mesh has no triangles ({len(v)} vertices, {len(f)} triangles); give a triangle mesh")
    if not np.all(np.isfinite(v)) or f.min() < 0 or f.max() >= len(v):
        raise InputError("mesh has non-finite vertices or triangle indices outside the vertex array; clean it first")
    n = vertex_normals(v, f, n)
    if uv is not None and uv.shape != (len(f), 3, 2):
        uv = None  # not one (u, v) per triangle corner: unusable, as if absent (uv="keep" then says so)
    for a in (v, f, n) + ((uv,) if uv is not None else ()):
        a.setflags(write=False)
    return Mesh(vertices=v, faces=f, vertex_normals=n, corner_uv=uv)


def _to_array(img: Any, where: str) -> np.ndarray:
    import open3d as o3d

    if isinstance(img, o3d.geometry.Image):
        return np.asarray(img)
    if isinstance(img, o3d.t.geometry.Image):
        return img.as_tensor().cpu().numpy()
    if isinstance(img, np.ndarray):
        return img
    raise InputError(f"{where} must be an o3d.geometry.Image, o3d.t.geometry.Image or numpy array, got "
                     f"{type(img).__name__}")


def _image(img: Any, i: int) -> tuple[np.ndarray, np.dtype]:
    """(H, W, 3) uint8/uint16 pixels of image ``i`` and the dtype it came in."""
    a = _to_array(img, f"images[{i}]")
    if a.ndim == 3 and a.shape[2] == 4:
        raise InputError(f"images[{i}] has an alpha channel; give (H, W, 3) RGB images")
    if a.ndim != 3 or a.shape[2] != 3:
        raise InputError(f"images[{i}] has shape {a.shape}; give (H, W, 3) RGB images (not grey or depth images)")
    dtype = a.dtype
    if dtype in (np.uint8, np.uint16):
        return np.ascontiguousarray(a), dtype
    if np.issubdtype(dtype, np.floating):
        if not np.isfinite(a).all():
            raise InputError(f"images[{i}] holds NaN or infinite values; give finite colours in [0, 1]")
        lo, hi = float(a.min()), float(a.max())
        if lo < -1e-6 or hi > 1 + 1e-6:
            raise InputError(f"images[{i}] is a float image with values in [{lo:.4g}, {hi:.4g}]; float images must be in "
                             "[0, 1] (divide 8-bit values by 255, 16-bit ones by 65535, or give the integer image)")
        return img_as_dtype(np.clip(a, 0.0, 1.0), np.uint16), dtype  # 16 bits keep a float image's precision
    raise InputError(f"images[{i}] has dtype {dtype}; give uint8, uint16 or float images in [0, 1]")


def _cameras(cameras: Any, n: int, sizes: list[tuple[int, int]]) -> list[tuple[np.ndarray, np.ndarray]]:
    """(intrinsic (3, 3), extrinsic (4, 4)) per image."""
    import open3d as o3d

    if isinstance(cameras, o3d.camera.PinholeCameraTrajectory):
        cameras = list(cameras.parameters)
    if isinstance(cameras, tuple) and len(cameras) == 2:
        Ks, Es = cameras
        try:
            Ks = [np.asarray(k.numpy() if hasattr(k, "numpy") else k, dtype=np.float64) for k in Ks]
            Es = [np.asarray(e.numpy() if hasattr(e, "numpy") else e, dtype=np.float64) for e in Es]
        except (TypeError, ValueError):
            raise InputError("cameras: (intrinsic_matrices, extrinsic_matrices) must hold (3, 3) and (4, 4) numeric "
                             "matrices") from None
        out = list(zip(Ks, Es))
        if len(Ks) != len(Es):
            raise InputError(f"cameras: {len(Ks)} intrinsic matrices but {len(Es)} extrinsic matrices")
    elif isinstance(cameras, (list, tuple)) and all(isinstance(c, o3d.camera.PinholeCameraParameters) for c in cameras):
        out = []
        for i, c in enumerate(cameras):
            w, h = c.intrinsic.width, c.intrinsic.height
            if (w, h) != (0, 0) and i < len(sizes) and (w, h) != sizes[i]:
                raise InputError(f"cameras[{i}] is for {w}x{h} images but images[{i}] is {sizes[i][0]}x{sizes[i][1]}")
            out.append((np.asarray(c.intrinsic.intrinsic_matrix, dtype=np.float64), np.asarray(c.extrinsic, np.float64)))
    else:
        raise InputError(
            "cameras must be an o3d.camera.PinholeCameraTrajectory, a list of o3d.camera.PinholeCameraParameters, "
            f"or (intrinsic_matrices, extrinsic_matrices); got {type(cameras).__name__}"
        )
    if len(out) != n:
        raise InputError(f"cameras: {len(out)} cameras for {n} images; give one camera per image")
    for i, (K, E) in enumerate(out):
        if K.shape != (3, 3) or E.shape != (4, 4):
            raise InputError(f"cameras[{i}]: intrinsic must be (3, 3) and extrinsic (4, 4), got {K.shape}, {E.shape}")
    return out


def _depth(d: Any, i: int, size: tuple[int, int], depth_scale: float) -> dict[str, np.ndarray]:
    """``{"depth_map": (H, W) metres}`` or ``{"points": (M, 3)}`` for ``depths[i]``."""
    import open3d as o3d

    if isinstance(d, o3d.geometry.PointCloud):
        return {"points": np.asarray(d.points)}
    if isinstance(d, o3d.t.geometry.PointCloud):
        return {"points": d.point.positions.numpy()}
    w, h = size
    if isinstance(d, o3d.geometry.RGBDImage):
        a, scale = np.asarray(d.depth), 1.0  # Open3D stores RGB-D depth as float metres
    else:
        a = _to_array(d, f"depths[{i}]")
        if a.ndim == 2 and a.shape[1] == 3 and a.shape != (h, w):
            return {"points": a}  # an (M, 3) array of world points
        if a.ndim == 3 and a.shape[2] == 1:
            a = a[..., 0]
        scale = 1.0 if np.issubdtype(a.dtype, np.floating) else float(depth_scale)
    if a.shape != (h, w):
        raise InputError(f"depths[{i}] has shape {a.shape}; give a ({h}, {w}) depth image, an RGBDImage or a point "
                         "cloud")
    return {"depth_map": a.astype(np.float64) / scale}


def _mask(m: Any, i: int, size: tuple[int, int], invert: bool) -> dict[str, Any]:
    """``{"mask_map": array}`` or ``{"mask": path}`` (the header checked) for ``masks[i]``; ``{}`` for None."""
    import os

    from .io.masks import check_mask_file

    w, h = size
    if m is None:
        return {}
    if isinstance(m, (str, os.PathLike)):
        check_mask_file(m, shape=(h, w), view=f"images[{i}]")
        return {"mask": m, "mask_invert": invert}
    return {"mask_map": _to_array(m, f"masks[{i}]"), "mask_invert": invert}


def _check_options(*, depth_scale: Any, **flags: Any) -> None:
    """The front door's own options: ``depth_scale`` a positive number, the flags booleans (named when not)."""
    if isinstance(depth_scale, bool) or not isinstance(depth_scale, (int, float, np.integer, np.floating)) \
            or not DEPTH_SCALE_RANGE[0] <= float(depth_scale) <= DEPTH_SCALE_RANGE[1]:
        raise InputError(f"depth_scale must be a positive number of depth units per metre, between "
                         f"{DEPTH_SCALE_RANGE[0]:g} and {DEPTH_SCALE_RANGE[1]:g} (1000: millimetres), got {depth_scale!r:.60}")
    for name, value in flags.items():
        if not isinstance(value, (bool, np.bool_)):
            raise InputError(f"{name} must be True or False, got {value!r:.60} ({type(value).__name__})")


def scene_from_open3d(
    mesh: Any, images: Sequence[Any], cameras: Any, *, depths: Sequence[Any] | None = None,
    depth_scale: float = View.depth_scale, names: Sequence[str] | None = None, masks: Sequence[Any] | None = None,
    mask_invert: bool = False,
) -> tuple[Scene, list[np.dtype]]:
    """An in-memory :class:`~o3d_seqcc.scene.Scene` from Open3D objects (see the module docstring).

    Returns
    -------
    (Scene, list of numpy.dtype)
        The scene, and the dtype each image came in (to give the corrected ones back the same way).
    """
    if isinstance(images, (str, bytes)) or not isinstance(images, Sequence) or not len(images):
        raise InputError(f"images must be a non-empty list of images, got {type(images).__name__}")
    pix = [_image(im, i) for i, im in enumerate(images)]
    sizes = [(p.shape[1], p.shape[0]) for p, _ in pix]
    cams = _cameras(cameras, len(pix), sizes)
    if depths is not None and len(depths) != len(pix):
        raise InputError(f"depths: {len(depths)} given for {len(pix)} images; give one per image (or None)")
    if masks is not None and (isinstance(masks, (str, bytes)) or not isinstance(masks, Sequence)
                              or len(masks) != len(pix)):
        raise InputError(f"masks: give one mask per image (or None for an image without one), a list of "
                         f"{len(pix)}; got {type(masks).__name__}")
    names = [f"{i:03d}" for i in range(len(pix))] if names is None else [str(n) for n in names]
    if len(names) != len(pix):
        raise InputError(f"names: {len(names)} given for {len(pix)} images")
    views = []
    for i, ((p, _), (K, E), name) in enumerate(zip(pix, cams, names)):
        extra = {} if depths is None or depths[i] is None else _depth(depths[i], i, sizes[i], depth_scale)
        extra.update({} if masks is None else _mask(masks[i], i, sizes[i], mask_invert))
        try:
            views.append(View(name=name, image=None, pixels=p, intrinsic=K, extrinsic=E, width=sizes[i][0],
                              height=sizes[i][1], **extra))
        except InputError as e:
            raise InputError(f"images[{i}] / cameras[{i}]: {e}") from None
    scene = Scene(mesh=_mesh(mesh), views=tuple(views))
    rep = check_cameras(scene, fix=_CAMERA_FIXES, where="cameras")  # before any work: the likely mistakes
    for w in rep.warnings:
        warn(f"cameras: {w}")
    return scene, [d for _, d in pix]


#: the fixes an Open3D user is told (extrinsics are world-to-camera, OpenCV axes, as Open3D's own)
_CAMERA_FIXES = {
    "inverse": "give world-to-camera extrinsics, as PinholeCameraParameters.extrinsic and project_images_to_albedo "
               "take them: extrinsic = numpy.linalg.inv(camera_to_world)",
    "opengl": "flip the camera axes to OpenCV's (y down, looking down +z): extrinsic = numpy.diag([1, -1, -1, 1]) @ "
              "extrinsic",
    "inverse+opengl": "extrinsic = numpy.diag([1, -1, -1, 1]) @ numpy.linalg.inv(camera_to_world) for camera-to-world "
                      "OpenGL poses",
}


def _like(original: Any, pixels: np.ndarray, dtype: np.dtype) -> Any:
    """``pixels`` in the type of ``original`` (Open3D legacy / tensor image or array) and its dtype."""
    import open3d as o3d

    if np.issubdtype(dtype, np.floating):
        pixels = (pixels.astype(np.float64) / 65535.0).astype(dtype)
    out = np.ascontiguousarray(pixels)
    if isinstance(original, o3d.geometry.Image):
        return o3d.geometry.Image(out)
    if isinstance(original, o3d.t.geometry.Image):
        return o3d.t.geometry.Image(o3d.core.Tensor(out))
    return out


def correct_images(
    mesh: Any,
    images: Sequence[Any],
    cameras: Any,
    *,
    depths: Sequence[Any] | None = None,
    masks: Sequence[Any] | None = None,
    mask_invert: bool = False,
    depth_scale: float = View.depth_scale,
    return_report: bool = False,
    settings: RunSettings | None = None,
    **options: Any,
) -> list | tuple[list, dict]:
    """Colour-correct registered images of a mesh toward a reference view (sequential pairwise correction).

    Parameters
    ----------
    mesh, images, cameras, depths, masks
        Open3D objects or arrays (see the module docstring): ``masks`` one per image (None: no mask).
    mask_invert : bool, default False
        The masks' other convention: nonzero = masked out.
    depth_scale : float, default :attr:`View.depth_scale <o3d_seqcc.scene.View>` (1000.0)
        Units per metre of integer depth images.
    return_report : bool, default False
        Also return the correction report, ``correct``'s report.json (:mod:`o3d_seqcc.report.schema`:
        ``report["correction"]`` holds the reference, graph edges, paths, unreachable views and
        per-view lookup tables; ``report["metrics"]`` the per-pair PSNR / CIEDE2000 before and
        after; ``report["timings_s"]``).
    settings : RunSettings or CorrectionSettings, optional
        Default :class:`~o3d_seqcc.settings.RunSettings` (the command line's defaults).
    **options
        Options changed from ``settings``, by their flat names (as :func:`o3d_seqcc.pipeline.correct_scene`):
        :class:`~o3d_seqcc.correction.settings.CorrectionSettings` fields (``reference``: the index
        of the reference image or ``"auto"``; ``method``; ``t_npm``; ``mappings``; ...) and
        :class:`~o3d_seqcc.visibility.settings.VisibilitySettings` fields.

    Returns
    -------
    list, or (list, dict)
        The corrected images, in the type and dtype each came in.
    """
    _check_options(depth_scale=depth_scale, return_report=return_report, mask_invert=mask_invert)
    rs = RunSettings.resolve(settings, options, where="correct_images", exclude=("metrics",))
    scene, dtypes = scene_from_open3d(mesh, images, cameras, depths=depths, depth_scale=depth_scale, masks=masks,
                                      mask_invert=mask_invert)
    job = pipeline.correct_scene(scene, settings=rs, metrics=return_report)
    out = [_like(orig, px, dt) for orig, px, dt in zip(images, job.result.images, dtypes)]
    return (out, job.report) if return_report else out


def texture_mesh(
    mesh: Any,
    images: Sequence[Any],
    cameras: Any,
    *,
    depths: Sequence[Any] | None = None,
    masks: Sequence[Any] | None = None,
    mask_invert: bool = False,
    correct: bool = True,
    depth_scale: float = View.depth_scale,
    return_result: bool = False,
    settings: RunSettings | None = None,
    **options: Any,
):
    """Texture a mesh from registered images: colour correction (optional), one image per face, an atlas.

    Parameters
    ----------
    mesh, images, cameras, depths, masks
        Open3D objects or arrays (see the module docstring): ``masks`` one per image (None: no mask).
    mask_invert : bool, default False
        The masks' other convention: nonzero = masked out.
    correct : bool, default True
        Colour-correct the images first (as :func:`correct_images`); False textures with the
        images as they are.
    depth_scale : float, default :attr:`View.depth_scale <o3d_seqcc.scene.View>` (1000.0)
    return_result : bool, default False
        Also return the :class:`~o3d_seqcc.pipeline.RunResult` (selection, seams, timings, and
        ``.save(out)`` to write OBJ/GLB and the report).
    settings : RunSettings or TextureSettings, optional
        Default :class:`~o3d_seqcc.settings.RunSettings` (the command line's defaults).
    **options
        Options changed from ``settings``, by their flat names (as :func:`o3d_seqcc.pipeline.run`):
        :class:`~o3d_seqcc.texturing.TextureSettings` fields (``selection``: ``"mrf"``,
        ``"largest-area"`` or ``"random"``; ``atlas_size``: ``"auto"``, sized to the charts at the
        photos' resolution, or an integer budget for its largest side; ``uv="keep"``: bake into the
        mesh's own ``triangle_uvs`` / ``triangle.texture_uvs``, the result keeping its triangles and
        UVs; ...),
        :class:`~o3d_seqcc.correction.settings.CorrectionSettings` fields (``reference``,
        ``method``, ``t_npm``, ...) and :class:`~o3d_seqcc.visibility.settings.VisibilitySettings` fields.

    Returns
    -------
    open3d.t.geometry.TriangleMesh, or (mesh, RunResult)
        ``vertex.positions``, ``vertex.normals``, ``triangle.indices``, ``triangle.texture_uvs``
        and the atlas as the ``albedo`` map of its material: ``o3d.visualization.draw`` shows it
        textured and ``o3d.t.io.write_triangle_mesh`` writes it.
    """
    _check_options(depth_scale=depth_scale, return_result=return_result, correct=correct, mask_invert=mask_invert)
    where = "texture_mesh" + ("" if correct else "(correct=False)")
    exclude = ("metrics",) if correct else CORRECTION_ONLY
    rs = RunSettings.resolve(settings, options, where=where, exclude=exclude)
    scene, _ = scene_from_open3d(mesh, images, cameras, depths=depths, depth_scale=depth_scale, masks=masks,
                                 mask_invert=mask_invert)
    res = pipeline.run(scene, settings=rs) if correct else pipeline.texture(scene, settings=rs)
    out = res.textured.to_open3d()
    return (out, res) if return_result else out
