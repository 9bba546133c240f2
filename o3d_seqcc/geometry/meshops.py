"""Mesh helpers every stage shares: vertex welding, edge topology, face adjacency, normals.

Plain arrays in and out (``vertices`` (N, 3) float, ``faces`` (F, 3) int), vectorised numpy, no
Python loop over faces or vertices. Meshes stored with split vertices (UV-unwrapped exports,
our own textured output) share no vertex index across a seam, so topology is computed on
*welded* vertices (:func:`weld_vertices`: the same position, up to a tolerance, is one vertex).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = [
    "EdgeTopology",
    "bounds",
    "corner_mean",
    "row_norms",
    "edge_topology",
    "face_adjacency",
    "face_normals",
    "oriented_face_normals",
    "vertex_normals",
    "FLOAT32_FAR",
    "float32_offset",
    "local_origin",
    "weld_vertices",
]

logger = logging.getLogger(__name__)


# numpy reduces a small axis (the 3 coordinates of a point, the 3 corners of a face) with a loop per
# element, several times slower than the same operations on whole columns; these give the same values
# (min / max are exact, sums are added in the order numpy adds them: first + second, then + third).


def bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(points.min(axis=0), points.max(axis=0))`` of (n, d) points, column by column (the same values).

    Parameters
    ----------
    points : (n, d) array, n >= 1

    Returns
    -------
    lo, hi : (d,) arrays of ``points``' dtype
    """
    p = np.asarray(points)
    if p.ndim != 2 or not len(p):
        return p.min(axis=0), p.max(axis=0)
    return (np.array([p[:, k].min() for k in range(p.shape[1])], dtype=p.dtype),
            np.array([p[:, k].max() for k in range(p.shape[1])], dtype=p.dtype))


def row_norms(a: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(a, axis=-1)`` of real vectors along a short last axis, bit for bit.

    Parameters
    ----------
    a : (..., d) float array

    Returns
    -------
    (...,) float array
        ``sqrt(a0*a0 + a1*a1 + ...)``, the squares added from the first, as numpy's sum does.
    """
    a = np.asarray(a)
    if a.shape[-1] == 0 or a.shape[-1] > 8 or not np.issubdtype(a.dtype, np.floating):
        return np.linalg.norm(a, axis=-1)
    s = a[..., 0] * a[..., 0]
    for k in range(1, a.shape[-1]):
        s = s + a[..., k] * a[..., k]
    return np.sqrt(s)


def corner_mean(tri: np.ndarray) -> np.ndarray:
    """``tri.mean(axis=1)`` of (F, 3, d) face corners, bit for bit: ``(c0 + c1 + c2) / 3``."""
    t = np.asarray(tri)
    if t.ndim != 3 or t.shape[1] != 3 or not np.issubdtype(t.dtype, np.floating):
        return t.mean(axis=1)
    return (t[:, 0] + t[:, 1] + t[:, 2]) / 3.0


def local_origin(vertices: np.ndarray) -> np.ndarray:
    """(3,) float64: the centre of the vertices' bounding box (zeros when there are none).

    Every single-precision step (Open3D ray casting, xatlas, GLB positions) takes coordinates
    minus this origin, so a scene far from the world origin (UTM-like coordinates) keeps the
    precision of one at the origin: float32 holds 1e7 only to the metre, 5 m to the micrometre.
    """
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    if not len(v):
        return np.zeros(3)
    lo, hi = bounds(v)
    return 0.5 * (lo + hi)


#: positions are written relative to their bounding box's centre when they lie more than this many
#: times its size from the origin (float32 keeps ~7 digits: 1e-5 of the size at this distance)
FLOAT32_FAR = 100.0


def float32_offset(vertices: np.ndarray) -> np.ndarray:
    """(3,) float64: what to subtract from ``vertices`` before a float32 format holds them.

    The bounding box's centre when the vertices lie more than :data:`FLOAT32_FAR` times the box's
    size from the origin (float32 would lose their shape there: at 1e7 m it holds metres), else
    zeros (files of scenes near the origin are written as they are).
    """
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    if not len(v):
        return np.zeros(3)
    lo, hi = bounds(v)
    size = float(np.max(hi - lo))
    far = float(np.max(np.abs(np.concatenate([lo, hi]))))
    return local_origin(v) if far > FLOAT32_FAR * max(size, 1e-12) else np.zeros(3)


def weld_vertices(vertices: np.ndarray, *, tol: float | None = None) -> np.ndarray:
    """Ids that merge vertices at the same position.

    Parameters
    ----------
    vertices : (N, 3) float array
    tol : float, optional
        Positions (relative to the bounding-box minimum) are rounded to multiples of this step
        before comparison; default ``1e-9 * max(diagonal, 1)`` (exact duplicates up to float
        noise).

    Returns
    -------
    (N,) int64
        Welded vertex id per vertex, in ``0 .. n_unique - 1``, numbered in the order of each
        group's first vertex.
    """
    v = np.asarray(vertices, dtype=np.float64)
    if len(v) == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = bounds(v)
    if tol is None:
        diag = float(np.linalg.norm(hi - lo))
        tol = max(diag, 1.0) * 1e-9
    q = np.round((v - lo) / float(tol)).astype(np.int64)
    # ids of the distinct rows in lexicographic order (np.unique(q, axis=0)'s inverse, 3x faster)
    order = np.lexsort((q[:, 2], q[:, 1], q[:, 0]))
    qs = q[order]
    new = np.ones(len(q), dtype=bool)
    new[1:] = (qs[1:, 0] != qs[:-1, 0]) | (qs[1:, 1] != qs[:-1, 1]) | (qs[1:, 2] != qs[:-1, 2])
    inv = np.empty(len(q), dtype=np.int64)
    inv[order] = np.cumsum(new) - 1
    # ids in the order of each group's first vertex, not of the rounded positions: the same ids wherever the mesh
    # lies (far from the origin a coordinate's last bit can move a vertex to a neighbouring cell of the same group)
    first = order[new]  # lexsort is stable: a run's first entry is its smallest vertex index
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[inv]


@dataclass(frozen=True, eq=False)
class EdgeTopology:
    """The interior edges of a mesh: edges shared by exactly two faces.

    Attributes
    ----------
    face_a, face_b : (E,) int64
        The two faces of each interior edge.
    corner_a0, corner_a1, corner_b0, corner_b1 : (E,) int64
        Local corners (0..2) of ``face_a`` / ``face_b`` at the edge's smaller (``0``) and larger
        (``1``) vertex id.
    edges : (E, 2) int64
        The vertex ids (in the indexing of the faces given) of each edge, smaller first.
    n_boundary, n_nonmanifold : int
        Edges with one face / with more than two faces (not in the arrays).
    """

    face_a: np.ndarray
    corner_a0: np.ndarray
    corner_a1: np.ndarray
    face_b: np.ndarray
    corner_b0: np.ndarray
    corner_b1: np.ndarray
    edges: np.ndarray
    n_boundary: int
    n_nonmanifold: int


def edge_topology(faces: np.ndarray) -> EdgeTopology:
    """Interior edges (shared by exactly two distinct faces) and the corners that bound them.

    Parameters
    ----------
    faces : (F, 3) int array
        Faces over (welded) vertex ids. Degenerate edges (both ends the same vertex) are not
        edges; an edge seen twice by the same face is not shared.

    Returns
    -------
    EdgeTopology
    """
    f = np.asarray(faces, dtype=np.int64)
    if f.ndim != 2 or f.shape[1] != 3:
        raise InputError(f"faces must be (F, 3), got {f.shape}")
    n_faces = len(f)
    c0 = np.tile(np.arange(3), n_faces)
    c1 = (c0 + 1) % 3
    fid = np.repeat(np.arange(n_faces), 3)
    a = f.reshape(-1)  # corner c0 of face fid
    b = f[:, [1, 2, 0]].reshape(-1)  # corner c1
    ok = a != b
    fid, c0, c1, a, b = fid[ok], c0[ok], c1[ok], a[ok], b[ok]
    swap = a > b
    lo, hi = np.where(swap, b, a), np.where(swap, a, b)
    clo, chi = np.where(swap, c1, c0), np.where(swap, c0, c1)
    key = lo * (int(f.max()) + 1 if f.size else 1) + hi
    order = np.argsort(key)
    sk = key[order]
    run = np.ones(len(sk), dtype=bool)  # the first of every run of equal keys
    run[1:] = sk[1:] != sk[:-1]
    start = np.flatnonzero(run)
    counts = np.diff(np.append(start, len(sk)))
    two = counts == 2
    p0, p1 = order[start[two]], order[start[two] + 1]
    i0, i1 = np.minimum(p0, p1), np.maximum(p0, p1)  # the edge's two corners in the faces' order
    good = fid[i0] != fid[i1]
    i0, i1 = i0[good], i1[good]
    return EdgeTopology(
        face_a=fid[i0], corner_a0=clo[i0], corner_a1=chi[i0],
        face_b=fid[i1], corner_b0=clo[i1], corner_b1=chi[i1],
        edges=np.stack([lo[i0], hi[i0]], axis=1),
        n_boundary=int(np.count_nonzero(counts == 1)),
        n_nonmanifold=int(np.count_nonzero(counts > 2)),
    )


def face_adjacency(faces: np.ndarray, vertices: np.ndarray | None = None, *, weld: bool = True) -> np.ndarray:
    """Pairs of faces that share an edge (interior manifold edges).

    Parameters
    ----------
    faces : (F, 3) int array
    vertices : (N, 3) float array, optional
        Needed for ``weld=True``: vertices at the same position count as one.
    weld : bool, default True
        Merge coincident vertices (:func:`weld_vertices`) before finding shared edges.

    Returns
    -------
    (E, 2) int64
        Face index pairs ``(p, q)`` with ``p < q``, one per pair of faces sharing an edge
        shared by exactly two faces, sorted. Non-manifold and degenerate edges are skipped.
    """
    f = np.asarray(faces, dtype=np.int64)
    if f.ndim != 2 or f.shape[1] != 3:
        raise InputError(f"faces must be (F, 3), got {f.shape}")
    if weld and vertices is not None:
        f = weld_vertices(vertices)[f]
    if len(f) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    topo = edge_topology(f)
    if topo.n_nonmanifold:
        logger.debug("face_adjacency: %d non-manifold edges skipped", topo.n_nonmanifold)
    if not len(topo.face_a):
        return np.zeros((0, 2), dtype=np.int64)
    p, q = np.minimum(topo.face_a, topo.face_b), np.maximum(topo.face_a, topo.face_b)
    n = int(len(f))
    key = np.sort(p * n + q)  # (p, q) pairs as one int64 key, sorted, then distinct
    key = key[np.concatenate([[True], key[1:] != key[:-1]])]
    return np.stack([key // n, key % n], axis=1).astype(np.int64)


def face_normals(vertices: np.ndarray, faces: np.ndarray, *, rel_tol: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Unit face normals by the right-hand rule on the winding.

    Parameters
    ----------
    vertices : (N, 3) float array
    faces : (F, 3) int array
    rel_tol : float, default 0.0
        A face is degenerate when twice its area is at most ``rel_tol * L * max(L, M)``, with
        ``L`` its longest edge and ``M`` its largest absolute coordinate (the scale of the
        rounding in its edge vectors): a measure of the face itself, so that one far-away
        vertex or stray triangle elsewhere in the mesh changes nothing; 0 flags only exactly
        zero areas.

    Returns
    -------
    normals : (F, 3) float64
        Unit normals, zero for degenerate faces.
    degenerate : (F,) bool
    """
    v = np.asarray(vertices, dtype=np.float64)
    tri = v[np.asarray(faces, dtype=np.int64)]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    n = np.cross(e1, e2)
    norm = row_norms(n)
    if rel_tol > 0:
        edge = np.sqrt(np.maximum.reduce([_sq(e1), _sq(e2), _sq(e2 - e1)]))
        t = np.abs(tri)
        mag = t[:, 0, 0]
        for i, j in ((0, 1), (0, 2), (1, 0), (1, 1), (1, 2), (2, 0), (2, 1), (2, 2)):  # .max(axis=(1, 2))
            mag = np.maximum(mag, t[:, i, j])
        degenerate = norm <= float(rel_tol) * edge * np.maximum(edge, mag)
    else:
        degenerate = norm <= 0.0
    return np.divide(n, norm[:, None], out=np.zeros_like(n), where=~degenerate[:, None]), degenerate


def _sq(e: np.ndarray) -> np.ndarray:
    """``(e * e).sum(1)`` of (n, 3) vectors, in numpy's order."""
    return e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1] + e[:, 2] * e[:, 2]


def oriented_face_normals(
    vertices: np.ndarray, faces: np.ndarray, vertex_normals: np.ndarray | None = None, *, rel_tol: float = 1e-12
) -> tuple[np.ndarray, np.ndarray, int]:
    """Unit face normals flipped where they disagree with the vertex normals.

    Returns
    -------
    normals : (F, 3) float64
    degenerate : (F,) bool
    flipped : int
        Number of faces whose winding normal was flipped.
    """
    fn, degenerate = face_normals(vertices, faces, rel_tol=rel_tol)
    flipped = 0
    if vertex_normals is not None and np.shape(vertex_normals) == np.shape(vertices):
        vn = np.asarray(vertex_normals, dtype=np.float64)
        f = np.asarray(faces, dtype=np.int64)
        s = vn[f[:, 0]] + vn[f[:, 1]] + vn[f[:, 2]]  # .sum(1) of the corners' normals, in its order
        flip = np.einsum("ij,ij->i", fn, s) < 0
        flipped = int(flip.sum())
        fn[flip] *= -1.0
    return fn, degenerate, flipped


def vertex_normals(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray | None = None) -> np.ndarray:
    """Unit vertex normals: the given ``normals`` where they are usable, else area-weighted face normals.

    Parameters
    ----------
    vertices : (N, 3) float array
    faces : (F, 3) int array
    normals : (N, 3) float array, optional
        Normals to keep where they are finite and non-zero.

    Returns
    -------
    (N, 3) float64
        Unit normals; ``(0, 0, 1)`` for vertices of no non-degenerate face.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = np.zeros_like(v) if normals is None or np.shape(normals) != v.shape else np.array(normals, dtype=np.float64)
    ln = np.linalg.norm(n, axis=1)
    bad = ~(ln > 1e-12) | ~np.isfinite(ln)
    if bad.any():
        tri = v[f]
        fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = twice the area
        acc = np.zeros_like(v)
        np.add.at(acc, f.reshape(-1), np.repeat(fn, 3, axis=0))
        n[bad] = acc[bad]
        ln = np.linalg.norm(n, axis=1)
    still = ~(ln > 1e-12) | ~np.isfinite(ln)
    n[still] = (0.0, 0.0, 1.0)
    ln[still] = 1.0
    return n / ln[:, None]
