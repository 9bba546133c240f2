"""The z-buffer filter (paper 3.2): test points of faces hidden from a camera by the mesh.

Any-hit ray queries with Open3D's ``RaycastingScene`` from the camera centre to every test point
(the three vertices, plus a barycentric grid about ``occlusion_spacing`` px apart for faces with
a large projection); see :func:`o3d_seqcc.visibility.compute_visibility`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["bary_grid", "occluded_faces"]


def bary_grid(level: int, *, interior_only: bool) -> np.ndarray:
    """(m, 3) barycentric grid points (i/L, j/L, k/L); optionally without the 3 vertices."""
    i, j = np.meshgrid(np.arange(level + 1), np.arange(level + 1), indexing="ij")
    keep = (i + j) <= level
    w = np.stack([level - i[keep] - j[keep], i[keep], j[keep]], axis=1).astype(np.float64) / level
    if interior_only:
        w = w[~(w == 1.0).any(axis=1)]
    return w


def occluded_faces(mesh, geom, views, areas: np.ndarray, fn_ok: np.ndarray, opts) -> tuple[np.ndarray, int]:
    """(V, F) occluded mask via any-hit ray queries; returns also the number of rays cast."""
    import open3d as o3d
    import open3d.core as o3c

    X = mesh.vertices
    faces = mesh.faces
    V, F = len(views), len(faces)
    rs = o3d.t.geometry.RaycastingScene()
    rs.add_triangles(
        o3c.Tensor(np.ascontiguousarray(X, dtype=np.float32)),
        o3c.Tensor(np.ascontiguousarray(faces, dtype=np.uint32)),
    )
    tol, atol = float(opts["occlusion_tol"]), float(opts["occlusion_atol"])

    def rays_to(C: np.ndarray, P: np.ndarray) -> np.ndarray:
        d = P - C[None, :]
        dist = np.linalg.norm(d, axis=1, keepdims=True)
        # scale so that t = 1 is the first distance that counts as "in front of the point"
        reach = np.maximum(dist * (1.0 - tol) - atol, 0.0)
        d = d * np.divide(reach, dist, out=np.zeros_like(dist), where=dist > 0)
        return np.concatenate([np.broadcast_to(C, d.shape), d], axis=1).astype(np.float32)

    def hidden(rays: list[np.ndarray]) -> np.ndarray:
        if not rays:
            return np.zeros(0, bool)
        allr = np.concatenate(rays)
        out = np.empty(len(allr), dtype=bool)
        step = 1 << 22
        for s in range(0, len(allr), step):
            out[s : s + step] = rs.test_occlusions(o3c.Tensor(allr[s : s + step]), tnear=0.0, tfar=1.0).numpy()
        return out

    # 1) vertices of the faces to test, all views in one batch
    rays, vids = [], []
    for v, view in enumerate(views):
        need = np.zeros(len(X), dtype=bool)
        need[faces[fn_ok[v]].ravel()] = True
        ids = np.flatnonzero(need)
        vids.append(ids)
        rays.append(rays_to(view.center, X[ids]))
    hid = hidden(rays)
    n_rays = len(hid)
    occluded = np.zeros((V, F), dtype=bool)
    off = 0
    for v in range(V):
        ids = vids[v]
        vh = np.zeros(len(X), dtype=bool)
        vh[ids] = hid[off : off + len(ids)]
        off += len(ids)
        occluded[v] = fn_ok[v] & geom.any3(vh)
    # 2) interior points of faces with a large projection
    spacing = float(opts["occlusion_spacing"])
    if spacing > 0:
        rays, owners = [], []
        for v, view in enumerate(views):
            area = areas[v]
            big = np.flatnonzero(fn_ok[v] & ~occluded[v] & (area > 2.0 * spacing**2))
            if not len(big):
                owners.append((v, big, None))
                continue
            level = np.clip(np.ceil(np.sqrt(2.0 * area[big]) / spacing), 2, opts["occlusion_max_level"]).astype(int)
            pts, own = [], []
            for L in np.unique(level):  # at most occlusion_max_level groups
                sel = big[level == L]
                w = bary_grid(int(L), interior_only=True)  # (m, 3)
                tri = X[faces[sel]]  # (k, 3, 3)
                pts.append(np.einsum("mj,kjc->kmc", w, tri).reshape(-1, 3))
                own.append(np.repeat(sel, len(w)))
            P = np.concatenate(pts)
            owners.append((v, np.concatenate(own), None))
            rays.append(rays_to(view.center, P))
        hid = hidden(rays)
        n_rays += len(hid)
        off = 0
        for v, own, _ in owners:
            h = hid[off : off + len(own)]
            off += len(own)
            occluded[v, own[h]] = True
    return occluded, n_rays
