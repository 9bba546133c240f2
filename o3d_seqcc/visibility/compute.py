"""Projection of a mesh into every view and the three visibility filters (paper 3.1-3.2).

For every view ``v`` and mesh face ``f``:

* **valid** (3.1): the face is not degenerate (zero 3D area) and its three vertices project
  inside the image, ``-0.5 <= u < W - 0.5`` and ``-0.5 <= v < H - 0.5`` (pixel centres at
  integers), in front of the camera (``z > 0``).
* **occluded** (3.2, z-buffering): some test point of the face is hidden by the mesh. The test
  points are the three vertices, plus, for faces whose projection is large (more than
  ``2 * occlusion_spacing**2`` px^2), the points of a barycentric grid spaced about
  ``occlusion_spacing`` px, so that a big face partly hidden by a thin occluder is caught (the
  paper's face-overlap rule). A point at distance ``d`` from the camera centre is hidden when an
  Open3D ``RaycastingScene`` any-hit query finds a triangle on the segment from the centre at a
  distance ``< d * (1 - occlusion_tol) - occlusion_atol``. Back-facing faces are not ray-tested
  (they are removed as oblique anyway).
* **depth_inconsistent** (3.2, depth consistency): the view's measured depth disagrees with the
  mesh. The depth image is the view's depth map, or else a rendering of its partial point cloud
  (nearest point per pixel, small holes filled with OpenCV's Navier-Stokes inpainting); a vertex
  is inconsistent when the depth image at its pixel (nearest) is non-zero and
  ``|z_mesh - z_image| > max(depth_atol, depth_tol * z_mesh)``; a face is inconsistent when any
  of its vertices is. Missing depth (0) is no evidence either way. Views with neither depth map
  nor point cloud skip this filter (logged). Optionally (``depth_edge_margin``) faces near depth
  discontinuities are dropped too.
* **oblique** (3.2, camera viewpoint): the angle between the face normal and the viewing
  direction exceeds ``max_angle``. The viewing direction is the ray from the face centroid to
  the camera centre (``oblique_reference="ray"``, default) or the reversed focal axis
  (``"axis"``, the paper's choice). Faces seen from behind (normal pointing away from the
  camera centre) are always oblique unless ``two_sided=True``.
* **masked** (a photo's mask, :mod:`o3d_seqcc.visibility.masks`): the face's projection comes
  within 4 px of a pixel the mask leaves out; such a face is not ray-tested. Views without a
  mask skip it; it is always on (give no mask to turn it off).

Face normals come from the winding and are flipped where they disagree with the mesh's vertex
normals (which :func:`~o3d_seqcc.scene.load_mesh` computes when the file has none).

Storage is sparse: :class:`Visibility` keeps one small :class:`~o3d_seqcc.visibility.per_view.ViewRecord`
per view (the ids of the faces valid in it, a filter bit per face, projected areas, angles),
computed by one task per view (:mod:`o3d_seqcc.visibility.per_view`; local threads or a Dask
cluster, :mod:`o3d_seqcc._shared.parallel`). Vertex projections are recomputed from the cameras when
asked for (:meth:`Visibility.vertex_uv`). Every stage reads it through one protocol,
:class:`~o3d_seqcc.visibility.dense.VisibilityLike` (the sparse methods); the dense (V, F) and
(V, N) arrays (``valid``, ``usable``, ``area``, ``uv``, ...) are for tests and figures only:
:meth:`Visibility.to_dense` (:mod:`o3d_seqcc.visibility.dense`), never built by ``run``.
"""


from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from ..geometry.camera import project_columns, project_points
from .depthmaps import depth_from_point_cloud
from ..errors import InputError, warn
from ..imaging.sequences import LRUCache
from ..geometry.meshops import oriented_face_normals
from .._shared.parallel import current as current_executor
from ..scene import Mesh, load_mesh
from .refine import refine_visibility
from .stray import drop_faces, stray_faces
from .dense import DenseViews, DenseVisibility, UsableFaces, VisibilityLike
from .per_view import ViewRecord, VisibilityJob, summarize_records, view_record
from .settings import FILTERS, VisibilitySettings
from .subpixel import subpixel_faces, warn_subpixel

__all__ = [
    "FILTERS",
    "DenseVisibility",
    "UsableFaces",
    "ViewRecord",
    "Visibility",
    "VisibilityLike",
    "VisibilitySettings",
    "compute_visibility",
    "depth_from_point_cloud",
    "project_points",
]  # depth_from_point_cloud (:mod:`.depthmaps`) and project_points (:mod:`.camera`) re-exported

logger = logging.getLogger(__name__)


_DENSE = ("valid", "occluded", "depth_inconsistent", "oblique", "usable", "area", "cos_angle", "uv", "depth", "_XT",
          "_cache")
#: :meth:`Visibility.face_uv` rounds pixel coordinates to 1 / this (1/8 px moved texture coordinates off the
#: photo by up to 1/16 px: a rendered-back photo kept 0.93 of its sharpness, 0.99 at 1/256)
FACE_UV_STEPS = 256
#: byte budget of a visibility's cache of per-view usable face ids and whole-mesh projections (past it, a view's
#: projection is computed for the vertices asked for; 128 MB held 60 MB of Fountain 300k's projections through the
#: whole bake, which recomputes them in milliseconds)
CACHE_BYTES = 32 * 2**20


@dataclass(frozen=True, eq=False)
class Visibility(DenseViews):
    """Per-view visibility of the mesh faces, one sparse record per view.

    Attributes
    ----------
    mesh : Mesh
        The mesh the records refer to.
    records : tuple of ViewRecord
        Per view: ids of the valid faces (ascending int32), filter bits, projected areas (px^2,
        float32) and cosines (float32); see :class:`~o3d_seqcc.visibility.per_view.ViewRecord`.
    stats : dict
        Counts (face-view incidences) per filter, per view and timings; see
        :func:`compute_visibility`.
    view_names : tuple of str
    options : dict
        The filter parameters used.
    cameras : tuple of ((V, 3, 3), (V, 4, 4)) float64 arrays, optional
        Intrinsics and extrinsics: vertex projections are computed from them on demand.
    uv_table : tuple of ((V, N, 2), (V, N)) float32 arrays, optional
        Stored vertex projections and depths instead (:meth:`from_arrays`).
    image_sizes : tuple of (width, height), optional
        Every view's image size in pixels (what ``t_npm="auto"`` is derived from).
    parent_faces : (F,) int64, optional
        The face of the input mesh each face of ``mesh`` is part of, when faces were split
        (``split_faces``); None when ``mesh`` is the input mesh.
    settings : VisibilitySettings, optional
        The options :func:`compute_visibility` ran with (None for :meth:`from_arrays`).

    The stages read it through :class:`~o3d_seqcc.visibility.dense.VisibilityLike` (the sparse
    methods below). Dense views for tests and figures (:class:`~o3d_seqcc.visibility.dense.DenseViews`,
    memory V x F): :meth:`to_dense`, and the same arrays as cached read-only properties ``valid``,
    ``occluded``, ``depth_inconsistent``, ``oblique``, ``usable`` (V, F) bool, ``area``,
    ``cos_angle`` (V, F) float32 (0 where not valid), ``uv`` (V, N, 2) float32 and ``depth``
    (V, N) float32; :meth:`from_dense` builds a visibility from such arrays.
    """

    mesh: Mesh
    records: tuple
    stats: dict = field(default_factory=dict)
    view_names: tuple[str, ...] = ()
    options: dict[str, Any] = field(default_factory=dict)
    cameras: tuple | None = None
    uv_table: tuple | None = None
    image_sizes: tuple | None = None
    parent_faces: np.ndarray | None = None
    settings: VisibilitySettings | None = None

    # ---- shape ---------------------------------------------------------------------------

    @property
    def n_views(self) -> int:
        return len(self.records)

    @property
    def n_faces(self) -> int:
        return int(len(self.mesh.faces))

    # ---- sparse access -------------------------------------------------------------------

    def valid_faces(self, v: int) -> np.ndarray:
        """(k,) int64 ascending ids of the faces valid in view ``v``."""
        return self.records[v].faces.astype(np.int64)

    @cached_property
    def _cache(self) -> LRUCache:
        return LRUCache(CACHE_BYTES)

    def usable_faces(self, v: int) -> np.ndarray:
        """(k,) int64 ascending ids of the faces usable in view ``v`` (cached; do not modify)."""
        r = self.records[v]
        return self._cache.get(("usable", v), lambda: r.faces[r.flags == 0].astype(np.int64))

    def usable_area(self, v: int) -> np.ndarray:
        """(k,) float32 projected areas (px^2) of :meth:`usable_faces` in view ``v`` (cached; do not modify)."""
        r = self.records[v]
        return self._cache.get(("usable_area", v), lambda: r.area[r.flags == 0])

    def usable_entries(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every usable (view, face) incidence, view-major (CSR rows = views).

        Returns
        -------
        indptr : (V+1,) int64
            Entries ``indptr[v]:indptr[v+1]`` belong to view ``v``.
        faces : (nnz,) int32
            Face ids, ascending within a view.
        area, cos_angle : (nnz,) float32
        """
        keep = [r.flags == 0 for r in self.records]
        counts = np.array([int(k.sum()) for k in keep], dtype=np.int64)
        indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        if not len(self.records):
            e = np.zeros(0, np.float32)
            return indptr, np.zeros(0, np.int32), e, e
        faces = np.concatenate([r.faces[k] for r, k in zip(self.records, keep)])
        area = np.concatenate([r.area[k] for r, k in zip(self.records, keep)])
        cos = np.concatenate([r.cos_angle[k] for r, k in zip(self.records, keep)])
        return indptr, faces, area, cos

    def usable_counts(self) -> np.ndarray:
        """(V,) int64: the number of usable faces of every view."""
        return np.array([int(np.count_nonzero(r.flags == 0)) for r in self.records], dtype=np.int64)

    def vertex_projection(self, v: int, vertex_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates and camera depths of some vertices in view ``v``.

        Parameters
        ----------
        v : int
        vertex_ids : (n,) int
            Any vertex ids (repeats allowed).

        Returns
        -------
        uv : (n, 2) float32
            NaN at or behind the camera plane.
        z : (n,) float32
        """
        ids = np.asarray(vertex_ids, dtype=np.int64).reshape(-1)
        if self.uv_table is not None:
            return self.uv_table[0][v][ids], self.uv_table[1][v][ids]
        if self.cameras is None:
            raise InputError("this visibility holds no vertex projections (Visibility.from_dense without uv=): it "
                             "serves the view selection only")
        n = self._XT.shape[1]
        if 12 * n * self.n_views <= CACHE_BYTES:  # every view's whole projection fits the cache: keep them
            uv, z = self._cache.get(("projection", v), lambda: self._project(v, None))
            return _gather(uv, z, ids)
        mark = np.zeros(n, dtype=bool)
        mark[ids] = True
        uniq = np.flatnonzero(mark)  # each vertex projected once
        uv, z = self._project(v, uniq)
        local = np.empty(n, dtype=np.int64)
        local[uniq] = np.arange(len(uniq))
        return _gather(uv, z, local[ids])

    def _project(self, v: int, ids: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        K, E = self.cameras
        XT = self._XT if ids is None else np.ascontiguousarray(self._XT[:, ids])
        u, vv, z = project_columns(XT, K[v], E[v])
        return np.stack([u, vv], axis=1).astype(np.float32), z.astype(np.float32)

    def vertex_uv(self, v: int, vertex_ids: np.ndarray) -> np.ndarray:
        """(n, 2) float32 pixel coordinates of some vertices in view ``v`` (see :meth:`vertex_projection`)."""
        return self.vertex_projection(v, vertex_ids)[0]

    def face_uv(self, selection: np.ndarray) -> np.ndarray:
        """Pixel coordinates of every face's corners in its selected view.

        Parameters
        ----------
        selection : (F,) int
            A view per face, -1 for none.

        Returns
        -------
        (F, 3, 2) float64
            NaN for faces with no view (and corners behind the camera). Rounded to 1/256 px
            (:data:`FACE_UV_STEPS`): the texturing's charts are these, and its atlas packing reacts
            to any change of them, so the ~1e-7 px that float64 rounding moves a projection of a
            scene 1e7 m from the origin must not reach it (the same scene at the origin then gives
            the same bytes).
        """
        labels = np.asarray(selection, dtype=np.int64).reshape(-1)
        if labels.shape != (self.n_faces,):
            raise InputError(f"selection has {labels.size} entries but the mesh has {self.n_faces} faces")
        out = np.full((self.n_faces, 3, 2), np.nan)
        if labels.size and labels.max() >= self.n_views:
            raise InputError(f"selection holds view indices outside -1..{self.n_views - 1}")
        seen = np.flatnonzero(labels >= 0)
        order = seen[np.argsort(labels[seen], kind="stable")]
        views, starts = np.unique(labels[order], return_index=True)
        ends = np.r_[starts[1:], len(order)]
        faces = np.asarray(self.mesh.faces)
        for v, s0, s1 in zip(views, starts, ends):
            fs = order[s0:s1]
            out[fs] = self.vertex_uv(int(v), faces[fs].reshape(-1)).reshape(-1, 3, 2)
        return np.round(out * FACE_UV_STEPS) / FACE_UV_STEPS

    @cached_property
    def _XT(self) -> np.ndarray:
        return np.ascontiguousarray(np.asarray(self.mesh.vertices, dtype=np.float64).T)

    @property
    def nbytes(self) -> int:
        """Bytes held by the per-view records."""
        return int(sum(r.nbytes for r in self.records))

    def __getstate__(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k not in _DENSE}


def _gather(uv: np.ndarray, z: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(uv[ids], z[ids])`` of (n, 2) float32 pixel coordinates and (n,) depths: the coordinate pairs taken as
    one 8-byte item each (a one-dimensional take, several times faster than numpy's row indexing; the same
    bits)."""
    pairs = np.take(uv.view(np.float64).reshape(-1), ids)
    return pairs.view(np.float32).reshape(-1, 2), np.take(z, ids)


# --------------------------------------------------------------------------------------------
# main entry point
# --------------------------------------------------------------------------------------------


def compute_visibility(
    scene,
    *,
    mesh: Mesh | str | os.PathLike | None = None,
    settings: VisibilitySettings | None = None,
    n_jobs: int | None = None,
    **options: Any,
) -> Visibility:
    """Project the mesh into every view and apply the paper's three filters.

    Parameters
    ----------
    scene : Scene
    mesh : Mesh or path, optional
        Default ``scene.load_mesh()``.
    settings : VisibilitySettings, optional
        The filter and split options; default :class:`~o3d_seqcc.visibility.settings.VisibilitySettings`
        (its attributes document each option, its range and default).
    n_jobs : int, optional
        Threads for the per-view tasks (projection, depth maps, ray queries), joblib semantics
        (None: the active ``joblib.parallel_config`` or 1; -1: all cores). Inside
        :func:`o3d_seqcc._shared.parallel.use` with a Dask client the tasks run on its cluster instead.
    **options
        Fields of :class:`~o3d_seqcc.visibility.settings.VisibilitySettings` changed from
        ``settings`` (``occlusion_tol``, ``depth_tol``, ``max_angle``, ``filters``,
        ``split_faces``, ...; None: the settings' value).

    Returns
    -------
    Visibility
        One sparse record per view (``settings``: the options used). ``stats`` has ``n_views``, ``n_faces``, ``degenerate_faces``,
        ``normals_flipped``, ``split`` (:class:`~o3d_seqcc.visibility.refine.Refinement` stats), the totals (face-view incidences) ``valid``, ``occluded``,
        ``depth_inconsistent``, ``oblique``, ``masked``, ``usable``, the cumulative counts of Figure 3 (``cumulative``;
        ``+mask`` last when a view has a mask), ``masked_share`` (view name -> the share of its pixels its mask
        leaves out, for the views with one), ``per_view`` (a list of dicts with the same counts plus
        ``depth_source`` and ``masked_share``),
        ``views_seeing_nothing`` (names), ``rays`` and ``timings`` (seconds per stage).

    Raises
    ------
    InputError
        No view sees any face; depth maps of the wrong size or dtype; unreadable point clouds;
        an unknown filter or ``oblique_reference``, out-of-range thresholds (a ``ValueError``).
    UnknownSettingError
        An option that is not a field of the settings (a ``TypeError``).

    Examples
    --------
    >>> import tempfile, o3d_seqcc as sc
    >>> room = sc.make_synthetic_scene(tempfile.mkdtemp() + '/room', n_views=3, width=96, height=72, seed=1,
    ...                                seen_only=True)
    >>> vis = sc.compute_visibility(room.scene)
    >>> len(vis.usable_counts()), bool((vis.usable_counts() > 0).all())
    (3, True)
    """
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    vs = VisibilitySettings.resolve(settings, options, where="compute_visibility")
    split_faces = vs.split_faces
    opts = vs.filter_options()
    if mesh is None:
        mesh = scene.load_mesh()
    elif not isinstance(mesh, Mesh):
        mesh = load_mesh(mesh)
    X = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    vn = getattr(mesh, "vertex_normals", None)
    if vn is None or np.shape(vn) != X.shape or not np.all(np.isfinite(vn)):
        import open3d as o3d

        m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(X), o3d.utility.Vector3iVector(faces.astype(np.int32)))
        m.compute_vertex_normals()
        logger.info("mesh has no (valid) vertex normals: computed them from the winding")
        mesh = Mesh(vertices=X, faces=faces, vertex_normals=np.asarray(m.vertex_normals, dtype=np.float64))
    fn, degenerate, flipped = oriented_face_normals(mesh.vertices, mesh.faces, getattr(mesh, "vertex_normals", None))
    if degenerate.any():
        logger.info("%d degenerate (zero-area) faces excluded", int(degenerate.sum()))
    if flipped:
        logger.info("%d face normals flipped to agree with the vertex normals", flipped)
    views = scene.views
    job = VisibilityJob(views, X, faces, fn, degenerate, opts)
    del fn
    timings["prepare"] = time.perf_counter() - t0

    t1 = time.perf_counter()
    ex = current_executor(n_jobs)
    records: list[ViewRecord] = ex.map(view_record, range(len(views)), ex.share(job), desc="visibility", unit="view")
    timings["views"] = time.perf_counter() - t1
    subpixel = subpixel_faces(records, len(faces))
    warn_subpixel(subpixel, f" of the mesh {scene.mesh}" if isinstance(getattr(scene, "mesh", None), (str, os.PathLike))
                  else "")
    parent, split = None, {"rounds": 0, "input_faces": int(len(faces)), "faces_split": 0, "faces_added": 0}
    stray = stray_faces(X, faces, records, np.array([v.center for v in views]).reshape(-1, 3))
    if stray.any():  # far-away junk no photo sees: it would set the scene's scale (the split's too) and take the atlas
        mesh, records, far = drop_faces(mesh, records, stray)
        n, degenerate, parent = int(stray.sum()), degenerate[~stray], np.flatnonzero(~stray).astype(np.int64)
        if split_faces:  # the kept faces, ray cast against the whole mesh as before (its tree and depth images)
            job = VisibilityJob(views, mesh.vertices, mesh.faces, np.stack(job.fn, axis=1)[~stray], degenerate, opts,
                                occluder=job)
        where = f" {scene.mesh}" if isinstance(getattr(scene, "mesh", None), (str, os.PathLike)) else ""
        warn(f"{n} face{'s' if n > 1 else ''} of the mesh{where} lie far from everything the photos see (up to "
             f"{far:.3g} scene units away: floating junk of the scan?) and no photo sees them: left out of the "
             "visibility, the atlas and the textured mesh; remove them from the mesh to silence this")
    if split_faces:
        t1 = time.perf_counter()
        ref = refine_visibility(job, records, ex, vertex_normals=mesh.vertex_normals, min_px=vs.split_min_px,
                                max_distortion=vs.split_max_distortion, max_rounds=vs.split_max_rounds)
        split = {**ref.stats, "input_faces": int(len(faces))}
        if split["faces_added"]:
            mesh = Mesh(vertices=ref.vertices, faces=ref.faces, vertex_normals=ref.vertex_normals)
            records, degenerate = ref.records, ref.degenerate
            parent = ref.parent if parent is None else parent[ref.parent]
            logger.info("split %d faces no view holds whole into parts (%d faces more, %d rounds)",
                        split["faces_split"], split["faces_added"], split["rounds"])
        timings["split_faces"] = time.perf_counter() - t1
    del job
    stats = summarize_records(views, records, opts, scene_mesh=getattr(scene, "mesh", ""))
    timings.update(stats["timings"])
    stats.update(n_faces=int(len(mesh.faces)), degenerate_faces=int(degenerate.sum()), normals_flipped=flipped,
                 split={"enabled": bool(split_faces), **split}, stray_faces=int(stray.sum()), subpixel=subpixel,
                 timings=timings)
    timings["total"] = time.perf_counter() - t0
    logger.info(
        "visibility: %d views x %d faces: valid %d, occluded %d, depth-inconsistent %d, oblique %d -> usable %d (%.2f s)",
        len(views), len(mesh.faces), stats["valid"], stats["occluded"], stats["depth_inconsistent"], stats["oblique"],
        stats["usable"], timings["total"],
    )
    V = len(views)
    cams = (np.stack([np.asarray(v.intrinsic, np.float64) for v in views]) if V else np.zeros((0, 3, 3)),
            np.stack([np.asarray(v.extrinsic, np.float64) for v in views]) if V else np.zeros((0, 4, 4)))
    return Visibility(mesh=mesh, records=tuple(records), stats=stats, view_names=tuple(v.name for v in views),
                      options=opts, cameras=cams, image_sizes=tuple((int(v.width), int(v.height)) for v in views),
                      parent_faces=parent, settings=vs)
