"""Scene model: registered views (images + cameras) and a triangle mesh.

Plain frozen dataclasses with read-only arrays; files are read lazily (``View.load_image``,
``Scene.load_mesh``). Reading and writing scene *formats* (``scene.json``, MeshLab projects,
COLMAP, Meshroom, Open3D RGB-D folders) lives in :mod:`o3d_seqcc.io`.

Cameras follow Open3D's ``PinholeCameraParameters``: ``extrinsic`` maps world to camera
coordinates in OpenCV axes (x right, y down, z forward).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .geometry.distortion import Distortion
from .io.depth import check_depth_file, read_depth
from .io.images import read_image
from .io.regular_files import open_regular
from .io.missing import MissingImage, check_photo, missing_images, near_miss  # noqa: F401 (near_miss: moved there)
from .io.masks import check_mask_file, mask_array, mask_distorted, view_mask
from .io.mesh_files import read_mesh, read_point_cloud
from .geometry.meshops import face_normals
from ._shared.arguments import shown
from ._shared.numbers import check_numbers
from .errors import InputError

__all__ = [
    "FORMAT",
    "PRIMESENSE_INTRINSIC",
    "Mesh",
    "Scene",
    "View",
    "check_scene_argument",
    "load_mesh",
    "resolve_view",
    "summarise",
]

logger = logging.getLogger(__name__)

FORMAT = "o3d_seqcc.scene/1"
#: Open3D's PrimeSense default intrinsic (640x480, fx = fy = 525, cx = 319.5, cy = 239.5).
PRIMESENSE_INTRINSIC = np.array([[525.0, 0.0, 319.5], [0.0, 525.0, 239.5], [0.0, 0.0, 1.0]])

_RIGID_TOL = 1e-4
#: the depth scales accepted (depth units per metre): 1e-6 is a unit of 1000 km, 1e9 a nanometre
DEPTH_SCALE_RANGE = (1e-6, 1e9)
#: longest view name (names become output file names)
MAX_NAME_LENGTH = 120


def _frozen_array(a: np.ndarray, shape: tuple[int, ...], what: str) -> np.ndarray:
    try:
        arr = np.array(a, dtype=np.float64, copy=True)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be a {'x'.join(map(str, shape))} array of numbers") from None
    if arr.shape != shape:
        raise InputError(f"{what} must have shape {shape}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


def _check_intrinsic(K: np.ndarray, where: str) -> None:
    check_numbers(K, f"{where}: intrinsic", fix="give finite fx, fy, cx, cy")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise InputError(
            f"{where}: intrinsic has non-positive focal length (fx={K[0, 0]}, fy={K[1, 1]}); "
            "focal lengths are in pixels and must be > 0"
        )
    if not np.allclose(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0 or K[2, 0] != 0:
        raise InputError(f"{where}: intrinsic must be [[fx,s,cx],[0,fy,cy],[0,0,1]], got {K.tolist()}")


def _check_extrinsic(T: np.ndarray, where: str) -> None:
    check_numbers(T, f"{where}: extrinsic", fix="fix the camera pose")
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


def resolve_view(names: Sequence[str], view: str | int) -> int:
    """Index of a view given by name, by index, or by an index written as a string.

    A name always wins over a digit string (a view named ``"3"`` is that view, not index 3).

    Parameters
    ----------
    names : sequence of str
        View names in order.
    view : str or int

    Raises
    ------
    InputError
        Unknown name or index out of range; the message lists the valid names.
    """
    names = list(names)
    if isinstance(view, str):
        if view in names:
            return names.index(view)
        if view.strip().isdigit():
            view = int(view)
        else:
            shown = ", ".join(names[:20]) + (" ..." if len(names) > 20 else "")
            raise InputError(f"unknown view {view!r:.80}; valid names: {shown} (or an index 0..{len(names) - 1})")
    if isinstance(view, (int, np.integer)) and not isinstance(view, bool):
        if not 0 <= int(view) < len(names):
            raise InputError(f"view index {view} out of range 0..{len(names) - 1}")
        return int(view)
    raise InputError(f"a view is given by name or index, got {view!r:.80} ({type(view).__name__})")


@dataclass(frozen=True, eq=False)
class View:
    """One registered photo.

    Parameters
    ----------
    name : str
        Unique name, used for output file names.
    image : pathlib.Path or None
        RGB image file (8- or 16-bit); None for an in-memory view (``pixels``).
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
    pixels : (H, W, 3) uint8 / uint16 array, optional
        The image in memory, instead of a file (the Open3D front door builds such views);
        kept read-only, never written to.
    depth_map : (H, W) float array, optional
        Depth in metres in memory (0 = missing), instead of a depth file.
    points : (M, 3) float array, optional
        Partial point cloud in memory, instead of a file.
    distortion : Distortion, optional
        The photo's lens distortion: the image (and depth map, and mask) is undistorted as it is
        read (:meth:`load_image`, :meth:`load_depth`, :meth:`load_mask`) to the pinhole camera
        ``intrinsic`` (same size); see :mod:`o3d_seqcc.geometry.distortion`.
    mask : pathlib.Path, optional
        The photo's mask (:mod:`o3d_seqcc.io.masks`), its size: nonzero = kept, 0 = masked out (used nowhere).
    mask_invert : bool, default False
        The mask's other convention: nonzero = masked out.
    mask_map : (H, W) bool / integer array, optional
        The mask in memory (nonzero = kept unless ``mask_invert``), instead of a mask file.
    """

    name: str
    image: Path | None
    intrinsic: np.ndarray
    extrinsic: np.ndarray
    width: int
    height: int
    depth: Path | None = None
    depth_scale: float = 1000.0
    point_cloud: Path | None = None
    pixels: np.ndarray | None = field(default=None, repr=False)
    depth_map: np.ndarray | None = field(default=None, repr=False)
    points: np.ndarray | None = field(default=None, repr=False)
    distortion: Distortion | None = field(default=None, repr=False)
    mask: Path | None = None
    mask_invert: bool = False
    mask_map: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"view name must be a non-empty string, got {self.name!r:.80}")
        where = f"view {self.name!r:.80}"
        if any(c in self.name for c in '/\\:*?"<>|') or self.name in (".", "..") or any(ord(c) < 32 for c in self.name):
            raise InputError(f"{where}: name is used as a file name; avoid / \\ : * ? \" < > | and control characters")
        if len(self.name) > MAX_NAME_LENGTH:
            raise InputError(f"{where}: name is {len(self.name)} characters long; at most {MAX_NAME_LENGTH} (it names "
                             "output files)")
        if self.image is None and self.pixels is None:
            raise InputError(f"{where}: give an image file (image=) or the pixels in memory (pixels=)")
        object.__setattr__(self, "image", None if self.image is None else Path(self.image))
        object.__setattr__(self, "depth", None if self.depth is None else Path(self.depth))
        object.__setattr__(self, "point_cloud", None if self.point_cloud is None else Path(self.point_cloud))
        object.__setattr__(self, "mask", None if self.mask is None else Path(self.mask))
        object.__setattr__(self, "mask_invert", bool(self.mask_invert))
        object.__setattr__(self, "intrinsic", _frozen_array(self.intrinsic, (3, 3), f"{where}: intrinsic"))
        object.__setattr__(self, "extrinsic", _frozen_array(self.extrinsic, (4, 4), f"{where}: extrinsic"))
        _check_intrinsic(self.intrinsic, where)
        _check_extrinsic(self.extrinsic, where)
        try:
            w, h = int(self.width), int(self.height)
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"{where}: width/height must be integers") from None
        if w <= 0 or h <= 0 or w != self.width or h != self.height:
            raise InputError(f"{where}: width/height must be positive integers, got {self.width}x{self.height}")
        object.__setattr__(self, "width", w)
        object.__setattr__(self, "height", h)
        try:
            ds = float(self.depth_scale)
        except (TypeError, ValueError):
            raise InputError(f"{where}: depth_scale must be a number (depth units per metre), got "
                             f"{self.depth_scale!r:.40}") from None
        lo, hi = DEPTH_SCALE_RANGE
        if not lo <= ds <= hi:  # NaN, inf, denormals and a 0 or negative scale too
            raise InputError(f"{where}: depth_scale must be between {lo:g} and {hi:g} depth units per metre (1000: "
                             f"millimetres, 1: metres), got {self.depth_scale!r:.40}")
        object.__setattr__(self, "depth_scale", ds)
        if self.distortion is not None and not isinstance(self.distortion, Distortion):
            raise InputError(f"{where}: distortion must be an o3d_seqcc.geometry.distortion.Distortion, got "
                             f"{type(self.distortion).__name__}")
        self._freeze_memory(where)

    def _freeze_memory(self, where: str) -> None:
        """Check the in-memory arrays against width x height and keep read-only copies."""
        if self.pixels is not None:
            px = np.asarray(self.pixels)
            if px.ndim != 3 or px.shape[2] != 3 or px.shape[:2] != (self.height, self.width):
                raise InputError(f"{where}: pixels must be ({self.height}, {self.width}, 3) RGB, got shape {px.shape}")
            if px.dtype not in (np.uint8, np.uint16):
                raise InputError(f"{where}: pixels must be uint8 or uint16, got {px.dtype} (convert floats with "
                                 "o3d_seqcc.imaging.arrays.img_as_dtype)")
            px = np.array(px, copy=True)
            px.setflags(write=False)
            object.__setattr__(self, "pixels", px)
        if self.depth_map is not None:
            d = np.array(self.depth_map, dtype=np.float64, copy=True)
            if d.shape != (self.height, self.width):
                raise InputError(f"{where}: depth_map must be ({self.height}, {self.width}) metres, got shape {d.shape}")
            d[~np.isfinite(d) | (d < 0)] = 0.0
            d.setflags(write=False)
            object.__setattr__(self, "depth_map", d)
        if self.mask_map is not None:
            object.__setattr__(self, "mask_map", mask_array(self.mask_map, (self.height, self.width), where))
        if self.points is not None:
            p = np.array(self.points, dtype=np.float64, copy=True).reshape(-1, 3)
            p = p[np.isfinite(p).all(axis=1)]
            if not len(p):
                raise InputError(f"{where}: points holds no finite point")
            p.setflags(write=False)
            object.__setattr__(self, "points", p)

    @property
    def in_memory(self) -> bool:
        """The image is held in memory (``pixels``), not in a file."""
        return self.pixels is not None

    @property
    def has_depth(self) -> bool:
        """A depth map or a point cloud is available for the depth-consistency filter."""
        return any(x is not None for x in (self.depth, self.depth_map, self.point_cloud, self.points))

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
            and all(a is b for a, b in zip((self.pixels, self.depth_map, self.points, self.mask_map),
                                           (other.pixels, other.depth_map, other.points, other.mask_map)))
            and self.distortion == other.distortion
            and (self.mask, self.mask_invert) == (other.mask, other.mask_invert)
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
        """(3,) camera centre in world coordinates: the point the extrinsic maps to the camera's origin.

        Solved (``-R^-1 t``), not ``-R^T t``: rotations read from files are orthonormal to ~1e-6
        only (Fountain's key.log), and 1e-6 of a translation of 5e5 m (geo-referenced scans) is
        0.5 m.
        """
        return -np.linalg.solve(self.rotation, self.translation)

    @property
    def axis(self) -> np.ndarray:
        """(3,) unit focal axis (camera +z) in world coordinates."""
        return self.rotation[2].copy()

    @property
    def distorted(self) -> bool:
        """The photo has lens distortion that :meth:`load_image` removes."""
        return self.distortion is not None and self.distortion.images and not self.distortion.is_zero

    def load_image(self) -> np.ndarray:
        """Read the image: (H, W, 3) uint8/uint16 RGB, undistorted to ``intrinsic`` when the view has a
        ``distortion``; raises if its size is not width x height."""
        if self.pixels is not None:
            img = self.pixels
        else:
            img = read_image(self.image)
            if img.shape[:2] != (self.height, self.width):
                raise InputError(
                    f"view {self.name!r}: image {self.image} is {img.shape[1]}x{img.shape[0]} but the scene says "
                    f"{self.width}x{self.height}; fix width/height (and the intrinsic) or the image"
                )
        if self.distorted:
            img = self.distortion.undistort(img, self.intrinsic)
            img.setflags(write=False)
        return img

    def load_depth(self) -> np.ndarray | None:
        """Read the depth map in metres ((H, W) float64, 0 = missing; undistorted, nearest neighbour, when the
        view has a ``distortion``), or None without one."""
        if self.depth_map is not None:
            d = self.depth_map
        elif self.depth is None:
            return None
        else:
            d = read_depth(self.depth, self.depth_scale, shape=(self.height, self.width))
        if self.distortion is not None and self.distortion.depth and not self.distortion.is_zero:
            d = self.distortion.undistort(d, self.intrinsic, nearest=True)
        return d

    @property
    def has_mask(self) -> bool:
        """The photo has a mask (a file or in memory)."""
        return self.mask is not None or self.mask_map is not None

    def load_mask(self) -> np.ndarray | None:
        """Read the mask: (H, W) bool, True where the photo's pixels count, False where they are masked out
        (:func:`o3d_seqcc.io.masks.view_mask`: ``mask_invert`` applied, undistorted with a distorted photo), or None."""
        return view_mask(self)

    def load_points(self) -> np.ndarray | None:
        """The partial point cloud ((M, 3) float64 world points), or None without one."""
        if self.points is not None:
            return self.points
        if self.point_cloud is None:
            return None
        return read_point_cloud(self.point_cloud)

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
    corner_uv : (F, 3, 2) float64 or None
        Texture coordinates of every face corner (OBJ convention: origin bottom-left), for
        ``uv="keep"``; a mesh read from a file leaves it None (they are read when asked for:
        :func:`~o3d_seqcc.io.mesh_files.read_corner_uv`).
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_normals: np.ndarray
    corner_uv: np.ndarray | None = None

    @property
    def face_normals(self) -> np.ndarray:
        """(F, 3) unit face normals (zero for degenerate faces), right-hand rule on the winding."""
        return face_normals(self.vertices, self.faces)[0]

    def to_open3d(self):
        """This mesh as ``open3d.geometry.TriangleMesh`` (legacy)."""
        import open3d as o3d

        m = o3d.geometry.TriangleMesh(  # copies: Open3D needs writeable buffers, ours are read-only
            o3d.utility.Vector3dVector(np.array(self.vertices)), o3d.utility.Vector3iVector(self.faces.astype(np.int32))
        )
        m.vertex_normals = o3d.utility.Vector3dVector(np.array(self.vertex_normals))
        return m


@lru_cache(maxsize=4)
def _load_mesh_cached(path: str, mtime_ns: int, size: int) -> Mesh:
    p = Path(path)
    v, f, n = read_mesh(p)  # the file layer: regular file, header counts, finite and sane vertices
    if n is None:
        import open3d as o3d

        m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v), o3d.utility.Vector3iVector(f.astype(np.int32)))
        m.compute_vertex_normals()
        n = np.asarray(m.vertex_normals, dtype=np.float64)
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
    if not p.exists():
        raise InputError(f"mesh not found: {path} (check the 'mesh' entry or pass mesh=...)")
    if not p.is_file():
        open_regular(p, "mesh").close()  # raises, naming what it is (a FIFO, a folder, ...)
    st = p.stat()
    if st.st_size == 0:
        raise InputError(f"mesh {path} is an empty file")
    return _load_mesh_cached(str(p), st.st_mtime_ns, st.st_size)


@dataclass(frozen=True, eq=False)
class Scene:
    """A triangle mesh and the views registered to it.

    Parameters
    ----------
    mesh : pathlib.Path or Mesh
        Mesh file (PLY, OBJ, ...), world coordinates in metres, or the mesh in memory.
    views : tuple of View
        Views with unique names.
    source : pathlib.Path, optional
        The file or folder the scene was read from (set by :func:`~o3d_seqcc.load_scene`; not
        part of equality).
    options : dict, optional
        The keyword options :func:`~o3d_seqcc.load_scene` read it with (JSON values: paths as
        strings), so that it can be read again the same way (``o3d-seqcc report``); not part of
        equality.
    """

    mesh: Path | Mesh
    views: tuple[View, ...] = field(default_factory=tuple)
    source: Path | None = field(default=None, compare=False)
    options: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.mesh, Mesh):
            object.__setattr__(self, "mesh", Path(self.mesh))
        object.__setattr__(self, "source", None if self.source is None else Path(self.source))
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
        """Index of a view given by name, index or index as a string (see :func:`resolve_view`)."""
        return resolve_view(self.names, view)

    def __repr__(self) -> str:
        sizes = sorted({f"{v.width}x{v.height}" for v in self.views})
        depth = sum(v.depth is not None for v in self.views)
        return (f"Scene({len(self.views)} views {'/'.join(sizes)}, {depth} with depth, mesh={str(self.mesh)!r}, "
                f"views={self.names[0]!r}..{self.names[-1]!r})")

    def load_mesh(self) -> Mesh:
        """The mesh as arrays (see :func:`load_mesh`)."""
        return self.mesh if isinstance(self.mesh, Mesh) else load_mesh(self.mesh)

    @property
    def in_memory(self) -> bool:
        """The mesh or any image is held in memory rather than in a file."""
        return isinstance(self.mesh, Mesh) or any(v.in_memory for v in self.views)

    def input_paths(self) -> list[Path]:
        """Every file the scene reads: its source (manifest, project, model folder), mesh, images, depth, point clouds."""
        paths = ([] if isinstance(self.mesh, Mesh) else [self.mesh]) + ([self.source] if self.source else [])
        for v in self.views:
            paths += [p for p in (v.image, v.depth, v.point_cloud, v.mask) if p is not None]
        return paths

    def replace_images(self, images: Sequence[str | os.PathLike]) -> "Scene":
        """A copy whose views point at other image files (same cameras), taken to be undistorted (pinhole)
        images: a view's lens distortion then applies to its depth map and its mask only (masks in memory have
        no file: they are not carried)."""
        if len(images) != len(self.views):
            raise ValueError("one image per view is needed")
        from dataclasses import replace

        # the views' pixels in memory (if any) give way to the files
        def undistorted(v: View) -> Distortion | None:  # the new images are the pinhole ones; a depth map is not
            if v.distortion is None or (v.depth is None and v.mask is None):
                return None
            return replace(v.distortion, images=False, masks=mask_distorted(v) if v.mask else None)

        return Scene(self.mesh, tuple(replace(v, image=Path(p), distortion=undistorted(v), pixels=None, mask_map=None)
                                      for v, p in zip(self.views, images)), source=self.source, options=self.options)

    def validate(self, *, check_images: bool = True) -> None:
        """Check that every referenced file exists and images have the declared size and type.

        Reads only image headers (Pillow), not pixels. Raises :class:`InputError`; the photos that are
        missing or unreadable are listed together in one :class:`~o3d_seqcc.errors.MissingImagesError`,
        which carries the scene without them.
        """
        self.load_mesh()
        missing: list[MissingImage] = []
        for v in self.views:
            if check_images and not v.in_memory:
                size = check_photo(v.name, v.image)
                if isinstance(size, MissingImage):
                    missing.append(size)
                    continue
                _check_size(v, size)
            try:
                if v.depth is not None:  # the header only: size and pixel budget before any decoding
                    check_depth_file(v.depth, shape=(v.height, v.width))
                if v.point_cloud is not None:
                    open_regular(v.point_cloud, "point cloud").close()
                if v.mask is not None:  # the header only: the size before any decoding
                    check_mask_file(v.mask, shape=(v.height, v.width), view=v.name)
            except InputError as e:
                raise InputError(f"view {v.name!r}: {e}") from None
        if missing:
            gone = {m.view for m in missing}
            kept = tuple(v for v in self.views if v.name not in gone)
            rest = Scene(self.mesh, kept, source=self.source, options=self.options) if kept else None
            raise missing_images(missing, total=len(self.views), where=str(self.source or ""), scene=rest)


def _check_size(v: View, size: tuple[int, int]) -> None:
    if size != (v.width, v.height):
        raise InputError(
            f"view {v.name!r}: image {v.image} is {size[0]}x{size[1]} but the scene says {v.width}x{v.height}; "
            "fix width/height (and the intrinsic) or the image"
        )


def summarise(scene: Scene) -> dict:
    """A JSON-friendly summary of a scene: views, sizes, depth, mesh size and bounds, camera spread."""
    m = scene.load_mesh()
    centres = np.array([v.center for v in scene.views])
    return {
        "views": len(scene.views),
        "names": scene.names[:3] + (["..."] if len(scene.views) > 3 else []),
        "image_size": sorted({f"{v.width}x{v.height}" for v in scene.views}),
        "with_depth": sum(v.depth is not None for v in scene.views),
        "with_point_cloud": sum(v.point_cloud is not None for v in scene.views),
        "with_mask": sum(v.has_mask for v in scene.views),
        "distorted": sum(v.distorted for v in scene.views),
        "mesh": "(in memory)" if isinstance(scene.mesh, Mesh) else str(scene.mesh),
        "mesh_vertices": int(len(m.vertices)),
        "mesh_faces": int(len(m.faces)),
        "mesh_bounds": [m.vertices.min(0).round(3).tolist(), m.vertices.max(0).round(3).tolist()],
        "camera_centre_bounds": [centres.min(0).round(3).tolist(), centres.max(0).round(3).tolist()],
    }


def check_scene_argument(scene: Any, mesh: Any = None) -> None:
    """``scene``: a :class:`~o3d_seqcc.scene.Scene` or a non-empty path; ``mesh``: None or a path."""
    if not isinstance(scene, (Scene, str, os.PathLike)) or isinstance(scene, str) and not scene:
        raise InputError(f"scene must be a Scene or the path of a scene (scene.json or its folder, a .mlp, a COLMAP "
                         f"model, ...), got {shown(scene)}")
    if mesh is not None and (not isinstance(mesh, (str, os.PathLike)) or isinstance(mesh, str) and not mesh):
        raise InputError(f"mesh must be the path of a mesh file, got {shown(mesh)}")
