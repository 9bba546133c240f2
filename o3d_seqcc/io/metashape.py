"""Agisoft Metashape camera exports (``cameras.xml``: File > Export > Export Cameras, Agisoft XML).

::

    <document version="1.5.0">
      <chunk>
        <sensors>
          <sensor id="0" label="..." type="frame">
            <resolution width="5472" height="3648"/>
            <calibration type="frame" class="adjusted">
              <resolution width="5472" height="3648"/>
              <f>3650.1</f> <cx>11.2</cx> <cy>-27.7</cy> <b1>..</b1> <b2>..</b2>
              <k1>..</k1> <k2>..</k2> <k3>..</k3> <k4>..</k4> <p1>..</p1> <p2>..</p2>
            </calibration>
          </sensor>
        </sensors>
        <components> <component id="0"> <transform> ... </transform> </component> </components>  (2.x)
        <cameras>
          <camera id="0" sensor_id="0" component_id="0" label="IMG_0001">   (maybe inside <group>)
            <transform>16 numbers</transform>
          </camera>
        </cameras>
        <transform> <rotation>9</rotation> <translation>3</translation> <scale>1</scale> </transform>  (1.x)
      </chunk>
    </document>

The frame camera model is the Metashape manual's (appendix "Camera models"): for a point
``(X, Y, Z)`` in camera axes (x right, y down, looking down +z: OpenCV's), ``x = X / Z``, ``y =
Y / Z``, ``x' = x (1 + K1 r^2 + K2 r^4 + K3 r^6 + K4 r^8) + P1 (r^2 + 2 x^2) + 2 P2 x y``, ``y' =
y (...) + P2 (r^2 + 2 y^2) + 2 P1 x y``, ``u = w / 2 + cx + x' (f + B1) + y' B2``, ``v = h / 2 +
cy + y' f``, with ``u, v`` measured from the image's top-left corner (the top-left pixel's
centre at (0.5, 0.5); Agisoft forum, "Are cx, cy offsets from the image center?"). Hence our
principal point ``(w / 2 + cx - 0.5, h / 2 + cy - 0.5)``, and Metashape's ``P1, P2`` are OpenCV's
``p2, p1``. Cameras OpenCV's model expresses exactly (``K4 = B2 = 0``; ``B1`` goes into ``fx =
f + B1``) are undistorted with it, the others with the ``"metashape"`` model of
:mod:`o3d_seqcc.geometry.distortion`; the view's camera is the pinhole
:meth:`~o3d_seqcc.geometry.distortion.Distortion.pinhole` of the photo's size. A sensor's
``adjusted`` calibration is preferred to its ``initial`` one.

A camera's ``<transform>`` is its camera-to-chunk pose (row-major, rigid). The chunk's
``<transform>`` (Metashape 1.x) or the camera's component's (``component_id``, Metashape 2.x)
maps chunk to world coordinates: ``X_world = scale R X_chunk + translation``; the mesh must be in
those world coordinates (for a georeferenced chunk, Metashape's geocentric frame). A file with
both, differing, is refused (which applies is not documented). Cameras without a transform (not
aligned) and disabled ones (``enabled="false"``) are skipped with one warning.

Metashape stores no image path: each camera's image is found by its ``label`` (a file name, with
or without its suffix, or a path whose file name is used) in ``image_dir``, or beside the XML file
without it; the missing ones are listed. The file holds no mesh: ``mesh=`` is required.

Refused, with the element and its line: other sensor types (fisheye, spherical, cylindrical,
RPC), PhotoScan's older calibrations (``fx``/``fy``/``skew`` instead of ``f``), multi-camera
rigs (sensors with a ``master_id``), non-rigid camera transforms, hostile values. The XML is
parsed with expat without any document type declaration (a DOCTYPE or ENTITY is refused before
anything is expanded), files over :data:`MAX_XML_BYTES` and elements nested deeper than 64.
"""

from __future__ import annotations

import logging
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path, PurePosixPath
from xml.parsers import expat

import numpy as np

from .._shared.numbers import check_numbers
from ..errors import InputError
from ..geometry.distortion import Distortion
from ..scene import Scene, View
from .regular_files import open_regular
from .missing import MissingImage, missing_images

__all__ = ["IMAGE_SUFFIXES", "MAX_XML_BYTES", "detect", "load"]

logger = logging.getLogger(__name__)

#: the largest XML file read
MAX_XML_BYTES = 512 * 2**20
#: the suffixes tried after a camera label that has none of them
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp", ".webp", ".jp2", ".exr")
_MAX_DEPTH = 64
_MAX_SIZE = 1_000_000
_DISTORTION_TERMS = ("k1", "k2", "k3", "k4", "p1", "p2", "b1", "b2")


def _looks_like(path: Path) -> bool:
    try:
        with path.open("rb") as fh:
            head = fh.read(1 << 20).decode("latin-1")
    except OSError:
        return False
    head = re.sub(r"<\?.*?\?>|<!--.*?-->|<!DOCTYPE[^\[>]*(\[.*?\])?\s*>", "", head, flags=re.S)  # load() refuses a DTD
    head = head.lstrip("\ufeff\xef\xbb\xbf \t\r\n")
    return bool(re.match(r"<document[\s>/]", head)) and "<chunk" in head and \
        bool(re.search(r"<(sensors|cameras)[\s>/]", head))


def detect(path: Path) -> Path | None:
    """The XML to read: ``path`` (an ``.xml`` Metashape document) or ``path / "cameras.xml"``; else None."""
    if path.is_dir():
        cand = path / "cameras.xml"
        return cand if cand.is_file() and _looks_like(cand) else None
    return path if path.is_file() and path.suffix.lower() == ".xml" and _looks_like(path) else None


class _Doc:
    """An XML document parsed by expat into ElementTree elements, with each element's line."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.lines: dict[ET.Element, int] = {}
        with open_regular(path, "Metashape cameras file") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size > MAX_XML_BYTES:
                raise InputError(f"{path} is {size / 2**20:.0f} MB, more than the {MAX_XML_BYTES >> 20} MB a cameras "
                                 "file needs; is it the right file?")
            data = fh.read()
        parser = expat.ParserCreate()
        parser.buffer_text = True
        parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
        stack: list[ET.Element] = []
        text: dict[ET.Element, list[str]] = {}
        self.root: ET.Element | None = None

        def refuse(*_args) -> None:
            raise InputError(f"{path}, line {parser.CurrentLineNumber}: the XML declares a document type or entities, "
                             "which a Metashape export never does (and which could expand without bound); refused")

        def start(tag: str, attrs: dict) -> None:
            if len(stack) >= _MAX_DEPTH:
                raise InputError(f"{path}, line {parser.CurrentLineNumber}: elements nested more than {_MAX_DEPTH} "
                                 "deep; not a Metashape cameras file")
            el = ET.Element(tag, attrs) if not stack else ET.SubElement(stack[-1], tag, attrs)
            if self.root is None:
                self.root = el
            self.lines[el] = parser.CurrentLineNumber
            stack.append(el)

        def end(_tag: str) -> None:
            el = stack.pop()
            if el in text:
                el.text = "".join(text.pop(el))

        def chars(data: str) -> None:
            if stack and not len(stack[-1]):
                text.setdefault(stack[-1], []).append(data)

        parser.StartDoctypeDeclHandler = refuse
        parser.EntityDeclHandler = refuse
        parser.StartElementHandler = start
        parser.EndElementHandler = end
        parser.CharacterDataHandler = chars
        try:
            parser.Parse(data, True)
        except expat.ExpatError as e:
            raise InputError(f"{path}, line {e.lineno}: not well-formed XML ({expat.ErrorString(e.code)}); is the "
                             "file cut? export the cameras again") from None
        except InputError:
            raise
        except (LookupError, ValueError) as e:  # an unknown declared encoding, ...
            raise InputError(f"{path}, line {parser.CurrentLineNumber}: cannot read the XML ({e}); save it as UTF-8") \
                from None
        if self.root is None:
            raise InputError(f"{path}: empty XML document")

    def where(self, el: ET.Element) -> str:
        return f"{self.path}, line {self.lines.get(el, '?')}: <{el.tag}>"

    def numbers(self, el: ET.Element, n: int, what: str) -> np.ndarray:
        try:
            vals = np.array([float(x) for x in (el.text or "").split()], dtype=np.float64)
        except ValueError:
            vals = np.zeros(0)
        if len(vals) != n or np.any(np.abs(vals) > 1e15):
            raise InputError(f"{self.where(el)}: {what} must be {n} finite number{'s' if n > 1 else ''}, got "
                             f"{(el.text or '').strip()!r:.80}")
        named = self.where(el) + ("" if what == f"<{el.tag}>" else f": {what}")
        return check_numbers(vals, named, fix="fix or re-export the cameras")

    def number(self, parent: ET.Element, tag: str, default: float | None = None) -> float:
        el = parent.find(tag)
        if el is None:
            if default is None:
                raise InputError(f"{self.where(parent)}: missing <{tag}>")
            return default
        return float(self.numbers(el, 1, f"<{tag}>")[0])

    def size(self, el: ET.Element) -> tuple[int, int]:
        try:
            w, h = int(el.get("width", "")), int(el.get("height", ""))
        except ValueError:
            w = h = 0
        if not (0 < w <= _MAX_SIZE and 0 < h <= _MAX_SIZE):
            raise InputError(f"{self.where(el)}: width and height must be positive integers (pixels), got "
                             f"{el.get('width')!r:.20} x {el.get('height')!r:.20}")
        return w, h


def _sensor(doc: _Doc, s: ET.Element) -> dict:
    """A frame sensor's size and calibration (None when it has none), or why it cannot be read."""
    out: dict = {"where": doc.where(s), "type": s.get("type", "frame"), "calibration": None}
    if s.get("master_id") not in (None, s.get("id")):
        out["refused"] = "a multi-camera rig's slave sensor (master_id), which this reader does not compose"
        return out
    if out["type"] != "frame":
        out["refused"] = f"a {out['type']!r} sensor; only frame (pinhole) cameras are read"
        return out
    res = s.find("resolution")
    if res is None:
        raise InputError(f"{doc.where(s)}: missing <resolution width height>")
    out["size"] = doc.size(res)
    cals = s.findall("calibration")
    cal = next((c for cls in ("adjusted", "initial", None) for c in cals if c.get("class") == cls), None)
    if cal is None:
        return out
    if cal.get("type", "frame") != "frame":
        raise InputError(f"{doc.where(cal)}: a {cal.get('type')!r} calibration; only frame (pinhole) cameras are read")
    if cal.find("f") is None and (cal.find("fx") is not None or cal.find("fy") is not None):
        raise InputError(f"{doc.where(cal)}: an older PhotoScan calibration (fx, fy, absolute cx, cy); export the "
                         "cameras from Metashape 1.5 or later (f, cx and cy from the image centre, b1, b2)")
    cres = cal.find("resolution")
    if cres is not None and doc.size(cres) != out["size"]:
        raise InputError(f"{doc.where(cres)}: the calibration's resolution {doc.size(cres)} differs from the sensor's "
                         f"{out['size']}; export the cameras of the full-size photos")
    f = doc.number(cal, "f")
    if not 1e-3 <= f <= 1e8:
        raise InputError(f"{doc.where(cal)}: focal length f = {f} px must be in [1e-3, 1e8]")
    terms = {t: doc.number(cal, t, 0.0) for t in ("cx", "cy", *_DISTORTION_TERMS)}
    if any(abs(v) > 1e6 for v in terms.values()) or doc.number(cal, "skew", 0.0) != 0:
        raise InputError(f"{doc.where(cal)}: implausible calibration terms {terms} (or a skew); check the export")
    out["calibration"] = {"f": f, **terms}
    if s.find("rolling_shutter") is not None and s.find("rolling_shutter").get("enabled", "").lower() in ("true", "1"):
        out["rolling_shutter"] = True
    return out


def _intrinsic(sensor: dict) -> tuple[np.ndarray, Distortion | None]:
    """Our pinhole matrix of a sensor and its distortion (pixel centres at integers)."""
    w, h = sensor["size"]
    c = sensor["calibration"]
    K = np.array([[c["f"], 0.0, 0.5 * w + c["cx"] - 0.5], [0.0, c["f"], 0.5 * h + c["cy"] - 0.5], [0.0, 0.0, 1.0]])
    try:
        if c["k4"] == 0 and c["b2"] == 0:  # OpenCV's model: B1 into fx, P1/P2 swapped
            K[0, 0] += c["b1"]
            coeffs = [c["k1"], c["k2"], c["p2"], c["p1"], c["k3"]]
            if not any(coeffs):
                return K, None
            lens = Distortion("opencv", coeffs, K)
        else:
            lens = Distortion("metashape", [c[t] for t in _DISTORTION_TERMS], K)
        return lens.pinhole(w, h), lens
    except InputError as e:
        raise InputError(f"{sensor['where']}: {e}") from None


def _similarity(doc: _Doc, t: ET.Element) -> np.ndarray:
    """The 4x4 of a chunk or component ``<transform>`` (rotation, translation, scale; or 16 numbers)."""
    M = np.eye(4)
    if not len(t):
        A = doc.numbers(t, 16, "a 4x4 transform").reshape(4, 4)
        s = np.cbrt(np.linalg.det(A[:3, :3]))
        if not (s > 0 and np.allclose(A[3], [0, 0, 0, 1]) and np.abs(A[:3, :3].T @ A[:3, :3] / s**2 - np.eye(3)).max()
                < 1e-6):
            raise InputError(f"{doc.where(t)}: not a similarity (rotation, translation, uniform scale)")
        return A
    R = np.eye(3) if t.find("rotation") is None else doc.numbers(t.find("rotation"), 9, "<rotation>").reshape(3, 3)
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
        raise InputError(f"{doc.where(t)}: <rotation> is not a rotation matrix")
    scale = doc.number(t, "scale", 1.0)
    if not 1e-12 < scale < 1e12:
        raise InputError(f"{doc.where(t)}: <scale> {scale} must be positive")
    M[:3, :3] = scale * R
    if t.find("translation") is not None:
        M[:3, 3] = doc.numbers(t.find("translation"), 3, "<translation>")
    return M


def _world_pose(doc: _Doc, cam: ET.Element, tr: ET.Element, to_world: np.ndarray) -> np.ndarray:
    """World-to-camera extrinsic of a camera-to-chunk ``<transform>`` and a chunk-to-world similarity."""
    T = doc.numbers(tr, 16, "a camera <transform> (4x4, row-major)").reshape(4, 4)
    Rc = T[:3, :3]
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9) or np.abs(Rc.T @ Rc - np.eye(3)).max() > 1e-4 \
            or np.linalg.det(Rc) < 0:
        raise InputError(f"{doc.where(tr)}: camera {cam.get('label')!r:.60}'s transform is not a rigid camera-to-chunk "
                         "pose (rotation + translation)")
    s = np.cbrt(np.linalg.det(to_world[:3, :3]))
    R = to_world[:3, :3] / s @ Rc  # camera-to-world rotation
    C = to_world[:3, :3] @ T[:3, 3] + to_world[:3, 3]
    ext = np.eye(4)
    ext[:3, :3] = R.T
    ext[:3, 3] = -R.T @ C
    return ext


def _transforms(doc: _Doc, chunk: ET.Element) -> tuple[np.ndarray | None, dict[str, np.ndarray]]:
    ct = chunk.find("transform")
    chunk_T = None if ct is None else _similarity(doc, ct)
    comps = {}
    for comp in chunk.findall("components/component"):
        t = comp.find("transform")
        if t is not None:
            comps[comp.get("id", "")] = _similarity(doc, t)
    active = chunk.find("components")
    if active is not None and active.get("active_id") in comps:  # for cameras without a component_id
        comps[""] = comps[active.get("active_id")]
    if chunk_T is not None and any(not np.allclose(M, chunk_T) for M in comps.values()):
        raise InputError(f"{doc.where(ct)}: the chunk has a transform and its components other ones; which maps the "
                         "cameras to the world is not documented: export the cameras again from one Metashape version")
    return chunk_T, comps


class _Images:
    """The image files of one folder by lower-case name (one listing)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.by_name: dict[str, list[Path]] = {}
        try:
            for e in os.scandir(folder):
                if e.is_file():
                    self.by_name.setdefault(e.name.lower(), []).append(Path(e.path))
        except OSError as e:
            raise InputError(f"cannot list the image folder {folder}: {e.strerror}") from None

    def find(self, label: str) -> list[Path]:
        rel = label.replace("\\", "/")
        if not PurePosixPath(rel).is_absolute() and (self.folder / rel).is_file():
            return [self.folder / rel]
        base = PurePosixPath(rel).name.lower()
        names = [base] if base.endswith(IMAGE_SUFFIXES) else [base + s for s in IMAGE_SUFFIXES]
        return sorted({p for n in names for p in self.by_name.get(n, [])})


def _view_name(label: str, i: int, taken: set[str]) -> str:
    """The view name of a camera label: its file name without an image suffix, unique (``_i`` appended)."""
    stem = PurePosixPath(label.replace("\\", "/")).name
    stem = PurePosixPath(stem).stem if stem.lower().endswith(IMAGE_SUFFIXES) else stem
    name = stem if stem not in taken else f"{stem}_{i}"
    taken.add(name)
    return name


def load(path: Path, *, mesh: str | os.PathLike | None = None, image_dir: str | os.PathLike | None = None) -> Scene:
    """Load the aligned cameras of an Agisoft Metashape ``cameras.xml``.

    Parameters
    ----------
    path : pathlib.Path
        The XML file.
    mesh : path-like
        Mesh file in the chunk's world coordinates, absolute or relative to the file's folder
        (required: the file holds cameras only).
    image_dir : path-like, optional
        Folder of the photos, found by camera label; default the XML file's folder.

    Raises
    ------
    InputError
        No mesh, hostile or malformed XML (the element and its line), unsupported sensors,
        missing images (one :class:`~o3d_seqcc.errors.MissingImagesError` listing the labels and
        their lines), no aligned camera.
    """
    if mesh is None:
        raise InputError(f"{path} is a Metashape cameras file, which holds no mesh: pass the mesh (exported from "
                         "Metashape in the same coordinates) explicitly (mesh=... / --mesh MESH)")
    doc = _Doc(path)
    root = doc.root
    chunks = root.findall("chunk")
    if root.tag != "document" or not chunks:
        raise InputError(f"{doc.where(root)}: expected a Metashape <document> holding a <chunk>; export the cameras "
                         "as Agisoft XML")
    if len(chunks) > 1:
        logger.warning("%s holds %d chunks; the first is read", path, len(chunks))
    chunk = chunks[0]
    sensors = {s.get("id", ""): s for s in chunk.findall("sensors/sensor")}
    read_sensors: dict[str, dict] = {}
    chunk_T, comps = _transforms(doc, chunk)
    folder = Path(image_dir) if image_dir is not None else path.parent
    if not folder.is_dir():
        raise InputError(f"image_dir {folder} is not a folder")
    images = _Images(folder)
    cameras = chunk.find("cameras")
    if cameras is None:
        raise InputError(f"{doc.where(chunk)}: the chunk has no <cameras>; export the cameras (Agisoft XML) again")
    posed, skipped, missing = [], [], []
    for cam in cameras.iter("camera"):
        label = cam.get("label") or ""
        tr = cam.find("transform")
        if cam.get("enabled", "true").lower() in ("false", "0") or tr is None:
            skipped.append(label or cam.get("id", "?"))
            continue
        if not label.strip():
            raise InputError(f"{doc.where(cam)}: a camera without a label (its image cannot be found)")
        sid = cam.get("sensor_id", "")
        if sid not in sensors:
            raise InputError(f"{doc.where(cam)}: camera {label!r:.60} refers to sensor {sid!r:.20}, which <sensors> "
                             "does not define")
        if sid not in read_sensors:
            read_sensors[sid] = _sensor(doc, sensors[sid])
        sensor = read_sensors[sid]
        if "refused" in sensor:
            raise InputError(f"{sensor['where']}: camera {label!r:.60} uses {sensor['refused']}")
        if sensor["calibration"] is None:
            raise InputError(f"{sensor['where']}: sensor {sid!r:.20} (camera {label!r:.60}) has no <calibration>; "
                             "export the cameras after aligning them")
        to_world = comps.get(cam.get("component_id", ""), chunk_T if chunk_T is not None else np.eye(4))
        found = images.find(label)
        if len(found) > 1:
            raise InputError(f"{doc.where(cam)}: camera {label!r:.60} matches several images in {folder}: "
                             f"{', '.join(p.name for p in found[:4])}; keep one, or pass image_dir=")
        if not found:
            missing.append((cam, label))
            continue
        posed.append((cam, label, sid, _world_pose(doc, cam, tr, to_world), found[0]))
    seen: dict[Path, str] = {}
    for cam, label, _, _, file in posed:
        if file in seen:
            raise InputError(f"{doc.where(cam)}: cameras {seen[file]!r:.60} and {label!r:.60} both find {file} (Metashape "
                             "stores labels, not paths): relabel the cameras in Metashape so that each names its photo")
        seen[file] = label
    if skipped:
        logger.warning("%s: %d camera(s) are not aligned (no transform) or disabled and are skipped: %s", path,
                       len(skipped), ", ".join(skipped[:5]) + (" ..." if len(skipped) > 5 else ""))
    if not posed and not missing:
        raise InputError(f"{path}: no aligned camera (none has a <transform>); align the photos in Metashape first")
    if any(read_sensors[sid].get("rolling_shutter") for _, _, sid, _, _ in posed):
        logger.warning("%s: a sensor has rolling-shutter compensation, which is not modelled (each photo is read as "
                       "taken at one instant)", path)
    intrinsics = {sid: _intrinsic(read_sensors[sid]) for sid in {p[2] for p in posed}}
    views, names = [], set()
    for i, (cam, label, sid, ext, file) in enumerate(posed):
        K, lens = intrinsics[sid]
        w, h = read_sensors[sid]["size"]
        name = _view_name(label, i, names)
        try:
            views.append(View(name=name, image=file, intrinsic=K, extrinsic=ext, width=w, height=h, distortion=lens))
        except InputError as e:
            raise InputError(f"{doc.where(cam)}: camera {label!r:.60}: {e}") from None
    mesh_path = Path(mesh)
    if not mesh_path.is_absolute() and not mesh_path.exists():
        mesh_path = path.parent / mesh_path
    if missing:
        gone = [MissingImage(_view_name(label, len(posed) + k, names),
                             folder / PurePosixPath(label.replace("\\", "/")).name,
                             f"no photo named after the label in {folder} (Metashape stores labels, not paths)",
                             f"{path}: line {doc.lines.get(cam, '?')}")
                for k, (cam, label) in enumerate(missing)]
        raise missing_images(gone, total=len(posed) + len(missing), where=str(path),
                             hint="pass image_dir= (--image-dir DIR) to the folder of the photos",
                             scene=Scene(mesh=mesh_path, views=tuple(views)) if views else None)
    logger.info("%s: Metashape cameras, %d aligned of %d, %d sensor(s), mesh %s", path, len(views),
                len(views) + len(skipped), len(intrinsics), mesh_path)
    return Scene(mesh=mesh_path, views=tuple(views))
