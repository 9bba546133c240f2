"""One view's visibility: the task :func:`~o3d_seqcc.visibility.compute_visibility` runs per view.

:class:`VisibilityJob` holds what every view's task shares: the mesh geometry (vertices, faces,
oriented face normals, centroids), the filter options, the views, a spatial index of the faces
and, built on first use in each process, Open3D's ``RaycastingScene`` of the mesh. It is
scattered once to every Dask worker (or shared by the local threads); :func:`view_record` then
computes view ``i``'s :class:`ViewRecord`: the ids of the faces *valid* in the view (all three
vertices inside the image, in front of the camera, not degenerate), a bit per filter that
removed them (:data:`OCCLUDED`, :data:`DEPTH`, :data:`OBLIQUE`, :data:`MASKED`: seen through the
photo's mask, :mod:`o3d_seqcc.visibility.masks`; usable = no bit set), their projected areas and
the cosines of their viewing angles.

Only faces whose spatial chunk intersects the view's frustum are looked at: faces are grouped
into chunks of :data:`CHUNK_FACES` consecutive faces along a Morton curve of their centroids,
and a chunk whose bounding box lies entirely outside one of the five frustum planes (by a
relative margin far above rounding) cannot hold a valid face. A view's work is then
proportional to the faces it sees, not to the mesh, and the record holds exactly what the
full per-face computation gives.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from ..geometry.camera import project_columns
from ..geometry.meshops import bounds, corner_mean, local_origin
from .depthmaps import DepthImage, depth_edges, depth_from_point_cloud
from ..errors import InputError, warn
from ..imaging.sequences import LRUCache
from ..io.depth import depth_in_metres, read_stored_depth
from .masks import mask_image, masked_faces
from .occlusion import occluded_view, same_positions, take_over

__all__ = ["CHUNK_FACES", "DEPTH", "MASKED", "OBLIQUE", "OCCLUDED", "ViewRecord", "VisibilityJob", "summarize_records",
           "view_record"]

logger = logging.getLogger("o3d_seqcc.visibility")  # the visibility's log (its warnings name views)

#: filter bits of :attr:`ViewRecord.flags`
OCCLUDED, DEPTH, OBLIQUE, MASKED = 1, 2, 4, 8
#: faces per spatial chunk of the frustum culling
CHUNK_FACES = 1024
#: bytes of depth images a job keeps for the later passes over the views (the split faces' parts): at least
#: this, up to :data:`DEPTH_CACHE_MAX_BYTES` when every view's depth image fits (a least-recently-used cache
#: smaller than the views' cycle misses every time: 10 depth maps of 6 MP were decoded 167 times in 8 rounds)
DEPTH_CACHE_BYTES = 256 * 2**20
#: the most the depth cache grows to so that all of a job's depth images stay
DEPTH_CACHE_MAX_BYTES = 1024 * 2**20


@dataclass(frozen=True, eq=False)
class ViewRecord:
    """The faces one view sees and what the filters say about them.

    Attributes
    ----------
    faces : (k,) int32
        Ids of the faces valid in the view, ascending.
    flags : (k,) uint8
        Bits :data:`OCCLUDED`, :data:`DEPTH`, :data:`OBLIQUE`, :data:`MASKED` of the filters that
        removed each face; 0 = usable (a masked face is not ray-tested: never also occluded).
    area : (k,) float32
        Projected area in px^2.
    cos_angle : (k,) float32
        Cosine between the oriented face normal and the direction from the face centroid to
        the camera centre (negative: seen from behind).
    info : dict
        The view's entry of ``stats["per_view"]`` (name, depth source, disagreement, counts).
    n_rays : int
        Occlusion test points (:func:`~o3d_seqcc.visibility.occlusion.occluded_view`: a ray each, vertices at one
        position sharing theirs).
    n_known : int
        Vertices of visible faces with a depth measurement (for the disagreement warning).
    seconds : dict
        Time spent per step (``project+depth``, ``occlusion``).
    """

    faces: np.ndarray
    flags: np.ndarray
    area: np.ndarray
    cos_angle: np.ndarray
    info: dict = field(default_factory=dict)
    n_rays: int = 0
    n_known: int = 0
    seconds: dict = field(default_factory=dict)

    @property
    def usable(self) -> np.ndarray:
        """(k,) bool: no filter removed the face."""
        return self.flags == 0

    @property
    def nbytes(self) -> int:
        return int(self.faces.nbytes + self.flags.nbytes + self.area.nbytes + self.cos_angle.nbytes)


def _part1by2(x: np.ndarray) -> np.ndarray:
    """Spread the 10 low bits of ``x`` to every third bit (Morton code helper)."""
    x = x.astype(np.uint32)
    x = (x | (x << 16)) & np.uint32(0x030000FF)
    x = (x | (x << 8)) & np.uint32(0x0300F00F)
    x = (x | (x << 4)) & np.uint32(0x030C30C3)
    return (x | (x << 2)) & np.uint32(0x09249249)


def morton_chunks(tri: np.ndarray, cen: np.ndarray, ptr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Faces grouped into chunks along a Morton curve of their centroids, and the chunks' boxes.

    Parameters
    ----------
    tri : (F, 3, 3) float64
        The faces' corners.
    cen : (F, 3) float64
        Their centroids.
    ptr : (C+1,) int
        Chunk ``c`` holds the faces ``perm[ptr[c]:ptr[c+1]]``.

    Returns
    -------
    perm : (F,) int64
        The faces in curve order (stable for equal codes).
    corners : (C, 8, 3) float64
        The eight corners of every chunk's bounding box.
    """
    lo, hi = bounds(cen)
    q = np.clip((cen - lo) / np.maximum(hi - lo, 1e-300) * 1023.0, 0, 1023).astype(np.uint32)
    code = _part1by2(q[:, 0]) | (_part1by2(q[:, 1]) << np.uint32(1)) | (_part1by2(q[:, 2]) << np.uint32(2))
    perm = np.argsort(code, kind="stable")
    starts = ptr[:-1]
    box_lo = np.minimum.reduceat(np.minimum(np.minimum(tri[:, 0], tri[:, 1]), tri[:, 2])[perm], starts)  # (C, 3)
    box_hi = np.maximum.reduceat(np.maximum(np.maximum(tri[:, 0], tri[:, 1]), tri[:, 2])[perm], starts)
    corners = np.stack(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij"), axis=-1).reshape(8, 3)
    return perm.astype(np.int64), np.where(corners[None, :, :] == 0, box_lo[:, None, :], box_hi[:, None, :])


def frustum_chunks(corners: np.ndarray, view) -> np.ndarray:
    """(C,) bool: the chunks (boxes' ``corners`` (C, 8, 3)) not wholly beyond one of the view's frustum planes.

    A box is dropped only when all its corners lie beyond one plane (``u >= -0.5``, ``u < W - 0.5``,
    ``v >= -0.5``, ``v < H - 0.5``, ``z > 0``) by a relative margin far above rounding, so no face
    inside it can have a corner inside the image.
    """
    K, E = np.asarray(view.intrinsic, np.float64), np.asarray(view.extrinsic, np.float64)
    pc = corners @ E[:3, :3].T + E[:3, 3]  # (C, 8, 3) camera frame
    fx, s, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    W, H = view.width, view.height
    planes = np.array([
        [fx, s, cx + 0.5],  # u >= -0.5
        [-fx, -s, W - 0.5 - cx],  # u < W - 0.5
        [0.0, fy, cy + 0.5],  # v >= -0.5
        [0.0, -fy, H - 0.5 - cy],  # v < H - 0.5
        [0.0, 0.0, 1.0],  # z > 0
    ])
    vals = pc @ planes.T  # (C, 8, 5)
    margin = 1e-9 * np.abs(pc).max(axis=(1, 2))[:, None] * np.abs(planes).sum(axis=1)[None, :] + 1e-300
    return ~(vals.max(axis=1) < -margin).any(axis=1)


def chunk_members(perm: np.ndarray, ptr: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Ascending ids of the faces in the chunks ``keep`` ((C,) bool) of :func:`morton_chunks`."""
    return np.sort(perm[np.repeat(keep, ptr[1:] - ptr[:-1])])


class VisibilityJob:
    """What every view's visibility task shares (see the module docstring).

    Parameters
    ----------
    views : sequence of View
    vertices : (N, 3) float64
    faces : (F, 3) int64
    normals : (F, 3) float64
        Oriented unit face normals.
    degenerate : (F,) bool
    opts : dict
        The filter options of :func:`~o3d_seqcc.visibility.compute_visibility`.
    occluder : VisibilityJob, optional
        The job whose mesh hides faces from the cameras (default: this one's). A job over some
        faces of a mesh (the parts of split faces, :mod:`o3d_seqcc.visibility.refine`) casts its rays
        against the whole mesh this way, and shares its ray-casting tree.

    Ray casting is single precision (Open3D): it works in a local frame, the mesh and the rays
    minus :attr:`origin` (the centre of the mesh's bounding box), so a scene 1e7 m from the world
    origin is hit-tested as precisely as one at the origin.
    """

    def __init__(self, views, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, degenerate: np.ndarray,
                 opts: dict, *, occluder: "VisibilityJob | None" = None) -> None:
        X = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces, dtype=np.int64)
        self.views = tuple(views)
        self.opts = dict(opts)
        self.occluder = occluder
        self.origin = occluder.origin if occluder is not None else local_origin(X)
        # the camera centres, solved once per job (View.center solves R c = -t at each call)
        self.centers = occluder.centers if occluder is not None else np.array([v.center for v in self.views])
        self.X = X
        self.faces = f
        # vertices at one position (three per face in UV-unwrapped exports) share their occlusion ray
        self.same = same_positions(X) if len(X) > len(f) else None
        self.XT = np.ascontiguousarray(X.T)
        self.f0, self.f1, self.f2 = (np.ascontiguousarray(f[:, i]) for i in range(3))
        tri = X[f]
        cen = corner_mean(tri)
        self.cen = [np.ascontiguousarray(cen[:, i]) for i in range(3)]
        self.fn = [np.ascontiguousarray(normals[:, i]) for i in range(3)]
        self.degenerate = np.asarray(degenerate, dtype=bool)
        self._chunk(tri, cen)
        self._rs = None
        self._lock = threading.Lock()
        need = sum(_depth_bytes(v) for v in self.views)
        self._depths = LRUCache(max(DEPTH_CACHE_BYTES, need if need <= DEPTH_CACHE_MAX_BYTES else 0))
        self._masks = LRUCache(DEPTH_CACHE_BYTES // 2)  # one bit a pixel: 100 views of 20 MP

    def mask(self, i: int):
        """View ``i``'s :class:`~o3d_seqcc.visibility.masks.MaskImage` or None, read once per process while the
        masks fit (:attr:`occluder`'s cache, when given)."""
        if self.occluder is not None:
            return self.occluder.mask(i)
        if not self.views[i].has_mask:
            return None
        return self._masks.get(i, lambda: mask_image(self.views[i]))

    def depth(self, i: int):
        """View ``i``'s (depth image or None, source name or None), read once per process while it fits
        :data:`DEPTH_CACHE_BYTES` (or all of them, up to :data:`DEPTH_CACHE_MAX_BYTES`; :attr:`occluder`'s
        cache, when given)."""
        if self.occluder is not None:
            return self.occluder.depth(i)
        return self._depths.get(i, lambda: _depth_image(self.views[i], self.opts))

    def _chunk(self, tri: np.ndarray, cen: np.ndarray) -> None:
        F = len(self.faces)
        self.chunk_ptr = np.arange(0, F + CHUNK_FACES, CHUNK_FACES).clip(max=F)
        if F <= 4 * CHUNK_FACES:  # small meshes: no culling
            self.chunk_perm = None
            return
        self.chunk_perm, self.chunk_corners = morton_chunks(tri, cen, self.chunk_ptr)

    def candidates(self, view) -> np.ndarray | None:
        """Ascending ids of the faces in chunks that meet the view's frustum; None = all faces."""
        if self.chunk_perm is None:
            return None
        keep = frustum_chunks(self.chunk_corners, view)
        ptr = self.chunk_ptr
        n_keep = int((ptr[1:] - ptr[:-1])[keep].sum())
        if n_keep >= 0.5 * len(self.faces):
            return None
        return chunk_members(self.chunk_perm, ptr, keep)

    def raycaster(self):
        """Open3D's ``RaycastingScene`` of the mesh (of :attr:`occluder`'s, when given) in the local frame
        (minus :attr:`origin`), built once per process and committed (or the camera check's of the same
        arrays, :func:`~o3d_seqcc.visibility.occlusion.take_over`)."""
        if self.occluder is not None:
            return self.occluder.raycaster()
        if self._rs is None:
            with self._lock:
                if self._rs is None:
                    import open3d as o3d
                    import open3d.core as o3c

                    handed = take_over(self.X, self.faces, self.origin)
                    if handed is not None:
                        self._rs = handed
                        return handed
                    rs = o3d.t.geometry.RaycastingScene()
                    rs.add_triangles(o3c.Tensor(np.ascontiguousarray(self.X - self.origin, dtype=np.float32)),
                                     o3c.Tensor(np.ascontiguousarray(self.faces, dtype=np.uint32)))
                    rs.test_occlusions(o3c.Tensor(np.zeros((1, 6), np.float32)))  # commit before concurrent use
                    self._rs = rs
        return self._rs

    def __getstate__(self) -> dict:
        d = self.__dict__.copy()
        d["_rs"] = None
        del d["_lock"]
        return d

    def __setstate__(self, d: dict) -> None:
        self.__dict__.update(d)
        self._lock = threading.Lock()


def _depth_bytes(view) -> int:
    """The bytes a view's :class:`~o3d_seqcc.visibility.depthmaps.DepthImage` is expected to hold: 2 a pixel for a
    16-bit PNG depth map, 8 for any other depth (float maps, rendered point clouds), 0 without."""
    if not view.has_depth:
        return 0
    png = view.depth_map is None and view.depth is not None and str(view.depth).lower().endswith(".png")
    return (2 if png else 8) * int(view.width) * int(view.height)


def _depth_image(view, opts: dict):
    """(depth image or None, source name or None) of a view, as a :class:`~o3d_seqcc.visibility.depthmaps.DepthImage`:
    a 16-bit map read as stored (its counts), any other as :meth:`View.load_depth` gives it."""
    dist = view.distortion
    if (view.depth_map is None and view.depth is not None
            and (dist is None or not dist.depth or dist.is_zero)):  # load_depth is the map in metres
        stored = read_stored_depth(view.depth, shape=(view.height, view.width))
        if stored.dtype == np.uint16:
            return DepthImage(counts=stored, scale=view.depth_scale), "depth"
        return DepthImage(depth_in_metres(stored, view.depth_scale)), "depth"
    D = view.load_depth()  # raises InputError naming the file on wrong size / dtype
    if D is not None:
        return DepthImage(D), "depth"
    points = view.load_points()
    if points is not None:
        return DepthImage(depth_from_point_cloud(points, view.intrinsic, view.extrinsic, view.width, view.height,
                                                 fill_radius=opts["fill_radius"])), "point_cloud"
    return None, None


def view_record(i: int, job: VisibilityJob) -> ViewRecord:
    """Visibility of view ``i``: projection, validity, areas, angles and the three filters.

    Parameters
    ----------
    i : int
        View index in ``job.views``.
    job : VisibilityJob

    Returns
    -------
    ViewRecord
    """
    t0 = time.perf_counter()
    view, opts = job.views[i], job.opts
    filters = opts["filters"]
    W, H = view.width, view.height
    cand = job.candidates(view)
    if cand is None:  # every face: the mesh's own arrays
        l0, l1, l2, XT, vs = job.f0, job.f1, job.f2, job.XT, None
        cen, fn, degenerate = job.cen, job.fn, job.degenerate
    else:  # the candidate faces, their vertices renumbered 0..n-1 in ascending id order
        need = np.zeros(len(job.X), dtype=bool)
        for f in (job.f0, job.f1, job.f2):
            need[f[cand]] = True
        vs = np.flatnonzero(need)
        local = np.empty(len(job.X), dtype=np.int64)
        local[vs] = np.arange(len(vs))
        l0, l1, l2 = (local[f[cand]] for f in (job.f0, job.f1, job.f2))
        XT = np.ascontiguousarray(job.XT[:, vs])
        cen, fn = [c[cand] for c in job.cen], [c[cand] for c in job.fn]
        degenerate = job.degenerate[cand]
    u, v, z = project_columns(XT, view.intrinsic, view.extrinsic)
    with np.errstate(invalid="ignore"):
        inside = (z > 0) & (u >= -0.5) & (u < W - 0.5) & (v >= -0.5) & (v < H - 0.5)
    idx = np.flatnonzero(inside[l0] & inside[l1] & inside[l2] & ~degenerate)
    i0, i1, i2 = l0[idx], l1[idx], l2[idx]
    area = (0.5 * np.abs((u[i1] - u[i0]) * (v[i2] - v[i0]) - (v[i1] - v[i0]) * (u[i2] - u[i0]))).astype(np.float32)
    C = job.centers[i]
    dx, dy, dz = C[0] - cen[0][idx], C[1] - cen[1][idx], C[2] - cen[2][idx]
    dist = np.sqrt(dx * dx + dy * dy + dz * dz)
    n0, n1, n2 = fn[0][idx], fn[1][idx], fn[2][idx]
    cos = (n0 * dx + n1 * dy + n2 * dz) / np.maximum(dist, 1e-300)
    if opts["oblique_reference"] == "ray":
        cos_ref = cos
    else:
        a = -view.axis
        cos_ref = n0 * a[0] + n1 * a[1] + n2 * a[2]
    if opts["two_sided"]:
        cos_ref = np.abs(cos_ref)
        back = np.zeros(len(idx), dtype=bool)
    else:
        back = cos <= 0
    oblique = back | (cos_ref < math.cos(math.radians(opts["max_angle"])))
    if "oblique" not in filters:
        oblique = np.zeros(len(idx), dtype=bool)
    info: dict = {"name": view.name, "depth_source": None}
    M = job.mask(i)
    masked = np.zeros(len(idx), dtype=bool) if M is None else masked_faces(M, u, v, i0, i1, i2)
    if M is not None:
        info["masked_share"] = round(M.share, 6)
    bad_v = known_v = near_v = None
    if "depth" in filters:
        D, info["depth_source"] = job.depth(i)
        if D is not None:
            vid = np.flatnonzero(inside)
            c = np.clip(np.floor(u[vid] + 0.5), 0, W - 1).astype(np.intp)
            r = np.clip(np.floor(v[vid] + 0.5), 0, H - 1).astype(np.intp)
            d = D.at(r, c)
            known_v = np.zeros(len(u), dtype=bool)
            bad_v = np.zeros(len(u), dtype=bool)
            known_v[vid] = d > 0
            zi = z[vid]
            bad_v[vid] = (d > 0) & (np.abs(zi - d) > np.maximum(opts["depth_atol"], opts["depth_tol"] * zi))
            if int(opts["depth_edge_margin"]) > 0:
                edge = depth_edges(D.image(), int(opts["depth_edge_margin"]), opts["depth_atol"], opts["depth_tol"])
                near_v = np.zeros(len(u), dtype=bool)
                near_v[vid] = edge[r, c]
    t1 = time.perf_counter()
    occluded = np.zeros(len(idx), dtype=bool)
    n_rays = 0
    if "occlusion" in filters:
        front = np.flatnonzero(~back & ~masked)  # masked faces: no rays
        ids = idx[front] if cand is None else cand[idx[front]]
        occluded[front], n_rays = occluded_view(job.raycaster, job.X, job.faces, C, ids, area[front], opts,
                                                origin=job.origin, same=job.same)
    t2 = time.perf_counter()
    depth_bad = np.zeros(len(idx), dtype=bool)
    n_known = 0
    if bad_v is not None:
        bad_any = bad_v if near_v is None else (bad_v | near_v)
        depth_bad = bad_any[i0] | bad_any[i1] | bad_any[i2]
        ok = ~occluded & ~back & ~masked
        vert = np.zeros(len(u), dtype=bool)
        for ii in (i0, i1, i2):
            vert[ii[ok]] = True
        vert &= known_v
        n_known = int(vert.sum())
        info["depth_disagreement"] = float(bad_v[vert].mean()) if n_known else 0.0
    flags = occluded.view(np.uint8) * np.uint8(OCCLUDED) | depth_bad.view(np.uint8) * np.uint8(DEPTH) | (
        oblique.view(np.uint8) * np.uint8(OBLIQUE)) | masked.view(np.uint8) * np.uint8(MASKED)  # as uint8 throughout
    faces = (idx if cand is None else cand[idx]).astype(np.int32)
    info.update(valid=int(len(idx)), occluded=int(occluded.sum()), depth_inconsistent=int(depth_bad.sum()),
                oblique=int(oblique.sum()), masked=int(masked.sum()), usable=int(np.count_nonzero(flags == 0)))
    return ViewRecord(faces=faces, flags=flags, area=area, cos_angle=cos.astype(np.float32), info=info,
                      n_rays=int(n_rays), n_known=n_known,
                      seconds={"project+depth": t1 - t0, "occlusion": t2 - t1, "compare": time.perf_counter() - t2})


def summarize_records(views, records: list, opts: dict, *, scene_mesh: object = "") -> dict:
    """The statistics of all views' records (``Visibility.stats`` without the mesh's counts), with the warnings.

    Warns about views whose depth data disagrees with the mesh, a scene without depth, views that
    see no face; raises :class:`~o3d_seqcc.errors.InputError` when no view sees any face.
    """
    filters = opts["filters"]
    V = len(views)
    timings = {f"{step} (sum over views)": float(sum(r.seconds.get(step, 0.0) for r in records))
               for step in ("project+depth", "occlusion", "compare")}  # CPU of all workers
    per_view = [dict(r.info) for r in records]
    for view, r, entry in zip(views, records, per_view):
        if "depth_disagreement" in entry:
            frac = entry["depth_disagreement"]
            if r.n_known >= 30 and frac > opts["max_depth_disagreement"]:
                src = (view.depth if entry["depth_source"] == "depth" else view.point_cloud) or "(in memory)"
                warn(
                    f"view {view.name!r}: {frac:.0%} of the visible mesh vertices disagree with its "
                    f"{entry['depth_source'].replace('_', ' ')} {src} by more than "
                    f"max({opts['depth_atol']}, {opts['depth_tol']:.0%} of depth); is it registered to the mesh "
                    "(same units / depth_scale, same pose)?"
                )
        elif "depth" in filters:
            logger.info("view %r has neither a depth map nor a point cloud: depth-consistency filter skipped", view.name)
    if "depth" in filters and V and not any(v.has_depth for v in views):
        warn("no view has a depth map or a point cloud: the depth-consistency filter is off, so surfaces hidden "
             "from a camera by geometry the mesh lacks may be mapped wrongly; give depth maps (--depth-dir, "
             "load_scene(..., depth_dir=)) when you have them")
    blind = [views[v] for v in range(V) if per_view[v].get("masked_share") == 1.0]
    for view in blind:
        warn(f"view {view.name!r}: its mask {view.mask or '(in memory)'} masks every pixel: the view contributes "
             "nothing (if 0 marks what to keep there, state the other convention: mask_invert / --mask-invert)")
    if V and len(blind) == V:
        raise InputError(f"every photo's mask masks every pixel ({V} views): nothing is left to colour the mesh; if the "
                         "masks mark what to keep with nonzero values, drop mask_invert (--mask-invert), else add it")
    nothing = [views[v].name for v in range(V) if not len(records[v].faces)]
    for name in nothing:
        warn(f"view {name!r} sees no face of the mesh (wrong pose, or looking away?); it gets no mappings")
    if V and len(nothing) == V:
        raise InputError(
            f"no overlap: none of the {V} views sees a face of the mesh {scene_mesh}; "
            "check that the camera poses (extrinsic, world-to-camera) and the mesh use the same coordinate frame"
        )
    for view, entry in zip(views, per_view):
        if entry["valid"] and not entry["usable"]:
            logger.warning("view %r: all %d visible faces were removed by the filters", view.name, entry["valid"])

    def total(key: str) -> int:
        return int(sum(e.get(key, 0) for e in per_view))

    m1 = int(sum(np.count_nonzero((r.flags & OCCLUDED) == 0) for r in records))
    m2 = int(sum(np.count_nonzero((r.flags & (OCCLUDED | DEPTH)) == 0) for r in records))
    masks = any("masked_share" in e for e in per_view)
    m3 = int(sum(np.count_nonzero((r.flags & (OCCLUDED | DEPTH | OBLIQUE)) == 0) for r in records)) if masks else None
    return {
        "n_views": V,
        "n_faces": None,
        "valid": total("valid"),
        "occluded": total("occluded"),
        "depth_inconsistent": total("depth_inconsistent"),
        "oblique": total("oblique"),
        "masked": total("masked"),
        "usable": total("usable"),
        "cumulative": {"valid": total("valid"), "+occlusion": m1, "+depth": m2,
                       **({"+oblique": m3, "+mask": total("usable")} if masks else {"+oblique": total("usable")})},
        "masked_share": {e["name"]: e["masked_share"] for e in per_view if "masked_share" in e},
        "views_seeing_nothing": nothing,
        "views_without_depth": [e["name"] for e in per_view if e["depth_source"] is None],
        "rays": int(sum(r.n_rays for r in records)),
        "per_view": per_view,
        "timings": timings,
    }
