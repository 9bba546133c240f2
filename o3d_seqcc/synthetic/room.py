"""The synthetic room: geometry, textures (photos bundled with scikit-image), cameras, ray casting.

A closed room (inward-facing walls, floor and ceiling) with occluding furniture (a table, a tall
cabinet, a sideboard); every planar side is a mosaic of photos (planar projection, bilinear
sampling) with albedo in :data:`ALBEDO_RANGE`. Cameras sit on a jittered ring inside the room
and look outwards; :func:`render_view` ray-casts one view with Open3D's ``RaycastingScene``.
The rendered colour is the surface albedo only (no shading), so one surface point has exactly
the same colour in every view.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..imaging.arrays import img_as_dtype, sample_bilinear

__all__ = ["ALBEDO_RANGE", "DEFAULT_CELL_SIZE", "LAYOUTS", "ROOM", "TEXTURES", "RoomGeometry", "build_geometry",
           "keep_faces", "look_extrinsic", "render_view", "ring_slots", "sample_cameras"]

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
class RoomGeometry:
    vertices: np.ndarray  # (N, 3) float64
    faces: np.ndarray  # (F, 3) int64
    normals: np.ndarray  # (N, 3) float64
    face_surface: np.ndarray  # (F,) int64 index into surfaces
    surfaces: tuple[_Surface, ...]
    groups: dict[str, tuple[int, int]]


def build_geometry(cell: float = DEFAULT_CELL_SIZE) -> RoomGeometry:
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
    return RoomGeometry(
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


def _albedo(geom: RoomGeometry, points: np.ndarray, face_ids: np.ndarray) -> np.ndarray:
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
            tex = _texture(s.textures[ti])
            out[rows[m]] = sample_bilinear(tex, (u[m] - iu[m]) * tex.shape[1] - 0.5, (v[m] - iv[m]) * tex.shape[0] - 0.5)
    return out


# --------------------------------------------------------------------------------------------
# cameras and rendering
# --------------------------------------------------------------------------------------------


def look_extrinsic(center: np.ndarray, yaw: float, pitch: float, roll: float) -> np.ndarray:
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


#: camera layouts of :func:`sample_cameras`
LAYOUTS = ("ring", "two-rings")


def sample_cameras(
    rng: np.random.Generator, n_views: int, *, layout: str = "ring"
) -> list[tuple[np.ndarray, float, float, float]]:
    """Camera centres and angles on a jittered ring inside the room, looking outwards.

    Neighbours are ``360 / n_views`` deg apart when that is at most 30 (12 or more views: a
    full ring), else 25 deg (an arc); view 0 is in the middle of the chain (:func:`ring_slots`).
    ``layout="two-rings"``: every other camera is lower and looks up (12-22 deg) while the others
    are higher and look down (26-38 deg), so floor, ceiling and walls are all seen, as in a scan.
    """
    if layout not in LAYOUTS:
        raise ValueError(f"unknown camera layout {layout!r}; valid: {', '.join(LAYOUTS)}")
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
    if layout == "two-rings":
        for i, (c, yaw, _, roll) in enumerate(out):
            up = i % 2 == 1
            c = c.copy()
            c[2] = rng.uniform(1.0, 1.3) if up else rng.uniform(1.6, 1.9)
            pitch = np.deg2rad(rng.uniform(12.0, 22.0) if up else rng.uniform(-38.0, -26.0))
            out[i] = (c, yaw, float(pitch), roll)
    return out


def keep_faces(geom: RoomGeometry, keep: np.ndarray) -> tuple[RoomGeometry, np.ndarray]:
    """The geometry with only the faces in ``keep`` ((F,) bool) and their vertices, order kept.

    Returns the new geometry and the (F,) int64 map old face id -> new face id (-1 if dropped).
    """
    keep = np.asarray(keep, dtype=bool)
    face_map = np.full(len(geom.faces), -1, dtype=np.int64)
    face_map[keep] = np.arange(int(keep.sum()))
    faces = geom.faces[keep]
    used = np.unique(faces)
    vmap = np.full(len(geom.vertices), -1, dtype=np.int64)
    vmap[used] = np.arange(len(used))
    groups = {}
    for name, (a, b) in geom.groups.items():
        n_before, n_in = int(keep[:a].sum()), int(keep[a:b].sum())
        if n_in:
            groups[name] = (n_before, n_before + n_in)
    return RoomGeometry(vertices=geom.vertices[used], faces=vmap[faces], normals=geom.normals[used],
                        face_surface=geom.face_surface[keep], surfaces=geom.surfaces, groups=groups), face_map


def _pixel_rays(K: np.ndarray, extrinsic: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Origin (3,) and (H*W, 3) world directions with camera-frame z = 1 (pixel centres at integers)."""
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    d_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1).reshape(-1, 3)
    R, t = extrinsic[:3, :3], extrinsic[:3, 3]
    return -R.T @ t, d_cam @ R


def render_view(rc, geom: RoomGeometry, K, extrinsic, width: int, height: int):
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
        img_as_dtype(color.reshape(height, width, 3), np.uint8),
    )
