"""Scene model: registered views (images + cameras) and a triangle mesh.

The native manifest is ``scene.json`` in format ``o3d_seqcc.scene/1``::

    {"format": "o3d_seqcc.scene/1",
     "mesh": "mesh.ply",
     "views": [{"name": "v00", "image": "images/v00.png", "width": 640, "height": 480,
                "intrinsic": [[fx,0,cx],[0,fy,cy],[0,0,1]],
                "extrinsic": [[r,r,r,t],[r,r,r,t],[r,r,r,t],[0,0,0,1]],
                "depth": "depth/v00.png", "depth_scale": 1000.0,
                "point_cloud": "scans/s0.ply"}]}

Paths are relative to the JSON file. ``depth``, ``depth_scale`` (units per metre, default
1000) and ``point_cloud`` are optional. Besides the manifest, :func:`load_scene` reads an
Open3D RGB-D folder (``image/``, ``depth/``, ``scene/key.log``) and COLMAP text models
(``cameras.txt`` + ``images.txt``); both need the mesh passed explicitly.

Cameras follow Open3D's ``PinholeCameraParameters``: ``extrinsic`` maps world to camera
coordinates in OpenCV axes (x right, y down, z forward).
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ._io import read_depth, read_image, write_json
from .errors import InputError

__all__ = [
    "FORMAT",
    "PRIMESENSE_INTRINSIC",
    "Mesh",
    "Scene",
    "View",
    "load_mesh",
    "load_scene",
    "save_scene",
]

logger = logging.getLogger(__name__)

FORMAT = "o3d_seqcc.scene/1"
#: Open3D's PrimeSense default intrinsic (640x480, fx = fy = 525, cx = 319.5, cy = 239.5).
PRIMESENSE_INTRINSIC = np.array([[525.0, 0.0, 319.5], [0.0, 525.0, 239.5], [0.0, 0.0, 1.0]])

_RIGID_TOL = 1e-4


def _frozen_array(a: np.ndarray, shape: tuple[int, ...], what: str) -> np.ndarray:
    arr = np.array(a, dtype=np.float64, copy=True)
    if arr.shape != shape:
        raise InputError(f"{what} must have shape {shape}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


def _check_intrinsic(K: np.ndarray, where: str) -> None:
    if not np.all(np.isfinite(K)):
        raise InputError(f"{where}: intrinsic contains NaN/inf; give finite fx, fy, cx, cy")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise InputError(
            f"{where}: intrinsic has non-positive focal length (fx={K[0, 0]}, fy={K[1, 1]}); "
            "focal lengths are in pixels and must be > 0"
        )
    if not np.allclose(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0 or K[2, 0] != 0:
        raise InputError(f"{where}: intrinsic must be [[fx,s,cx],[0,fy,cy],[0,0,1]], got {K.tolist()}")


def _check_extrinsic(T: np.ndarray, where: str) -> None:
    if not np.all(np.isfinite(T)):
        raise InputError(f"{where}: extrinsic contains NaN/inf; fix the camera pose")
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise InputError(f"{where}: extrinsic's last row must be [0, 0, 0, 1], got {T[3].tolist()}")
    R = T[:3, :3]
    err = np.abs(R.T @ R - np.eye(3)).max()
    det = np.linalg.det(R)
    if err > _RIGID_TOL or abs(det - 1.0) > _RIGID_TOL:
        raise InputError(
            f"{where}: extrinsic is not rigid (|R^T R - I| = {err:.2e}, det R = {det:.4f}); it must be a "
            "rotation + translation, world-to-camera, without scale or reflection"
        )


@dataclass(frozen=True, eq=False)
class View:
    """One registered photo.

    Parameters
    ----------
    name : str
        Unique name, used for output file names.
    image : pathlib.Path
        RGB image file (8- or 16-bit).
    intrinsic : (3, 3) float64 array
        Pinhole matrix in pixels, pixel centres at integer coordinates.
    extrinsic : (4, 4) float64 array
        World-to-camera rigid transform, OpenCV axes (x right, y down, z forward).
    width, height : int
        Image size in pixels.
    depth : pathlib.Path, optional
        Depth map registered to the image (single channel).
    depth_scale : float, default 1000.0
        Depth units per metre.
    point_cloud : pathlib.Path, optional
        Partial point cloud (world coordinates) captured from this view's set-up.
    """

    name: str
    image: Path
    intrinsic: np.ndarray
    extrinsic: np.ndarray
    width: int
    height: int
    depth: Path | None = None
    depth_scale: float = 1000.0
    point_cloud: Path | None = None

    def __post_init__(self) -> None:
        where = f"view {self.name!r}"
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"view name must be a non-empty string, got {self.name!r}")
        if any(c in self.name for c in '/\\:*?"<>|') or self.name in (".", ".."):
            raise InputError(f"{where}: name is used as a file name; avoid / \\ : * ? \" < > |")
        object.__setattr__(self, "image", Path(self.image))
        object.__setattr__(self, "depth", None if self.depth is None else Path(self.depth))
        object.__setattr__(self, "point_cloud", None if self.point_cloud is None else Path(self.point_cloud))
        object.__setattr__(self, "intrinsic", _frozen_array(self.intrinsic, (3, 3), f"{where}: intrinsic"))
        object.__setattr__(self, "extrinsic", _frozen_array(self.extrinsic, (4, 4), f"{where}: extrinsic"))
        _check_intrinsic(self.intrinsic, where)
        _check_extrinsic(self.extrinsic, where)
        try:
            w, h = int(self.width), int(self.height)
        except (TypeError, ValueError):
            raise InputError(f"{where}: width/height must be integers") from None
        if w <= 0 or h <= 0 or w != self.width or h != self.height:
            raise InputError(f"{where}: width/height must be positive integers, got {self.width}x{self.height}")
        object.__setattr__(self, "width", w)
        object.__setattr__(self, "height", h)
        ds = float(self.depth_scale)
        if not np.isfinite(ds) or ds <= 0:
            raise InputError(f"{where}: depth_scale must be > 0 (units per metre), got {self.depth_scale}")
        object.__setattr__(self, "depth_scale", ds)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, View):
            return NotImplemented
        return (
            self.name == other.name
            and self.image == other.image
            and np.array_equal(self.intrinsic, other.intrinsic)
            and np.array_equal(self.extrinsic, other.extrinsic)
            and (self.width, self.height, self.depth, self.depth_scale, self.point_cloud)
            == (other.width, other.height, other.depth, other.depth_scale, other.point_cloud)
        )

    __hash__ = None  # type: ignore[assignment]

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) world-to-camera rotation."""
        return self.extrinsic[:3, :3]

    @property
    def translation(self) -> np.ndarray:
        """(3,) world-to-camera translation."""
        return self.extrinsic[:3, 3]

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in world coordinates."""
        return -self.rotation.T @ self.translation

    @property
    def axis(self) -> np.ndarray:
        """(3,) unit focal axis (camera +z) in world coordinates."""
        return self.rotation[2].copy()

    def load_image(self) -> np.ndarray:
        """Read the image: (H, W, 3) uint8/uint16 RGB; raises if its size is not width x height."""
        img = read_image(self.image)
        if img.shape[:2] != (self.height, self.width):
            raise InputError(
                f"view {self.name!r}: image {self.image} is {img.shape[1]}x{img.shape[0]} but the scene says "
                f"{self.width}x{self.height}; fix width/height (and the intrinsic) or the image"
            )
        return img

    def load_depth(self) -> np.ndarray | None:
        """Read the depth map in metres ((H, W) float64, 0 = missing), or None without one."""
        if self.depth is None:
            return None
        return read_depth(self.depth, self.depth_scale, shape=(self.height, self.width))

    def to_open3d(self):
        """This camera as ``open3d.camera.PinholeCameraParameters``."""
        import open3d as o3d

        p = o3d.camera.PinholeCameraParameters()
        K = self.intrinsic
        p.intrinsic = o3d.camera.PinholeCameraIntrinsic(self.width, self.height, K[0, 0], K[1, 1], K[0, 2], K[1, 2])
        p.extrinsic = np.array(self.extrinsic)
        return p


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh as plain arrays.

    Attributes
    ----------
    vertices : (N, 3) float64
    faces : (F, 3) int64, indices into ``vertices``
    vertex_normals : (N, 3) float64, unit length (computed when the file has none)
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_normals: np.ndarray

    @property
    def face_normals(self) -> np.ndarray:
        """(F, 3) unit face normals (zero for degenerate faces), right-hand rule on the winding."""
        v = self.vertices[self.faces]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        return np.divide(n, norm, out=np.zeros_like(n), where=norm > 0)

    def to_open3d(self):
        """This mesh as ``open3d.geometry.TriangleMesh`` (legacy)."""
        import open3d as o3d

        m = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(self.vertices), o3d.utility.Vector3iVector(self.faces.astype(np.int32))
        )
        m.vertex_normals = o3d.utility.Vector3dVector(self.vertex_normals)
        return m


@lru_cache(maxsize=4)
def _load_mesh_cached(path: str, mtime_ns: int, size: int) -> Mesh:
    import open3d as o3d

    p = Path(path)
    mesh = o3d.io.read_triangle_mesh(str(p), enable_post_processing=False, print_progress=False)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.triangles, dtype=np.int64)
    if len(f) == 0:
        raise InputError(
            f"mesh {p} has no triangles (is it a point cloud or a non-triangle mesh?); "
            "give a triangle mesh (PLY/OBJ/OFF/GLB), triangulate polygons first (MeshLab: Filters > "
            "Polygonal and Quad Mesh > Turn into a Pure-Triangular mesh)"
        )
    if not np.all(np.isfinite(v)):
        raise InputError(f"mesh {p} has non-finite vertex coordinates; clean it (remove NaN vertices)")
    if f.min() < 0 or f.max() >= len(v):
        raise InputError(f"mesh {p} has face indices outside the vertex array")
    if mesh.has_vertex_normals():
        n = np.asarray(mesh.vertex_normals, dtype=np.float64)
    else:
        mesh.compute_vertex_normals()
        n = np.asarray(mesh.vertex_normals, dtype=np.float64)
        logger.info("mesh %s has no vertex normals: computed them", p)
    for a in (v, f, n):
        a.setflags(write=False)
    return Mesh(vertices=v, faces=f, vertex_normals=n)


def load_mesh(path: str | os.PathLike) -> Mesh:
    """Load a triangle mesh (any format Open3D reads) as arrays; cached per file version.

    Raises
    ------
    InputError
        Missing file, no triangles, non-finite vertices.
    """
    p = Path(path).resolve()
    if not p.is_file():
        raise InputError(f"mesh not found: {path} (check the 'mesh' entry or pass mesh=...)")
    st = p.stat()
    if st.st_size == 0:
        raise InputError(f"mesh {path} is an empty file")
    return _load_mesh_cached(str(p), st.st_mtime_ns, st.st_size)


@dataclass(frozen=True, eq=False)
class Scene:
    """A triangle mesh and the views registered to it.

    Parameters
    ----------
    mesh : pathlib.Path
        Mesh file (PLY, OBJ, ...), world coordinates in metres.
    views : tuple of View
        Views with unique names.
    """

    mesh: Path
    views: tuple[View, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        object.__setattr__(self, "mesh", Path(self.mesh))
        object.__setattr__(self, "views", tuple(self.views))
        if not self.views:
            raise InputError("scene has no views; add at least one registered image")
        seen: set[str] = set()
        for v in self.views:
            if not isinstance(v, View):
                raise InputError(f"scene views must be View objects, got {type(v).__name__}")
            if v.name in seen:
                raise InputError(f"duplicate view name {v.name!r}: view names must be unique (they name output files)")
            seen.add(v.name)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Scene):
            return NotImplemented
        return self.mesh == other.mesh and self.views == other.views

    __hash__ = None  # type: ignore[assignment]

    def __len__(self) -> int:
        return len(self.views)

    @property
    def names(self) -> list[str]:
        """View names in order."""
        return [v.name for v in self.views]

    def index(self, view: str | int) -> int:
        """Index of a view given by name or index; raises listing the valid names."""
        if isinstance(view, (int, np.integer)) and not isinstance(view, bool):
            if not 0 <= int(view) < len(self.views):
                raise InputError(f"view index {view} out of range 0..{len(self.views) - 1}")
            return int(view)
        for i, v in enumerate(self.views):
            if v.name == view:
                return i
        raise InputError(f"unknown view {view!r}; valid names: {', '.join(self.names)}")

    def load_mesh(self) -> Mesh:
        """The mesh as arrays (see :func:`load_mesh`)."""
        return load_mesh(self.mesh)

    def replace_images(self, images: Sequence[str | os.PathLike]) -> "Scene":
        """A copy whose views point at other image files (same cameras)."""
        if len(images) != len(self.views):
            raise ValueError("one image per view is needed")
        from dataclasses import replace

        return Scene(self.mesh, tuple(replace(v, image=Path(p)) for v, p in zip(self.views, images)))

    def validate(self, *, check_images: bool = True) -> None:
        """Check that every referenced file exists and images have the declared size and type.

        Reads only image headers (Pillow), not pixels. Raises :class:`InputError`.
        """
        load_mesh(self.mesh)
        for v in self.views:
            if check_images:
                _check_image_header(v)
            if v.depth is not None and not v.depth.is_file():
                raise InputError(f"view {v.name!r}: depth map not found: {v.depth}")
            if v.point_cloud is not None and not v.point_cloud.is_file():
                raise InputError(f"view {v.name!r}: point cloud not found: {v.point_cloud}")


def _check_image_header(v: View) -> None:
    from PIL import Image, UnidentifiedImageError

    if not v.image.is_file():
        raise InputError(f"view {v.name!r}: image not found: {v.image} (check the path in the scene file)")
    try:
        with Image.open(v.image) as im:
            size, mode = im.size, im.mode
    except (UnidentifiedImageError, OSError) as e:
        raise InputError(f"view {v.name!r}: cannot read image {v.image}: {e}; re-save it as PNG or JPEG") from None
    if mode in ("L", "I;16", "I;16B", "I", "F", "1", "LA", "P", "PA"):
        # palette images may still be colour; let OpenCV decide on load
        if mode not in ("P", "PA"):
            kind = "grey-scale" if "A" not in mode else "grey-scale with alpha"
            raise InputError(f"view {v.name!r}: image {v.image} is {kind}; colour correction needs RGB images")
    if mode in ("RGBA", "RGBa", "LA", "PA"):
        raise InputError(
            f"view {v.name!r}: image {v.image} has an alpha channel; save it as 3-channel RGB "
            "(e.g. `convert in.png -alpha off out.png`)"
        )
    if size != (v.width, v.height):
        raise InputError(
            f"view {v.name!r}: image {v.image} is {size[0]}x{size[1]} but the scene says {v.width}x{v.height}; "
            "fix width/height (and the intrinsic) or the image"
        )


# --------------------------------------------------------------------------------------------
# scene.json
# --------------------------------------------------------------------------------------------


def _join(root: Path, rel: str) -> Path:
    return Path(os.path.normpath(root / rel))


def _load_json(path: Path) -> Scene:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: not valid JSON ({e})") from None
    if not isinstance(data, dict):
        raise InputError(f"{path}: expected a JSON object with 'format', 'mesh' and 'views'")
    fmt = data.get("format")
    if fmt != FORMAT:
        raise InputError(
            f"{path}: unknown scene format {fmt!r}; this version of o3d_seqcc reads {FORMAT!r} "
            "(upgrade o3d_seqcc or re-export the scene)"
        )
    root = path.parent
    for key in ("mesh", "views"):
        if key not in data:
            raise InputError(f"{path}: missing required key {key!r}")
    if not isinstance(data["views"], list):
        raise InputError(f"{path}: 'views' must be a list")
    views = []
    for i, d in enumerate(data["views"]):
        where = f"{path}: views[{i}]"
        if not isinstance(d, dict):
            raise InputError(f"{where} must be an object")
        missing = [k for k in ("name", "image", "width", "height", "intrinsic", "extrinsic") if k not in d]
        if missing:
            raise InputError(f"{where} ({d.get('name', '?')}) is missing {', '.join(missing)}")
        unknown = set(d) - {"name", "image", "width", "height", "intrinsic", "extrinsic", "depth", "depth_scale", "point_cloud"}
        if unknown:
            raise InputError(f"{where} has unknown keys {sorted(unknown)}")
        try:
            views.append(
                View(
                    name=d["name"],
                    image=_join(root, d["image"]),
                    intrinsic=np.asarray(d["intrinsic"], dtype=np.float64),
                    extrinsic=np.asarray(d["extrinsic"], dtype=np.float64),
                    width=d["width"],
                    height=d["height"],
                    depth=None if d.get("depth") is None else _join(root, d["depth"]),
                    depth_scale=d.get("depth_scale", 1000.0),
                    point_cloud=None if d.get("point_cloud") is None else _join(root, d["point_cloud"]),
                )
            )
        except InputError as e:
            raise InputError(f"{path}: {e}") from None
        except (TypeError, ValueError) as e:
            raise InputError(f"{where}: malformed entry ({e})") from None
    try:
        return Scene(mesh=_join(root, data["mesh"]), views=tuple(views))
    except InputError as e:
        raise InputError(f"{path}: {e}") from None


def _rel(p: Path, root: Path) -> str:
    return Path(os.path.relpath(Path(p).resolve(), root.resolve())).as_posix()


def save_scene(scene: Scene, path: str | os.PathLike) -> Path:
    """Write ``scene`` as a ``scene.json`` manifest (format ``o3d_seqcc.scene/1``), atomically.

    Paths are stored relative to the manifest's folder. ``load_scene(save_scene(s, p)) == s``
    exactly (floats are written with full precision).

    Parameters
    ----------
    scene : Scene
    path : path-like
        Manifest path (conventionally ``.../scene.json``).

    Returns
    -------
    pathlib.Path
        The manifest path.
    """
    path = Path(path)
    root = path.parent
    root.mkdir(parents=True, exist_ok=True)
    views = []
    for v in scene.views:
        d = {
            "name": v.name,
            "image": _rel(v.image, root),
            "width": v.width,
            "height": v.height,
            "intrinsic": v.intrinsic.tolist(),
            "extrinsic": v.extrinsic.tolist(),
        }
        if v.depth is not None:
            d["depth"] = _rel(v.depth, root)
            d["depth_scale"] = v.depth_scale
        if v.point_cloud is not None:
            d["point_cloud"] = _rel(v.point_cloud, root)
        views.append(d)
    return write_json(path, {"format": FORMAT, "mesh": _rel(scene.mesh, root), "views": views})


# --------------------------------------------------------------------------------------------
# Open3D RGB-D folder (SampleFountainRGBDImages layout)
# --------------------------------------------------------------------------------------------

_IMAGE_EXT = {".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp"}


def read_log_trajectory(path: str | os.PathLike) -> list[np.ndarray]:
    """Read a ``.log`` trajectory (blocks of a header line + 4 rows): camera-to-world 4x4 poses."""
    path = Path(path)
    rows = [ln.split() for ln in path.read_text(encoding="utf-8").splitlines() if ln.strip()]
    if len(rows) % 5:
        raise InputError(f"{path}: a .log trajectory has blocks of 5 lines (header + 4x4 matrix); got {len(rows)} lines")
    poses = []
    for b in range(0, len(rows), 5):
        try:
            poses.append(np.array([[float(x) for x in r] for r in rows[b + 1 : b + 5]], dtype=np.float64))
        except ValueError:
            raise InputError(f"{path}: block {b // 5} does not hold a 4x4 numeric matrix") from None
        if poses[-1].shape != (4, 4):
            raise InputError(f"{path}: block {b // 5} does not hold a 4x4 matrix")
    return poses


def _list_images(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in _IMAGE_EXT and not p.name.startswith("."))


def load_rgbd_folder(
    root: str | os.PathLike,
    *,
    mesh: str | os.PathLike,
    intrinsic: np.ndarray | None = None,
    depth_scale: float = 1000.0,
) -> Scene:
    """Load an Open3D RGB-D folder: ``image/``, ``depth/`` (optional), ``scene/key.log``.

    Images, depth maps and poses are paired in sorted order. ``key.log`` holds camera-to-world
    poses; the extrinsic is their inverse.

    Parameters
    ----------
    root : path-like
        The folder.
    mesh : path-like
        Mesh file, absolute or relative to ``root``.
    intrinsic : (3, 3) array, optional
        Defaults to :data:`PRIMESENSE_INTRINSIC`.
    depth_scale : float, default 1000.0
    """
    root = Path(root)
    img_dir, depth_dir, log = root / "image", root / "depth", root / "scene" / "key.log"
    if not img_dir.is_dir() or not log.is_file():
        raise InputError(f"{root}: not an Open3D RGB-D folder (needs image/ and scene/key.log)")
    images = _list_images(img_dir)
    depths = _list_images(depth_dir) if depth_dir.is_dir() else []
    poses = read_log_trajectory(log)
    if len(images) != len(poses):
        raise InputError(f"{root}: {len(images)} images in image/ but {len(poses)} poses in scene/key.log")
    if depths and len(depths) != len(images):
        raise InputError(f"{root}: {len(images)} images but {len(depths)} depth maps; they are paired in sorted order")
    K = PRIMESENSE_INTRINSIC if intrinsic is None else np.asarray(intrinsic, dtype=np.float64)
    mesh_path = Path(mesh)
    if not mesh_path.is_absolute() and not mesh_path.exists():
        mesh_path = root / mesh_path
    from PIL import Image

    with Image.open(images[0]) as im:
        w, h = im.size
    views = []
    for i, (img, pose) in enumerate(zip(images, poses)):
        if not np.all(np.isfinite(pose)):
            raise InputError(f"{log}: pose {i} contains NaN/inf")
        ext = np.linalg.inv(pose)
        ext[3] = [0.0, 0.0, 0.0, 1.0]
        views.append(
            View(
                name=img.stem,
                image=img,
                intrinsic=K,
                extrinsic=ext,
                width=w,
                height=h,
                depth=depths[i] if depths else None,
                depth_scale=depth_scale,
            )
        )
    return Scene(mesh=mesh_path, views=tuple(views))


# --------------------------------------------------------------------------------------------
# COLMAP text model
# --------------------------------------------------------------------------------------------


def _qvec2rotmat(q: Iterable[float]) -> np.ndarray:
    w, x, y, z = np.asarray(list(q), dtype=np.float64) / np.linalg.norm(list(q))
    return np.array(
        [
            [1 - 2 * y * y - 2 * z * z, 2 * x * y - 2 * w * z, 2 * x * z + 2 * w * y],
            [2 * x * y + 2 * w * z, 1 - 2 * x * x - 2 * z * z, 2 * y * z - 2 * w * x],
            [2 * x * z - 2 * w * y, 2 * y * z + 2 * w * x, 1 - 2 * x * x - 2 * y * y],
        ]
    )


def load_colmap(
    model_dir: str | os.PathLike,
    *,
    mesh: str | os.PathLike,
    image_dir: str | os.PathLike | None = None,
) -> Scene:
    """Load a COLMAP text model (``cameras.txt``, ``images.txt``) with undistorted cameras.

    Supported camera models: PINHOLE, SIMPLE_PINHOLE, and SIMPLE_RADIAL / RADIAL / OPENCV only
    when their distortion parameters are all zero (run ``colmap image_undistorter`` first).
    COLMAP's pixel convention (centre of the top-left pixel at 0.5) is converted to ours
    (pixel centres at integers): cx, cy are shifted by -0.5.

    Parameters
    ----------
    model_dir : path-like
        Folder with ``cameras.txt`` and ``images.txt``.
    mesh : path-like
        Mesh file, absolute or relative to ``model_dir``.
    image_dir : path-like, optional
        Folder of the images; default: ``images/`` next to the model or in its parent folders.
    """
    model_dir = Path(model_dir)
    cams_txt, imgs_txt = model_dir / "cameras.txt", model_dir / "images.txt"
    for p in (cams_txt, imgs_txt):
        if not p.is_file():
            raise InputError(f"COLMAP model {model_dir}: {p.name} not found (export the model as TXT)")
    cams: dict[int, tuple[int, int, np.ndarray]] = {}
    for ln in cams_txt.read_text(encoding="utf-8").splitlines():
        if not ln.strip() or ln.startswith("#"):
            continue
        tok = ln.split()
        cid, model, w, h = int(tok[0]), tok[1], int(tok[2]), int(tok[3])
        prm = [float(x) for x in tok[4:]]
        if model == "PINHOLE":
            fx, fy, cx, cy = prm[:4]
        elif model == "SIMPLE_PINHOLE":
            fx, cx, cy = prm[:3]
            fy = fx
        elif model in ("SIMPLE_RADIAL", "RADIAL") and all(p == 0 for p in prm[3:]):
            fx, cx, cy = prm[:3]
            fy = fx
        elif model in ("OPENCV", "FULL_OPENCV") and all(p == 0 for p in prm[4:]):
            fx, fy, cx, cy = prm[:4]
        else:
            raise InputError(
                f"{cams_txt}: camera {cid} uses model {model} with distortion; undistort the images first "
                "(`colmap image_undistorter`) to get PINHOLE cameras"
            )
        cams[cid] = (w, h, np.array([[fx, 0, cx - 0.5], [0, fy, cy - 0.5], [0, 0, 1.0]]))
    if image_dir is None:
        cands = [model_dir / "images", model_dir.parent / "images", model_dir.parent.parent / "images"]
        image_dir = next((c for c in cands if c.is_dir()), model_dir)
    image_dir = Path(image_dir)
    lines = [ln for ln in imgs_txt.read_text(encoding="utf-8").splitlines() if not ln.startswith("#")]
    views = []
    for k in range(0, len(lines), 2):
        if not lines[k].strip():
            continue
        tok = lines[k].split()
        if len(tok) < 10:
            raise InputError(f"{imgs_txt}: malformed image line {lines[k]!r}")
        q, t, cid, name = [float(x) for x in tok[1:5]], [float(x) for x in tok[5:8]], int(tok[8]), " ".join(tok[9:])
        if cid not in cams:
            raise InputError(f"{imgs_txt}: image {name} refers to camera {cid}, not in cameras.txt")
        w, h, K = cams[cid]
        ext = np.eye(4)
        ext[:3, :3] = _qvec2rotmat(q)
        ext[:3, 3] = t
        views.append(View(name=Path(name).stem, image=image_dir / name, intrinsic=K, extrinsic=ext, width=w, height=h))
    mesh_path = Path(mesh)
    if not mesh_path.is_absolute() and not mesh_path.exists():
        mesh_path = model_dir / mesh_path
    return Scene(mesh=mesh_path, views=tuple(views))


# --------------------------------------------------------------------------------------------
# dispatcher
# --------------------------------------------------------------------------------------------


def load_scene(
    path: str | os.PathLike,
    *,
    mesh: str | os.PathLike | None = None,
    intrinsic: np.ndarray | None = None,
    image_dir: str | os.PathLike | None = None,
    validate: bool = True,
) -> Scene:
    """Load a scene, detecting its format.

    Parameters
    ----------
    path : path-like
        A ``scene.json`` manifest (or a folder containing one), an Open3D RGB-D folder
        (``image/``, ``depth/``, ``scene/key.log``), or a COLMAP text model folder
        (``cameras.txt``, ``images.txt``).
    mesh : path-like, optional
        Mesh file; required for RGB-D folders and COLMAP models, overrides the manifest's.
    intrinsic : (3, 3) array, optional
        RGB-D folders only; default PrimeSense (fx = fy = 525, cx = 319.5, cy = 239.5).
    image_dir : path-like, optional
        COLMAP only: folder of the images.
    validate : bool, default True
        Check files, image headers (size, grey, alpha) and the mesh now rather than later.

    Returns
    -------
    Scene
        Images are not read (lazy); use ``View.load_image``.

    Raises
    ------
    InputError
        Unknown layout, missing files, malformed cameras, duplicate names, ...
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"scene not found: {p}")
    if p.is_dir() and (p / "scene.json").is_file():
        p = p / "scene.json"
    if p.is_file():
        if p.suffix.lower() != ".json":
            raise InputError(f"{p}: expected a scene.json manifest, an Open3D RGB-D folder or a COLMAP model folder")
        scene = _load_json(p)
        if mesh is not None:
            scene = Scene(Path(mesh), scene.views)
    elif (p / "scene" / "key.log").is_file() and (p / "image").is_dir():
        if mesh is None:
            cands = sorted((p / "scene").glob("*.ply"))
            raise InputError(
                f"{p} is an Open3D RGB-D folder: pass the mesh explicitly (mesh=... / --mesh), "
                f"e.g. one of {[c.name for c in cands]}"
            )
        scene = load_rgbd_folder(p, mesh=mesh, intrinsic=intrinsic)
    elif (p / "cameras.txt").is_file() and (p / "images.txt").is_file():
        if mesh is None:
            raise InputError(f"{p} is a COLMAP model: pass the mesh explicitly (mesh=... / --mesh)")
        scene = load_colmap(p, mesh=mesh, image_dir=image_dir)
    else:
        raise InputError(
            f"{p}: unknown scene layout; expected scene.json, an Open3D RGB-D folder (image/, depth/, "
            "scene/key.log) or a COLMAP text model (cameras.txt, images.txt)"
        )
    if validate:
        scene.validate()
    return scene
