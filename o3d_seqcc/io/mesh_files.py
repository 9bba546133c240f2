"""Meshes and point clouds through the file layer (:mod:`o3d_seqcc.io`), checked before and after Open3D reads them.

Before: a regular file (no FIFO, device or folder; found without blocking), not empty, whose
PLY / OFF / STL header declares no more elements than the file can hold
(:func:`o3d_seqcc.io.headers.mesh_header_problem`: a 250-byte header declaring 2e9 vertices is
an error, not a 24 GB allocation). Open3D reads the file through the open descriptor when its
name is not UTF-8. After: vertices finite and within :data:`MAX_COORDINATE`,
face indices inside the vertex array; point-cloud points that are not are dropped with a warning.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO, Iterator

import numpy as np

from ..errors import InputError, warn
from . import headers
from .regular_files import file_size, open_regular

__all__ = ["MAX_COORDINATE", "check_mesh_file", "read_corner_uv", "read_mesh", "read_point_cloud"]

#: mesh vertices and point-cloud points beyond +-this (in the scene's units) are not a scan: a corrupt
#: value (1e300), or the wrong units; every computation on them would overflow or lose all precision
#: (a depth beyond it is missing, :func:`~o3d_seqcc.io.depth.depth_in_metres`)
MAX_COORDINATE = 1e12


@contextmanager
def _decoder_name(path: Path, f: BinaryIO) -> Iterator[str]:
    """A name under which a decoder that takes file names (Open3D) opens the file ``f`` holds open.

    The path itself when it is valid UTF-8; else an ASCII symbolic link (with the same suffix)
    to the open descriptor, so the bytes of the name never reach the decoder.
    """
    name = os.fspath(path)
    try:
        name.encode("utf-8")
        yield name
        return
    except UnicodeEncodeError:
        pass
    suffix = path.suffix.lower()
    suffix = suffix if suffix.isascii() else ""
    tmp = tempfile.mkdtemp(prefix="o3d_seqcc-read-")
    try:
        link = os.path.join(tmp, "input" + suffix)
        fd_path = f"/proc/self/fd/{f.fileno()}"
        os.symlink(fd_path if os.path.exists(fd_path) else os.path.abspath(os.fsencode(path)).decode(
            "utf-8", "surrogateescape"), link)
        yield link
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _check_geometry_header(path: Path, f: BinaryIO, what: str) -> int:
    size = file_size(f)
    if size == 0:
        raise InputError(f"{what} {path} is an empty file")
    f.seek(0)
    problem = headers.mesh_header_problem(f.read(65536), size, path.suffix.lower())
    f.seek(0)
    if problem:
        raise InputError(f"{what} {path}: {problem} (a truncated or corrupt file); export it again")
    return size


def check_mesh_file(path: str | os.PathLike, what: str = "mesh") -> Path:
    """Check a mesh file before a reader opens it by name: a regular file whose header counts fit its size."""
    path = Path(path)
    with open_regular(path, what) as f:
        _check_geometry_header(path, f, what)
    return path


def _far(path: Path, what: str, v: np.ndarray) -> None:
    a = np.abs(v)
    bad = ~((a[:, 0] <= MAX_COORDINATE) & (a[:, 1] <= MAX_COORDINATE) & (a[:, 2] <= MAX_COORDINATE))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        x = v[i]
        kind = "non-finite" if not np.all(np.isfinite(x)) else f"beyond +-{MAX_COORDINATE:.0e}"
        raise InputError(f"{what} {path} has {int(bad.sum())} vertices with {kind} coordinates (vertex {i} at "
                         f"({x[0]:.3g}, {x[1]:.3g}, {x[2]:.3g})): corrupt values, or the wrong units; clean the mesh "
                         "(remove those vertices)")


def read_mesh(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Read a triangle mesh file (any format Open3D reads), checked before and after.

    Returns
    -------
    vertices : (N, 3) float64
    faces : (F, 3) int64
    normals : (N, 3) float64 or None
        The file's vertex normals, None without them.

    Raises
    ------
    InputError
        Missing, not a regular file, empty, a header declaring more elements than the file holds,
        no triangles, vertices that are not finite or beyond :data:`MAX_COORDINATE`, face indices
        outside the vertex array.
    """
    import open3d as o3d

    path = Path(path)
    with open_regular(path, "mesh") as f:
        _check_geometry_header(path, f, "mesh")
        with _decoder_name(path, f) as name:
            mesh = o3d.io.read_triangle_mesh(name, enable_post_processing=False, print_progress=False)
    v = np.array(mesh.vertices, dtype=np.float64)
    tri = np.array(mesh.triangles, dtype=np.int64)
    if len(tri) == 0:
        raise InputError(
            f"mesh {path} has no triangles (is it a point cloud or a non-triangle mesh?); "
            "give a triangle mesh (PLY/OBJ/OFF/GLB), triangulate polygons first (MeshLab: Filters > "
            "Polygonal and Quad Mesh > Turn into a Pure-Triangular mesh)"
        )
    if not np.all(np.isfinite(v)):
        raise InputError(f"mesh {path} has non-finite vertex coordinates; clean it (remove NaN vertices)")
    _far(path, "mesh", v)
    if tri.min() < 0 or tri.max() >= len(v):
        raise InputError(f"mesh {path} has face indices outside the vertex array")
    n = np.array(mesh.vertex_normals, dtype=np.float64) if mesh.has_vertex_normals() else None
    return v, tri, n


def read_corner_uv(path: str | os.PathLike, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The texture coordinates of every face corner of a mesh file, aligned with :func:`read_mesh`'s faces.

    OBJ (``vt``), PLY with per-vertex ``s``/``t``, ``u``/``v`` or ``texture_u``/``texture_v``, glTF / GLB
    (``TEXCOORD_0``), read with trimesh (``process=False``, the file's vertex and face order) in the OBJ
    convention: origin at the bottom-left, v up (trimesh flips glTF's top-left origin).

    Parameters
    ----------
    path : path
    vertices, faces : (N, 3) float, (F, 3) int
        The mesh as :func:`read_mesh` read it (the corners are matched by position).

    Returns
    -------
    (F, 3, 2) float64

    Raises
    ------
    InputError
        No texture coordinates, or faces that do not match :func:`read_mesh`'s.
    """
    import trimesh

    path = Path(path)
    with open_regular(path, "mesh") as f:
        with _decoder_name(path, f) as name:
            try:
                t = trimesh.load(name, file_type=path.suffix.lstrip(".").lower() or None, process=False,
                                 maintain_order=True, force="mesh")
            except Exception as exc:  # noqa: BLE001 - trimesh raises many types for a file it cannot parse
                raise InputError(f"mesh {path}: its texture coordinates could not be read ({exc})") from exc
    uv = getattr(getattr(t, "visual", None), "uv", None)
    if uv is None or len(uv) != len(t.vertices):
        raise InputError(f"mesh {path} has no texture coordinates (OBJ vt, PLY s/t, GLB TEXCOORD_0): --uv keep bakes "
                         "into a mesh's own UV layout; unwrap it first (Blender: UV > Smart UV Project) or drop "
                         "--uv keep for a new atlas")
    tv, tf = np.asarray(t.vertices, dtype=np.float64), np.asarray(t.faces, dtype=np.int64)
    want = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    scale = max(float(np.abs(want).max(initial=0.0)), 1.0)
    if tf.shape != np.asarray(faces).shape or not np.allclose(tv[tf], want, rtol=0.0, atol=1e-5 * scale):
        raise InputError(f"mesh {path}: its faces as read with their texture coordinates ({len(tf)}) are not the "
                         f"{len(faces)} faces read for the geometry (polygons, or a file trimesh and Open3D read "
                         "differently): triangulate it and save it again as OBJ, PLY or GLB")
    return np.asarray(uv, dtype=np.float64)[tf]


def read_point_cloud(path: str | os.PathLike) -> np.ndarray:
    """(M, 3) float64 points of a point-cloud file (PLY, PCD, ...), checked like :func:`read_mesh`.

    Points that are not finite or lie beyond :data:`MAX_COORDINATE` are dropped with a warning
    giving their number (organised clouds mark missing points with NaN).

    Raises
    ------
    InputError
        Missing, not a regular file, a header declaring more points than the file holds, or no
        (sane) point.
    """
    import open3d as o3d

    path = Path(path)
    with open_regular(path, "point cloud") as f:
        _check_geometry_header(path, f, "point cloud")
        with _decoder_name(path, f) as name:
            pc = o3d.io.read_point_cloud(name)
    pts = np.array(pc.points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        raise InputError(f"point cloud {path} has no points (unreadable or empty file); give a PLY/PCD with points")
    ok = (np.abs(pts) <= MAX_COORDINATE).all(axis=1)
    if not ok.all():
        warn(f"point cloud {path}: {int((~ok).sum())} of {len(pts)} points are not finite or lie beyond "
             f"+-{MAX_COORDINATE:.0e}: dropped")
        pts = pts[ok]
        if not len(pts):
            raise InputError(f"point cloud {path} has no finite point; give a PLY/PCD with points")
    return pts
