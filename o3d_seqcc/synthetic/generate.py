"""Synthetic test / demo scenes: a textured room rendered by ray casting, with known photometry.

:func:`make_synthetic_scene` builds a closed room (inward-facing walls, floor and ceiling) with
occluding furniture (a table, a tall cabinet, a sideboard), textures every planar side with a
real photo shipped by scikit-image (planar projection, bilinear sampling), renders ``n_views``
pinhole cameras placed on a ring inside the room (view 0 in the middle of the chain) and
looking outwards with Open3D's
``RaycastingScene``, and writes::

    out_dir/
      scene.json          manifest (o3d_seqcc.scene/1), views have depth maps
      mesh.ply            the room + furniture, vertex normals
      images/vNN.png      renders after the per-view photometric change (the "photos")
      gt/vNN.png          unchanged renders (ground truth, identical surface colour in all views)
      depth/vNN.png       uint16 depth in millimetres (camera z, 0 = no hit)
      face_ids/vNN.npy    (H, W) int32 ray-cast face id per pixel (-1 = no hit)
      points/vNN.npy      (H, W, 3) float32 world point per pixel (NaN where no hit)
      synthetic.json      generator parameters, per-view photometric parameters, face groups

The rendered colour is the surface albedo only (no shading), so one surface point has exactly
the same ground-truth colour in every view; the photometric change of view ``i`` is
:func:`apply_photometric` with ``transforms[name]`` (exposure gain, per-channel white balance,
clip to [0, 1], per-channel gamma, S-curve), then rounding to 8 bits. View 0 is left unchanged.
"""

from __future__ import annotations

import io
import json
import logging
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..imaging.arrays import img_as_dtype
from ..io import raster_checks
from ..io.atomic import atomic_path, atomic_write_bytes
from ..io.images import read_image, write_image
from ..io.json_files import write_json
from ..io.load import load_scene, save_scene
from ..io.output import check_output, output_folder
from ..evaluation.photometric import (
    HARD_CHANGE_RANGES,
    apply_photometric,
    identity_photometric,
    sample_camera_change,
    sample_photometric,
)
from ..scene import Scene, View
from .room import (
    DEFAULT_CELL_SIZE,
    ROOM,
    RoomGeometry,
    build_geometry,
    keep_faces,
    look_extrinsic,
    render_view,
    sample_cameras,
)

__all__ = ["PHOTOMETRIC_MODES", "SYNTHETIC_FORMAT", "SyntheticScene", "load_synthetic", "make_synthetic_scene",
           "perturb_poses"]

logger = logging.getLogger(__name__)

SYNTHETIC_FORMAT = "o3d_seqcc.synthetic/1"
#: Valid values of ``photometric``.
PHOTOMETRIC_MODES = ("none", "camera", "camera-hard")


@dataclass(frozen=True, eq=False)
class SyntheticScene:
    """A generated synthetic scene (see the module docstring for the folder layout).

    Attributes
    ----------
    scene : Scene
        The scene, already saved at ``root / "scene.json"``; every view has a depth map.
    gt_images : dict of str to pathlib.Path
        View name -> unchanged render (uint8 RGB PNG).
    transforms : dict of str to dict
        View name -> photometric parameters applied (see :func:`apply_photometric`).
    face_ids : dict of str to pathlib.Path
        View name -> ``.npy`` with the (H, W) int32 ray-cast face id per pixel (-1 = no hit).
    points : dict of str to pathlib.Path
        View name -> ``.npy`` with the (H, W, 3) float32 world point per pixel (NaN = no hit).
    root : pathlib.Path
        The output folder.
    face_groups : dict of str to (int, int)
        Half-open face-index ranges ``[start, stop)`` of the parts of the mesh: ``"room"``
        (walls, floor, ceiling) and each piece of furniture (``"table"``, ``"cabinet"``,
        ``"sideboard"``).
    metadata : dict
        The content of ``synthetic.json``.
    """

    scene: Scene
    gt_images: dict[str, Path]
    transforms: dict[str, dict]
    face_ids: dict[str, Path]
    points: dict[str, Path]
    root: Path | None = None
    face_groups: dict[str, tuple[int, int]] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)

    def _name(self, view: str | int) -> str:
        return self.scene.views[self.scene.index(view)].name

    def load_gt(self, view: str | int) -> np.ndarray:
        """Ground-truth render of a view (name or index): (H, W, 3) uint8 RGB."""
        return read_image(self.gt_images[self._name(view)])

    def load_face_ids(self, view: str | int) -> np.ndarray:
        """(H, W) int32 face id per pixel of a view (-1 = no hit)."""
        return np.load(self.face_ids[self._name(view)])

    def load_points(self, view: str | int) -> np.ndarray:
        """(H, W, 3) float32 world point per pixel of a view (NaN = no hit)."""
        return np.load(self.points[self._name(view)])

    @property
    def furniture_faces(self) -> np.ndarray:
        """(F,) bool mask over the mesh faces: True for furniture, False for the room shell."""
        n = max(stop for _, stop in self.face_groups.values()) if self.face_groups else 0
        mask = np.zeros(n, dtype=bool)
        for name, (a, b) in self.face_groups.items():
            if name != "room":
                mask[a:b] = True
        return mask


def _save_npy(path: Path, arr: np.ndarray) -> Path:
    buf = io.BytesIO()
    np.save(buf, arr, allow_pickle=False)
    return atomic_write_bytes(path, buf.getvalue())


def _write_depth(path: Path, depth_m: np.ndarray, depth_scale: float) -> Path:
    import cv2

    d = np.clip(np.rint(depth_m * depth_scale), 0, 65535).astype(np.uint16)
    ok, buf = cv2.imencode(".png", d)
    if not ok:
        raise OSError(f"OpenCV could not encode {path}")
    return atomic_write_bytes(path, buf.tobytes())


def _moved(extrinsic: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """The world-to-camera matrix of a camera moved with the world by ``shift``: ``E' (x + shift) = E x``."""
    E = np.array(extrinsic, dtype=np.float64)
    E[:3, 3] = E[:3, 3] - E[:3, :3] @ shift
    return E


def _write_mesh(path: Path, geom: RoomGeometry) -> Path:
    import open3d as o3d

    m = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(geom.vertices), o3d.utility.Vector3iVector(geom.faces.astype(np.int32))
    )
    m.vertex_normals = o3d.utility.Vector3dVector(geom.normals)
    with atomic_path(path) as tmp:
        if not o3d.io.write_triangle_mesh(str(tmp), m, write_ascii=False, compressed=False, print_progress=False):
            raise OSError(f"Open3D could not write {path}")
    return path


_SUBDIRS = {"images": ".png", "gt": ".png", "depth": ".png", "face_ids": ".npy", "points": ".npy"}


def make_synthetic_scene(
    out_dir: str | os.PathLike,
    *,
    n_views: int = 12,
    width: int = 320, height: int = 240,
    seed: int = 0,
    photometric: str = "camera",
    overwrite: bool = False,
    cell_size: float = DEFAULT_CELL_SIZE,
    layout: str = "ring",
    seen_only: bool = False,
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> SyntheticScene:
    """Generate a synthetic room scene with known photometric changes (see the module docstring).

    Parameters
    ----------
    out_dir : path-like
        Output folder; created. Must not exist or be empty unless ``overwrite``.
    n_views : int, default 12
        Number of views (>= 1), named ``v00``, ``v01``, ... on a ring of cameras looking
        outwards: 12 or more views make a full ring (360 / n_views deg apart), fewer an arc of
        25 deg steps; view 0 (the unchanged reference) is in the middle of the chain
        (:func:`ring_slots`), ring neighbours overlap, far-apart views do not.
    width, height : int, default 320, 240
        Image size in pixels (>= 8). Intrinsic: fx = fy = 0.8 * width, principal point at the
        image centre ((width - 1) / 2, (height - 1) / 2).
    seed : int, default 0
        Seed of ``numpy.random.default_rng`` for the cameras and the photometric changes;
        the output is byte-identical for a given seed.
    photometric : {"camera", "camera-hard", "none"}, default "camera"
        ``"camera"``: every view but view 0 gets random exposure (0.6-1.6x), white balance
        (+-20 % per channel), per-channel gamma (0.65-1.5) and an S-curve (strength 0-0.5),
        drawn camera-like (:func:`sample_photometric`); the textures' albedo is in
        :data:`ALBEDO_RANGE` so exposure clips only a little;
        ``"camera-hard"``: the same model drawn uniformly over
        :data:`~o3d_seqcc.evaluation.photometric.HARD_CHANGE_RANGES` (exposure 0.65-1.42, gamma 0.67-1.43
        independently per channel, S-curve 0-0.6; :func:`~o3d_seqcc.evaluation.photometric.sample_camera_change`);
        ``"none"``: the images are the ground-truth renders.
    overwrite : bool, default False
        Replace an existing ``out_dir`` that holds an earlier output of o3d_seqcc (a folder
        with files o3d_seqcc did not write is never replaced). The folder is written as a
        whole (:func:`o3d_seqcc.io.output.output_folder`: staged beside it, then swapped in).
    cell_size : float, default 0.06
        Edge length (metres) of the square cells (two triangles each) tessellating walls, floor
        and furniture (ceiling 3x coarser): 0.06 gives about 46k faces; larger is coarser
        (fewer vertex mappings per pair).
    layout : {"ring", "two-rings"}, default "ring"
        Camera layout (:func:`~o3d_seqcc.synthetic.room.sample_cameras`): one ring looking slightly
        down, or alternate cameras looking up and down (floor, ceiling and walls all seen).
    seen_only : bool, default False
        Keep only the faces some camera sees (hit by at least one pixel ray), as a reconstructed
        mesh only holds what was captured; the backs of furniture and hidden corners go.
    origin : (3,) float, default (0, 0, 0)
        Where the room's corner is in world coordinates, e.g. ``(5e5, 4e6, 100)`` for UTM-like
        coordinates: the room is rendered at the world origin (the same images for every
        ``origin``), then the mesh (double-precision PLY), the cameras and ``points/`` (float64
        then) are moved there.

    Returns
    -------
    SyntheticScene

    Raises
    ------
    InputError
        ``out_dir`` is a file or non-empty without ``overwrite``; invalid sizes or mode.

    Examples
    --------
    >>> import tempfile, o3d_seqcc as sc
    >>> room = sc.make_synthetic_scene(tempfile.mkdtemp() + '/room', n_views=3, width=96, height=72, seed=1,
    ...                                seen_only=True)
    >>> sorted(p.name for p in room.root.iterdir() if p.is_dir())
    ['depth', 'face_ids', 'gt', 'images', 'points']
    >>> len(room.scene.views)
    3
    """
    out_dir = Path(out_dir)
    if photometric not in PHOTOMETRIC_MODES:
        raise InputError(f"unknown photometric={photometric!r}; valid: {', '.join(PHOTOMETRIC_MODES)}")
    for nm, val, lo in (("n_views", n_views, 1), ("width", width, 8), ("height", height, 8)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < lo:
            raise InputError(f"{nm} must be an integer >= {lo}, got {val!r}")
    if not (isinstance(cell_size, (int, float, np.floating)) and 0.01 <= float(cell_size) <= 1.0):
        raise InputError(f"cell_size must be a number of metres in [0.01, 1], got {cell_size!r}")
    try:
        shift = np.asarray(origin, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise InputError(f"origin must be three numbers (metres), got {origin!r}") from None
    if not np.all(np.isfinite(shift)):
        raise InputError(f"origin must be three finite numbers (metres), got {origin!r}")
    if n_views > 100:
        raise InputError(f"n_views must be <= 100 (names are v00..v99), got {n_views}")
    if int(width) * int(height) > raster_checks.MAX_IMAGE_PIXELS:
        raise InputError(f"width x height = {int(width) * int(height)} pixels, over the limit of "
                         f"{raster_checks.MAX_IMAGE_PIXELS} pixels (--max-image-pixels); choose smaller images")
    check_output(out_dir, overwrite=overwrite)  # before the work: never into a file or over files not ours
    import open3d as o3d

    n_views, width, height = int(n_views), int(width), int(height)
    rng = np.random.default_rng(seed)
    geom = build_geometry(float(cell_size))
    rc = o3d.t.geometry.RaycastingScene(nthreads=0)
    rc.add_triangles(o3d.core.Tensor(geom.vertices.astype(np.float32)), o3d.core.Tensor(geom.faces.astype(np.uint32)))

    f = 0.8 * width
    K = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
    cams = sample_cameras(rng, n_views, layout=layout)
    draw = {
        "camera": sample_photometric,
        "camera-hard": lambda r: sample_camera_change(r, **HARD_CHANGE_RANGES),
        "none": lambda r: identity_photometric(),
    }[photometric]
    params = [identity_photometric()] + [draw(rng) for _ in range(n_views - 1)]
    names = [f"v{i:02d}" for i in range(n_views)]
    extrinsics = [look_extrinsic(c, yaw, pitch, roll) for c, yaw, pitch, roll in cams]
    renders = [render_view(rc, geom, K, ext, width, height) for ext in extrinsics]
    if seen_only:
        seen = np.zeros(len(geom.faces), dtype=bool)
        for face, *_ in renders:
            seen[face[face >= 0]] = True
        geom, face_map = keep_faces(geom, seen)
        renders = [(np.where(face >= 0, face_map[np.maximum(face, 0)], -1).astype(np.int32), *rest)
                   for face, *rest in renders]
    if shift.any():  # rendered at the origin, then moved: the images do not depend on origin
        geom = replace(geom, vertices=geom.vertices + shift)
        extrinsics = [_moved(E, shift) for E in extrinsics]
        cams = [(c + shift, yaw, pitch, roll) for c, yaw, pitch, roll in cams]
        renders = [(face, pts.astype(np.float64) + shift, *rest) for face, pts, *rest in renders]
    with output_folder(out_dir, overwrite=overwrite, command="synthetic") as stage:  # written as a whole
        mesh_path = _write_mesh(stage / "mesh.ply", geom)
        views, gt_paths, fid_paths, pt_paths, transforms, per_view = [], {}, {}, {}, {}, []
        for name, (c, yaw, pitch, roll), ext, (face, pts, depth, gt), prm in zip(names, cams, extrinsics, renders, params):
            img = gt if photometric == "none" or name == names[0] else img_as_dtype(apply_photometric(gt, prm), np.uint8)
            gt_paths[name] = write_image(stage / "gt" / f"{name}.png", gt)
            img_path = write_image(stage / "images" / f"{name}.png", img)
            depth_path = _write_depth(stage / "depth" / f"{name}.png", depth, 1000.0)
            fid_paths[name] = _save_npy(stage / "face_ids" / f"{name}.npy", face)
            pt_paths[name] = _save_npy(stage / "points" / f"{name}.npy", pts)
            transforms[name] = prm
            hit = face >= 0
            if not hit.all():
                logger.warning("synthetic view %s: %d pixels hit nothing", name, int((~hit).sum()))
            groups_seen = sorted(g for g, (a, b) in geom.groups.items() if np.any((face >= a) & (face < b)))
            per_view.append(
                {
                    "name": name,
                    "center": c.tolist(),
                    "yaw_deg": float(np.rad2deg(yaw)),
                    "pitch_deg": float(np.rad2deg(pitch)),
                    "roll_deg": float(np.rad2deg(roll)),
                    "photometric": prm,
                    "groups_seen": groups_seen,
                    "mean_abs_diff": float(np.abs(img.astype(np.float64) - gt).mean()),
                }
            )
            views.append(
                View(name=name, image=img_path, intrinsic=K, extrinsic=ext, width=width, height=height, depth=depth_path, depth_scale=1000.0)
            )
        scene = Scene(mesh=mesh_path, views=tuple(views))
        save_scene(scene, stage / "scene.json")
        meta = {
            "format": SYNTHETIC_FORMAT,
            "seed": int(seed),
            "n_views": n_views,
            "width": width,
            "height": height,
            "photometric": photometric,
            "cell_size": float(cell_size),
            "layout": layout,
            "seen_only": bool(seen_only),
            "origin": shift.tolist(),
            "room": list(ROOM),
            "n_faces": int(len(geom.faces)),
            "n_vertices": int(len(geom.vertices)),
            "face_groups": {k: list(v) for k, v in geom.groups.items()},
            "surfaces": [{"name": s.name, "group": s.group, "tiles": list(s.tiles), "textures": list(s.textures)} for s in geom.surfaces],
            "photometric_model": "y = (1-s)*x' + s*x'^2*(3-2x'), x' = clip(x*gain*wb[c], 0, 1)**gamma[c]; uint8 = round(255*y)",
            "views": per_view,
        }
        write_json(stage / "synthetic.json", meta)
    logger.info("synthetic scene: %d views %dx%d, %d faces -> %s", n_views, width, height, len(geom.faces), out_dir)
    return load_synthetic(out_dir)


def load_synthetic(out_dir: str | os.PathLike) -> SyntheticScene:
    """Reopen a folder written by :func:`make_synthetic_scene`.

    Raises
    ------
    InputError
        Not a synthetic scene folder (no ``synthetic.json`` / ``scene.json``) or files missing.
    """
    out_dir = Path(out_dir)
    meta_path = out_dir / "synthetic.json"
    if not meta_path.is_file():
        raise InputError(f"{out_dir} is not a synthetic scene folder (no synthetic.json); generate one with make_synthetic_scene")
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise InputError(f"{meta_path}: not valid JSON ({e}); regenerate the scene") from None
    if meta.get("format") != SYNTHETIC_FORMAT:
        raise InputError(f"{meta_path}: unknown format {meta.get('format')!r}, expected {SYNTHETIC_FORMAT!r}; regenerate the scene")
    scene = load_scene(out_dir / "scene.json")
    paths: dict[str, dict[str, Path]] = {"gt": {}, "face_ids": {}, "points": {}}
    for name in scene.names:
        for sub in paths:
            p = out_dir / sub / f"{name}{_SUBDIRS[sub]}"
            if not p.is_file():
                raise InputError(f"synthetic scene {out_dir}: missing {p}; regenerate the scene (overwrite=True)")
            paths[sub][name] = p
    transforms = {v["name"]: v["photometric"] for v in meta["views"]}
    return SyntheticScene(
        scene=scene,
        gt_images=paths["gt"],
        transforms=transforms,
        face_ids=paths["face_ids"],
        points=paths["points"],
        root=out_dir,
        face_groups={k: (int(a), int(b)) for k, (a, b) in meta["face_groups"].items()},
        metadata=meta,
    )


def perturb_poses(scene: Scene, degrees: float, *, seed: int = 0, keep: tuple[int, ...] = (0,)) -> Scene:
    """The scene with every camera rotated about its own centre by ``degrees`` (registration error).

    Simulates the colour / geometry registration error of real captures (fountain: 2-17 px):
    each view's extrinsic ``[R | t]`` becomes ``[Q R | Q t]`` with ``Q`` a rotation by exactly
    ``degrees`` about a random axis (seeded), so the camera centre stays put and the image of the
    mesh shifts by about ``fx * radians(degrees)`` pixels. The images and depth maps are not
    touched: mappings computed from the returned scene pair slightly wrong pixels, as on real
    data, while the ground truth of :func:`make_synthetic_scene` stays valid for scoring.

    Parameters
    ----------
    scene : Scene
    degrees : float
        Rotation angle (>= 0) applied to every view not in ``keep``.
    seed : int, default 0
        Seed of the random axes (``np.random.default_rng``).
    keep : tuple of int, default (0,)
        Indices of views left exact (e.g. the reference).

    Returns
    -------
    Scene
        A new scene; ``scene`` is not modified.
    """
    import dataclasses

    if not np.isfinite(degrees) or degrees < 0:
        raise ValueError(f"degrees must be a finite angle >= 0, got {degrees!r}")
    rng = np.random.default_rng(seed)
    a = np.deg2rad(float(degrees))
    views = []
    for i, v in enumerate(scene.views):
        axis = rng.normal(size=3)
        if i in keep or a == 0:
            views.append(v)
            continue
        axis /= np.linalg.norm(axis)
        k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
        q = np.eye(3) + np.sin(a) * k + (1.0 - np.cos(a)) * (k @ k)
        e = np.array(v.extrinsic, dtype=np.float64)
        e[:3, :3] = q @ e[:3, :3]
        e[:3, 3] = q @ e[:3, 3]
        views.append(dataclasses.replace(v, extrinsic=e))
    return dataclasses.replace(scene, views=tuple(views))
