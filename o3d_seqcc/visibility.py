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

Face normals come from the winding and are flipped where they disagree with the mesh's vertex
normals (which :func:`~o3d_seqcc.scene.load_mesh` computes when the file has none).
"""

from __future__ import annotations

import logging
import math
import os
import time
from dataclasses import dataclass, field
from typing import Any, Iterable

import numpy as np

from .camera import project_columns, project_points
from .depthmaps import depth_edges, depth_from_point_cloud
from .errors import InputError, warn
from .meshops import oriented_face_normals
from .occlusion import occluded_faces
from .progress import track
from .scene import Mesh, load_mesh

__all__ = [
    "FILTERS",
    "UsableFaces",
    "Visibility",
    "compute_visibility",
    "depth_from_point_cloud",
    "project_points",
]  # depth_from_point_cloud (:mod:`.depthmaps`) and project_points (:mod:`.camera`) re-exported

logger = logging.getLogger(__name__)

#: names of the filters of :func:`compute_visibility`
FILTERS = ("occlusion", "depth", "oblique")


class UsableFaces:
    """Shape of a (V, F) ``usable`` face mask: what every per-view visibility record exposes."""

    usable: np.ndarray

    @property
    def n_views(self) -> int:
        return int(self.usable.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.usable.shape[1])


@dataclass(frozen=True, eq=False)
class Visibility(UsableFaces):
    """Per-view visibility of every mesh face.

    Attributes
    ----------
    uv : (V, N, 2) float32
        Pixel coordinates (x right, y down, pixel centres at integers) of every mesh vertex in
        every view; NaN for vertices at or behind the camera plane (z <= 0).
    depth : (V, N) float32
        Camera z of every vertex in every view (scene units; <= 0 behind the camera).
    valid : (V, F) bool
        All three vertices project inside ``[-0.5, W-0.5) x [-0.5, H-0.5)`` with z > 0, and the
        face is not degenerate (zero 3D area).
    occluded, depth_inconsistent, oblique : (V, F) bool
        Faces removed by each filter (each a subset of ``valid``; computed independently, except
        that back-facing faces are not ray-tested for occlusion).
    usable : (V, F) bool
        ``valid & ~occluded & ~depth_inconsistent & ~oblique``.
    area : (V, F) float32
        Projected face area in px^2 (0 where not valid).
    cos_angle : (V, F) float32
        Cosine between the (oriented) face normal and the unit direction from the face centroid
        to the camera centre (negative: seen from behind; 0 for degenerate faces).
    stats : dict
        Counts (face-view incidences) per filter, per view and timings; see
        :func:`compute_visibility`.
    mesh : Mesh
        The mesh the arrays refer to.
    view_names : tuple of str
    options : dict
        The filter parameters used.
    """

    uv: np.ndarray
    depth: np.ndarray
    valid: np.ndarray
    occluded: np.ndarray
    depth_inconsistent: np.ndarray
    oblique: np.ndarray
    usable: np.ndarray
    area: np.ndarray
    cos_angle: np.ndarray
    stats: dict
    mesh: Mesh
    view_names: tuple[str, ...] = ()
    options: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_arrays(
        cls, mesh: Mesh, uv: np.ndarray, usable: np.ndarray, *, area: np.ndarray | None = None,
        cos_angle: np.ndarray | None = None, depth: np.ndarray | None = None, view_names: tuple[str, ...] = (),
    ) -> "Visibility":
        """A visibility from your own per-view arrays (no filter run: ``valid = usable``).

        Parameters
        ----------
        mesh : Mesh
        uv : (V, N, 2) float
            Pixel coordinates of every vertex in every view.
        usable : (V, F) bool
        area, cos_angle : (V, F) float, optional
            Projected face areas (px^2; default: computed from ``uv``) and cosines (default 1).
        depth : (V, N) float, optional
            Camera z of every vertex (default 1).
        view_names : tuple of str
        """
        uv = np.asarray(uv, dtype=np.float32)
        usable = np.asarray(usable, dtype=bool)
        V, F = usable.shape
        faces = np.asarray(mesh.faces)
        if uv.shape != (V, len(mesh.vertices), 2) or F != len(faces):
            raise InputError(f"uv must be ({V}, {len(mesh.vertices)}, 2) and usable ({V}, {len(faces)}), got "
                             f"{uv.shape} and {usable.shape}")
        if area is None:
            p = uv[:, faces].astype(np.float64)
            e1, e2 = p[:, :, 1] - p[:, :, 0], p[:, :, 2] - p[:, :, 0]
            area = 0.5 * np.abs(e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0])
        none = np.zeros((V, F), dtype=bool)
        return cls(uv=uv, depth=np.ones(uv.shape[:2], np.float32) if depth is None else np.asarray(depth, np.float32),
                   valid=usable.copy(), occluded=none, depth_inconsistent=none, oblique=none, usable=usable,
                   area=np.asarray(area, dtype=np.float32),
                   cos_angle=np.ones((V, F), np.float32) if cos_angle is None else np.asarray(cos_angle, np.float32),
                   stats={}, mesh=mesh, view_names=tuple(view_names))

    def face_uv(self, selection: np.ndarray) -> np.ndarray:
        """Pixel coordinates of every face's corners in its selected view.

        Parameters
        ----------
        selection : (F,) int
            A view per face, -1 for none.

        Returns
        -------
        (F, 3, 2) float64
            NaN for faces with no view (and corners behind the camera).
        """
        labels = np.asarray(selection, dtype=np.int64).reshape(-1)
        if labels.shape != (self.n_faces,):
            raise InputError(f"selection has {labels.size} entries but the mesh has {self.n_faces} faces")
        out = np.full((self.n_faces, 3, 2), np.nan)
        seen = labels >= 0
        if labels.size and labels.max() >= self.n_views:
            raise InputError(f"selection holds view indices outside -1..{self.n_views - 1}")
        faces = np.asarray(self.mesh.faces)
        out[seen] = self.uv[labels[seen][:, None], faces[seen]]
        return out

    def usable_counts(self) -> np.ndarray:
        """(V,) int64: the number of usable faces of every view."""
        return np.asarray(self.usable).sum(axis=1).astype(np.int64)

    def stage_masks(self) -> dict[str, np.ndarray]:
        """Cumulative (V, F) masks as in the paper's Figure 3.

        Keys ``"valid"``, ``"+occlusion"``, ``"+depth"``, ``"+oblique"`` (= ``usable``).
        """
        m1 = self.valid & ~self.occluded
        m2 = m1 & ~self.depth_inconsistent
        return {"valid": self.valid, "+occlusion": m1, "+depth": m2, "+oblique": m2 & ~self.oblique}


# --------------------------------------------------------------------------------------------
# main entry point
# --------------------------------------------------------------------------------------------


class _Geometry:
    """Column-major copies of the mesh arrays used by the per-view work (no BLAS in hot paths)."""

    def __init__(self, mesh: Mesh, fn: np.ndarray, degenerate: np.ndarray) -> None:
        X = np.asarray(mesh.vertices, dtype=np.float64)
        f = np.asarray(mesh.faces, dtype=np.int64)
        self.n_vertices = len(X)
        self.XT = np.ascontiguousarray(X.T)  # (3, N)
        self.f0, self.f1, self.f2 = (np.ascontiguousarray(f[:, i]) for i in range(3))
        cen = X[f].mean(axis=1)
        self.cen = [np.ascontiguousarray(cen[:, i]) for i in range(3)]
        self.fn = [np.ascontiguousarray(fn[:, i]) for i in range(3)]
        self.degenerate = degenerate

    def any3(self, vert_mask: np.ndarray) -> np.ndarray:
        return vert_mask[self.f0] | vert_mask[self.f1] | vert_mask[self.f2]

    def all3(self, vert_mask: np.ndarray) -> np.ndarray:
        return vert_mask[self.f0] & vert_mask[self.f1] & vert_mask[self.f2]


def _per_view(view, i: int, g: _Geometry, opts, res: dict[str, np.ndarray]) -> dict:
    """Projection, validity, area, angles and the depth-consistency test of view ``i``.

    Writes row ``i`` of the (V, ...) arrays in ``res``; returns the per-vertex depth test.
    """
    W, H = view.width, view.height
    u, v, z = project_columns(g.XT, view.intrinsic, view.extrinsic)
    with np.errstate(invalid="ignore"):
        inside = (z > 0) & (u >= -0.5) & (u < W - 0.5) & (v >= -0.5) & (v < H - 0.5)
    valid = g.all3(inside) & ~g.degenerate
    idx = np.flatnonzero(valid)
    i0, i1, i2 = g.f0[idx], g.f1[idx], g.f2[idx]
    area = res["area"][i]
    area[idx] = 0.5 * np.abs((u[i1] - u[i0]) * (v[i2] - v[i0]) - (v[i1] - v[i0]) * (u[i2] - u[i0]))
    C = view.center
    dx, dy, dz = C[0] - g.cen[0], C[1] - g.cen[1], C[2] - g.cen[2]
    dist = np.sqrt(dx * dx + dy * dy + dz * dz)
    cos = (g.fn[0] * dx + g.fn[1] * dy + g.fn[2] * dz) / np.maximum(dist, 1e-300)
    if opts["oblique_reference"] == "ray":
        cos_ref = cos
    else:
        a = -view.axis
        cos_ref = g.fn[0] * a[0] + g.fn[1] * a[1] + g.fn[2] * a[2]
    if opts["two_sided"]:
        cos_ref = np.abs(cos_ref)
        back = np.zeros_like(valid)
    else:
        back = cos <= 0
    res["oblique"][i] = valid & (back | (cos_ref < math.cos(math.radians(opts["max_angle"]))))
    res["uv"][i, :, 0] = u
    res["uv"][i, :, 1] = v
    res["depth"][i] = z
    res["valid"][i] = valid
    res["cos_angle"][i] = cos
    res["back"][i] = valid & back
    out = {
        "depth_source": None,
        "vertex_depth_bad": None,
        "vertex_depth_known": None,
    }
    if "depth" not in opts["filters"]:
        return out
    D = view.load_depth()  # raises InputError naming the file on wrong size / dtype
    if D is not None:
        out["depth_source"] = "depth"
    else:
        points = view.load_points()
        if points is not None:
            D = depth_from_point_cloud(points, view.intrinsic, view.extrinsic, W, H, fill_radius=opts["fill_radius"])
            out["depth_source"] = "point_cloud"
    if D is None:
        return out
    vid = np.flatnonzero(inside)
    c = np.clip(np.floor(u[vid] + 0.5), 0, W - 1).astype(np.intp)
    r = np.clip(np.floor(v[vid] + 0.5), 0, H - 1).astype(np.intp)
    d = D[r, c]
    known = np.zeros(g.n_vertices, dtype=bool)
    bad = np.zeros(g.n_vertices, dtype=bool)
    known[vid] = d > 0
    zi = z[vid]
    bad[vid] = (d > 0) & (np.abs(zi - d) > np.maximum(opts["depth_atol"], opts["depth_tol"] * zi))
    out["vertex_depth_bad"] = bad
    out["vertex_depth_known"] = known
    margin = int(opts["depth_edge_margin"])
    if margin > 0:
        edge = depth_edges(D, margin, opts["depth_atol"], opts["depth_tol"])
        near = np.zeros(g.n_vertices, dtype=bool)
        near[vid] = edge[r, c]
        out["vertex_near_edge"] = near
    return out


def compute_visibility(
    scene,
    *,
    mesh: Mesh | str | os.PathLike | None = None,
    occlusion_tol: float = 0.01,
    occlusion_atol: float = 1e-3,
    occlusion_spacing: float = 4.0,
    occlusion_max_level: int = 64,
    depth_tol: float = 0.03,
    depth_atol: float = 0.05,
    max_depth_disagreement: float = 0.5,
    fill_radius: int = 6,
    depth_edge_margin: int = 0,
    max_angle: float = 75.0,
    oblique_reference: str = "ray",
    two_sided: bool = False,
    filters: Iterable[str] = FILTERS,
    n_jobs: int | None = None,
) -> Visibility:
    """Project the mesh into every view and apply the paper's three filters.

    Parameters
    ----------
    scene : Scene
    mesh : Mesh or path, optional
        Default ``scene.load_mesh()``.
    occlusion_tol : float, default 0.01
        Relative z-buffer tolerance: a test point at distance ``d`` is hidden when the mesh is hit
        closer than ``d * (1 - occlusion_tol) - occlusion_atol``.
    occlusion_atol : float, default 1e-3
        Absolute z-buffer tolerance in scene units (1 mm for metric scenes).
    occlusion_spacing : float, default 4.0
        Spacing in px of the interior test points of faces larger than ``2 * spacing**2`` px^2;
        0 tests vertices only.
    occlusion_max_level : int, default 64
        Cap on the interior grid level (at most ~2000 test points per face and view).
    depth_tol : float, default 0.03
        Relative depth-consistency threshold (3 % of the mesh depth) ...
    depth_atol : float, default 0.05
        ... with this absolute floor in scene units (5 cm): inconsistent when
        ``|z_mesh - z_image| > max(depth_atol, depth_tol * z_mesh)``. The defaults absorb the
        few-cm noise of consumer depth sensors and TSDF meshes; a 30 cm disagreement is caught
        up to 10 m.
    max_depth_disagreement : float, default 0.5
        Warn when more than this fraction of the vertices of a view's valid, unoccluded faces
        disagree with its depth data (depth map or point cloud not registered to the mesh?).
    fill_radius : int, default 6
        Hole filling of depth images rendered from point clouds, see
        :func:`depth_from_point_cloud`. Depth maps are used as they are (0 = no evidence).
    depth_edge_margin : int, default 0
        Also mark as depth-inconsistent the faces with a vertex within this many pixels of a
        depth discontinuity (a jump beyond the depth tolerance in the depth image). Guards
        against colour/depth misregistration (fountain: 2-17 px) sampling the wrong side of an
        occluding contour; 0 (the paper) disables it.
    max_angle : float, default 75.0
        Oblique threshold in degrees between the face normal and the viewing direction.
    oblique_reference : {"ray", "axis"}, default "ray"
        Viewing direction: from the face centroid to the camera centre, or the camera's focal
        axis (the paper). "ray" is the default because at the image border the focal axis
        underestimates the true viewing angle by up to the half field of view.
    two_sided : bool, default False
        Treat faces as two-sided (no back-face removal; angles use ``|cos|``). For meshes with
        unreliable orientation.
    filters : iterable of str, default all of ``FILTERS``
        Filters to apply (``"occlusion"``, ``"depth"``, ``"oblique"``); disabled filters give
        all-False masks.
    n_jobs : int, optional
        Workers for the per-view work (projection, depth maps), joblib semantics (None: the
        active ``joblib.parallel_config`` or 1; -1: all cores); threads are preferred.
        The ray queries use all cores through Open3D.

    Returns
    -------
    Visibility
        ``stats`` has ``n_views``, ``n_faces``, ``degenerate_faces``, ``normals_flipped``, the
        totals (face-view incidences) ``valid``, ``occluded``, ``depth_inconsistent``,
        ``oblique``, ``usable``, the cumulative counts of Figure 3 (``cumulative``),
        ``per_view`` (a list of dicts with the same counts plus ``depth_source``),
        ``views_seeing_nothing`` (names), ``rays`` and ``timings`` (seconds per stage).

    Raises
    ------
    InputError
        No view sees any face; depth maps of the wrong size or dtype; unreadable point clouds.
    ValueError
        Unknown filter or ``oblique_reference``, out-of-range thresholds.
    """
    from joblib import Parallel, delayed

    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    filters = tuple(filters)
    unknown = set(filters) - set(FILTERS)
    if unknown:
        raise ValueError(f"unknown filter(s) {sorted(unknown)}; valid: {', '.join(FILTERS)}")
    if oblique_reference not in ("ray", "axis"):
        raise ValueError(f"unknown oblique_reference {oblique_reference!r}; valid: 'ray', 'axis'")
    if not 0.0 < float(max_angle) <= 180.0:
        raise InputError(f"max_angle (--max-angle) must be in (0, 180] degrees, got {max_angle}")
    if not (0 <= occlusion_tol < 1 and occlusion_atol >= 0):
        raise InputError(f"occlusion_tol (--occlusion-tol) must be in [0, 1) and occlusion_atol >= 0, "
                         f"got {occlusion_tol}, {occlusion_atol}")
    if not (depth_tol >= 0 and depth_atol >= 0):
        raise InputError(f"depth_tol (--depth-tol) and depth_atol (--depth-atol) must be >= 0, got {depth_tol}, {depth_atol}")
    opts = {
        "occlusion_tol": float(occlusion_tol),
        "occlusion_atol": float(occlusion_atol),
        "occlusion_spacing": float(occlusion_spacing),
        "occlusion_max_level": int(occlusion_max_level),
        "depth_tol": float(depth_tol),
        "depth_atol": float(depth_atol),
        "max_depth_disagreement": float(max_depth_disagreement),
        "fill_radius": int(fill_radius),
        "depth_edge_margin": int(depth_edge_margin),
        "max_angle": float(max_angle),
        "oblique_reference": oblique_reference,
        "two_sided": bool(two_sided),
        "filters": filters,
    }
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
    geom = _Geometry(mesh, fn, degenerate)
    views = scene.views
    V, F = len(views), len(faces)
    timings["prepare"] = time.perf_counter() - t0

    t1 = time.perf_counter()
    N = len(X)
    res = {
        "uv": np.zeros((V, N, 2), np.float32),
        "depth": np.zeros((V, N), np.float32),
        "valid": np.zeros((V, F), bool),
        "area": np.zeros((V, F), np.float32),
        "cos_angle": np.zeros((V, F), np.float32),
        "oblique": np.zeros((V, F), bool),
        "back": np.zeros((V, F), bool),
    }
    per = list(track(Parallel(n_jobs=n_jobs, prefer="threads", require="sharedmem", return_as="generator")(
        delayed(_per_view)(view, i, geom, opts, res) for i, view in enumerate(views)), desc="visibility", total=V,
        unit="view"))
    timings["project+depth"] = time.perf_counter() - t1

    valid, back = res["valid"], res["back"]
    oblique = res["oblique"] if "oblique" in filters else np.zeros((V, F), bool)

    t2 = time.perf_counter()
    n_rays = 0
    if "occlusion" in filters and valid.any():
        front = valid & ~back
        occluded, n_rays = occluded_faces(mesh, geom, views, res["area"], front, opts)
    else:
        occluded = np.zeros((V, F), bool)
    timings["occlusion"] = time.perf_counter() - t2

    t3 = time.perf_counter()
    depth_bad = np.zeros((V, F), bool)
    per_view = []
    for v, (view, p) in enumerate(zip(views, per)):
        entry = {"name": view.name, "depth_source": p["depth_source"]}
        if p["vertex_depth_bad"] is not None:
            bad_v = p["vertex_depth_bad"]
            if p.get("vertex_near_edge") is not None:
                bad_v = bad_v | p["vertex_near_edge"]
            depth_bad[v] = valid[v] & geom.any3(bad_v)
            ok = valid[v] & ~occluded[v] & ~back[v]
            vert = np.zeros(len(X), bool)
            vert[faces[ok].ravel()] = True
            vert &= p["vertex_depth_known"]
            n_known = int(vert.sum())
            frac = float(p["vertex_depth_bad"][vert].mean()) if n_known else 0.0
            entry["depth_disagreement"] = frac
            if n_known >= 30 and frac > opts["max_depth_disagreement"]:
                src = (view.depth if p["depth_source"] == "depth" else view.point_cloud) or "(in memory)"
                msg = (
                    f"view {view.name!r}: {frac:.0%} of the visible mesh vertices disagree with its "
                    f"{p['depth_source'].replace('_', ' ')} {src} by more than "
                    f"max({opts['depth_atol']}, {opts['depth_tol']:.0%} of depth); is it registered to the mesh "
                    "(same units / depth_scale, same pose)?"
                )
                warn(msg)
        elif "depth" in filters:
            logger.info("view %r has neither a depth map nor a point cloud: depth-consistency filter skipped", view.name)
        per_view.append(entry)
    timings["depth-compare"] = time.perf_counter() - t3
    if "depth" in filters and V and not any(v.has_depth for v in views):
        warn("no view has a depth map or a point cloud: the depth-consistency filter is off, so surfaces hidden "
             "from a camera by geometry the mesh lacks may be mapped wrongly; give depth maps (--depth-dir, "
             "load_scene(..., depth_dir=)) when you have them")

    usable = valid & ~occluded & ~depth_bad & ~oblique
    nothing = [views[v].name for v in range(V) if not valid[v].any()]
    for name in nothing:
        msg = f"view {name!r} sees no face of the mesh entirely (wrong pose, or looking away?); it gets no mappings"
        warn(msg)
    if V and not valid.any():
        raise InputError(
            f"no overlap: none of the {V} views sees a whole face of the mesh {getattr(scene, 'mesh', '')}; "
            "check that the camera poses (extrinsic, world-to-camera) and the mesh use the same coordinate frame"
        )
    for v in range(V):
        per_view[v].update(
            valid=int(valid[v].sum()),
            occluded=int(occluded[v].sum()),
            depth_inconsistent=int(depth_bad[v].sum()),
            oblique=int(oblique[v].sum()),
            usable=int(usable[v].sum()),
        )
        if valid[v].any() and not usable[v].any():
            logger.warning("view %r: all %d visible faces were removed by the filters", views[v].name, int(valid[v].sum()))
    m1 = valid & ~occluded
    m2 = m1 & ~depth_bad
    stats = {
        "n_views": V,
        "n_faces": F,
        "degenerate_faces": int(degenerate.sum()),
        "normals_flipped": flipped,
        "valid": int(valid.sum()),
        "occluded": int(occluded.sum()),
        "depth_inconsistent": int(depth_bad.sum()),
        "oblique": int(oblique.sum()),
        "usable": int(usable.sum()),
        "cumulative": {
            "valid": int(valid.sum()),
            "+occlusion": int(m1.sum()),
            "+depth": int(m2.sum()),
            "+oblique": int(usable.sum()),
        },
        "views_seeing_nothing": nothing,
        "views_without_depth": [e["name"] for e in per_view if e["depth_source"] is None],
        "rays": int(n_rays),
        "per_view": per_view,
        "timings": timings,
    }
    uv, depth, area, cos = res["uv"], res["depth"], res["area"], res["cos_angle"]
    timings["total"] = time.perf_counter() - t0
    logger.info(
        "visibility: %d views x %d faces: valid %d, occluded %d, depth-inconsistent %d, oblique %d -> usable %d (%.2f s)",
        V, F, stats["valid"], stats["occluded"], stats["depth_inconsistent"], stats["oblique"], stats["usable"],
        timings["total"],
    )
    return Visibility(
        uv=uv,
        depth=depth,
        valid=valid,
        occluded=occluded,
        depth_inconsistent=depth_bad,
        oblique=oblique,
        usable=usable,
        area=area,
        cos_angle=cos,
        stats=stats,
        mesh=mesh,
        view_names=tuple(v.name for v in views),
        options=opts,
    )
