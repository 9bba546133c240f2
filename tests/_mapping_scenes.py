"""Tiny scenes for the visibility / mappings tests: meshes, look-at cameras, ray-cast depth maps."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from o3d_seqcc import Scene, View, save_scene

W, H, F_PX = 80, 60, 70.0
K = np.array([[F_PX, 0.0, (W - 1) / 2], [0.0, F_PX, (H - 1) / 2], [0.0, 0.0, 1.0]])


def grid(origin, e1, e2, n1: int, n2: int) -> tuple[np.ndarray, np.ndarray]:
    """Tessellated parallelogram origin + s e1 + t e2; normal along e1 x e2."""
    origin, e1, e2 = (np.asarray(x, dtype=np.float64) for x in (origin, e1, e2))
    s, t = np.meshgrid(np.linspace(0, 1, n1 + 1), np.linspace(0, 1, n2 + 1), indexing="xy")
    v = origin + s.reshape(-1, 1) * e1 + t.reshape(-1, 1) * e2
    idx = np.arange(v.shape[0]).reshape(n2 + 1, n1 + 1)
    p00, p10, p01, p11 = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    f = np.concatenate([np.stack([p00, p10, p11], 1), np.stack([p00, p11, p01], 1)])
    return v, f


def box(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Closed box with outward normals (12 triangles)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    f = np.array(
        [
            [0, 2, 1], [1, 2, 3],  # bottom (z = lo), normal -z
            [4, 5, 6], [5, 7, 6],  # top, +z
            [0, 1, 4], [1, 5, 4],  # y = lo, -y
            [2, 6, 3], [3, 6, 7],  # y = hi, +y
            [0, 4, 2], [2, 4, 6],  # x = lo, -x
            [1, 3, 5], [3, 7, 5],  # x = hi, +x
        ]
    )
    return v, f


def merge(*parts) -> tuple[np.ndarray, np.ndarray]:
    vs, fs, off = [], [], 0
    for v, f in parts:
        vs.append(v)
        fs.append(f + off)
        off += len(v)
    return np.concatenate(vs), np.concatenate(fs)


def look_at(center, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """World-to-camera extrinsic (OpenCV axes) of a camera at ``center`` looking at ``target``."""
    C = np.asarray(center, float)
    z = np.asarray(target, float) - C
    z /= np.linalg.norm(z)
    x = np.cross(-np.asarray(up, float), z)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    E = np.eye(4)
    E[:3, :3] = np.stack([x, y, z])
    E[:3, 3] = -E[:3, :3] @ C
    return E


def write_mesh(path: Path, v: np.ndarray, f: np.ndarray, *, normals: bool = True) -> Path:
    import open3d as o3d

    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v), o3d.utility.Vector3iVector(f.astype(np.int32)))
    if normals:
        m.compute_vertex_normals()
    o3d.io.write_triangle_mesh(str(path), m, write_vertex_normals=normals)
    return path


def render_depth(v: np.ndarray, f: np.ndarray, E: np.ndarray, K_: np.ndarray = K, w: int = W, h: int = H) -> np.ndarray:
    """(h, w) float64 camera z of the mesh per pixel (0 = no hit), by ray casting pixel centres."""
    import open3d as o3d
    import open3d.core as o3c

    rs = o3d.t.geometry.RaycastingScene()
    rs.add_triangles(o3c.Tensor(v.astype(np.float32)), o3c.Tensor(f.astype(np.uint32)))
    u, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    d_cam = np.stack([(u - K_[0, 2]) / K_[0, 0], (vv - K_[1, 2]) / K_[1, 1], np.ones_like(u)], -1).reshape(-1, 3)
    R, t = E[:3, :3], E[:3, 3]
    d = d_cam @ R  # R^T d
    C = -R.T @ t
    rays = np.concatenate([np.broadcast_to(C, d.shape), d], 1).astype(np.float32)
    th = rs.cast_rays(o3c.Tensor(rays))["t_hit"].numpy().astype(np.float64)  # = camera z (dir has z_cam = 1)
    th[~np.isfinite(th)] = 0.0
    return th.reshape(h, w)


def make_scene(
    root: Path,
    mesh: tuple[np.ndarray, np.ndarray],
    cameras: list[np.ndarray],
    *,
    depth: str | None = "map",
    depth_edit=None,
    mesh_normals: bool = True,
) -> Scene:
    """Scene with grey images, the mesh and per-view depth ("map", "cloud" or None).

    ``depth_edit(view_index, depth) -> depth`` may alter the rendered depth before saving.
    """
    root = Path(root)
    (root / "images").mkdir(parents=True, exist_ok=True)
    v, f = mesh
    mpath = write_mesh(root / "mesh.ply", v, f, normals=mesh_normals)
    views = []
    for i, E in enumerate(cameras):
        img = root / "images" / f"v{i}.png"
        cv2.imwrite(str(img), np.full((H, W, 3), 128, np.uint8))
        kw = {}
        if depth is not None:
            D = render_depth(v, f, E)
            if depth_edit is not None:
                D = depth_edit(i, D)
            if depth == "map":
                (root / "depth").mkdir(exist_ok=True)
                p = root / "depth" / f"v{i}.png"
                cv2.imwrite(str(p), np.round(D * 1000).astype(np.uint16))
                kw["depth"] = p
            else:
                import open3d as o3d

                (root / "clouds").mkdir(exist_ok=True)
                # back-project every other pixel -> a sparse partial point cloud
                u, vv = np.meshgrid(np.arange(0, W, 2, dtype=float), np.arange(0, H, 2, dtype=float))
                z = D[::2, ::2]
                ok = z > 0
                xc = np.stack([(u - K[0, 2]) / K[0, 0] * z, (vv - K[1, 2]) / K[1, 1] * z, z], -1)[ok]
                R, t = E[:3, :3], E[:3, 3]
                pw = (xc - t) @ R  # R^T (x - t)
                p = root / "clouds" / f"v{i}.ply"
                o3d.io.write_point_cloud(str(p), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pw)))
                kw["point_cloud"] = p
        views.append(View(name=f"v{i}", image=img, intrinsic=K, extrinsic=E, width=W, height=H, **kw))
    scene = Scene(mesh=mpath, views=tuple(views))
    save_scene(scene, root / "scene.json")
    return scene


def plane(n: int = 24, size: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Square on z = 0 centred at the origin, normal +z, n x n cells."""
    return grid((-size / 2, -size / 2, 0.0), (size, 0, 0), (0, size, 0), n, n)


def down_cameras() -> list[np.ndarray]:
    """Two cameras 2 m above the plane looking down at it from different sides (y axis as 'up')."""
    return [
        look_at((-0.3, 0.1, 2.0), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0)),
        look_at((0.35, -0.15, 1.8), (0.05, 0.0, 0.0), up=(0.0, 1.0, 0.0)),
    ]
