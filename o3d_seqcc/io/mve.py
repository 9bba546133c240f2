"""MVE scenes and texrecon's camera folders: the inputs mvs-texturing's ``texrecon`` takes as ``IN_SCENE``.

Two formats (nmoehrle/mvs-texturing ``libs/tex/generate_texture_views.cpp``):

**"cam-folder"** (texrecon's ``SCENE_FOLDER``, ``from_images_and_camera_files``): a folder with
one ``NAME.cam`` per photo and the photo ``NAME.png`` / ``.jpg`` / ``.jpeg`` / ``.tif`` /
``.tiff`` beside it (same stem; when several, the first texrecon's search finds: the names after
the ``.cam`` in sorted order, then those before). A ``.cam`` file is two lines::

    tx ty tz R00 R01 R02 R10 R11 R12 R20 R21 R22
    f [d0 [d1 [paspect [ppx ppy]]]]

the world-to-camera rotation (row-major) and translation, ``x_cam = R x + t``, in OpenCV axes
(MVE's ``CameraInfo``: ``fill_world_to_cam``; ``fill_gl_viewtrans`` negates rows 2 and 3 for
OpenGL), then the focal length ``f``, normalised, the radial distortion ``d0 d1``, the pixel
aspect (default 1) and the principal point ``ppx ppy``, normalised (default 0.5 0.5, the centre).

**"mve"** (texrecon's ``MVE_SCENE::EMBEDDING``, ``from_mve_scene``): an MVE scene folder,
``views/view_NNNN.mve/meta.ini`` (INI: ``[view]`` ``id``, ``name``; ``[camera]``
``focal_length``, ``pixel_aspect``, ``principal_point``, ``radial_distortion`` (2 numbers),
``rotation`` (9), ``translation`` (3): the same camera, simonfuhrmann/mve
``libs/mve/view.cc``, ``View::load_meta_data``), with the images (embeddings) beside it as
``NAME.png`` / ``.jpg`` / ``.jpeg``. The embedding read is ``undistorted`` when a calibrated view
has one (what MVE's ``sfmrecon`` and ``makescene`` write and texrecon is usually given), else
``original``; :func:`load`'s ``embedding=`` names another (the scene path cannot carry
texrecon's ``::EMBEDDING`` suffix: a path is checked to exist before its format is detected).
Views without a camera (``focal_length`` 0 or absent) or without the embedding are skipped with
one warning each, as texrecon skips the latter (and a ``.cam`` without a photo beside it: nothing
names the photo there); photos found but unreadable are listed together in one
:class:`~o3d_seqcc.errors.MissingImagesError` (``skip_missing=True`` goes on without them).
MVE's raw ``.mvei`` images and the deprecated single-file views are refused with the way out.

Pixels (MVE ``CameraInfo::fill_calibration`` in ``libs/mve/camera.cc``, for an image of
``w x h`` read from its header): with ``a = (w / h) paspect``, ``fx = f w``, ``fy = f w paspect``
when ``a >= 1`` (landscape), else ``fx = f h / paspect``, ``fy = f h`` (f is normalised by the
larger side, paspect applied to y); ``cx = ppx w``, ``cy = ppy h`` in MVE's pixel coordinates,
whose top-left pixel's centre is at (0.5, 0.5) (texrecon's ``TextureView::get_pixel_coords``
subtracts 0.5 before sampling; MVE's ``FeatureSet`` adds 0.5 to pixel indices). Ours (centres
at integers) are therefore ``cx = ppx w - 0.5``, ``cy = ppy h - 0.5``.

Radial distortion (MVE ``libs/mve/image_tools.h``), about the image centre, never the principal
point, with radii normalised by ``n = f max(w, h)`` pixels:

- ``d1 != 0``: ``image_undistort_k2k4`` (MVE's and Bundler's model; ``sfmrecon`` derives
  ``undistorted`` from ``original`` with it): the undistorted pixel ``p`` is read from the
  photo at ``c + (p - c) (1 + d0 rho^2 + d1 rho^4)``, ``rho = |p - c| / n``, ``c = ((w - 1) / 2,
  (h - 1) / 2)`` in our coordinates (MVE: ``x + 0.5 - w / 2``). With the principal point at the
  centre and paspect 1 this is OpenCV's ``(k1, k2) = (d0, d1)`` (model ``"opencv"``), else
  ``"pixel-radial"``.
- ``d1 == 0``, ``d0 != 0``: ``image_undistort_vsfm`` (VisualSfM's model, which texrecon's
  ``.cam`` reader applies then, and ``makescene`` for NVM imports, whose ``dist[1]`` is 0): the
  photo's pixel ``d`` shows ``c + (d - c) (1 + d0 rho_d^2)``; its centre is ``c = (w / 2, h / 2)``
  in pixel indices (MVE computes ``x - w / 2`` there): model ``"pixel-radial-inverse"``.

texrecon undistorts the photos of a camera folder this way (leaving black borders) and reads
an MVE scene's embedding as it is, so only the ``original`` embedding of an MVE scene gets its
camera's distortion here. The view's camera is :meth:`~o3d_seqcc.geometry.distortion.Distortion.pinhole`
(the photo's own when the undistorted image needs nothing from outside the photo). Unlike
texrecon, a ``d1`` with ``d0 = 0`` is applied (texrecon tests ``d0`` alone). Zero distortion
gives a pinhole view. Neither format holds a mesh: ``mesh=`` is required.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from .._shared.numbers import parse_number
from ..errors import InputError
from ..geometry.distortion import Distortion
from ..scene import MAX_NAME_LENGTH, Scene, View
from .regular_files import open_regular
from .missing import MissingImage, check_photo, missing_images

__all__ = ["CAM_IMAGE_SUFFIXES", "EMBEDDINGS", "calibration", "detect", "detect_cam_folder", "lens", "load",
           "load_cam_folder"]

logger = logging.getLogger(__name__)

#: image suffixes texrecon pairs with a .cam file (its test: .PNG, .JPG, TIFF, JPEG; and .tif)
CAM_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff")
#: the embeddings tried, in order, when none is named
EMBEDDINGS = ("undistorted", "original")
_VIEW_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
_MAX_TEXT = 1 << 20


# ------------------------------------------------------------------------------------------ the camera


def _number(tok: str, where: str, what: str) -> float:
    return parse_number(tok, f"{where}: {what}", fix="write the camera again")


def _intrinsics(f: float, d: tuple[float, float], paspect: float, pp: tuple[float, float], where: str) -> None:
    """Refuse values no camera has (``f = 0`` is checked by the callers: no camera)."""
    if not 1e-6 <= f <= 1e6:
        raise InputError(f"{where}: focal length {f} is not a normalised focal length (> 0: the focal length in "
                         "pixels divided by the larger image side)")
    if not 1e-3 <= paspect <= 1e3:
        raise InputError(f"{where}: pixel aspect {paspect} must be > 0 (1 for square pixels)")
    if not all(abs(x) <= 1e3 for x in pp):
        raise InputError(f"{where}: principal point {list(pp)} is not normalised (0.5 0.5 is the image centre)")
    if not all(abs(x) <= 1e6 for x in d):
        raise InputError(f"{where}: radial distortion {list(d)} is implausible")


def _pose(R: list[float], t: list[float], where: str) -> None:
    """Refuse a rotation whose entries leave [-1, 1] and an absurd translation, where they are read."""
    if max(map(abs, R)) > 1.001:
        raise InputError(f"{where}: the rotation's entries must lie in [-1, 1] (a rotation matrix), got "
                         f"{max(map(abs, R)):.6g}")
    if max(map(abs, t)) > 1e12:
        raise InputError(f"{where}: implausible translation {list(t)}")


def calibration(f: float, paspect: float, pp: tuple[float, float], width: int, height: int) -> np.ndarray:
    """Our (3, 3) intrinsic (pixel centres at integers) of an MVE camera on a ``width`` x ``height`` image.

    MVE's ``CameraInfo::fill_calibration`` with the principal point moved by -0.5 (see the module
    docstring).
    """
    w, h = float(width), float(height)
    if (w / h) * paspect < 1.0:  # portrait
        fx, fy = f * h / paspect, f * h
    else:
        fx, fy = f * w, f * w * paspect
    return np.array([[fx, 0.0, pp[0] * w - 0.5], [0.0, fy, pp[1] * h - 0.5], [0.0, 0.0, 1.0]])


def lens(f: float, d: tuple[float, float], K: np.ndarray, width: int, height: int) -> tuple[np.ndarray, Distortion | None]:
    """The view's pinhole matrix and its :class:`Distortion` (None without) for MVE's radial distortion ``d``.

    ``K`` is :func:`calibration`'s; the models are the module docstring's.
    """
    d0, d1 = d
    if d0 == 0 and d1 == 0:
        return K, None
    w, h = int(width), int(height)
    n = f * max(w, h)
    if d1 == 0:
        dist = Distortion("pixel-radial-inverse", (d0, w / 2, h / 2, n), K)
    else:
        c = ((w - 1) / 2, (h - 1) / 2)
        if K[0, 0] == n and K[1, 1] == n and K[0, 1] == 0 and (K[0, 2], K[1, 2]) == c:
            dist = Distortion("opencv", (d0, d1, 0.0, 0.0), K)
        else:
            dist = Distortion("pixel-radial", (d0, d1, c[0], c[1], n), K)
    return dist.pinhole(w, h), dist


def _view(name: str, image: Path, f: float, d: tuple[float, float], paspect: float, pp: tuple[float, float],
          R: list[float], t: list[float], where: str, *, distorted: bool = True) -> View | MissingImage:
    size = check_photo(name, image, where=where)  # unreadable: listed by the caller
    if isinstance(size, MissingImage):
        return size
    w, h = size
    try:
        K0 = calibration(f, paspect, pp, w, h)
        K, dist = lens(f, d, K0, w, h) if distorted else (K0, None)
        ext = np.eye(4)
        ext[:3, :3] = np.reshape(R, (3, 3))
        ext[:3, 3] = t
        return View(name=name, image=image, intrinsic=K, extrinsic=ext, width=w, height=h, distortion=dist)
    except InputError as e:
        raise InputError(f"{where}: {e}") from None


def _read_text(path: Path, what: str) -> str:
    with open_regular(path, what) as fh:
        raw = fh.read(_MAX_TEXT + 1)
    if len(raw) > _MAX_TEXT:
        raise InputError(f"{path}: more than {_MAX_TEXT // 1024} KB; not {what}")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file; is it {what}?") from None


def _mesh_path(mesh: str | os.PathLike | None, root: Path, what: str) -> Path:
    if mesh is None:
        raise InputError(f"{root} is {what}, which holds no mesh: pass the mesh explicitly (mesh=... / --mesh)")
    p = Path(mesh)
    return p if p.is_absolute() or p.exists() else root / p


def _skipped(where: Path, what: str, names: list[str]) -> None:
    if names:
        logger.warning("%s: %d %s, skipped: %s", where, len(names), what,
                       ", ".join(names[:5]) + (" ..." if len(names) > 5 else ""))


def _unique(name: str, fallback: str, taken: set[str]) -> str:
    ok = (name and len(name) <= MAX_NAME_LENGTH - 8 and name not in (".", "..")
          and not any(c in name for c in '/\\:*?"<>|') and all(ord(c) >= 32 for c in name))
    base = out = name if ok else fallback
    k = 1
    while out in taken:
        out, k = f"{base}_{k}", k + 1
    taken.add(out)
    return out


# ------------------------------------------------------------------------------------------ cam folder


def detect_cam_folder(path: Path) -> Path | None:
    """``path`` when it is a folder holding ``.cam`` files, else None."""
    if not path.is_dir():
        return None
    try:
        return path if any(p.suffix.lower() == ".cam" and p.is_file() for p in path.iterdir()) else None
    except OSError:
        return None


def _read_cam(path: Path) -> tuple[float, tuple[float, float], float, tuple[float, float], list[float], list[float]]:
    """(f, (d0, d1), paspect, (ppx, ppy), R (9), t (3)) of a .cam file, as texrecon reads it."""
    lines = [ln.rstrip("\r") for ln in _read_text(path, "a texrecon .cam file").split("\n")]  # std::getline
    while lines and not lines[-1].strip():
        lines.pop()
    if len(lines) < 2:
        raise InputError(f"{path}: a .cam file has two lines, 'tx ty tz R00 ... R22' and 'f [d0 d1 [paspect [ppx "
                         f"ppy]]]', got {len(lines)}")
    ext, intr = lines[0].split(), lines[1].split()
    if len(ext) != 12:
        raise InputError(f"{path}: line 1: expected 12 numbers 'tx ty tz R00 R01 R02 R10 R11 R12 R20 R21 R22' "
                         f"(translation and world-to-camera rotation), got {len(ext)}")
    if len(intr) not in (1, 2, 3, 4, 6):
        raise InputError(f"{path}: line 2: expected 'f [d0 [d1 [paspect [ppx ppy]]]]' (1 to 4, or 6 numbers), got "
                         f"{len(intr)}")
    e = [_number(x, f"{path}: line 1", "value") for x in ext]
    names = ("focal length", "distortion d0", "distortion d1", "pixel aspect", "principal point x", "principal point y")
    v = [_number(x, f"{path}: line 2", what) for x, what in zip(intr, names)]
    v += [0.0, 0.0, 1.0, 0.5, 0.5][len(v) - 1:]
    f, d, paspect, pp = v[0], (v[1], v[2]), v[3], (v[4], v[5])
    if f < 0:
        raise InputError(f"{path}: line 2: negative focal length {f}; it must be > 0")
    _pose(e[3:], e[:3], f"{path}: line 1")
    if f > 0:
        _intrinsics(f, d, paspect, pp, f"{path}: line 2")
    return f, d, paspect, pp, e[3:], e[:3]


def _cam_image(cam: Path, names: list[str], ambiguous: list[str]) -> Path | None:
    """The photo texrecon pairs with ``cam``: same stem, an image suffix; after it in sorted order first."""
    stem = cam.name[:-4]
    cands = [n for n in names if n[:-len(Path(n).suffix) or None] == stem and Path(n).suffix.lower()
             in CAM_IMAGE_SUFFIXES]
    order = [n for n in cands if n > cam.name] + [n for n in reversed(cands) if n < cam.name]
    if len(order) > 1:
        ambiguous.append(f"{cam.name} -> {order[0]}")
    return cam.parent / order[0] if order else None


def load_cam_folder(folder: Path, *, mesh: str | os.PathLike | None = None) -> Scene:
    """Load a texrecon camera folder (``NAME.cam`` + ``NAME.png`` / ``.jpg`` / ... pairs).

    Parameters
    ----------
    folder : pathlib.Path
    mesh : path-like
        Mesh file, absolute or relative to ``folder`` (required).

    Raises
    ------
    InputError
        No mesh, a malformed ``.cam`` (file and line named), no photo for any camera, unreadable
        photos (one :class:`~o3d_seqcc.errors.MissingImagesError` listing them).
    """
    mesh_path = _mesh_path(mesh, folder, "a texrecon camera folder (.cam files)")
    names = sorted(p.name for p in folder.iterdir())
    cams = [folder / n for n in names if n.lower().endswith(".cam") and len(n) > 4 and (folder / n).is_file()]
    views, taken, no_image, no_camera, ambiguous, unreadable = [], set(), [], [], [], []
    for cam in cams:
        f, d, paspect, pp, R, t = _read_cam(cam)
        image = _cam_image(cam, names, ambiguous)
        if image is None:
            no_image.append(cam.name)
            continue
        if f == 0:
            no_camera.append(cam.name)
            continue
        v = _view(_unique(cam.name[:-4], "view", taken), image, f, d, paspect, pp, R, t, str(cam))
        (unreadable if isinstance(v, MissingImage) else views).append(v)
    if ambiguous:
        logger.warning("%s: several photos share a camera's name; taken as texrecon takes them: %s", folder,
                       ", ".join(ambiguous[:5]) + (" ..." if len(ambiguous) > 5 else ""))
    _skipped(folder, "camera file(s) without a photo of the same name (.png, .jpg, .jpeg, .tif, .tiff)", no_image)
    _skipped(folder, "camera(s) with focal length 0 (not calibrated)", no_camera)
    if unreadable:
        raise missing_images(unreadable, total=len(views) + len(unreadable), where=str(folder),
                             scene=Scene(mesh=mesh_path, views=tuple(views)) if views else None)
    if not views:
        raise InputError(f"{folder}: no calibrated camera with a photo: every NAME.cam needs a NAME.png, .jpg, .jpeg, "
                         ".tif or .tiff beside it and a focal length > 0")
    logger.info("%s: texrecon camera folder, %d views, mesh %s", folder, len(views), mesh_path)
    return Scene(mesh=mesh_path, views=tuple(views))


# ------------------------------------------------------------------------------------------ MVE scene


def detect(path: Path) -> Path | None:
    """``path`` when it is an MVE scene folder (``views/*.mve``), else None."""
    views = path / "views"
    if not views.is_dir():
        return None
    try:
        return path if any(p.suffix == ".mve" for p in views.iterdir()) else None
    except OSError:
        return None


def _parse_ini(path: Path) -> dict[str, tuple[str, int]]:
    """MVE's ``util::parse_ini``: ``section.key`` -> (value, 1-based line)."""
    out: dict[str, tuple[str, int]] = {}
    section = ""
    for i, raw in enumerate(_read_text(path, "an MVE meta.ini").split("\n"), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if line.startswith("[") and line.endswith("]"):
            section = line[1:-1]
            continue
        key, sep, value = line.partition("=")
        if not sep or not key.strip():
            raise InputError(f"{path}: line {i}: expected 'key = value' or '[section]', got {line[:60]!r}")
        if not section:
            raise InputError(f"{path}: line {i}: key {key.strip()[:40]!r} before any [section]")
        out[f"{section}.{key.strip()}"] = (value.strip(), i)
    return out


def _values(meta: dict, key: str, n: int, path: Path, default: list[float] | None = None) -> list[float]:
    if key not in meta:
        if default is None:
            raise InputError(f"{path}: [camera] has focal_length but no {key.split('.')[1]} ({n} numbers); write the "
                             "view's camera again")
        return default
    value, line = meta[key]
    where = f"{path}: line {line}"
    toks = value.split()
    if len(toks) != n:
        raise InputError(f"{where}: {key.split('.')[1]} needs {n} number(s), got {len(toks)}")
    return [_number(x, where, key.split(".")[1]) for x in toks]


def _embedding_file(view_dir: Path, embedding: str) -> Path | None:
    files = sorted(p for p in view_dir.iterdir() if p.stem == embedding and p.is_file())
    usable = [p for p in files if p.suffix.lower() in _VIEW_IMAGE_SUFFIXES]
    if usable:
        return usable[0]
    if any(p.suffix.lower() == ".mvei" for p in files):
        raise InputError(f"{view_dir}: the {embedding!r} embedding is an MVE raw image ({embedding}.mvei), which is "
                         "not read; export it as PNG or JPEG, or name another embedding")
    return None


def _embeddings(view_dir: Path) -> set[str]:
    return {p.stem for p in view_dir.iterdir() if p.suffix.lower() in _VIEW_IMAGE_SUFFIXES + (".mvei",)}


def _read_view(view_dir: Path) -> dict | None:
    """The camera, id and name of an MVE view (None without a camera)."""
    if not view_dir.is_dir():
        raise InputError(f"{view_dir}: an MVE view in the deprecated single-file format; upgrade the scene with MVE's "
                         "sceneupgrade")
    path = view_dir / "meta.ini"
    if not path.is_file():
        raise InputError(f"{view_dir}: an MVE view without meta.ini")
    meta = _parse_ini(path)
    vid = meta.get("view.id", ("", 0))
    try:
        view_id = int(vid[0]) if vid[0] else -1
    except ValueError:
        raise InputError(f"{path}: line {vid[1]}: view id {vid[0][:20]!r} is not an integer") from None
    (f,) = _values(meta, "camera.focal_length", 1, path, [0.0])
    if f == 0:
        return {"id": view_id, "dir": view_dir, "camera": None}
    where = f"{path}: line {meta['camera.focal_length'][1]}"
    if f < 0:
        raise InputError(f"{where}: negative focal length {f}; it must be > 0 (0: no camera)")
    cam = {"f": f, "d": tuple(_values(meta, "camera.radial_distortion", 2, path, [0.0, 0.0])),
           "paspect": _values(meta, "camera.pixel_aspect", 1, path, [1.0])[0],
           "pp": tuple(_values(meta, "camera.principal_point", 2, path, [0.5, 0.5])),
           "R": _values(meta, "camera.rotation", 9, path), "t": _values(meta, "camera.translation", 3, path)}
    _intrinsics(cam["f"], cam["d"], cam["paspect"], cam["pp"], where)
    _pose(cam["R"], cam["t"], f"{path}: line {meta['camera.rotation'][1]}")
    return {"id": view_id, "dir": view_dir, "name": meta.get("view.name", ("", 0))[0], "camera": cam,
            "where": str(path)}


def load(path: Path, *, mesh: str | os.PathLike | None = None, embedding: str | None = None) -> Scene:
    """Load an MVE scene folder.

    Parameters
    ----------
    path : pathlib.Path
        The scene folder (holding ``views/``).
    mesh : path-like
        Mesh file, absolute or relative to the scene folder (required).
    embedding : str, optional
        The image embedding to read (texrecon's ``SCENE::EMBEDDING``); default ``undistorted``
        when a calibrated view has it, else ``original``. Only ``original`` carries the
        camera's radial distortion.

    Raises
    ------
    InputError
        No mesh, a malformed ``meta.ini`` (file and line named), deprecated views, ``.mvei``
        images, no calibrated view with the embedding, unreadable photos (one
        :class:`~o3d_seqcc.errors.MissingImagesError` listing them).
    """
    mesh_path = _mesh_path(mesh, path, "an MVE scene")
    dirs = sorted(p for p in (path / "views").iterdir() if p.suffix == ".mve")
    read = [_read_view(d) for d in dirs]
    calibrated = [v for v in read if v["camera"] is not None]
    _skipped(path / "views", "view(s) without a camera (focal_length 0)", [v["dir"].name for v in read
                                                                          if v["camera"] is None])
    if not calibrated:
        raise InputError(f"{path / 'views'}: no view has a camera (every meta.ini lacks a focal_length > 0); run "
                         "MVE's sfmrecon first")
    if embedding is None:
        found = set().union(*(_embeddings(v["dir"]) for v in calibrated))
        embedding = next((e for e in EMBEDDINGS if e in found), None)
        if embedding is None:
            raise InputError(f"{path}: the calibrated views have no 'undistorted' or 'original' image (found: "
                             f"{', '.join(sorted(found)[:8]) or 'none'}); name the embedding (embedding=...)")
    views, taken, missing, unreadable = [], set(), [], []
    for v in sorted(calibrated, key=lambda v: (v["id"], v["dir"].name)):
        image = _embedding_file(v["dir"], embedding)
        if image is None:
            missing.append(v["dir"].name)
            continue
        c = v["camera"]
        name = _unique(v["name"], v["dir"].stem, taken)
        got = _view(name, image, c["f"], c["d"], c["paspect"], c["pp"], c["R"], c["t"], v["where"],
                    distorted=embedding == "original")
        (unreadable if isinstance(got, MissingImage) else views).append(got)
    _skipped(path / "views", f"view(s) without the {embedding!r} image", missing)
    if unreadable:
        raise missing_images(unreadable, total=len(views) + len(unreadable), where=str(path),
                             scene=Scene(mesh=mesh_path, views=tuple(views)) if views else None)
    if not views:
        raise InputError(f"{path}: no calibrated view has the {embedding!r} image ({embedding}.png / .jpg)")
    logger.info("%s: MVE scene, embedding %r, %d views, mesh %s", path, embedding, len(views), mesh_path)
    return Scene(mesh=mesh_path, views=tuple(views))
