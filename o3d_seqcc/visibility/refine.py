"""Faces no photo holds whole, split until the photos that see their parts hold those parts whole.

A face is usable in a photo only if all of it projects inside the photo and none of it is hidden
(paper 3.1-3.2). Big triangles (a floor, a wall, a facade of a low-poly scan) are then often
usable in no photo at all although every part of them is seen by some photo: their projection
is clipped by the image border, or partly occluded, or larger than any image. Such faces are
split (:func:`refine_visibility`, called by :func:`o3d_seqcc.visibility.compute_visibility`):

1. *candidates*: faces usable in no view (and not degenerate), new since the last round;
2. *probe*, one task per view: a candidate is *partly seen* in a view when it meets the view's
   frustum, faces the camera, is larger than ``min_px`` there (its longest edge in pixels, or any
   corner behind the camera), and one of its test points (a barycentric grid about 16 px apart,
   at most 153 points) projects into the image, on a pixel the photo's mask keeps, passes the oblique
   angle and the depth map, and is not hidden by the mesh (the z-buffer rays of :mod:`o3d_seqcc.visibility.occlusion`);
3. the partly seen faces are bisected twice (:func:`o3d_seqcc.geometry.meshsplit.bisect`: conforming
   longest-edge bisection, so the mesh stays welded and free of T-junctions; neighbours split
   where an edge of theirs is split), the visibility of every new face is computed by the same
   per-view task as the others' (:func:`~o3d_seqcc.visibility.per_view.view_record`, ray cast against
   the input mesh: the parts lie exactly on it), and merged into the views' records;

until no candidate is partly seen or after ``max_rounds`` rounds (each divides a face's area by
about 4). Faces wholly hidden or outside every photo are never split, and a part below
``min_px`` stays as it is, so a dense mesh (faces of a few pixels) is left nearly untouched.
Deterministic: the faces and their order depend only on the inputs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .._shared.parallel import LocalExecutor
from ..geometry.camera import project_columns
from ..geometry.meshops import corner_mean, face_normals, row_norms, weld_vertices
from ..geometry.meshsplit import bisect, coarsen
from .occlusion import _hidden, _rays_to, bary_grid
from .masks import masked_points
from .per_view import (DEPTH, MASKED, OBLIQUE, OCCLUDED, ViewRecord, VisibilityJob, chunk_members, frustum_chunks,
                       morton_chunks, view_record)

__all__ = ["PROBE_SPACING", "Refinement", "coverage", "distortion", "refine_visibility"]

#: spacing in pixels of the test points of a candidate face in :func:`probe_view`
PROBE_SPACING = 16.0
_MAX_PROBE_LEVEL = 16
#: candidates per spatial chunk of a probe's frustum culling
PROBE_CHUNK = 256


@dataclass(frozen=True, eq=False)
class Refinement:
    """The refined mesh and its visibility records (:func:`refine_visibility`).

    Attributes
    ----------
    vertices : (N', 3) float64
    faces : (F', 3) int64
    vertex_normals : (N', 3) float64
    normals : (F', 3) float64
        Oriented unit face normals (a part has its face's).
    degenerate : (F',) bool
    parent : (F',) int64
        The input face of every face.
    records : list of ViewRecord
    stats : dict
        ``rounds``, ``faces_split`` (input faces), ``faces_added``, ``probed`` (candidate faces
        probed over all rounds), ``distorted`` (faces split for their texture distortion).
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_normals: np.ndarray
    normals: np.ndarray
    degenerate: np.ndarray
    parent: np.ndarray
    records: list
    stats: dict = field(default_factory=dict)


class ProbeJob:
    """What every view's task of a round shares: the candidates' corners (c, 3, 3) and normals (c, 3), the base job,
    and the corners of the faces whose texture displacement each view measures (:func:`distortion`).

    Many candidates (more than ``4 * PROBE_CHUNK``) are grouped into chunks along a Morton curve
    (:func:`~o3d_seqcc.visibility.per_view.morton_chunks`), so that a view's probe looks only at
    those in chunks that meet its frustum (the others are outside it: never partly seen).

    Parameters
    ----------
    base : VisibilityJob
    tri : (c, 3, 3) float64
    normals : (c, 3) float64
    min_px : float
    bent_tri : (m, 3, 3) float64, optional
        Faces to measure, grouped by the view they are measured in: view ``i``'s are
        ``bent_tri[bent_ptr[i]:bent_ptr[i+1]]``.
    bent_ptr : (V+1,) int64, optional
    """

    def __init__(self, base: VisibilityJob, tri: np.ndarray, normals: np.ndarray, min_px: float,
                 bent_tri: np.ndarray | None = None, bent_ptr: np.ndarray | None = None) -> None:
        self.base = base
        self.tri = np.asarray(tri, dtype=np.float64)
        self.normals = np.asarray(normals, dtype=np.float64)
        self.min_px = float(min_px)
        self.bent_tri, self.bent_ptr = bent_tri, bent_ptr
        c = len(self.tri)
        self.chunk_ptr = np.arange(0, c + PROBE_CHUNK, PROBE_CHUNK).clip(max=c)
        self.chunk_perm = self.chunk_corners = None
        if c > 4 * PROBE_CHUNK:
            self.chunk_perm, self.chunk_corners = morton_chunks(self.tri, corner_mean(self.tri), self.chunk_ptr)

    def candidates(self, view) -> np.ndarray | None:
        """Ascending indices of the candidates in chunks that meet the view's frustum; None = all of them."""
        if self.chunk_perm is None:
            return None
        return chunk_members(self.chunk_perm, self.chunk_ptr, frustum_chunks(self.chunk_corners, view))


def round_view(i: int, job: ProbeJob) -> tuple[np.ndarray, np.ndarray]:
    """View ``i``'s task of a round: :func:`probe_view`, and the displacement (:func:`distortion`) of its faces
    (``job.bent_tri``'s group ``i``; empty without)."""
    seen = probe_view(i, job)
    if job.bent_ptr is None:
        return seen, np.zeros(0)
    s0, s1 = int(job.bent_ptr[i]), int(job.bent_ptr[i + 1])
    return seen, _displacement(job.bent_tri[s0:s1], job.base.views[i])


#: rows per block of :func:`_row_product`: OpenBLAS multiplies a block this small on the calling thread
_PRODUCT_ROWS = 4096


def _row_product(a: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``a @ m`` for (n, 3) rows ``a`` and a (3, k) matrix, in blocks of :data:`_PRODUCT_ROWS` rows.

    Each row's values are those of the row alone (the same product kernel, the same values as
    the (n/3, 3, 3) stack of per-face products, which costs a matrix call per face), and no
    block is large enough for OpenBLAS to start its threads (which spin: the per-view tasks
    keep the cores busy already).
    """
    out = np.empty((len(a), m.shape[1]))
    for s in range(0, len(a), _PRODUCT_ROWS):
        np.matmul(a[s:s + _PRODUCT_ROWS], m, out=out[s:s + _PRODUCT_ROWS])
    return out


def probe_view(i: int, job: ProbeJob) -> np.ndarray:
    """(c,) bool: the candidates partly seen in view ``i`` and larger than ``min_px`` there (module docstring)."""
    base, opts = job.base, job.base.opts
    view = base.views[i]
    out = np.zeros(len(job.tri), dtype=bool)
    if not len(job.tri):
        return out
    C = base.centers[i]
    sub = job.candidates(view)  # those in chunks that meet the frustum, then those facing the camera
    if not opts["two_sided"]:
        tri0, nrm = (job.tri[:, 0], job.normals) if sub is None else (job.tri[sub, 0], job.normals[sub])
        front = np.flatnonzero(np.einsum("ij,ij->i", nrm, C - tri0) > 0)
        sub = front if sub is None else sub[front]
    tri, n = (job.tri, job.normals) if sub is None else (job.tri[sub], job.normals[sub])
    c = len(tri)
    if not c:
        return out
    K, E = np.asarray(view.intrinsic, np.float64), np.asarray(view.extrinsic, np.float64)
    W, H = view.width, view.height
    pc = (_row_product(tri.reshape(-1, 3), E[:3, :3].T) + E[:3, 3]).reshape(c, 3, 3)  # camera frame
    fx, s, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    planes = np.array([[fx, s, cx + 0.5], [-fx, -s, W - 0.5 - cx], [0.0, fy, cy + 0.5], [0.0, -fy, H - 0.5 - cy],
                       [0.0, 0.0, 1.0]])
    side = _row_product(pc.reshape(-1, 3), planes.T).reshape(c, 3, 5)
    outside = (np.maximum(np.maximum(side[:, 0], side[:, 1]), side[:, 2]) <= 0).any(axis=1)  # all corners beyond a plane
    z = pc[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(z > 0, (fx * pc[..., 0] + s * pc[..., 1]) / z + cx, np.nan)
        v = np.where(z > 0, fy * pc[..., 1] / z + cy, np.nan)
    nxt = [1, 2, 0]
    side = np.sqrt((u - u[:, nxt]) ** 2 + (v - v[:, nxt]) ** 2)  # (c, 3) edge lengths in pixels
    edge = np.maximum(np.maximum(side[:, 0], side[:, 1]), side[:, 2])
    edge = np.where((z[:, 0] > 0) & (z[:, 1] > 0) & (z[:, 2] > 0), edge, np.inf)
    keep = np.flatnonzero(~outside & (edge > job.min_px))
    if not len(keep):
        return out
    level = np.clip(np.ceil(np.minimum(edge[keep], 1e9) / PROBE_SPACING), 2, _MAX_PROBE_LEVEL).astype(np.int64)
    pts, own = [], []
    for L in np.unique(level):  # at most 15 groups
        sel = keep[level == L]
        w = bary_grid(int(L), interior_only=False)  # (m, 3), the corners included
        pts.append(np.einsum("mj,kjc->kmc", w, tri[sel]).reshape(-1, 3))
        own.append(np.repeat(sel, len(w)))
    P, owner = np.concatenate(pts), np.concatenate(own)
    pu, pv, pz = project_columns(np.ascontiguousarray(P.T), K, E)
    with np.errstate(invalid="ignore"):
        ok = (pz > 0) & (pu >= -0.5) & (pu < W - 0.5) & (pv >= -0.5) & (pv < H - 0.5)
    if "oblique" in opts["filters"]:
        d = C - P
        dist = np.maximum(row_norms(d), 1e-300)
        cos = np.einsum("ij,ij->i", n[owner], d) / dist if opts["oblique_reference"] == "ray" else n[owner] @ -view.axis
        cos = np.abs(cos) if opts["two_sided"] else cos
        ok &= cos >= math.cos(math.radians(opts["max_angle"]))
    idx = np.flatnonzero(ok)
    idx = idx[~masked_points(base.mask(i), pu[idx], pv[idx])]  # on a masked pixel: not seen
    if len(idx) and "depth" in opts["filters"]:
        D, _ = base.depth(i)
        if D is not None:
            col = np.clip(np.floor(pu[idx] + 0.5), 0, W - 1).astype(np.intp)
            row = np.clip(np.floor(pv[idx] + 0.5), 0, H - 1).astype(np.intp)
            d = D.at(row, col)
            zi = pz[idx]
            bad = (d > 0) & (np.abs(zi - d) > np.maximum(opts["depth_atol"], opts["depth_tol"] * zi))
            idx = idx[~bad]
    if len(idx) and "occlusion" in opts["filters"]:
        rays = _rays_to(C, P[idx], float(opts["occlusion_tol"]), float(opts["occlusion_atol"]), base.origin)
        idx = idx[~_hidden(base.raycaster(), rays)]
    seen = owner[idx]  # repeats: a face with several points seen
    out[seen if sub is None else sub[seen]] = True
    return out


#: barycentric points where :func:`distortion` compares the projective and the affine map (centroid, edge midpoints)
_DISTORTION_POINTS = np.array([[1 / 3, 1 / 3, 1 / 3], [0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5]])


def distortion(vertices: np.ndarray, faces: np.ndarray, records: list, views, among: np.ndarray) -> np.ndarray:
    """(F,) float64: how far, in pixels, a face's texture would be displaced inside it in its largest usable view.

    A face's texture coordinates are its corners' projections (image charts), and a renderer
    interpolates them linearly over the face, while the photo maps the face projectively: inside
    a face that spans a large range of depths the two differ (the texture slides). The error is
    measured at the centroid and the edge midpoints, in the view where the face's projection is
    largest among those where it is usable (the one the selection favours; the first such view
    on a tie); 0 for faces not in ``among`` ((F,) bool) or usable nowhere.
    """
    return _distortion(vertices, faces, records, None, views, among)


def _distortion(vertices: np.ndarray, faces: np.ndarray, records: list, ids: np.ndarray | None, views,
                among: np.ndarray) -> np.ndarray:
    """:func:`distortion` from records over some of the faces: ``ids`` maps their face ids to ``faces``' (None:
    the same ids)."""
    out = np.zeros(len(faces))
    best_f, best_v = _best_views(records, ids, among)
    X = np.asarray(vertices, dtype=np.float64)
    for v in np.unique(best_v):
        fs = best_f[best_v == v]
        out[fs] = _displacement(X[faces[fs]], views[v])
    return out


def _best_views(records: list, ids: np.ndarray | None, among: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The faces in ``among`` ((F,) bool) usable in some view (ascending), and the view of each where its projected
    area is largest (the first on a tie); ``ids`` as in :func:`_distortion`."""
    best = np.full(len(among), -np.inf, dtype=np.float32)
    best_v = np.full(len(among), -1, dtype=np.int64)
    for v, r in enumerate(records):
        fs = r.faces if ids is None else ids[r.faces]
        k = (r.flags == 0) & among[fs]
        fs, a = fs[k], r.area[k]
        up = a > best[fs]
        best[fs[up]] = a[up]
        best_v[fs[up]] = v
    best_f = np.flatnonzero(best_v >= 0)
    return best_f, best_v[best_f]


def _displacement(tri: np.ndarray, view) -> np.ndarray:
    """(m,) float64: the texture displacement in pixels of faces ``tri`` (m, 3, 3) in ``view`` (inf where a point
    projects to NaN)."""
    K, E = np.asarray(view.intrinsic, np.float64), np.asarray(view.extrinsic, np.float64)
    pts = np.concatenate([tri, np.einsum("pj,mjc->mpc", _DISTORTION_POINTS, tri)], axis=1)  # (m, 7, 3)
    u, w, _ = project_columns(np.ascontiguousarray(pts.reshape(-1, 3).T), K, E)
    uv = np.stack([u, w], axis=1).reshape(len(tri), 7, 2)
    affine = np.einsum("pj,mjc->mpc", _DISTORTION_POINTS, uv[:, :3])
    e = row_norms(uv[:, 3:] - affine)  # (m, 4)
    err = np.maximum(np.maximum(e[:, 0], e[:, 1]), np.maximum(e[:, 2], e[:, 3]))
    return np.nan_to_num(err, nan=np.inf)


class _Records:
    """The views' records over faces renumbered every round, renumbered once at the end.

    Holds pieces: the input records and the records of every round's new faces, each with the
    current id of its faces (-1: split or merged since). A round renumbers the ids (a gather per
    piece), not the records; :meth:`records` merges the pieces into one record per view.
    """

    def __init__(self, records: list, n_faces: int) -> None:
        self.pieces = [(list(records), np.arange(n_faces, dtype=np.int64))]
        self.usable_any = np.zeros(n_faces, dtype=bool)
        self._mark(records, None)

    def _mark(self, records: list, ids: np.ndarray | None) -> None:
        for r in records:
            u = r.faces[r.flags == 0]
            self.usable_any[u if ids is None else ids[u]] = True

    def renumber(self, old_to_new: np.ndarray, n_faces: int) -> None:
        """Faces renumbered (``old_to_new``: (F_old,) new id or -1), ``n_faces`` of them now."""
        self.pieces = [(recs, np.where(cur >= 0, old_to_new[cur], -1)) for recs, cur in self.pieces]
        ua = np.zeros(n_faces, dtype=bool)
        kept = old_to_new >= 0
        ua[old_to_new[kept]] = self.usable_any[kept]
        self.usable_any = ua

    def add(self, records: list, ids: np.ndarray) -> None:
        """The records of new faces: their face ``j`` is the current face ``ids[j]``."""
        self.pieces.append((list(records), np.asarray(ids, dtype=np.int64)))
        self._mark(records, ids)

    def records(self) -> list:
        """One :class:`ViewRecord` per view over the current faces (ascending ids), merged on local threads; the
        pieces are released view by view."""
        return LocalExecutor().map(self._merged, range(len(self.pieces[0][0])), desc="split faces", unit="view")

    def _merged(self, v: int) -> ViewRecord:
        base = self.pieces[0][0][v]
        parts = [(recs[v], cur[recs[v].faces]) for recs, cur in self.pieces]
        for recs, _ in self.pieces:
            recs[v] = None
        keep = [ids >= 0 for _, ids in parts]
        faces = np.concatenate([ids[k] for (_, ids), k in zip(parts, keep)])
        order = np.argsort(faces, kind="stable")

        def cat(name: str) -> np.ndarray:
            return np.concatenate([getattr(r, name)[k] for (r, _), k in zip(parts, keep)])[order]

        flags = cat("flags")
        info = dict(base.info)
        info.update(valid=int(len(faces)), occluded=int(np.count_nonzero(flags & OCCLUDED)),
                    depth_inconsistent=int(np.count_nonzero(flags & DEPTH)),
                    oblique=int(np.count_nonzero(flags & OBLIQUE)), masked=int(np.count_nonzero(flags & MASKED)),
                    usable=int(np.count_nonzero(flags == 0)))
        secs: dict = {}
        for r, _ in parts:
            for k, t in r.seconds.items():
                secs[k] = secs.get(k, 0.0) + t
        return ViewRecord(faces=faces[order].astype(np.int32), flags=flags, area=cat("area"),
                          cos_angle=cat("cos_angle"), info=info, n_rays=int(sum(r.n_rays for r, _ in parts)),
                          n_known=base.n_known, seconds=secs)


def refine_visibility(job: VisibilityJob, records: list, ex, *, vertex_normals: np.ndarray, min_px: float = 4.0,
                      max_distortion: float = 0.5, max_rounds: int = 8) -> Refinement:
    """Split the faces no view can use whole but some view sees in part (module docstring).

    Parameters
    ----------
    job : VisibilityJob
        The job ``records`` were computed with (mesh, oriented normals, options, views).
    records : list of ViewRecord
        One per view. When faces are added the list is emptied (the input records are released view
        by view as the refined ones are built).
    ex : executor
        :func:`o3d_seqcc._shared.parallel.current`'s (the probes and the parts' visibility run on it).
    vertex_normals : (N, 3) float64
    min_px : float, default 4.0
        A face is split only where its longest edge is above this many pixels in a view that sees
        part of it.
    max_distortion : float, default 0.5
        Faces usable somewhere are split when their texture would be displaced by more than this
        many pixels inside them (:func:`distortion`; large faces seen in depth); ``inf``: never.
    max_rounds : int, default 8
        Rounds of (probe, two bisections, visibility of the parts).

    Returns
    -------
    Refinement
        The input arrays themselves when nothing is split.
    """
    X, f = job.X, job.faces
    fn = np.stack(job.fn, axis=1)
    deg = job.degenerate
    vn = np.asarray(vertex_normals, dtype=np.float64)
    F0 = len(f)
    parent = np.arange(F0, dtype=np.int64)
    fresh = np.ones(F0, dtype=bool)
    welded = ends = None
    V = len(job.views)
    stats = {"rounds": 0, "probed": 0, "distorted": 0, "merged_back": 0}
    book = _Records(records, F0)
    latest, latest_ids = book.pieces[0][0], None  # the records of the fresh faces
    for _ in range(int(max_rounds)):
        usable_any = book.usable_any
        cand = np.flatnonzero(fresh & ~usable_any & ~deg)
        if not V:
            break
        marked = np.zeros(0, dtype=np.int64)
        measure = np.isfinite(max_distortion)
        bent_f, bent_ptr = np.zeros(0, dtype=np.int64), None
        if measure:  # each face's displacement is measured by the task of its largest usable view
            best_f, best_v = _best_views(latest, latest_ids, fresh & usable_any & ~deg)
            order = np.argsort(best_v, kind="stable")
            bent_f = best_f[order]
            bent_ptr = np.concatenate([[0], np.cumsum(np.bincount(best_v, minlength=V))])
        res = []
        if len(cand) or len(bent_f):
            stats["probed"] += int(len(cand))
            rj = ProbeJob(job, X[f[cand]], fn[cand], min_px, X[f[bent_f]] if measure else None, bent_ptr)
            res = ex.map(round_view, range(V), ex.share(rj), desc="split faces", unit="view")
            del rj
        if len(cand):
            marked = cand[np.logical_or.reduce([r[0] for r in res])]
        if measure:
            out = np.zeros(len(f))
            if len(bent_f):
                out[bent_f] = np.concatenate([r[1] for r in res])
            bent = np.flatnonzero(out > max_distortion)
            stats["distorted"] = stats.get("distorted", 0) + int(len(bent))
            marked = np.union1d(marked, bent)
        del res
        if not len(marked):
            break
        stats["rounds"] += 1
        if welded is None:
            welded = weld_vertices(X)
            ends = np.full((len(X), 2), -1, dtype=np.int64)
        b1 = bisect(X, f, marked, vertex_normals=vn, welded=welded)
        w1 = np.concatenate([welded, welded.max() + 1 + np.arange(b1.n_new_vertices)])
        once = np.zeros(len(f), dtype=bool)
        once[marked] = True
        twice = np.flatnonzero(once[b1.parent])
        b2 = bisect(b1.vertices, b1.faces, twice, vertex_normals=b1.vertex_normals, welded=w1)
        welded = np.concatenate([w1, w1.max() + 1 + np.arange(b2.n_new_vertices)])
        ends = np.concatenate([ends, b1.edge_vertices, b2.edge_vertices])  # what every new vertex is the midpoint of
        up = b1.parent[b2.parent]  # face of this round -> face before it
        n1 = np.bincount(b1.parent, minlength=len(f))
        n2 = np.bincount(b2.parent, minlength=len(b1.faces))
        unsplit = (n1[up] == 1) & (n2[b2.parent] == 1)
        old_to_new = np.full(len(f), -1, dtype=np.int64)
        old_to_new[up[unsplit]] = np.flatnonzero(unsplit)
        X, f, vn = b2.vertices, b2.faces, b2.vertex_normals
        new = np.flatnonzero(~unsplit)
        fn, deg, parent = fn[up], deg[up].copy(), parent[up]
        deg[new] = face_normals(X, f[new], rel_tol=1e-12)[1]  # rel_tol of oriented_face_normals, whole-mesh extent
        latest, latest_ids = _new_face_records(job, ex, X, f, fn, deg, new), new
        book.renumber(old_to_new, len(f))
        book.add(latest, new)
        fresh = np.zeros(len(f), dtype=bool)
        fresh[new] = True
    if stats["rounds"]:  # parts no view can use, all of one bisection: merged back (fewer unseen faces)
        f2, origin, rep = coarsen(f, welded, ends, ~book.usable_any)
        if (origin < 0).any():
            n_old = len(f)
            old_to_new = np.full(n_old, -1, dtype=np.int64)
            old_to_new[origin[origin >= 0]] = np.flatnonzero(origin >= 0)
            parent, fn = parent[rep], fn[rep]
            used = np.zeros(len(X), dtype=bool)
            used[f2.reshape(-1)] = True
            remap = np.cumsum(used) - 1
            X, vn, f = X[used], vn[used], remap[f2]
            new = np.flatnonzero(origin < 0)
            deg = deg[rep].copy()
            deg[new] = face_normals(X, f[new], rel_tol=1e-12)[1]
            book.renumber(old_to_new, len(f))
            book.add(_new_face_records(job, ex, X, f, fn, deg, new), new)
            stats["merged_back"] = int(n_old - len(f))
        if len(f) != F0 and isinstance(records, list):  # the caller takes the refined records: the book releases
            records.clear()  # the input ones as it merges (a tuple, e.g. after the far junk is dropped, stays)
        del latest
        records = book.records()
    split = np.bincount(parent, minlength=F0) > 1
    stats.update(input_faces=int(F0), faces_split=int(split.sum()), faces_added=int(len(f) - F0))
    return Refinement(vertices=X, faces=f, vertex_normals=vn, normals=fn, degenerate=deg, parent=parent,
                      records=list(records), stats=stats)


def _new_face_records(job: VisibilityJob, ex, X, f, fn, deg, new) -> list:
    """Every view's record of the faces ``new`` (ids into ``f``; a record's face ``j`` is ``new[j]``)."""
    mask = np.zeros(len(X), dtype=bool)
    mask[f[new].reshape(-1)] = True
    used = np.flatnonzero(mask)  # the new faces' vertices, ascending
    local = np.empty(len(X), dtype=np.int64)
    local[used] = np.arange(len(used))
    part_job = VisibilityJob(job.views, X[used], local[f[new]], fn[new], deg[new], job.opts, occluder=job)
    return ex.map(view_record, range(len(job.views)), ex.share(part_job), desc="split faces", unit="view")


def coverage(vis, labels: np.ndarray) -> dict:
    """How much of the input mesh a selection textures, counted in the input's faces and in area.

    Parameters
    ----------
    vis : Visibility
        Its ``mesh`` (maybe refined) and ``parent_faces``.
    labels : (F,) int
        A view per face of ``vis.mesh``, -1 = none.

    Returns
    -------
    dict
        ``input_faces`` (those kept: far-away junk dropped by the visibility is not counted),
        ``split_input_faces`` (split into parts), ``unseen_input_faces`` (no part textured), ``partly_seen_input_faces`` (some parts textured, some not) and
        ``unseen_area`` (the untextured share of the surface area, in [0, 1]).
    """
    X = np.asarray(vis.mesh.vertices, dtype=np.float64)
    f = np.asarray(vis.mesh.faces, dtype=np.int64)
    seen = np.asarray(labels) >= 0
    parent = vis.parent_faces if vis.parent_faces is not None else np.arange(len(f))
    n_in = int((vis.stats.get("split") or {}).get("input_faces") or (int(parent.max()) + 1 if len(parent) else 0))
    area = 0.5 * np.linalg.norm(np.cross(X[f[:, 1]] - X[f[:, 0]], X[f[:, 2]] - X[f[:, 0]]), axis=1)
    some = np.bincount(parent, weights=seen, minlength=n_in) > 0
    gaps = np.bincount(parent, weights=~seen, minlength=n_in) > 0
    parts = np.bincount(parent, minlength=n_in)
    kept = parts > 0  # far-away junk left out of the visibility (stray.py) is not counted
    return {"input_faces": int(kept.sum()), "split_input_faces": int((parts > 1).sum()),
            "unseen_input_faces": int((kept & ~some).sum()), "partly_seen_input_faces": int((some & gaps).sum()),
            "unseen_area": round(float(area[~seen].sum() / max(area.sum(), 1e-300)), 6)}
