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
from typing import Any, Callable, Mapping

import numpy as np

from ..visibility.camera_checks import FLIP, MIN_AREA_SEEN, check_cameras
from ..errors import InputError, MissingImagesError, warn
from .._shared.registry import Registry
from ..scene import Scene, View, check_scene_argument
from . import bundler, colmap, meshlab, meshroom, metashape, mve, nvm, openmvs, rgbd_folder, scene_json
from .paths import find_file
from .masks import attach_masks
from .missing import MissingImage, missing_images

__all__ = ["AXES", "EXTRINSIC_CONVENTIONS", "SCENE_FORMATS", "SceneFormat", "detect_format", "load_scene",
           "save_scene"]

#: values of ``load_scene(extrinsic=)`` / ``--extrinsic``: what the file's pose matrices map
EXTRINSIC_CONVENTIONS = ("world-to-camera", "camera-to-world")
#: values of ``load_scene(axes=)`` / ``--axes``: the file's camera axes
AXES = ("opencv", "opengl")


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
    poses : str or None
        The format's own pose convention (a value of :data:`EXTRINSIC_CONVENTIONS`) when its
        cameras are pose matrices (or quaternion + translation) that ``extrinsic=`` may restate;
        None when they are a rotation and a centre in a fixed convention (``extrinsic=`` and
        ``axes=`` do not apply).
    """

    name: str
    description: str
    detect: Callable[[Path], Path | None]
    load: Callable[..., Scene]
    poses: str | None = None


def _detect_mlp(path: Path) -> Path | None:
    return None if path.is_dir() else find_file(path, name="", suffix=".mlp")


#: The scene formats, in detection order (written out: a :class:`~o3d_seqcc._shared.registry.Registry` of
#: :class:`SceneFormat`; ``SCENE_FORMATS.register(name, SceneFormat(...))`` adds one, detected last).
SCENE_FORMATS: Registry[SceneFormat] = Registry("scene format", {
    f.name: f
    for f in (
        SceneFormat("scene.json", "a scene.json manifest or its folder", scene_json.detect, scene_json.load,
                    "world-to-camera"),
        SceneFormat("meshlab", "a MeshLab project (.mlp)", _detect_mlp, meshlab.load_mlp),
        SceneFormat("meshroom", "Meshroom/AliceVision SfM data (cameras.sfm or its folder)", meshroom.detect, meshroom.load),
        SceneFormat("rgbd-folder", "an Open3D RGB-D folder (image/, depth/, scene/key.log)", rgbd_folder.detect,
                    rgbd_folder.load, "camera-to-world"),
        SceneFormat("colmap", "a COLMAP model folder (cameras/images .txt or .bin)", colmap.detect, colmap.load,
                    "world-to-camera"),
        SceneFormat("openmvs", "an OpenMVS interface file (scene.mvs)", openmvs.detect, openmvs.load),
        SceneFormat("nvm", "a VisualSFM NVM_V3 file (.nvm)", nvm.detect, nvm.load),
        SceneFormat("metashape", "an Agisoft Metashape cameras export (cameras.xml or its folder)", metashape.detect,
                    metashape.load),
        SceneFormat("mve", "an MVE scene folder (views/*.mve/meta.ini)", mve.detect, mve.load),
        SceneFormat("cam-folder", "a texrecon camera folder (NAME.cam beside each photo)", mve.detect_cam_folder,
                    mve.load_cam_folder),
        SceneFormat("bundler", "a Bundler v0.3 file (bundle.out, or its folder, with list.txt)", bundler.detect,
                    bundler.load),
    )
})


def detect_format(path: str | os.PathLike, format: str = "auto") -> tuple[SceneFormat, Path]:
    """The format of a scene path and the file or folder to read (what :func:`load_scene` dispatches on).

    Raises
    ------
    InputError
        Missing path, unknown layout (the message lists the formats), unknown ``format`` name,
        or a path that is not of the named format.
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
        return found
    try:
        fmt = SCENE_FORMATS[format]
    except InputError as e:
        raise InputError(f"{e}, or 'auto' (detected from the path)") from None
    hit = fmt.detect(p)
    if hit is None:
        raise InputError(f"{p} is not {fmt.description}")
    return fmt, hit


def load_scene(
    path: str | os.PathLike,
    *,
    mesh: str | os.PathLike | None = None,
    format: str = "auto",
    intrinsic: np.ndarray | str | os.PathLike | None = None,
    image_dir: str | os.PathLike | None = None,
    depth_dir: str | os.PathLike | None = None,
    depth_scale: float = View.depth_scale,
    masks: str | os.PathLike | None = None,
    mask_invert: bool = False,
    extrinsic: str | None = None,
    axes: str | None = None,
    check_cameras: bool = True,
    validate: bool = True,
    skip_missing: bool = False,
    allow_unseen: bool = False,
) -> Scene:
    """Load a scene, detecting its format, and check its cameras against its mesh.

    Parameters
    ----------
    path : path-like
        A ``scene.json`` manifest (or its folder), a MeshLab project (``.mlp``), Meshroom's
        ``cameras.sfm`` (or its folder), an Open3D RGB-D folder, a COLMAP model folder (text
        or binary), an OpenMVS interface file (``scene.mvs``), a VisualSFM ``NVM_V3`` file
        (``.nvm``: its first model), an Agisoft Metashape cameras export (``cameras.xml``, or
        its folder), an MVE scene folder (``views/*.mve``; the ``undistorted`` images, else
        ``original``), a texrecon camera folder (``NAME.cam`` beside each photo) or a Bundler
        v0.3 ``bundle.out`` (or its folder) with its ``list.txt``; see :data:`SCENE_FORMATS`.
    mesh : path-like, optional
        Mesh file; required for RGB-D folders, COLMAP, Meshroom, NVM, Metashape, MVE, texrecon
        camera folders and Bundler, overrides the others'.
    format : str, default "auto"
        A name of :data:`SCENE_FORMATS` to skip detection.
    intrinsic : (3, 3) array or path-like, optional
        RGB-D folders only: the colour camera's pinhole matrix, or a file holding it (Open3D's
        ``PinholeCameraIntrinsic`` JSON, whose width and height must be the images'; or a text
        3x3 matrix); default PrimeSense (fx = fy = 525, cx = 319.5, cy = 239.5), which only
        640x480 images may use.
    image_dir : path-like, optional
        COLMAP, Meshroom, OpenMVS, NVM, Metashape and Bundler only: folder of the images.
    depth_dir : path-like, optional
        Folder of depth maps registered to the images, for the views that have none (MeshLab
        projects, COLMAP and Meshroom models carry no depth): ``<view name>.png`` or the image's
        file name with a depth extension (``.png``, ``.tif``, ``.tiff``, ``.exr``).
    depth_scale : float, default :attr:`View.depth_scale <o3d_seqcc.scene.View>` (1000.0)
        Units per metre of the depth maps of ``depth_dir`` (1000: millimetres).
    masks : path-like, optional
        Folder of per-photo masks (:mod:`o3d_seqcc.io.masks`): PNG / JPEG / TIFF named after the
        image (``<stem>.png``, ...) or the view (Meshroom: its ``<viewId>.png`` too; OpenMVS:
        ``<stem>.mask.png``), the photo's size, nonzero = kept, 0 = masked out: masked pixels
        count nowhere (visibility, mappings, view selection, bake). They replace the masks the
        scene names (``scene.json``'s ``"mask"``, OpenMVS's ``maskName``) for the views they
        cover; views without one are used whole (a warning names them).
    mask_invert : bool, default False
        The masks' other convention, nonzero = masked out (``--mask-invert``): for the masks of
        ``masks`` and those the scene names.
    extrinsic : {"world-to-camera", "camera-to-world"}, optional
        What the file's pose matrices map, when it is not the format's own convention
        (``scene.json`` and COLMAP: world-to-camera; an RGB-D folder's ``key.log``:
        camera-to-world); the other value inverts every pose. Default: the format's, and
        camera-to-world matrices given in its place are refused by the camera check. Not for
        formats whose cameras are a rotation and a centre (MeshLab, Meshroom, OpenMVS).
    axes : {"opencv", "opengl"}, optional
        The file's camera axes: OpenCV (x right, y down, looking down +z; every format's own)
        or OpenGL (y up, looking down -z: flipped on loading). Default: OpenCV, and OpenGL
        cameras given in its place are refused by the camera check. Same formats as
        ``extrinsic``.
    check_cameras : bool, default True
        Check the cameras against the mesh (:func:`o3d_seqcc.visibility.camera_checks.check_cameras`):
        an :class:`InputError` when they look camera-to-world, OpenGL or in other units than
        the mesh (the message names the fix), or when the photos do not show the mesh (see
        ``allow_unseen``); warnings when most of the mesh faces no camera. Needs ``validate``.
    validate : bool, default True
        Check files, image headers (size, grey, alpha) and the mesh now rather than later.
    skip_missing : bool, default False
        Go on without the photos that are missing or unreadable (``--skip-missing-images``), with
        one warning naming them; ``scene.options["skipped_images"]`` maps their view names to
        their paths (``report.json`` shows it). Without it they are one
        :class:`~o3d_seqcc.errors.MissingImagesError` listing them all; every photo missing is
        that error either way. Photos that readers open as they load (for their size) are
        skipped then, the others by ``validate``.
    allow_unseen : bool, default False
        Go on (with a warning) when the camera check finds less than
        :data:`~o3d_seqcc.visibility.camera_checks.MIN_AREA_SEEN` (10 %) of the mesh seen by any
        camera and the photos hardly showing it (under
        :data:`~o3d_seqcc.visibility.camera_checks.MIN_FRONT_SEEN` of their pixels,
        :meth:`~o3d_seqcc.visibility.camera_checks.CameraReport.hardly_seen`) (``--allow-unseen``);
        by default that is an :class:`InputError` naming the camera check and the likely causes:
        a mesh from another scene, other units, other camera conventions.

    Returns
    -------
    Scene
        Images are not read (lazy); use ``View.load_image``.

    Raises
    ------
    InputError
        Unknown layout (the message lists the formats), an option the format does not take,
        missing files, malformed cameras, duplicate names, cameras that look like another
        convention, a mesh the photos do not show, ...; missing or unreadable photos are one
        :class:`~o3d_seqcc.errors.MissingImagesError` listing them all.

    Examples
    --------
    >>> import tempfile, o3d_seqcc as sc
    >>> room = sc.make_synthetic_scene(tempfile.mkdtemp() + '/room', n_views=3, width=96, height=72, seed=1,
    ...                                seen_only=True)
    >>> scene = sc.load_scene(room.root)  # the folder of its scene.json
    >>> scene.names, scene.views[0].width
    (['v00', 'v01', 'v02'], 96)
    """
    fmt, target = detect_format(path, format)
    p = Path(path)
    conv = _conventions(fmt, p, extrinsic, axes)
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
    if masks is not None and "masks" in accepted:  # the format's own mask names (Meshroom's view ids) first
        options["masks"] = masks
    skipped: list[MissingImage] = []
    try:
        scene = fmt.load(target, **options)
    except MissingImagesError as e:
        scene = _without_missing(e, skip_missing, skipped)
    views = scene.views if depth_dir is None else _with_depth(scene.views, Path(depth_dir), depth_scale)
    if conv["invert"] or conv["flip"]:
        views = tuple(_restated(v, conv, target) for v in views)
    views = attach_masks(views, None if "masks" in options else masks, invert=bool(mask_invert))
    given = {"format": None if format == "auto" else format, "image_dir": image_dir, "depth_dir": depth_dir,
             "depth_scale": None if depth_dir is None else float(depth_scale), "extrinsic": extrinsic, "axes": axes,
             "intrinsic": intrinsic, "check_cameras": None if check_cameras else False,
             "skip_missing": True if skip_missing else None, "allow_unseen": True if allow_unseen else None,
             "masks": masks, "mask_invert": True if mask_invert else None}
    recorded = {k: (str(Path(v).resolve()) if isinstance(v, (str, os.PathLike)) and k.endswith(("_dir", "intrinsic",
                                                                                                  "masks"))
                    else np.asarray(v, dtype=np.float64).tolist() if k == "intrinsic" else v)
                for k, v in given.items() if v is not None}
    scene = Scene(scene.mesh, views, source=target, options=recorded)
    if validate:
        try:
            scene.validate()
        except MissingImagesError as e:
            hint = ("pass image_dir= (--image-dir DIR) if the images are elsewhere"
                    if "image_dir" in accepted and image_dir is None else "")
            scene = _without_missing(e, skip_missing, skipped, hint)
            scene.validate()  # what is left: sizes, depth maps
    if skipped:
        scene = Scene(scene.mesh, scene.views, source=target,
                      options={**recorded, "skipped_images": {m.view: str(m.path) for m in skipped}})
        warn(f"{target}: going on without {len(skipped)} of {len(skipped) + len(scene.views)} photos, missing or "
             "unreadable (skip_missing=True / --skip-missing-images): "
             + "; ".join(f"view {m.view!r} ({m.path})" for m in skipped))
    if validate and check_cameras:
        run_camera_check(scene, fmt, target, extrinsic=extrinsic, axes=axes, allow_unseen=allow_unseen)
    return scene


def as_scene(scene: Scene | str | os.PathLike, mesh: str | os.PathLike | None = None,
             scene_options: Mapping[str, Any] | None = None) -> Scene:
    """The scene a pipeline function was given: ``scene`` itself, or :func:`load_scene` of the path.

    Parameters
    ----------
    scene : Scene or path-like
    mesh : path-like, optional
        Mesh to use instead of the scene's.
    scene_options : mapping, optional
        Keyword options of :func:`load_scene` (``skip_missing``, ``allow_unseen``, ``masks``,
        ``image_dir``, ...), for a path only: a loaded Scene was loaded with its own.

    Raises
    ------
    InputError
        ``scene_options`` with a Scene, or a name :func:`load_scene` does not take (the message
        lists those it takes).
    """
    check_scene_argument(scene, mesh)
    opts = dict(scene_options or {})
    if isinstance(scene, Scene):
        if opts:
            raise InputError(f"scene_options ({', '.join(sorted(opts))}) apply when scene is a path; the Scene given "
                             "was loaded already: pass them to load_scene instead")
        return scene if mesh is None else Scene(Path(mesh), scene.views, source=scene.source)
    valid = sorted(n for n in inspect.signature(load_scene).parameters if n not in ("path", "mesh"))
    unknown = sorted(set(opts) - set(valid))
    if unknown:
        raise InputError(f"scene_options: load_scene takes no {', '.join(map(repr, unknown))}; "
                         f"valid: {', '.join(valid)}")
    return load_scene(scene, mesh=mesh, **opts)


def _without_missing(e: MissingImagesError, skip: bool, skipped: list[MissingImage], hint: str = "") -> Scene:
    """The scene of ``e`` without its missing photos (added to ``skipped``) when ``skip``, else ``e`` raised
    (with the format's ``hint`` to find the photos, when given).

    Every photo missing is an error either way, listing those skipped before too.
    """
    if not skip and hint:
        raise missing_images(e.missing, total=e.total, where=e.where, hint=hint, scene=e.scene) from None
    if not skip:
        raise e
    if e.scene is None:
        if not skipped and not hint:
            raise e
        every = [*skipped, *e.missing]
        raise missing_images(every, total=len(skipped) + e.total, where=e.where, hint=hint) from None
    skipped.extend(e.missing)
    return e.scene


def _conventions(fmt: SceneFormat, p: Path, extrinsic: str | None, axes: str | None) -> dict[str, bool]:
    """Whether the loaded poses are to be inverted / flipped for ``extrinsic=`` / ``axes=``."""
    if extrinsic is not None and extrinsic not in EXTRINSIC_CONVENTIONS:
        raise InputError(f"unknown extrinsic convention {extrinsic!r}; valid: {', '.join(EXTRINSIC_CONVENTIONS)}")
    if axes is not None and axes not in AXES:
        raise InputError(f"unknown camera axes {axes!r}; valid: {', '.join(AXES)}")
    for name, value in (("extrinsic", extrinsic), ("axes", axes)):
        if value is not None and fmt.poses is None:
            raise InputError(f"{name}= does not apply to {fmt.description} ({p}): its cameras are a rotation and a "
                             "centre in the format's own convention; drop it")
    return {"invert": extrinsic is not None and extrinsic != fmt.poses, "flip": axes == "opengl"}


def _restated(v: View, conv: dict[str, bool], target: Path) -> View:
    E = np.array(v.extrinsic)
    if conv["invert"]:
        E = np.linalg.inv(E)
        E[3] = [0.0, 0.0, 0.0, 1.0]
    if conv["flip"]:
        E = FLIP @ E
    try:
        return replace(v, extrinsic=E)
    except InputError as e:
        raise InputError(f"{target}: {e}") from None


def camera_fixes(fmt: SceneFormat) -> dict[str, str]:
    """The fix an error names for each likely camera mistake in a scene of format ``fmt``."""
    tail = "; if the cameras are right after all, check_cameras=False (--no-camera-check) skips this check"
    scale = ("scale the mesh by {s} (MeshLab: Filters > Normals, Curvatures and Orientation > Transform: Scale) or "
             "the camera positions by the inverse, so that both use one unit" + tail)
    if fmt.poses is None:
        redo = f"re-export the cameras from the program that wrote this {fmt.description}"
        return {"inverse": redo + tail, "opengl": redo + tail, "inverse+opengl": redo + tail, "scale": scale}
    other = EXTRINSIC_CONVENTIONS[1 - EXTRINSIC_CONVENTIONS.index(fmt.poses)]
    return {
        "inverse": f"set extrinsic='{other}' (--extrinsic {other}) if its matrices are {other}, or invert them" + tail,
        "opengl": "set axes='opengl' (--axes opengl) if its cameras use OpenGL axes, or flip them "
                  "(diag(1, -1, -1, 1) @ extrinsic)" + tail,
        "inverse+opengl": f"set extrinsic='{other}' and axes='opengl' (--extrinsic {other} --axes opengl)" + tail,
        "scale": scale,
    }


def run_camera_check(scene: Scene, fmt: SceneFormat, target: Path, *, extrinsic: str | None = None,
                     axes: str | None = None, raise_on_mistake: bool = True, allow_unseen: bool = False,
                     **options: Any):
    """:func:`~o3d_seqcc.visibility.camera_checks.check_cameras` with the fixes of ``fmt``; warnings emitted.

    The conventions stated (``extrinsic``, ``axes``) are not second-guessed. A mesh the photos do not
    show (:meth:`~o3d_seqcc.visibility.camera_checks.CameraReport.hardly_seen`) raises (with
    ``raise_on_mistake``) unless ``allow_unseen``.
    """
    skip = tuple(n for n, stated in (("inverse", extrinsic), ("opengl", axes)) if stated is not None)
    least = 0.0 if allow_unseen or not raise_on_mistake else MIN_AREA_SEEN
    rep = check_cameras(scene, skip=skip, fix=camera_fixes(fmt), where=str(target), raise_on_mistake=raise_on_mistake,
                        min_area_seen=least, **options)
    for w in rep.warnings:
        warn(f"{target}: {w}")
    return rep


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

    Examples
    --------
    >>> import tempfile, o3d_seqcc as sc
    >>> room = sc.make_synthetic_scene(tempfile.mkdtemp() + '/room', n_views=3, width=96, height=72, seed=1,
    ...                                seen_only=True)
    >>> path = sc.save_scene(room.scene, room.root / 'copy.json')
    >>> sc.load_scene(path).names == room.scene.names
    True
    """
    return scene_json.save(scene, path)
