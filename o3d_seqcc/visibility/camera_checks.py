"""Camera sanity before any heavy work: do the cameras see the mesh the way photos do?

A scene whose cameras follow another convention than the one assumed loads and runs without
complaint and textures nothing: camera-to-world matrices read as world-to-camera, OpenGL camera
axes (y up, looking down -z) read as OpenCV ones (y down, looking down +z), a mesh in
millimetres with cameras in metres. :func:`check_cameras` tells those apart cheaply, in
milliseconds per view, from what a correctly registered photo looks like: most of its pixels
show the mesh *from the front* (the surface's normal towards the camera, nothing in between).

For a few views (at most ``max_views``, evenly spaced) it casts a coarse grid of rays (about
``grid`` x ``grid * H / W``) through the image and counts the rays whose first hit is a
front-facing face: the view's *front fraction*. The median over the views is computed for the
cameras as given and, when that is low, for each alternative reading of them
(:data:`HYPOTHESES`: the inverse of every extrinsic, the OpenGL flip, both, the mesh scaled by
0.001 / 0.01 / 100 / 1000 relative to the camera positions). An alternative that makes the
photos look like photos where the given cameras do not (median front fraction at least
:data:`MIN_FRONT` and :data:`RATIO` times the given one, :data:`MIN_SHARE` of the views at
:data:`MIN_VIEW_FRONT` or more each, and at least as much of the mesh seen) is a likely mistake:
:func:`check_cameras` raises :class:`~o3d_seqcc.errors.InputError` naming it, with the numbers
and the fix. Correct scenes are never refused on a tie: inside a closed room the flipped
cameras see walls too, and then nothing is said.

The share of the mesh some camera sees (``area_seen``) is measured on up to ``samples`` faces
drawn at random (weights: their areas clipped at the 99th percentile, so a few huge junk
triangles far away weigh no more than ordinary faces): a face counts as seen when its centroid
projects inside a view, faces it and the ray to it is not blocked. Less than
:data:`MIN_AREA_SEEN` of it seen is warned about; when the photos hardly show it either (median
front fraction under :data:`MIN_FRONT_SEEN`) and no mistake is likely, the mesh is not the one
photographed (another scene's, other units, other conventions): an
:class:`~o3d_seqcc.errors.InputError` when ``min_area_seen`` asks for it (as
:func:`~o3d_seqcc.load_scene` does unless ``allow_unseen=True``). A room with one photo sees 6 %
of its mesh, all of the photo showing it: a warning only.

All of it runs in a local frame (the mesh's bounding-box centre subtracted) in float32 with
Open3D's ``RaycastingScene``; nothing is kept.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..geometry.meshops import local_origin, oriented_face_normals
from .occlusion import hand_over

__all__ = ["CameraReport", "HYPOTHESES", "MIN_AREA_SEEN", "MIN_FRONT", "MIN_FRONT_SEEN", "RATIO", "check_cameras",
           "hypothesis_extrinsic"]

logger = logging.getLogger(__name__)

#: diag(1, -1, -1, 1): OpenGL camera axes (x right, y up, looking down -z) <-> OpenCV (y down, +z)
FLIP = np.diag([1.0, -1.0, -1.0, 1.0])
#: scales of the mesh relative to the camera positions tried (units: m vs mm, cm)
SCALES = (1e-3, 1e-2, 1e2, 1e3)
#: the alternative readings of the cameras tried, and what each means
HYPOTHESES: dict[str, str] = {
    "inverse": "the poses look inverted (camera-to-world where world-to-camera is expected, or the reverse)",
    "opengl": "the cameras look OpenGL (y up, looking down -z)",
    "inverse+opengl": "the poses look camera-to-world in OpenGL axes (as NeRF and Blender write them)",
    **{f"scale:{s:g}": f"the mesh looks {1 / s:g}x the cameras' units" for s in SCALES},
}
_READ = {"inverse": "with every pose inverted", "opengl": "with the camera axes flipped",
         "inverse+opengl": "with every pose inverted and its axes flipped",
         **{f"scale:{s:g}": f"with the mesh scaled by {s:g}" for s in SCALES}}
#: an alternative must reach this median front fraction ...
MIN_FRONT = 0.3
#: ... and this many times the given cameras' (plus 0.05) ...
RATIO = 3.0
#: ... and at least :data:`MIN_SHARE` of the checked views must each reach :data:`MIN_VIEW_FRONT` with it
#: (a real registration is consistent over the views; random cameras are not)
MIN_VIEW_FRONT, MIN_SHARE = 0.2, 0.8
#: less of the mesh seen than this (share of its area) is warned about, and refused by
#: :func:`~o3d_seqcc.load_scene` (unless ``allow_unseen``) when the photos show it less than :data:`MIN_FRONT_SEEN`
MIN_AREA_SEEN = 0.1
#: ... median front fraction under which the photos do not show the mesh
MIN_FRONT_SEEN = 0.1


def hypothesis_extrinsic(extrinsic: np.ndarray, name: str) -> np.ndarray:
    """(4, 4) world-to-camera extrinsic under an alternative reading of ``extrinsic``.

    Parameters
    ----------
    extrinsic : (4, 4) float
        As given (world-to-camera, OpenCV axes, assumed).
    name : str
        ``"given"`` or a key of :data:`HYPOTHESES`.
    """
    E = np.asarray(extrinsic, dtype=np.float64)
    if name == "given":
        return E
    if name == "inverse":
        return np.linalg.inv(E)
    if name == "opengl":
        return FLIP @ E
    if name == "inverse+opengl":
        return FLIP @ np.linalg.inv(E)
    if name.startswith("scale:"):  # mesh x s  <=>  camera positions / s
        out = E.copy()
        out[:3, 3] /= float(name.split(":", 1)[1])
        return out
    raise ValueError(f"unknown camera hypothesis {name!r}; valid: 'given', {', '.join(map(repr, HYPOTHESES))}")


@dataclass(frozen=True)
class CameraReport:
    """What :func:`check_cameras` found.

    Attributes
    ----------
    views : int
        Views of the scene.
    views_checked : int
        Views whose front fraction was measured (at most ``max_views``).
    front_fraction : float
        Median over the checked views of the share of their image rays that hit the mesh from
        the front, cameras as given; 0..1.
    area_seen : float
        Share of the mesh (sampled faces, clipped-area weights) that some view sees from the
        front, unoccluded; 0..1.
    faces_sampled : int
    views_seeing_nothing : list of str
        Views none of whose rays and none of whose sampled faces meet the mesh from the front.
    hypotheses : dict
        Alternative name -> {"front_fraction", "area_seen"} for the alternatives measured.
    mistake : str or None
        The likely alternative reading (a key of :data:`HYPOTHESES`), or None.
    warnings : list of str
    seconds : float
    """

    views: int
    views_checked: int
    front_fraction: float
    area_seen: float
    faces_sampled: int
    views_seeing_nothing: list[str] = field(default_factory=list)
    hypotheses: dict[str, dict[str, float]] = field(default_factory=dict)
    mistake: str | None = None
    warnings: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def also_likely(self) -> list[str]:
        """Other alternatives that fit within 0.05 of the likely one (a closed room cannot tell them apart)."""
        if self.mistake is None:
            return []
        best = self.hypotheses[self.mistake]["front_fraction"]
        return [k for k, v in self.hypotheses.items() if k != self.mistake and v["front_fraction"] >= best - 0.05]

    def describe_mistake(self) -> str:
        """One sentence with the numbers: what the cameras look like and how much better that reading is."""
        if self.mistake is None:
            return ""
        alt = self.hypotheses[self.mistake]
        text = (f"{HYPOTHESES[self.mistake]}: {_READ[self.mistake]}, {alt['front_fraction']:.0%} of the pixels of "
                f"the {self.views_checked} views checked show the mesh from the front and {alt['area_seen']:.0%} of "
                f"the mesh faces a camera (as given: {self.front_fraction:.0%} and {self.area_seen:.0%})")
        others = self.also_likely
        if others:
            text += " (as likely: " + "; ".join(_READ[k] for k in others) + ")"
        return text

    def error_message(self, where: str = "", fix: dict[str, str] | None = None) -> str:
        """The :class:`~o3d_seqcc.errors.InputError` text for :attr:`mistake`: what, the numbers, the fix.

        ``fix`` maps an alternative (or its family: ``"scale"``) to the fix to name; ``{s}`` in
        a scale fix becomes the factor to scale the mesh by.
        """
        if self.mistake is None:
            return ""
        fixes = fix or {}
        family = self.mistake.split(":")[0]
        how = fixes.get(self.mistake) or fixes.get(family) or _GENERIC_FIX.get(family, "")
        if family == "scale":
            how = how.replace("{s}", f"{float(self.mistake.split(':')[1]):g}")
        return f"{where + ': ' if where else ''}{self.describe_mistake()}; {how}"

    def hardly_seen(self, least: float = MIN_AREA_SEEN) -> bool:
        """No likely mistake, less than ``least`` of the mesh seen and the photos hardly showing it (median front
        fraction under :data:`MIN_FRONT_SEEN`): the mesh is not the one photographed."""
        return self.mistake is None and self.area_seen < least and self.front_fraction < MIN_FRONT_SEEN

    def unseen_message(self, where: str = "", fix: dict[str, str] | None = None, least: float = MIN_AREA_SEEN) -> str:
        """The :class:`~o3d_seqcc.errors.InputError` text for a mesh the cameras hardly see (less than ``least``):
        the share seen, the likely causes and their fixes (``fix`` as :meth:`error_message`'s, each up to its
        first ``"; "``)."""
        fixes = fix or {}

        def how(family: str) -> str:
            text = (fixes.get(family) or _GENERIC_FIX[family]).split("; ")[0]
            return text.replace(" by {s}", "").replace(" by the inverse", "")

        conventions = how("inverse")
        if how("opengl") != conventions:
            conventions += f"; or {how('opengl')}"
        return (f"{where + ': ' if where else ''}the camera check finds only {self.area_seen:.0%} of the mesh seen by "
                f"the {self.views} cameras (less than {least:.0%}) and {self.front_fraction:.0%} of the pixels of the "
                f"{self.views_checked} views checked showing it from the front (less than {MIN_FRONT_SEEN:.0%}): the "
                "photos do not show this mesh. Likely: the mesh of another scene or another reconstruction (give "
                f"the scene's own, --mesh), other units ({how('scale')}) or other camera conventions ({conventions}). "
                "If only this little of the mesh was photographed, allow_unseen=True (--allow-unseen) textures what "
                "is seen")

    def to_dict(self) -> dict:
        """JSON-friendly form (rounded)."""
        return {
            "views_checked": self.views_checked,
            "front_fraction": round(self.front_fraction, 4),
            "area_seen": round(self.area_seen, 4),
            "faces_sampled": self.faces_sampled,
            "views_seeing_nothing": list(self.views_seeing_nothing),
            "hypotheses": {k: {kk: round(vv, 4) for kk, vv in v.items()} for k, v in self.hypotheses.items()},
            "mistake": self.mistake,
            "warnings": list(self.warnings),
            "seconds": round(self.seconds, 3),
        }


class _Geometry:
    """The mesh in a local frame, its ray-casting scene, a sample of faces; normals computed for the faces
    met only (nothing per face of the whole mesh but Open3D's tree)."""

    def __init__(self, mesh, samples: int, seed: int) -> None:
        import open3d as o3d

        self.X = np.asarray(mesh.vertices, dtype=np.float64)
        self.F = np.asarray(mesh.faces, dtype=np.int64)
        vn = getattr(mesh, "vertex_normals", None)
        self.vn = vn if vn is not None and np.shape(vn) == self.X.shape else None
        X, F = self.X, self.F
        self.origin = local_origin(X)
        self.rc = o3d.t.geometry.RaycastingScene()
        self.rc.add_triangles(o3d.core.Tensor(np.ascontiguousarray(X - self.origin, dtype=np.float32)),
                              o3d.core.Tensor(np.ascontiguousarray(F, dtype=np.uint32)))
        rng = np.random.default_rng(seed)
        ids = np.sort(rng.choice(len(F), size=min(samples, len(F)), replace=False))
        normals, degenerate = self.normals(ids, with_degenerate=True)
        self.ids = ids[~degenerate]
        self.sample_normals = normals[~degenerate]
        a, b, c = (X[F[self.ids, k]] for k in range(3))
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        w = np.minimum(area, np.quantile(area, 0.99)) if len(area) else area
        self.weights = w / w.sum() if len(w) and w.sum() > 0 else np.full(len(w), 1.0 / max(len(w), 1))
        self.centroids = (a + b + c) / 3.0 - self.origin

    def normals(self, ids: np.ndarray, *, with_degenerate: bool = False):
        """(k, 3) unit normals of faces ``ids``, oriented by the vertex normals (as the visibility filters do)."""
        f = self.F[ids]
        local, inv = np.unique(f, return_inverse=True)
        n, degenerate, _ = oriented_face_normals(self.X[local], inv.reshape(f.shape),
                                                 None if self.vn is None else self.vn[local])
        return (n, degenerate) if with_degenerate else n

    def cast(self, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """First hits of rays (one call per :data:`_CHUNK` rays): distances (inf: none) and face ids."""
        import open3d as o3d

        th = np.empty(len(dirs), dtype=np.float32)
        pid = np.empty(len(dirs), dtype=np.int64)
        for s in range(0, len(dirs), _CHUNK):
            rays = np.empty((min(_CHUNK, len(dirs) - s), 6), dtype=np.float32)
            rays[:, :3] = origins[s:s + len(rays)]
            rays[:, 3:] = dirs[s:s + len(rays)]
            ans = self.rc.cast_rays(o3d.core.Tensor(rays))
            th[s:s + len(rays)] = ans["t_hit"].numpy()
            pid[s:s + len(rays)] = ans["primitive_ids"].numpy()
        return th, pid


#: rays per ray-casting call
_CHUNK = 1 << 21


def _families(name: str) -> set[str]:
    """``"inverse+opengl"`` -> {"inverse", "opengl"}; ``"scale:0.001"`` -> {"scale"}."""
    return {part.split(":")[0] for part in name.split("+")}


def _centre(geo: _Geometry, E: np.ndarray) -> np.ndarray:
    """The camera centre in the local frame, solved (``-R^-1 t``, as ``View.center``: files hold rotations
    orthonormal to ~1e-6 only, and ``-R^T t`` is then 0.5 m off at 5e5 m from the origin)."""
    try:
        return -np.linalg.solve(E[:3, :3], E[:3, 3]) - geo.origin
    except np.linalg.LinAlgError:  # a singular reading (a bad alternative): as transposed
        return -E[:3, :3].T @ E[:3, 3] - geo.origin


def _front_fractions(geo: _Geometry, views, checked: np.ndarray, name: str, grid: int) -> np.ndarray:
    """Per checked view, the share of a coarse grid of its rays whose first hit is a front-facing face."""
    origins, dirs, sizes = [], [], []
    for i in checked:
        view = views[i]
        E = hypothesis_extrinsic(view.extrinsic, name)
        gw = max(2, int(grid))
        gh = max(2, int(round(gw * view.height / view.width)))
        u = (np.arange(gw) + 0.5) * view.width / gw - 0.5
        v = (np.arange(gh) + 0.5) * view.height / gh - 0.5
        uu, vv = np.meshgrid(u, v)
        pix = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)], axis=1)
        d = pix @ np.linalg.inv(view.intrinsic).T @ E[:3, :3]  # R^T (K^-1 x), as rows
        dirs.append(d / np.linalg.norm(d, axis=1, keepdims=True))
        origins.append(np.broadcast_to(_centre(geo, E), d.shape))
        sizes.append(len(d))
    d = np.concatenate(dirs)
    th, pid = geo.cast(np.concatenate(origins), d)
    hit = np.isfinite(th)
    front = np.zeros(len(d), dtype=bool)
    front[hit] = np.einsum("ij,ij->i", d[hit], geo.normals(pid[hit])) < 0
    return np.array([f.mean() for f in np.split(front, np.cumsum(sizes)[:-1])])


def _area_seen(geo: _Geometry, views, name: str) -> tuple[float, np.ndarray]:
    """Share of the sampled mesh area some view sees (centroid inside, facing it, ray unblocked), and the
    number of sampled faces each view sees; rays cast in batches of about :data:`_CHUNK`."""
    seen = np.zeros(len(geo.ids), dtype=bool)
    counts = np.zeros(len(views), dtype=np.int64)
    batch: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []

    def flush() -> None:
        if not batch:
            return
        cand = np.concatenate([b[1] for b in batch])
        dist = np.concatenate([b[2] for b in batch])
        C = np.concatenate([np.broadcast_to(b[3], (len(b[1]), 3)) for b in batch])
        d = geo.centroids[cand] - C
        th, pid = geo.cast(C, d / np.maximum(dist, 1e-300)[:, None])
        vis = (pid == geo.ids[cand]) | (th >= dist * (1.0 - 1e-3))
        seen[cand[vis]] = True
        own = np.concatenate([np.full(len(b[1]), b[0]) for b in batch])
        counts[:] += np.bincount(own[vis], minlength=len(views))
        batch.clear()

    pending = 0
    for k, view in enumerate(views):
        E = hypothesis_extrinsic(view.extrinsic, name)
        R, t = E[:3, :3], E[:3, 3]
        C = _centre(geo, E)
        Xc = geo.centroids @ R.T + (R @ geo.origin + t)
        z = Xc[:, 2]
        K = view.intrinsic
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = Xc[:, 0] / z, Xc[:, 1] / z
            u = K[0, 0] * x + K[0, 1] * y + K[0, 2]
            v = K[1, 1] * y + K[1, 2]
            inside = (z > 0) & (u >= -0.5) & (u < view.width - 0.5) & (v >= -0.5) & (v < view.height - 0.5)
        to_cam = C - geo.centroids
        cand = np.flatnonzero(inside & (np.einsum("ij,ij->i", geo.sample_normals, to_cam) > 0))
        if len(cand):
            batch.append((k, cand, np.linalg.norm(to_cam[cand], axis=1), C))
            pending += len(cand)
        if pending >= _CHUNK:
            flush()
            pending = 0
    flush()
    return float(geo.weights[seen].sum()), counts


def check_cameras(
    scene,
    *,
    skip: tuple[str, ...] = (),
    max_views: int = 64,
    max_area_views: int = 1024,
    grid: int = 32,
    samples: int = 8192,
    seed: int = 0,
    raise_on_mistake: bool = True,
    fix: dict[str, str] | None = None,
    where: str = "",
    min_area_seen: float = 0.0,
) -> CameraReport:
    """Check a scene's cameras against its mesh; raise on a likely convention mistake.

    Parameters
    ----------
    scene : Scene
    skip : tuple of str
        Families of alternatives not to try, among ``"inverse"``, ``"opengl"`` and ``"scale"``:
        the conventions the user stated.
    max_views : int, default 64
        Views whose front fraction is measured (evenly spaced over the scene).
    max_area_views : int, default 1024
        Views used for ``area_seen`` (all of them up to this many).
    grid : int, default 32
        Rays across the image width (rows in proportion).
    samples : int, default 8192
        Faces sampled for ``area_seen``.
    seed : int, default 0
    raise_on_mistake : bool, default True
        Raise :class:`~o3d_seqcc.errors.InputError` when an alternative reading is likely.
    fix : dict, optional
        Alternative name -> the fix to name in the error (default: a generic one).
    where : str, default ""
        Prefix of the messages (the scene file).
    min_area_seen : float, default 0.0
        With ``raise_on_mistake``, raise :class:`~o3d_seqcc.errors.InputError` when no mistake is
        likely, less than this share of the mesh is seen and the photos hardly show it
        (:meth:`CameraReport.hardly_seen`; :func:`~o3d_seqcc.load_scene` gives
        :data:`MIN_AREA_SEEN`); a warning below :data:`MIN_AREA_SEEN` either way.

    Returns
    -------
    CameraReport

    Raises
    ------
    InputError
        ``raise_on_mistake`` and a likely mistake: the message names it, the numbers and the fix;
        or a mesh the photos do not show (:meth:`CameraReport.unseen_message`).

    Examples
    --------
    >>> import tempfile, o3d_seqcc as sc
    >>> room = sc.make_synthetic_scene(tempfile.mkdtemp() + '/room', n_views=3, width=96, height=72, seed=1,
    ...                                seen_only=True)
    >>> report = sc.check_cameras(room.scene)
    >>> report.mistake is None, report.hardly_seen()
    (True, False)
    """
    t0 = time.perf_counter()
    views = scene.views
    mesh = scene.load_mesh()
    geo = _Geometry(mesh, samples, seed)
    V = len(views)
    checked = np.unique(np.linspace(0, V - 1, min(max_views, V)).round().astype(np.int64))
    area_views = views if V <= max_area_views else [views[i] for i in
                                                     np.unique(np.linspace(0, V - 1, max_area_views).round().astype(int))]
    ff0 = _front_fractions(geo, views, checked, "given", grid)
    area0, counts = _area_seen(geo, area_views, "given")
    front0 = float(np.median(ff0))
    hyps: dict[str, dict[str, float]] = {}
    mistake = None
    if front0 * RATIO + 0.05 < 1.0:  # an alternative could still win
        tried = [n for n in HYPOTHESES if not (_families(n) & set(skip))]
        for name in tried:
            ff = _front_fractions(geo, views, checked, name, grid)
            hyps[name] = {"front_fraction": float(np.median(ff)),
                          "views_like_photos": float(np.mean(ff >= MIN_VIEW_FRONT)), "area_seen": float("nan")}
        best = max(tried, key=lambda n: hyps[n]["front_fraction"], default=None)
        if best is not None:
            alt = hyps[best]["front_fraction"]
            if alt >= MIN_FRONT and alt >= RATIO * front0 + 0.05 and hyps[best]["views_like_photos"] >= MIN_SHARE:
                hyps[best]["area_seen"] = _area_seen(geo, area_views, best)[0]
                if hyps[best]["area_seen"] >= area0:
                    mistake = best
    names_nothing = []
    if V <= max_area_views:
        ffall = {int(i): f for i, f in zip(checked, ff0)}
        names_nothing = [v.name for i, v in enumerate(views) if counts[i] == 0 and ffall.get(i, 0.0) == 0.0]
    warnings = []
    for v in views:
        K = v.intrinsic
        if not (-0.5 <= K[0, 2] <= v.width - 0.5 and -0.5 <= K[1, 2] <= v.height - 0.5):
            warnings.append(f"view {v.name!r}: the principal point ({K[0, 2]:g}, {K[1, 2]:g}) lies outside its "
                            f"{v.width}x{v.height} image: is the intrinsic for another image size?")
            break
    if mistake is None and area0 < MIN_AREA_SEEN:
        warnings.append(f"only {area0:.0%} of the mesh faces a camera (the rest is behind, outside or hidden from "
                        f"every view): check that the poses are world-to-camera in OpenCV axes and that mesh and "
                        f"cameras share one frame and unit")
    rep = CameraReport(views=V, views_checked=len(checked), front_fraction=front0, area_seen=area0,
                       faces_sampled=len(geo.ids), views_seeing_nothing=names_nothing, hypotheses=hyps,
                       mistake=mistake, warnings=warnings, seconds=time.perf_counter() - t0)
    logger.info("camera check: %d views (%d checked), front fraction %.2f, %.0f%% of the mesh seen (%.2f s)%s", V,
                len(checked), front0, 100 * area0, rep.seconds, f"; likely {mistake}" if mistake else "")
    if mistake is not None and raise_on_mistake:
        raise InputError(rep.error_message(where, fix))
    if raise_on_mistake and rep.hardly_seen(min_area_seen):
        raise InputError(rep.unseen_message(where, fix, min_area_seen))
    hand_over(geo.X, geo.F, geo.origin, geo.rc)  # the visibility's ray casting needs the same scene
    return rep


_GENERIC_FIX = {
    "inverse": "invert the extrinsics (numpy.linalg.inv) or give world-to-camera ones",
    "opengl": "flip the camera axes (extrinsic = diag(1, -1, -1, 1) @ extrinsic)",
    "inverse+opengl": "use extrinsic = diag(1, -1, -1, 1) @ inv(pose) for each camera-to-world OpenGL pose",
    "scale": "scale the mesh by {s} (MeshLab: Filters > Normals, Curvatures and Orientation > Transform: Scale) or "
             "the camera positions by the inverse, so that both use one unit",
}
