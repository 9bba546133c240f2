"""The z-buffer filter (paper 3.2): test points of faces hidden from a camera by the mesh.

Any-hit ray queries with Open3D's ``RaycastingScene`` from the camera centre to every test point
(the three vertices, plus a barycentric grid about ``occlusion_spacing`` px apart for faces with
a large projection); see :func:`o3d_seqcc.visibility.compute_visibility`.
"""

from __future__ import annotations

import threading
import weakref
from typing import Any, Callable

import numpy as np

__all__ = ["bary_grid", "hand_over", "occluded_view", "take_over"]

_HANDED: list = []  # at most one (vertices ref, faces ref, origin, scene): the camera check's, for the visibility
_HANDED_LOCK = threading.Lock()


def hand_over(vertices: np.ndarray, faces: np.ndarray, origin: np.ndarray, scene: Any) -> None:
    """Keep a committed ``RaycastingScene`` of ``vertices - origin`` and ``faces`` for :func:`take_over`.

    The camera check (:mod:`o3d_seqcc.visibility.camera_checks`) builds the one the visibility
    needs (the same float32 triangles): handed over, it is not built twice. One is kept at a
    time (a newer one replaces it), and only while the arrays live.
    """
    with _HANDED_LOCK:
        _HANDED[:] = [(weakref.ref(vertices), weakref.ref(faces), np.array(origin, dtype=np.float64), scene)]


def take_over(vertices: np.ndarray, faces: np.ndarray, origin: np.ndarray) -> Any:
    """The scene :func:`hand_over` kept for these very arrays and origin (then no longer kept), else None."""
    with _HANDED_LOCK:
        if not _HANDED:
            return None
        v, f, o, scene = _HANDED[0]
        if v() is not vertices or f() is not faces or not np.array_equal(o, origin):
            return None
        _HANDED.clear()
        return scene


def bary_grid(level: int, *, interior_only: bool) -> np.ndarray:
    """(m, 3) barycentric grid points (i/L, j/L, k/L); optionally without the 3 vertices."""
    i, j = np.meshgrid(np.arange(level + 1), np.arange(level + 1), indexing="ij")
    keep = (i + j) <= level
    w = np.stack([level - i[keep] - j[keep], i[keep], j[keep]], axis=1).astype(np.float64) / level
    if interior_only:
        w = w[~(w == 1.0).any(axis=1)]
    return w


def _rays_to(C: np.ndarray, P: np.ndarray, tol: float, atol: float, origin: np.ndarray | None = None) -> np.ndarray:
    """(n, 6) float32 rays from ``C`` toward the points ``P``, scaled so that ``t = 1`` is the first
    distance that counts as "in front of the point" (``d * (1 - tol) - atol``); in the local frame
    of a ray-casting scene built minus ``origin`` (the directions in float64 before rounding).

    The distance is the sum of the squares in order (what ``np.linalg.norm(d, axis=1)`` computes),
    and the directions are rounded to float32 straight into the output: the same bits as building
    the float64 rays first, at half the passes.
    """
    d = P - C[None, :]
    sq = d * d
    dist = np.sqrt(sq[:, 0] + sq[:, 1] + sq[:, 2])
    reach = np.maximum(dist * (1.0 - tol) - atol, 0.0)
    scale = np.divide(reach, dist, out=np.zeros_like(dist), where=dist > 0)
    out = np.empty((len(d), 6), dtype=np.float32)
    out[:, :3] = C if origin is None else np.asarray(C, np.float64) - origin
    np.multiply(d, scale[:, None], out=out[:, 3:], casting="same_kind")
    return out


def _hidden(rs, rays: np.ndarray) -> np.ndarray:
    """Any-hit test of every ray on ``[0, 1]`` (in batches of 4M rays)."""
    import open3d.core as o3c

    out = np.empty(len(rays), dtype=bool)
    step = 1 << 22
    for s in range(0, len(rays), step):
        out[s : s + step] = rs.test_occlusions(o3c.Tensor(rays[s : s + step]), tnear=0.0, tfar=1.0).numpy()
    return out


def same_positions(X: np.ndarray) -> np.ndarray | None:
    """(N,) int64: for every vertex the first vertex with the very same coordinates (bit for bit), or None when
    all differ. A mesh stored with three vertices per face (UV-unwrapped exports) repeats each position about
    six times; their occlusion rays are the same rays."""
    b = np.ascontiguousarray(X, dtype=np.float64).view(np.uint64).reshape(-1, 3)
    order = np.lexsort((b[:, 2], b[:, 1], b[:, 0]))  # stable: a run's first is its smallest vertex index
    sb = b[order]
    new = np.ones(len(sb), dtype=bool)
    new[1:] = (sb[1:, 0] != sb[:-1, 0]) | (sb[1:, 1] != sb[:-1, 1]) | (sb[1:, 2] != sb[:-1, 2])
    if new.all():
        return None
    rep = np.empty(len(sb), dtype=np.int64)
    rep[order] = order[new][np.cumsum(new) - 1]
    return rep


def occluded_view(raycaster: Callable[[], Any], X: np.ndarray, faces: np.ndarray, center: np.ndarray,
                  front: np.ndarray, area: np.ndarray, opts: dict, *,
                  origin: np.ndarray | None = None, same: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Which of a view's front-facing valid faces are hidden by the mesh.

    Parameters
    ----------
    raycaster : callable
        Returns the mesh's (committed) ``open3d.t.geometry.RaycastingScene``; called only
        when there are rays to cast.
    X : (N, 3) float64
        Mesh vertices.
    faces : (F, 3) int64
    center : (3,) float64
        Camera centre.
    front : (m,) int
        Ascending ids of the faces to test.
    area : (m,) float32
        Their projected areas in px^2.
    opts : dict
        ``occlusion_tol``, ``occlusion_atol``, ``occlusion_spacing``, ``occlusion_max_level``.
    origin : (3,) float64, optional
        The ray-casting scene's local origin (it holds the mesh minus ``origin``).
    same : (N,) int64, optional
        :func:`same_positions` of ``X``: vertices at one position share their ray.

    Returns
    -------
    occluded : (m,) bool
    n_rays : int
        Test points: the vertices of the faces, then the interior points (a ray each; vertices at one
        position share theirs).
    """
    occluded = np.zeros(len(front), dtype=bool)
    if not len(front):
        return occluded, 0
    tol, atol = float(opts["occlusion_tol"]), float(opts["occlusion_atol"])
    rs = raycaster()
    # 1) the vertices of the faces
    need = np.zeros(len(X), dtype=bool)
    tri = faces[front]
    need[tri.ravel()] = True
    ids = np.flatnonzero(need)
    n_rays = len(ids)
    vh = np.zeros(len(X), dtype=bool)
    if same is None:
        vh[ids] = _hidden(rs, _rays_to(center, X[ids], tol, atol, origin))
    else:  # one ray per position, its answer for every vertex there
        first = np.zeros(len(X), dtype=bool)
        first[same[ids]] = True
        cast = np.flatnonzero(first)
        vh[cast] = _hidden(rs, _rays_to(center, X[cast], tol, atol, origin))
        vh[ids] = vh[same[ids]]
    occluded = vh[tri[:, 0]] | vh[tri[:, 1]] | vh[tri[:, 2]]
    # 2) interior points of faces with a large projection
    spacing = float(opts["occlusion_spacing"])
    if spacing > 0:
        big = np.flatnonzero(~occluded & (area > 2.0 * spacing**2))
        if len(big):
            level = np.clip(np.ceil(np.sqrt(2.0 * area[big]) / spacing), 2, opts["occlusion_max_level"]).astype(int)
            pts, own = [], []
            for L in np.unique(level):  # at most occlusion_max_level groups
                sel = big[level == L]
                w = bary_grid(int(L), interior_only=True)  # (m, 3)
                pts.append(np.einsum("mj,kjc->kmc", w, X[tri[sel]]).reshape(-1, 3))
                own.append(np.repeat(sel, len(w)))
            hid = _hidden(rs, _rays_to(center, np.concatenate(pts), tol, atol, origin))
            n_rays += len(hid)
            occluded[np.concatenate(own)[hid]] = True
    return occluded, n_rays
