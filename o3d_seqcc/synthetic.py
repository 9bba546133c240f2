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
import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ._io import atomic_path, atomic_write_bytes, read_image, write_image, write_json
from .errors import InputError
from .scene import Scene, View, load_scene, save_scene

__all__ = [
    "ALBEDO_RANGE",
    "DEFAULT_CELL_SIZE",
    "PHOTOMETRIC_MODES",
    "SYNTHETIC_FORMAT",
    "SyntheticScene",
    "apply_photometric",
    "identity_photometric",
    "load_synthetic",
    "make_synthetic_scene",
    "perturb_poses",
    "ring_slots",
    "sample_photometric",
]

logger = logging.getLogger(__name__)

SYNTHETIC_FORMAT = "o3d_seqcc.synthetic/1"
#: Valid values of ``photometric``.
PHOTOMETRIC_MODES = ("none", "camera")

# room size (metres): x, y, z (z up)
ROOM = (5.0, 4.0, 2.6)
#: Default tessellation cell size (metres): about 1.5k mesh vertices per 320x240 view, so that
#: consecutive views share several hundred vertices (the paper's t_npm = 400).
DEFAULT_CELL_SIZE = 0.06
# the ceiling is rarely seen: coarser
_CELL_FACTOR = {"room_z+": 3.0}
# furniture: name -> (min corner, max corner)
_FURNITURE: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "table": ((0.6, 0.6, 0.0), (1.8, 1.4, 0.75)),
    "cabinet": ((3.7, 2.75, 0.0), (4.3, 3.25, 2.0)),
    "sideboard": ((0.8, 3.3, 0.0), (2.2, 3.7, 0.9)),
}
#: Photos bundled with scikit-image (no download) used as textures: bright, dark, saturated.
TEXTURES = (
    "astronaut",
    "coffee",
    "chelsea",
    "rocket",
    "immunohistochemistry",
    "hubble_deep_field",
    "retina",
    "stereo_motorcycle",
)
# each surface is a mosaic of photos, tiles of about this size (metres)
_TILE = 1.2
# camera ring (centre x, y; radii x, y)
_RING = (2.5, 2.0, 0.4, 0.3)
# yaw step between ring neighbours: a full ring (360 / n_views) when n_views * 30 deg >= 360,
# otherwise an arc of 25 deg steps centred on view 0. The horizontal field of view is
# 2 atan(0.5 / 0.8) = 64 deg, so neighbours 25-30 deg apart share about half of the image and
# views two steps apart little or nothing: the colour-correction graph is a connected ring or
# chain, not complete.
_MAX_STEP = np.deg2rad(30.0)
_ARC_STEP = np.deg2rad(25.0)
#: Albedo range of the textures: photos are scaled linearly from [0, 1] into [lo, hi]. Real
#: surfaces rarely reflect more than ~80 % or less than ~3 %, so an exposure of up to 1.6x
#: (what a camera's auto-exposure allows) clips only the brightest patches, as in real photos.
ALBEDO_RANGE = (0.03, 0.8)
_MAX_TEXTURE_SIDE = 512


# --------------------------------------------------------------------------------------------
# result
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# photometry (pure functions)
# --------------------------------------------------------------------------------------------


def identity_photometric() -> dict[str, Any]:
    """Parameters of the identity photometric change (what view 0 gets)."""
    return {"gain": 1.0, "white_balance": [1.0, 1.0, 1.0], "gamma": [1.0, 1.0, 1.0], "s_curve": 0.0}


def sample_photometric(rng: np.random.Generator) -> dict[str, Any]:
    """Draw random camera-like photometric parameters.

    Every parameter spans the documented range, but like a camera's auto exposure and tone
    curve most draws are moderate: log exposure and the view's log tone-curve gamma, and the white-balance factors, are drawn
    from triangular distributions peaking at 1 (the identity) over the full range; the channels'
    gammas are that gamma times a small per-channel factor (log-normal, sigma 0.06, clipped to
    the range), so the colour cast comes mostly from the white balance, as in a camera.

    Parameters
    ----------
    rng : numpy.random.Generator

    Returns
    -------
    dict
        ``gain`` exposure factor in [0.6, 1.6]; ``white_balance`` three per-channel factors in
        [0.8, 1.2] (triangular, peak 1); ``gamma`` three per-channel exponents in [0.65, 1.5];
        ``s_curve`` strength in [0, 0.5] (uniform).
    """
    gain = float(np.exp(rng.triangular(np.log(0.6), 0.0, np.log(1.6))))
    wb = rng.triangular(0.8, 1.0, 1.2, size=3)
    g0 = np.exp(rng.triangular(np.log(0.65), 0.0, np.log(1.5)))
    gamma = np.clip(g0 * np.exp(rng.normal(0.0, 0.06, size=3)), 0.65, 1.5)
    s = float(rng.uniform(0.0, 0.5))
    return {"gain": gain, "white_balance": wb.tolist(), "gamma": gamma.tolist(), "s_curve": s}


def apply_photometric(image: np.ndarray, params: dict[str, Any]) -> np.ndarray:
    """Apply a photometric change (the camera model of the synthetic scenes).

    ``y = (1 - s) * x' + s * smoothstep(x')`` with ``x' = clip(x * gain * wb[c], 0, 1) ** gamma[c]``
    and ``smoothstep(x) = x^2 (3 - 2x)``, channel by channel.

    Parameters
    ----------
    image : (..., 3) array
        uint8 (0-255), uint16 (0-65535) or float in [0, 1], RGB.
    params : dict
        ``gain`` (float), ``white_balance`` (3 floats), ``gamma`` (3 floats), ``s_curve`` (float),
        as from :func:`sample_photometric`.

    Returns
    -------
    numpy.ndarray
        (..., 3) float64 in [0, 1] (not quantised; the generator stores
        ``round(255 * y)`` as uint8).
    """
    x = np.asarray(image)
    if x.dtype == np.uint8:
        x = x.astype(np.float64) / 255.0
    elif x.dtype == np.uint16:
        x = x.astype(np.float64) / 65535.0
    else:
        x = x.astype(np.float64)
    if x.shape[-1] != 3:
        raise ValueError(f"apply_photometric expects (..., 3) RGB, got shape {x.shape}")
    gain = float(params["gain"])
    wb = np.asarray(params["white_balance"], dtype=np.float64)
    gamma = np.asarray(params["gamma"], dtype=np.float64)
    s = float(params["s_curve"])
    y = np.clip(x * (gain * wb), 0.0, 1.0) ** gamma
    return np.clip((1.0 - s) * y + s * (y * y * (3.0 - 2.0 * y)), 0.0, 1.0)


def _to_uint8(x: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(x * 255.0), 0, 255).astype(np.uint8)


# --------------------------------------------------------------------------------------------
# geometry (pure numpy)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Surface:
    """A textured rectangle: ``origin`` is its top-left corner seen from the front, ``e1`` the
    full edge to the right, ``e2`` the full edge downwards; the front normal is ``e2 x e1``.
    Its texture is a mosaic of ``tiles = (nu, nv)`` photos, ``textures[j * nu + i]`` for tile
    column i, row j, each photo stretched over its tile."""

    name: str
    group: str
    origin: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    tiles: tuple[int, int]
    textures: tuple[str, ...]


def _rect(name: str, group: str, k: int, center, normal, size_right: float, size_down: float) -> _Surface:
    n = np.asarray(normal, dtype=np.float64)
    z = np.array([0.0, 0.0, 1.0])
    right = np.cross(z, n) if abs(n[2]) < 0.5 else np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(right, n)
    e1, e2 = right * size_right, down * size_down
    origin = np.asarray(center, dtype=np.float64) - 0.5 * (e1 + e2)
    nu, nv = max(1, round(size_right / _TILE)), max(1, round(size_down / _TILE))
    # neighbouring tiles (and neighbouring surfaces) get different photos
    tex = tuple(TEXTURES[(3 * k + i + 2 * j) % len(TEXTURES)] for j in range(nv) for i in range(nu))
    return _Surface(name, group, origin, e1, e2, (nu, nv), tex)


def _box_sides(name: str, lo, hi, k0: int, *, inward: bool, bottom: bool) -> list[_Surface]:
    """The sides +x, -x, +y, -y, +z (and -z) of an axis-aligned box; ``k0`` numbers the first."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    c, size = 0.5 * (lo + hi), hi - lo
    out = []
    sides = [(0, +1), (0, -1), (1, +1), (1, -1), (2, +1)] + ([(2, -1)] if bottom else [])
    for k, (axis, sign) in enumerate(sides):
        center = c.copy()
        center[axis] = hi[axis] if sign > 0 else lo[axis]
        normal = np.zeros(3)
        normal[axis] = -sign if inward else sign
        if axis == 2:
            sr, sd = size[0], size[1]
        else:
            sr, sd = size[1 - axis], size[2]
        out.append(_rect(f"{name}_{'xyz'[axis]}{'+' if sign > 0 else '-'}", name, k0 + k, center, normal, sr, sd))
    return out


def _surfaces() -> list[_Surface]:
    # the room shell: sides of a box seen from inside, then the furniture
    out = _box_sides("room", (0.0, 0.0, 0.0), ROOM, 0, inward=True, bottom=True)
    for name, (lo, hi) in _FURNITURE.items():
        out += _box_sides(name, lo, hi, len(out), inward=False, bottom=False)
    return out


def _tessellate(s: _Surface, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Grid of a rectangle: vertices (N, 3) and faces (F, 3) whose normals point along e2 x e1."""
    nu = max(1, int(np.ceil(np.linalg.norm(s.e1) / cell - 1e-9)))
    nv = max(1, int(np.ceil(np.linalg.norm(s.e2) / cell - 1e-9)))
    a = np.linspace(0.0, 1.0, nu + 1)
    b = np.linspace(0.0, 1.0, nv + 1)
    A, B = np.meshgrid(a, b, indexing="xy")  # (nv+1, nu+1)
    verts = s.origin + A.reshape(-1, 1) * s.e1 + B.reshape(-1, 1) * s.e2
    idx = np.arange((nu + 1) * (nv + 1)).reshape(nv + 1, nu + 1)
    p00, p10 = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    p01, p11 = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    # reversed winding of (right, down) so that the normal is e2 x e1 (the front normal)
    faces = np.concatenate([np.stack([p00, p11, p10], 1), np.stack([p00, p01, p11], 1)])
    return verts, faces


@dataclass(frozen=True)
class _Geometry:
    vertices: np.ndarray  # (N, 3) float64
    faces: np.ndarray  # (F, 3) int64
    normals: np.ndarray  # (N, 3) float64
    face_surface: np.ndarray  # (F,) int64 index into surfaces
    surfaces: tuple[_Surface, ...]
    groups: dict[str, tuple[int, int]]


def _build_geometry(cell: float = DEFAULT_CELL_SIZE) -> _Geometry:
    surfaces = _surfaces()
    verts, faces, normals, fsurf = [], [], [], []
    groups: dict[str, list[int]] = {}
    nv = nf = 0
    for k, s in enumerate(surfaces):
        v, f = _tessellate(s, cell * _CELL_FACTOR.get(s.name, 1.0))
        n = np.cross(s.e2, s.e1)
        n /= np.linalg.norm(n)
        verts.append(v)
        faces.append(f + nv)
        normals.append(np.broadcast_to(n, v.shape))
        fsurf.append(np.full(len(f), k, dtype=np.int64))
        g = groups.setdefault(s.group, [nf, nf])
        if g[1] != nf:
            raise AssertionError("surfaces of a group must be contiguous")
        g[1] = nf + len(f)
        nv += len(v)
        nf += len(f)
    return _Geometry(
        vertices=np.concatenate(verts),
        faces=np.concatenate(faces).astype(np.int64),
        normals=np.concatenate(normals).astype(np.float64),
        face_surface=np.concatenate(fsurf),
        surfaces=tuple(surfaces),
        groups={k: (int(a), int(b)) for k, (a, b) in groups.items()},
    )


# --------------------------------------------------------------------------------------------
# textures
# --------------------------------------------------------------------------------------------


@lru_cache(maxsize=None)
def _texture(name: str) -> np.ndarray:
    """A photo bundled with scikit-image as (H, W, 3) float32 albedo in :data:`ALBEDO_RANGE` (longest side <= 512)."""
    import cv2
    import skimage.data

    img = getattr(skimage.data, name)()
    if isinstance(img, tuple):  # stereo_motorcycle -> (left, right, disparity)
        img = img[0]
    img = np.asarray(img)[..., :3]
    h, w = img.shape[:2]
    scale = _MAX_TEXTURE_SIDE / max(h, w)
    if scale < 1:
        img = cv2.resize(img, (round(w * scale), round(h * scale)), interpolation=cv2.INTER_AREA)
    lo, hi = ALBEDO_RANGE
    out = (lo + (hi - lo) * (img.astype(np.float32) / 255.0)).astype(np.float32)
    out.setflags(write=False)
    return out


def _bilinear(tex: np.ndarray, s: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Sample ``tex`` at normalised coordinates (s, t) in [0, 1] (0 = left/top edge)."""
    h, w = tex.shape[:2]
    x = np.clip(s * w - 0.5, 0.0, w - 1.0)
    y = np.clip(t * h - 0.5, 0.0, h - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), w - 2 if w > 1 else 0)
    y0 = np.minimum(np.floor(y).astype(np.int64), h - 2 if h > 1 else 0)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    top = tex[y0, x0] * (1 - fx) + tex[y0, x1] * fx
    bot = tex[y1, x0] * (1 - fx) + tex[y1, x1] * fx
    return top * (1 - fy) + bot * fy


def _albedo(geom: _Geometry, points: np.ndarray, face_ids: np.ndarray) -> np.ndarray:
    """Surface colour of world points on given faces: (n, 3) float64 in [0, 1]."""
    out = np.zeros((len(points), 3), dtype=np.float64)
    surf = geom.face_surface[face_ids]
    for k in np.unique(surf):
        s = geom.surfaces[k]
        sel = surf == k
        d = points[sel] - s.origin
        nu, nv = s.tiles
        u = np.clip(d @ s.e1 / (s.e1 @ s.e1), 0.0, 1.0) * nu
        v = np.clip(d @ s.e2 / (s.e2 @ s.e2), 0.0, 1.0) * nv
        iu = np.minimum(u.astype(np.int64), nu - 1)
        iv = np.minimum(v.astype(np.int64), nv - 1)
        tile = iv * nu + iu
        rows = np.flatnonzero(sel)
        for ti in np.unique(tile):
            m = tile == ti
            out[rows[m]] = _bilinear(_texture(s.textures[ti]), u[m] - iu[m], v[m] - iv[m])
    return out


# --------------------------------------------------------------------------------------------
# cameras and rendering
# --------------------------------------------------------------------------------------------


def _look_extrinsic(center: np.ndarray, yaw: float, pitch: float, roll: float) -> np.ndarray:
    """World-to-camera (OpenCV axes) of a camera at ``center`` with yaw/pitch/roll (radians, z up)."""
    f = np.array([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)])
    right = np.cross(f, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(f, right)
    cr, sr = np.cos(roll), np.sin(roll)
    right, down = cr * right + sr * down, -sr * right + cr * down
    R = np.stack([right, down, f])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = -R @ center
    return T


def ring_slots(n_views: int) -> np.ndarray:
    """Ring position (in steps from view 0) of each view: ``0, 1, ..., n//2, -(n - n//2 - 1), ..., -1``.

    View ``i`` sits ``i`` steps counter-clockwise of view 0 for ``i <= n // 2`` and ``n - i``
    steps clockwise otherwise, so view 0 (the unchanged reference) is in the middle of the chain
    and cyclically consecutive indices are ring neighbours; with ``n * step = 360`` deg the two
    halves close into a full ring.
    """
    i = np.arange(int(n_views))
    return np.where(i <= n_views // 2, i, i - n_views)


def _sample_cameras(rng: np.random.Generator, n_views: int) -> list[tuple[np.ndarray, float, float, float]]:
    """Camera centres and angles on a jittered ring inside the room, looking outwards.

    Neighbours are ``360 / n_views`` deg apart when that is at most 30 (12 or more views: a
    full ring), else 25 deg (an arc); view 0 is in the middle of the chain (:func:`ring_slots`).
    """
    cx, cy, rx, ry = _RING
    step = 2 * np.pi / n_views if 2 * np.pi / n_views <= _MAX_STEP + 1e-9 else _ARC_STEP
    slots = ring_slots(n_views)
    out = []
    for i in range(n_views):
        theta = slots[i] * step + rng.uniform(-0.1, 0.1) * step
        c = np.array(
            [
                cx + rx * np.cos(theta) + rng.uniform(-0.05, 0.05),
                cy + ry * np.sin(theta) + rng.uniform(-0.05, 0.05),
                rng.uniform(1.2, 1.7),
            ]
        )
        yaw = theta + np.deg2rad(rng.uniform(-4.0, 4.0))
        pitch = np.deg2rad(rng.uniform(-18.0, -6.0))
        roll = np.deg2rad(rng.uniform(-3.0, 3.0))
        out.append((c, float(yaw), float(pitch), float(roll)))
    return out


def _pixel_rays(K: np.ndarray, extrinsic: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Origin (3,) and (H*W, 3) world directions with camera-frame z = 1 (pixel centres at integers)."""
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    d_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1).reshape(-1, 3)
    R, t = extrinsic[:3, :3], extrinsic[:3, 3]
    return -R.T @ t, d_cam @ R


def _render(rc, geom: _Geometry, K, extrinsic, width: int, height: int):
    """Ray cast one view: face ids (H, W) int32, points (H, W, 3) float32, z-depth (H, W) float64, gt (H, W, 3) uint8."""
    import open3d as o3d

    origin, dirs = _pixel_rays(K, extrinsic, width, height)
    rays = np.concatenate([np.broadcast_to(origin, dirs.shape), dirs], 1).astype(np.float32)
    ans = rc.cast_rays(o3d.core.Tensor(rays))
    t_hit = ans["t_hit"].numpy().astype(np.float64)
    prim = ans["primitive_ids"].numpy().astype(np.int64)
    hit = np.isfinite(t_hit) & (prim != o3d.t.geometry.RaycastingScene.INVALID_ID) & (prim < len(geom.faces))
    face = np.where(hit, prim, -1)
    pts = np.full((len(dirs), 3), np.nan)
    # the point on the hit face's plane along the exact (float64) ray: consistent with the camera
    fh = face[hit]
    v0 = geom.vertices[geom.faces[fh, 0]]
    n = geom.normals[geom.faces[fh, 0]]
    d = dirs[hit]
    denom = np.einsum("ij,ij->i", d, n)
    t_plane = np.einsum("ij,ij->i", v0 - origin, n) / np.where(np.abs(denom) > 1e-12, denom, 1e-12)
    t = np.where(np.abs(denom) > 1e-12, t_plane, t_hit[hit])
    pts[hit] = origin + t[:, None] * d
    depth = np.zeros(len(dirs))
    depth[hit] = t  # camera-frame z of the direction is 1
    color = np.zeros((len(dirs), 3))
    color[hit] = _albedo(geom, pts[hit], fh)
    return (
        face.reshape(height, width).astype(np.int32),
        pts.reshape(height, width, 3).astype(np.float32),
        depth.reshape(height, width),
        _to_uint8(color.reshape(height, width, 3)),
    )


# --------------------------------------------------------------------------------------------
# file output
# --------------------------------------------------------------------------------------------


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


def _write_mesh(path: Path, geom: _Geometry) -> Path:
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
_VIEW_FILE = re.compile(r"^v\d+\.(png|npy)$")


def _remove_stale(out_dir: Path, names: set[str]) -> None:
    """Delete view files of an earlier generation that the new one does not have (overwrite)."""
    for sub, ext in _SUBDIRS.items():
        d = out_dir / sub
        if not d.is_dir():
            continue
        for p in d.iterdir():
            if p.is_file() and _VIEW_FILE.match(p.name) and p.stem not in names:
                p.unlink()


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------


def make_synthetic_scene(
    out_dir: str | os.PathLike,
    *,
    n_views: int = 12,
    width: int = 320,
    height: int = 240,
    seed: int = 0,
    photometric: str = "camera",
    overwrite: bool = False,
    cell_size: float = DEFAULT_CELL_SIZE,
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
    photometric : {"camera", "none"}, default "camera"
        ``"camera"``: every view but view 0 gets random exposure (0.6-1.6x), white balance
        (+-20 % per channel), per-channel gamma (0.65-1.5) and an S-curve (strength 0-0.5),
        drawn camera-like (:func:`sample_photometric`); the textures' albedo is in
        :data:`ALBEDO_RANGE` so exposure clips only a little;
        ``"none"``: the images are the ground-truth renders.
    overwrite : bool, default False
        Allow writing into a non-empty ``out_dir`` (files of earlier views are replaced,
        view files the new scene does not have are removed; nothing else is touched).
    cell_size : float, default 0.06
        Edge length (metres) of the square cells (two triangles each) tessellating walls, floor
        and furniture (ceiling 3x coarser): 0.06 gives about 46k faces; larger is coarser
        (fewer vertex mappings per pair).

    Returns
    -------
    SyntheticScene

    Raises
    ------
    InputError
        ``out_dir`` is a file or non-empty without ``overwrite``; invalid sizes or mode.
    """
    out_dir = Path(out_dir)
    if photometric not in PHOTOMETRIC_MODES:
        raise InputError(f"unknown photometric={photometric!r}; valid: {', '.join(PHOTOMETRIC_MODES)}")
    for nm, val, lo in (("n_views", n_views, 1), ("width", width, 8), ("height", height, 8)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < lo:
            raise InputError(f"{nm} must be an integer >= {lo}, got {val!r}")
    if not (isinstance(cell_size, (int, float, np.floating)) and 0.01 <= float(cell_size) <= 1.0):
        raise InputError(f"cell_size must be a number of metres in [0.01, 1], got {cell_size!r}")
    if n_views > 100:
        raise InputError(f"n_views must be <= 100 (names are v00..v99), got {n_views}")
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"output folder {out_dir} is a file; give a folder path")
    if out_dir.is_dir() and any(out_dir.iterdir()) and not overwrite:
        raise InputError(f"output folder {out_dir} is not empty; choose another folder or pass overwrite=True (--overwrite)")
    import open3d as o3d

    n_views, width, height = int(n_views), int(width), int(height)
    rng = np.random.default_rng(seed)
    geom = _build_geometry(float(cell_size))
    out_dir.mkdir(parents=True, exist_ok=True)
    mesh_path = _write_mesh(out_dir / "mesh.ply", geom)

    rc = o3d.t.geometry.RaycastingScene(nthreads=0)
    rc.add_triangles(o3d.core.Tensor(geom.vertices.astype(np.float32)), o3d.core.Tensor(geom.faces.astype(np.uint32)))

    f = 0.8 * width
    K = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
    cams = _sample_cameras(rng, n_views)
    params = [identity_photometric()] + [
        sample_photometric(rng) if photometric == "camera" else identity_photometric() for _ in range(n_views - 1)
    ]
    names = [f"v{i:02d}" for i in range(n_views)]
    _remove_stale(out_dir, set(names))
    views, gt_paths, fid_paths, pt_paths, transforms, per_view = [], {}, {}, {}, {}, []
    for name, (c, yaw, pitch, roll), prm in zip(names, cams, params):
        ext = _look_extrinsic(c, yaw, pitch, roll)
        face, pts, depth, gt = _render(rc, geom, K, ext, width, height)
        img = gt if photometric == "none" or name == names[0] else _to_uint8(apply_photometric(gt, prm))
        gt_paths[name] = write_image(out_dir / "gt" / f"{name}.png", gt)
        img_path = write_image(out_dir / "images" / f"{name}.png", img)
        depth_path = _write_depth(out_dir / "depth" / f"{name}.png", depth, 1000.0)
        fid_paths[name] = _save_npy(out_dir / "face_ids" / f"{name}.npy", face)
        pt_paths[name] = _save_npy(out_dir / "points" / f"{name}.npy", pts)
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
    save_scene(scene, out_dir / "scene.json")
    meta = {
        "format": SYNTHETIC_FORMAT,
        "seed": int(seed),
        "n_views": n_views,
        "width": width,
        "height": height,
        "photometric": photometric,
        "cell_size": float(cell_size),
        "room": list(ROOM),
        "n_faces": int(len(geom.faces)),
        "n_vertices": int(len(geom.vertices)),
        "face_groups": {k: list(v) for k, v in geom.groups.items()},
        "surfaces": [{"name": s.name, "group": s.group, "tiles": list(s.tiles), "textures": list(s.textures)} for s in geom.surfaces],
        "photometric_model": "y = (1-s)*x' + s*x'^2*(3-2x'), x' = clip(x*gain*wb[c], 0, 1)**gamma[c]; uint8 = round(255*y)",
        "views": per_view,
    }
    write_json(out_dir / "synthetic.json", meta)
    logger.info("synthetic scene: %d views %dx%d, %d faces -> %s", n_views, width, height, len(geom.faces), out_dir)
    return SyntheticScene(
        scene=scene,
        gt_images=gt_paths,
        transforms=transforms,
        face_ids=fid_paths,
        points=pt_paths,
        root=out_dir,
        face_groups=dict(geom.groups),
        metadata=meta,
    )


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
