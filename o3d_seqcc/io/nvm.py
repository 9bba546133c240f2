"""VisualSFM NVM files (``NVM_V3``, usually ``*.nvm``): the cameras of the first reconstructed model.

The layout (VisualSFM's documentation, http://ccwu.me/vsfm/doc.html#nvm, and the readers of
Multicore Bundle Adjustment's ``util.h``, MVE's ``libs/mve/bundle_io.cc`` and vcglib's
``wrap/io_trimesh/import_nvm.h``), one record a line, blank lines between sections::

    NVM_V3 [FixedK fx cx fy cy [0]]
    <number of cameras>
    <file name> <focal length> <qw qx qy qz> <cx cy cz> <radial distortion> 0    (one line a camera)
    <number of points>
    <X Y Z> <R G B> <n> n x (<image index> <feature index> <x y>)                 (one line a point)
    ... more models (cameras, then points) ...
    0                                                                             (no more models)
    <PLY section>                                                                 (not read)

A camera is a focal length ``f`` in pixels (one for both axes), the world-to-camera rotation as
a quaternion ``(w, x, y, z)`` (normalised here) and the camera *centre* ``C`` (not the
translation), in OpenCV axes: the extrinsic is ``[R | -R C]``. The principal point is the image
centre, ``((W - 1) / 2, (H - 1) / 2)`` with pixel centres at integers (VisualSFM, like SiftGPU,
puts the top-left pixel's centre at (0.5, 0.5) and the centre at ``(W / 2, H / 2)``; OpenMVS's
``InterfaceVisualSFM`` and MVE's ``fill_calibration`` + texrecon's ``get_pixel_coords - 0.5``
agree); the image sizes come from the images' headers. ``NVM_V3 FixedK fx cx fy cy`` gives one
full calibration for every camera (its ``cx, cy`` in VisualSFM's pixel coordinates, so ours are
``cx - 0.5, cy - 0.5``; an optional fifth number must be 0); a camera line's focal length that
differs from it is reported and FixedK's is used.

The radial coefficient ``r`` is VisualSFM's "measurement distortion", defined on the measured
(distorted) point: ``x_u = x_d (1 + r |x_d|^2)`` with ``x = (pixel - principal point) / f`` (Multicore
Bundle Adjustment's ``ComputeProjection``, ``radial == -1``, with ``SetNormalizedMeasurementDistortion``),
the inverse direction of OpenCV's model. It is removed on the fly exactly
(:mod:`o3d_seqcc.geometry.distortion`, model ``"pixel-radial-inverse"`` with the principal point
as centre and ``f`` as radius); ``r = 0`` is a pinhole camera.

A file may hold several models (VisualSFM writes each connected reconstruction, then the
unregistered images as a model without points). The first model is read, as MVE's
``load_nvm_bundle`` (hence texrecon) and MeshLab's importer do; a warning names the models and
their cameras when others have points (split the file, or reorder its models, to texture
another). Points are not read, only checked (counts, measurement indices), to find the models.
Image paths are relative to the ``.nvm`` file (absolute ones kept, ``\\`` read as ``/``, quotes
around a name dropped), or looked up by file name in ``image_dir``. The file holds no mesh:
``mesh=`` is required.

Refused: other headers (``NVM_V3_R9T``, ``NVM_V4``, unknown options after ``NVM_V3``), FixedK with
``fx != fy`` together with a non-zero radial coefficient (VisualSFM does not define it), and
hostile values (non-finite numbers, focal lengths outside [1e-3, 1e8] px, ``|r| > 100``, a zero
quaternion, counts the file cannot hold).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np

from .._shared.numbers import parse_number
from ..errors import InputError
from ..geometry.distortion import Distortion
from ..scene import Scene, View
from .colmap import qvec_to_rotmat
from .paths import join_path
from .regular_files import open_regular
from .missing import MissingImage, check_photo, missing_images

__all__ = ["MAX_COUNT", "detect", "load"]

logger = logging.getLogger(__name__)

#: the most cameras or points one model may declare
MAX_COUNT = 50_000_000
_MAX_RADIAL = 100.0
_FOCAL_RANGE = (1e-3, 1e8)
_IS_SPACE = np.zeros(256, dtype=bool)
_IS_SPACE[[9, 10, 11, 12, 13, 32]] = True
_POW10 = 10 ** np.arange(12, dtype=np.int64)


def detect(path: Path) -> Path | None:
    """``path`` when it is a file whose first token is ``NVM_V3`` (or another ``NVM_`` header, refused by :func:`load`
    with the reason), else None."""
    if not path.is_file():
        return None
    try:
        with path.open("rb") as fh:
            head = fh.read(64)
    except OSError:
        return None
    tok = head.removeprefix(b"\xef\xbb\xbf").split(None, 1)
    return path if tok and tok[0].startswith(b"NVM_") else None


@dataclass(frozen=True)
class _Camera:
    line: int
    name: str
    focal: float
    rotation: np.ndarray
    centre: np.ndarray
    radial: float


class _Lines:
    """The file's lines and the number of tokens on each, found without a Python loop over lines."""

    def __init__(self, path: Path, data: bytes) -> None:
        self.path, self.data = path, data
        self.arr = np.frombuffer(data + b"\n", dtype=np.uint8)  # a last newline: every line ends with one
        nl = np.flatnonzero(self.arr == 10)
        self.start = np.concatenate([[0], nl + 1])  # line k is data[start[k]:start[k + 1] - 1]
        self.n = len(nl)
        ws = _IS_SPACE[self.arr]
        self.tok = np.flatnonzero(~ws & np.concatenate([[True], ws[:-1]]))  # where each token starts, and ends
        self.tok_end = np.flatnonzero(~ws[:-1] & ws[1:]) + 1
        self.before = np.searchsorted(self.tok, self.start)  # tokens before each line
        self.tokens = np.diff(self.before)

    def raw(self, k: int) -> bytes:
        return self.data[self.start[k]:self.start[k + 1] - 1]

    def text(self, k: int) -> str:
        raw = self.raw(k)
        try:
            return raw.decode("utf-8").strip()
        except UnicodeDecodeError:
            return raw.decode("latin-1").strip()

    def where(self, k: int) -> str:
        return f"{self.path}, line {k + 1}"

    def skip_blank(self, k: int) -> int:
        while k < self.n and self.tokens[k] == 0:
            k += 1
        return k

    def count(self, k: int, what: str) -> int:
        """The count alone on line ``k``, checked against the lines left."""
        tok = self.text(k).split()
        try:
            if len(tok) != 1:
                raise ValueError
            n = int(tok[0])
        except ValueError:
            raise InputError(f"{self.where(k)}: expected the number of {what} alone on the line, got "
                             f"{self.text(k)!r:.80}; is the file cut or edited?") from None
        if n < 0 or n > MAX_COUNT or n > self.n - k - 1:
            raise InputError(f"{self.where(k)}: {n} {what} declared, but the file holds {self.n - k - 1} more lines "
                             f"(at most {MAX_COUNT} are read); the file is cut or corrupt; export it again")
        return n


def _header(lines: _Lines) -> tuple[float, float, float, float] | None:
    """FixedK's ``(fx, cx, fy, cy)`` of the first line, or None."""
    tok = lines.text(0).removeprefix("\ufeff").split()
    if not tok or tok[0] != "NVM_V3":
        got = tok[0] if tok else ""
        raise InputError(f"{lines.where(0)}: not a VisualSFM NVM_V3 file (first token {got!r:.40}); the variants "
                         "NVM_V3_R9T and NVM_V4 are not read: export the model from VisualSFM as NVM_V3")
    opts = tok[1:]
    if not opts:
        return None
    if opts[0] != "FixedK" or len(opts) not in (5, 6):
        raise InputError(f"{lines.where(0)}: unknown header options {' '.join(opts)!r:.80} after NVM_V3; this reader "
                         "knows 'FixedK fx cx fy cy' (one calibration for every camera); remove the others")
    vals = [parse_number(x, f"{lines.where(0)}: FixedK ({name})", fix="FixedK takes four numbers fx cx fy cy")
            for x, name in zip(opts[1:], ("fx", "cx", "fy", "cy", "fifth number"))]
    fx, cx, fy, cy = vals[:4]
    if not all(np.isfinite(vals)) or not (_FOCAL_RANGE[0] <= min(fx, fy) and max(fx, fy) <= _FOCAL_RANGE[1]):
        raise InputError(f"{lines.where(0)}: FixedK {vals} must be finite with focal lengths fx, fy in "
                         f"[{_FOCAL_RANGE[0]:g}, {_FOCAL_RANGE[1]:g}] pixels")
    if len(vals) == 5 and vals[4] != 0:
        raise InputError(f"{lines.where(0)}: FixedK's fifth number is {vals[4]}; only 0 is read (its meaning is not "
                         "documented); give the radial distortion on the camera lines")
    return fx, cx, fy, cy


def _camera(lines: _Lines, k: int) -> _Camera:
    text = lines.text(k)
    parts = text.rsplit(None, 10)
    where = lines.where(k)
    if len(parts) != 11:
        raise InputError(f"{where}: expected a camera '<file name> <focal length> <qw qx qy qz> <cx cy cz> <radial> 0', "
                         f"got {text!r:.100}")
    name = parts[0].strip()
    if len(name) >= 2 and name[0] == name[-1] == '"':
        name = name[1:-1]
    f, qw, qx, qy, qz, cx, cy, cz, r, _zero = (
        parse_number(x, f"{where}: camera {name!r:.60}: {field}", fix="fix or re-export the model")
        for x, field in zip(parts[1:], ("focal length", "qw", "qx", "qy", "qz", "cx", "cy", "cz", "radial", "last 0")))
    if not _FOCAL_RANGE[0] <= f <= _FOCAL_RANGE[1]:
        raise InputError(f"{where}: camera {name!r:.60} has focal length {f} px; it must be in "
                         f"[{_FOCAL_RANGE[0]:g}, {_FOCAL_RANGE[1]:g}]")
    if abs(r) > _MAX_RADIAL:
        raise InputError(f"{where}: camera {name!r:.60} has radial distortion {r}; |r| <= {_MAX_RADIAL:g} "
                         "(VisualSFM's normalised coefficient is usually below 1)")
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            R = qvec_to_rotmat([qw, qx, qy, qz])
    except InputError as e:
        raise InputError(f"{where}: camera {name!r:.60}: {e}") from None
    if not name:
        raise InputError(f"{where}: empty image file name")
    return _Camera(k + 1, name, f, R, np.array([cx, cy, cz]), r)


def _integers(arr: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """The tokens ``arr[starts:ends]`` as non-negative integers (up to 12 digits), -1 where a token is not one."""
    length = ends - starts
    width = int(min(12, length.max())) if len(length) else 1
    col = np.arange(width)
    inside = col < length[:, None]
    digit = arr[np.minimum(starts[:, None] + col, len(arr) - 1)].astype(np.int64) - 48
    ok = (length <= 12) & np.all(~inside | ((digit >= 0) & (digit <= 9)), axis=1)
    value = np.sum(np.where(inside, digit, 0) * _POW10[np.clip(length[:, None] - 1 - col, 0, 11)], axis=1)
    return np.where(ok, value, -1)


def _skip_points(lines: _Lines, k: int, n: int, n_cameras: int) -> None:
    """Check the ``n`` point lines from line ``k`` (``X Y Z R G B m`` + m measurements) without reading them.

    Each line must hold ``7 + 4 m`` fields with ``m`` an integer, and each measurement's image
    index must be an integer below ``n_cameras`` (the points themselves are not used).
    """
    if n == 0:
        return
    counts = lines.tokens[k:k + n]
    arr, span = lines.arr, slice(lines.before[k], lines.before[k + n])
    starts, ends = lines.tok[span], lines.tok_end[span]
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    has_m = counts >= 7
    m = np.full(n, -1, dtype=np.int64)
    m[has_m] = _integers(arr, starts[first[has_m] + 6], ends[first[has_m] + 6])
    bad = (m < 0) | (counts != 7 + 4 * np.maximum(m, 0))
    if bad.any():
        j = int(np.argmax(bad))
        raise InputError(f"{lines.where(k + j)}: expected a point '<X Y Z> <R G B> <n> n x (<image> <feature> <x y>)' "
                         f"with 7 + 4 n fields (n an integer), got {lines.text(k + j)!r:.80}; the points section is "
                         "cut or corrupt")
    owner = np.repeat(np.arange(n), m)
    slot = np.arange(len(owner)) - np.repeat(np.cumsum(m) - m, m)
    tok = first[owner] + 7 + 4 * slot
    image = _integers(arr, starts[tok], ends[tok])
    wrong = (image < 0) | (image >= n_cameras)
    if wrong.any():
        i = int(np.argmax(wrong))
        j = int(owner[i])
        got = lines.raw(k + j).split()[int(tok[i] - first[j])].decode("latin-1")
        raise InputError(f"{lines.where(k + j)}: a measurement of image {got!r:.20}, not an image index 0.."
                         f"{n_cameras - 1}; the file is corrupt")


def _read(path: Path) -> tuple[tuple[float, float, float, float] | None, list[_Camera], list[tuple[int, int]]]:
    """(FixedK, the first model's cameras, (cameras, points) of every model) of an NVM file."""
    with open_regular(path, "NVM file") as fh:
        lines = _Lines(path, fh.read())
    fixed = _header(lines)
    first: list[_Camera] = []
    models: list[tuple[int, int]] = []
    k = lines.skip_blank(1)
    while k < lines.n:
        n_cams = lines.count(k, "cameras")
        if n_cams == 0:
            break
        k += 1
        cams = []
        for _ in range(n_cams):
            k = lines.skip_blank(k)
            if k >= lines.n:
                raise InputError(f"{path}: the file ends inside a model's cameras ({len(cams)} of {n_cams}); "
                                 "it is cut: export it again")
            if not models:
                cams.append(_camera(lines, k))
            elif lines.tokens[k] < 11:  # a later model: its cameras only counted
                raise InputError(f"{lines.where(k)}: expected a camera line, got {lines.text(k)!r:.80}")
            k += 1
        k = lines.skip_blank(k)
        n_pts = lines.count(k, "points") if k < lines.n else 0
        _skip_points(lines, k + 1, n_pts, n_cams)
        if not models:
            first = cams
        models.append((n_cams, n_pts))
        k = lines.skip_blank(k + 1 + n_pts)
    if not first:
        raise InputError(f"{path}: the NVM file holds no model with cameras (its first model count is 0); "
                         "reconstruct in VisualSFM and export again")
    return fixed, first, models


def _report_models(path: Path, models: list[tuple[int, int]]) -> None:
    if len(models) == 1:
        return
    desc = ", ".join(f"{c} cameras" + ("" if p else " without points") for c, p in models)
    if len(models) == 2 and models[1][1] == 0:
        logger.info("%s: reading the first model (%d cameras); the other (%d cameras without points) is VisualSFM's "
                    "list of unregistered images", path, models[0][0], models[1][0])
        return
    logger.warning("%s holds %d models (%s); only the first (%d cameras) is read, as MVE/texrecon and MeshLab do: to "
                   "texture with another model's cameras, move it first in the file (or split the file)",
                   path, len(models), desc, models[0][0])


def _image_path(name: str, root: Path, image_dir: Path | None) -> Path:
    rel = name.replace("\\", "/")
    if image_dir is not None:
        return image_dir / PurePosixPath(rel).name
    return Path(rel) if Path(rel).is_absolute() else join_path(root, rel)


def _intrinsic(cam: _Camera, fixed, w: int, h: int, where: str) -> tuple[np.ndarray, Distortion | None]:
    if fixed is None:
        K = np.array([[cam.focal, 0.0, 0.5 * (w - 1)], [0.0, cam.focal, 0.5 * (h - 1)], [0.0, 0.0, 1.0]])
    else:
        fx, cx, fy, cy = fixed
        K = np.array([[fx, 0.0, cx - 0.5], [0.0, fy, cy - 0.5], [0.0, 0.0, 1.0]])
        if cam.radial != 0 and fx != fy:
            raise InputError(f"{where}: a radial distortion ({cam.radial}) with FixedK's fx != fy ({fx}, {fy}) is not "
                             "defined by VisualSFM; undistort the images first (VisualSFM's 'undistorted' export)")
    if cam.radial == 0:
        return K, None
    try:
        lens = Distortion("pixel-radial-inverse", [cam.radial, K[0, 2], K[1, 2], cam.focal], K)
        return lens.pinhole(w, h), lens
    except InputError as e:
        raise InputError(f"{where}: {e}") from None


def load(path: Path, *, mesh: str | os.PathLike | None = None, image_dir: str | os.PathLike | None = None) -> Scene:
    """Load the first model of a VisualSFM NVM_V3 file.

    Parameters
    ----------
    path : pathlib.Path
        The ``.nvm`` file.
    mesh : path-like
        Mesh file, absolute or relative to the file's folder (required: the file holds points only).
    image_dir : path-like, optional
        Folder to look the images up in by file name, instead of the paths in the file.

    Raises
    ------
    InputError
        No mesh, another header, a malformed line (named with its line number), hostile
        values, missing or unreadable images (listed).
    """
    if mesh is None:
        raise InputError(f"{path} is a VisualSFM NVM file, which holds cameras and points but no mesh: pass the mesh "
                         "explicitly (mesh=... / --mesh MESH)")
    fixed, cams, models = _read(path)
    _report_models(path, models)
    img_root = None if image_dir is None else Path(image_dir)
    if img_root is not None and not img_root.is_dir():
        raise InputError(f"image_dir {img_root} is not a folder")
    files = [_image_path(c.name, path.parent, img_root) for c in cams]
    views, names, off_focal, missing = [], set(), [], []
    for i, (cam, file) in enumerate(zip(cams, files)):
        where = f"{path}, line {cam.line}"
        if fixed is not None and min(abs(cam.focal - x) for x in (fixed[0], fixed[2], 0.5 * (fixed[0] + fixed[2]))) \
                > 1e-6 * cam.focal:
            off_focal.append(cam.line)
        stem = PurePosixPath(cam.name.replace("\\", "/")).stem or f"view{i}"
        name = stem if stem not in names else f"{stem}_{i}"
        names.add(name)
        size = check_photo(name, file, where=f"{path}: line {cam.line}")  # missing or unreadable: listed below
        if isinstance(size, MissingImage):
            missing.append(size)
            continue
        w, h = size
        K, lens = _intrinsic(cam, fixed, w, h, where)
        ext = np.eye(4)
        ext[:3, :3] = cam.rotation
        ext[:3, 3] = -cam.rotation @ cam.centre
        try:
            views.append(View(name=name, image=file, intrinsic=K, extrinsic=ext, width=w, height=h, distortion=lens))
        except InputError as e:
            raise InputError(f"{where}: {e}") from None
    if off_focal:
        logger.warning("%s: %d camera line(s) (line %s) give a focal length other than FixedK's; FixedK's is used",
                       path, len(off_focal), ", ".join(map(str, off_focal[:5])) + (" ..." if len(off_focal) > 5 else ""))
    mesh_path = Path(mesh)
    if not mesh_path.is_absolute() and not mesh_path.exists():
        mesh_path = path.parent / mesh_path
    if missing:
        hint = "" if img_root is not None else "pass image_dir= (--image-dir DIR) if the images are elsewhere"
        raise missing_images(missing, total=len(cams), where=str(path), hint=hint,
                             scene=Scene(mesh=mesh_path, views=tuple(views)) if views else None)
    logger.info("%s: VisualSFM NVM, %d cameras of the first of %d model(s)%s, mesh %s", path, len(views), len(models),
                ", FixedK" if fixed else "", mesh_path)
    return Scene(mesh=mesh_path, views=tuple(views))
