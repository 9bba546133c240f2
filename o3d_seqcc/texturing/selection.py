"""Per-face view selection (paper 3.8, and an MRF beyond it).

:func:`select_views` picks one view per face (``(F,) int64``, ``-1`` = seen by no view) with one
of the methods of :data:`SELECTION_METHODS`:

- ``"mrf"`` (default, beyond the paper): a Potts Markov random field over face adjacency with a
  quality data term, solved by alpha-expansion graph cuts (PyMaxflow), as mvs-texturing does;
  it trades a little resolution for far fewer image transitions (texture seams);
- ``"largest-area"``: the usable view with the largest projected face area, paper 3.8;
- ``"random"``: uniform among the views where the face is *usable* (seeded), paper 3.8.

Only usable views are ever selected: never a view where the face is outside the image,
occluded, depth-inconsistent or too oblique (``visibility.usable``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from ..errors import InputError
from .._shared.registry import Registry
from ..geometry.meshops import face_adjacency
from .settings import MRF_SMOOTHNESS, TextureSettings, VisibilityLike

__all__ = ["SELECTION_METHODS", "count_transitions", "register_selection", "select_views", "selection_stats"]

logger = logging.getLogger(__name__)


def count_transitions(labels: np.ndarray, adjacency: np.ndarray) -> int:
    """Number of interior edges whose two faces use different views (both faces seen).

    Parameters
    ----------
    labels : (F,) int array
        View per face, -1 = unseen (edges touching an unseen face are not counted).
    adjacency : (E, 2) int array
        Face pairs from :func:`face_adjacency`.
    """
    lab = np.asarray(labels)
    if len(adjacency) == 0:
        return 0
    a, b = lab[adjacency[:, 0]], lab[adjacency[:, 1]]
    return int(np.count_nonzero((a != b) & (a >= 0) & (b >= 0)))


def selection_stats(labels: np.ndarray, adjacency: np.ndarray, n_views: int | None = None) -> dict[str, Any]:
    """Summary of a per-face selection: faces, unseen faces, transitions, views used.

    Returns
    -------
    dict
        ``faces``, ``unseen_faces``, ``transitions`` (see :func:`count_transitions`),
        ``interior_edges``, ``views_used`` and ``faces_per_view`` (list, length ``n_views``).
    """
    lab = np.asarray(labels, dtype=np.int64)
    nv = int(n_views if n_views is not None else (lab.max() + 1 if lab.size else 0))
    per_view = np.bincount(lab[lab >= 0], minlength=nv)
    return {
        "faces": int(len(lab)),
        "unseen_faces": int(np.count_nonzero(lab < 0)),
        "transitions": count_transitions(lab, adjacency),
        "interior_edges": int(len(adjacency)),
        "views_used": int(np.count_nonzero(per_view)),
        "faces_per_view": per_view.tolist(),
    }


# --------------------------------------------------------------------------------------------
# per-face view selection
# --------------------------------------------------------------------------------------------

SelectionFn = Callable[..., np.ndarray]


def register_selection(name: str) -> Callable[[SelectionFn], SelectionFn]:
    """Decorator adding a selection method ``fn(visibility, *, seed, **options) -> (F,) int64`` to
    :data:`SELECTION_METHODS`."""
    return SELECTION_METHODS.register(name)


@dataclass(frozen=True)
class _Entries:
    """Every usable (view, face) incidence, view-major: view ``v`` owns ``indptr[v]:indptr[v+1]``."""

    indptr: np.ndarray  # (V+1,) int64
    faces: np.ndarray  # (nnz,) int64, ascending within a view
    area: np.ndarray  # (nnz,) float64 (as given when ``quality`` is: unused then)
    cos_angle: np.ndarray | None  # (nnz,) float64
    n_views: int
    n_faces: int
    quality: np.ndarray | None = None  # (nnz,) float64: the data term's quality (ScoredVisibility)

    def view(self, v: int) -> slice:
        return slice(int(self.indptr[v]), int(self.indptr[v + 1]))


def _entries(visibility: VisibilityLike, *, cos: bool = False) -> _Entries:
    """The usable incidences of a visibility (:class:`~o3d_seqcc.visibility.Visibility`'s sparse records, or the
    scored ones of :class:`~o3d_seqcc.texturing.data_costs.ScoredVisibility` with their quality)."""
    indptr, faces, area, cos_angle = visibility.usable_entries()
    quality = getattr(visibility, "entry_quality", None)
    return _Entries(indptr, faces.astype(np.int64), area if quality is not None else area.astype(np.float64),
                    cos_angle.astype(np.float64) if cos else None, int(visibility.n_views), int(visibility.n_faces),
                    quality)


def _select_random(visibility: VisibilityLike, *, seed: int = 0) -> np.ndarray:
    """Uniformly random usable view per face (paper 3.8), reproducible for a given seed."""
    e = _entries(visibility)
    count = np.bincount(e.faces, minlength=e.n_faces)
    rng = np.random.default_rng(seed)
    k = np.floor(rng.random(e.n_faces) * np.maximum(count, 1)).astype(np.int64)
    lab = np.full(e.n_faces, -1, dtype=np.int64)
    rank = np.zeros(e.n_faces, dtype=np.int64)  # usable views of the face met so far, in view order
    for v in range(e.n_views):
        f = e.faces[e.view(v)]
        lab[f[rank[f] == k[f]]] = v  # the k-th usable view (0-based) of each face
        rank[f] += 1
    return lab


def _select_largest_area(visibility: VisibilityLike, *, seed: int = 0) -> np.ndarray:
    """Usable view with the largest projected face area (paper 3.8); ``seed`` is unused."""
    return _largest(_entries(visibility))


def _largest(e: _Entries, score: np.ndarray | None = None) -> np.ndarray:
    """Per face the usable view of largest area (or ``score``); ties go to the lowest view index."""
    score = np.nan_to_num(e.area if score is None else score, nan=-1.0)
    best = np.full(e.n_faces, -np.inf)
    lab = np.full(e.n_faces, -1, dtype=np.int64)
    for v in range(e.n_views):
        sl = e.view(v)
        f, sc = e.faces[sl], score[sl]
        better = sc > best[f]
        best[f[better]] = sc[better]
        lab[f[better]] = v
    return lab


#: data terms of the "mrf" method (the "log-" names are the older spellings of the first two)
_MRF_DATA_TERMS = ("area", "area-cos", "gmi", "log-area", "log-area-cos")


def _quality(e: _Entries, data_term: str) -> np.ndarray:
    """(nnz,) quality of every usable incidence under ``data_term``."""
    if e.quality is not None:
        return np.nan_to_num(e.quality, nan=0.0)
    if data_term == "gmi":
        raise InputError("data_term='gmi' reads the photos: call select_views(..., images=...)")
    area = np.nan_to_num(e.area, nan=0.0)
    if data_term in ("area-cos", "log-area-cos"):
        return area * np.clip(np.nan_to_num(e.cos_angle), 0.0, 1.0)
    return area


#: "gmi" data cost of a view without detail: texrecon's 1 - q / q_99.5 scaled so that the Potts weight
#: MRF_SMOOTHNESS (4) is texrecon's weight 1. Measured on Fountain (issue 19): 4x weaker smoothness
#: (16) renders with a higher variance of the Laplacian than texrecon's, but splits the "HAROLD HATCH"
#: lettering at misregistered seams (doubled edges count as detail); this balance keeps it whole.
GMI_COST = 4.0


def _mrf_data_cost(e: _Entries, data_term: str, max_cost: float) -> np.ndarray:
    """(nnz,) float64 data cost of every usable incidence (unusable ones are never considered).

    Area terms: ``-log(q / q_max of the face)`` (relative to the face's best view, clipped to
    ``max_cost``). GMI: ``GMI_COST * (1 - min(1, q / q_99.5))`` with the 99.5th percentile of
    all incidences (Waechter et al.), so detailed faces get strong data terms and pick their
    sharpest photo while plain ones follow the smoothness.
    """
    q = _quality(e, data_term)  # a new array: the steps below work in place
    np.maximum(q, 0.0, out=q)
    if data_term == "gmi":
        ref = float(np.percentile(q, 99.5)) if len(q) else 1.0
        q /= max(ref, 1e-12)
        np.minimum(q, 1.0, out=q)
        np.subtract(1.0, q, out=q)
        q *= GMI_COST
        return q
    qmax = np.zeros(e.n_faces)
    np.maximum.at(qmax, e.faces, q)
    qm = qmax[e.faces]
    with np.errstate(divide="ignore", invalid="ignore"):
        cost = -np.log(q / np.where(qm > 0, qm, 1.0))
    return np.clip(np.nan_to_num(cost, nan=max_cost, posinf=max_cost), 0.0, max_cost)


def _select_mrf(
    visibility: VisibilityLike,
    *,
    seed: int = 0,
    smoothness: float = MRF_SMOOTHNESS,
    data_term: str = "area",
    max_data_cost: float = 10.0,
    n_sweeps: int = 4,
    adjacency: np.ndarray | None = None,
    mesh: Any = None,
) -> np.ndarray:
    """Potts MRF labelling by alpha-expansion (beyond the paper; mvs-texturing's idea).

    Energy ``E(l) = sum_f D_f(l_f) + smoothness * #{(p, q) adjacent: l_p != l_q}`` with
    ``D_f(l) = -log(q_f(l) / max_l' q_f(l'))`` clipped to ``[0, max_data_cost]`` for usable
    views (``q`` = projected area, area x cos for ``"area-cos"``, or the quality of a
    :class:`~o3d_seqcc.texturing.data_costs.ScoredVisibility`, e.g. GMI) and a prohibitive cost
    for unusable ones. Starts from the best ``q`` of every face (energy only decreases, so the
    result never has more transitions *plus* data cost than it); each sweep runs one expansion move
    per view in a seeded random order, restricted to the faces where that view is usable;
    stops after ``n_sweeps`` or when a sweep changes nothing. Works on the usable incidences
    only (memory and time proportional to them, not to views x faces).

    Options
    -------
    smoothness : float, default :data:`MRF_SMOOTHNESS` (4.0)
        Potts weight per interior edge, in units of the data term (a factor e of area costs 1).
        On fountain, 1 / 4 / 8 give 962 / 680 / 602 image transitions, with seam metric (mean,
        after leveling) 0.26 / 0.20 / 0.19 and the sharpness of the render of view 16 unchanged
        (1.02x / 1.12x / 1.12x of the photo).
    data_term : {"area", "area-cos", "gmi"}, default "area"
        ``"gmi"`` needs a scored visibility (:func:`select_views` with ``images``); with one,
        its quality is used whatever the name.
    max_data_cost : float, default 10.0
    n_sweeps : int, default 4
    adjacency : (E, 2) int array, optional
        Face pairs (:func:`face_adjacency`); computed from ``mesh`` or ``visibility.mesh``.
    mesh : Mesh, optional
        Used only to compute the adjacency when not given.
    """
    import maxflow

    if smoothness < 0:
        raise ValueError(f"smoothness must be >= 0, got {smoothness}")
    if data_term not in _MRF_DATA_TERMS:
        raise ValueError(f"unknown data_term {data_term!r}; valid: {', '.join(map(repr, _MRF_DATA_TERMS[:3]))}")
    e = _entries(visibility, cos=data_term in ("area-cos", "log-area-cos"))
    n_views, n_faces = e.n_views, e.n_faces
    if adjacency is None:
        m = mesh if mesh is not None else visibility.mesh
        if m is None:
            raise InputError("mrf selection needs the mesh adjacency: pass adjacency= or mesh=")
        adjacency = face_adjacency(m.faces, m.vertices)
    adjacency = np.asarray(adjacency, dtype=np.int64).reshape(-1, 2)
    data = _mrf_data_cost(e, data_term, max_data_cost)
    labels = _largest(e, -data)
    seen = labels >= 0
    pairs = adjacency[seen[adjacency[:, 0]] & seen[adjacency[:, 1]]]
    if smoothness == 0 or len(pairs) == 0:
        return labels
    w = float(smoothness)
    rng = np.random.default_rng(seed)
    labels = labels.astype(np.int32)  # half the bytes for the moves' gathers (returned as int64)
    cur = np.zeros(n_faces)  # data cost of every face's current label
    for v in range(n_views):
        sl = e.view(v)
        mine = labels[e.faces[sl]] == v
        cur[e.faces[sl][mine]] = data[sl][mine]
    seen_idx = np.flatnonzero(seen)
    seen_pos = np.full(n_faces, -1, dtype=np.int64)
    seen_pos[seen_idx] = np.arange(len(seen_idx))
    cur_seen = cur[seen_idx]
    p0, p1 = np.ascontiguousarray(pairs[:, 0]), np.ascontiguousarray(pairs[:, 1])
    n_dis = int(np.count_nonzero(labels[p0] != labels[p1]))
    energy = float(cur_seen.sum()) + w * float(n_dis)  # = sum_f D_f(l_f) + w * transitions
    logger.debug("mrf: start energy %.1f, %d transitions", energy, n_dis)
    pos = np.empty(n_faces, dtype=np.int64)
    free = np.zeros(n_faces, dtype=bool)
    flag = np.zeros(n_faces, dtype=bool)  # scratch: the faces a move switched
    for sweep in range(int(n_sweeps)):
        changed = 0
        for alpha in rng.permutation(n_views):
            sl = e.view(int(alpha))
            fa = e.faces[sl]
            keep = labels[fa] != alpha  # unusable/unseen faces are never free
            fidx = fa[keep]
            nfree = len(fidx)
            if nfree == 0:
                continue
            d_alpha = data[sl][keep]
            pos[fidx] = np.arange(nfree)
            free[fidx] = True
            f0, f1 = free[p0], free[p1]
            inc = np.flatnonzero(f0 | f1)  # every pair with a free face, in pair order
            q0, q1, f0, f1 = p0[inc], p1[inc], f0[inc], f1[inc]
            l0, l1 = labels[q0], labels[q1]
            i0, i1 = pos[q0], pos[q1]  # positions (meaningless where the face is not free)
            diff = l0 != l1
            # unary costs of keeping (x=0) / switching to alpha (x=1)
            cost0 = cur[fidx]
            cost1 = d_alpha.copy()
            # both free: Potts expansion term, submodular
            both = f0 & f1
            bi, bj = i0[both], i1[both]
            A = w * diff[both]
            # E = A + (C-A) x_i + (D-C) x_j + (B+C-A-D)(1-x_i) x_j with B = C = w, D = 0
            cost1 += np.bincount(bi, weights=w - A, minlength=nfree)
            cost1 -= w * np.bincount(bj, minlength=nfree)
            cost0_add = np.zeros(nfree)
            # one free, one fixed: unary on the free one
            for i, lo, mask in ((i0, l1, f0 > f1), (i1, l0, f1 > f0)):
                im = i[mask]
                cost0_add += w * np.bincount(im, weights=diff[mask].astype(np.float64), minlength=nfree)
                cost1 += w * np.bincount(im, weights=(lo[mask] != alpha).astype(np.float64), minlength=nfree)
            cost0 += cost0_add
            free[fidx] = False
            g = maxflow.Graph[float](nfree, len(bi))
            nodes = g.add_nodes(nfree)  # 0 .. nfree - 1: the positions themselves
            if len(bi):
                g.add_edges(bi, bj, 2.0 * w - A, np.zeros(len(bi)))
            mn = np.minimum(cost0, cost1)
            g.add_grid_tedges(nodes, cost1 - mn, cost0 - mn)
            g.maxflow()
            switch = np.asarray(g.get_grid_segments(nodes), dtype=bool)
            if switch.any():
                sw = fidx[switch]
                flag[sw] = True
                s0, s1 = flag[q0], flag[q1]
                flag[sw] = False
                touched = s0 | s1  # the pairs of a switched face: their labels before and after
                before = int(np.count_nonzero(l0[touched] != l1[touched]))
                after = int(np.count_nonzero(np.where(s0, alpha, l0)[touched] != np.where(s1, alpha, l1)[touched]))
                old_cost = cur_seen[seen_pos[sw]]
                cur_seen[seen_pos[sw]] = d_alpha[switch]
                n_dis_new = n_dis - before + after
                e_new = float(cur_seen.sum()) + w * float(n_dis_new)  # the full sum: the same float as before
                if e_new < energy - 1e-9:
                    energy, n_dis = e_new, n_dis_new
                    labels[sw] = alpha
                    cur[sw] = d_alpha[switch]
                    changed += int(switch.sum())
                else:
                    cur_seen[seen_pos[sw]] = old_cost
        logger.debug("mrf: sweep %d, %d faces changed, energy %.1f", sweep, changed, energy)
        if changed == 0:
            break
    return labels.astype(np.int64)


#: name -> ``fn(visibility, *, seed, **options) -> (F,) int64`` (written out; :func:`register_selection` adds more)
SELECTION_METHODS: Registry[SelectionFn] = Registry("selection method", {
    "random": _select_random,
    "largest-area": _select_largest_area,
    "mrf": _select_mrf,
})


def select_views(
    visibility: VisibilityLike,
    *,
    method: str = TextureSettings.selection,
    seed: int = 0,
    images: Sequence[np.ndarray] | None = None,
    data_term: str | None = None,
    outlier_removal: str | None = None,
    **options: Any,
) -> np.ndarray:
    """Choose one view per face for texturing.

    Parameters
    ----------
    visibility : Visibility
        From :func:`o3d_seqcc.visibility.compute_visibility`; uses its usable (view, face)
        incidences with their projected areas (px^2) and cosines (``usable_entries()``, sparse)
        and, for ``"mrf"``, ``mesh``. Any object with dense ``usable`` (V, F) bool, ``area`` and
        ``cos_angle`` (V, F) arrays, ``n_views`` and ``n_faces`` works too.
    method : {"mrf", "largest-area", "random"}, default "mrf"
        See the module docstring and :data:`SELECTION_METHODS`.
    seed : int, default 0
        Seed of ``"random"`` and of the expansion order of ``"mrf"``.
    images : sequence of (H, W, 3) arrays, optional
        The (colour-corrected) photos, one per view, read once each: needed by the ``"gmi"``
        data term and by outlier removal (:mod:`~o3d_seqcc.texturing.data_costs`).
    data_term : {"area", "area-cos", "gmi"}, optional
        ``"mrf"``'s quality of a view for a face: projected area, area x cosine, or GMI (the
        photo's gradient magnitude integrated over the face's projection: detail, not only
        size). Default :attr:`TextureSettings.data_term` (``"gmi"``) when ``images`` are given,
        else ``"area"``.
    outlier_removal : {"median", "none", "gauss-clamping", "gauss-damping"}, optional
        Drop (damping: down-weight, ``"mrf"`` only) the views whose colour of a face is far from
        the consensus of its other views (every method; :func:`~o3d_seqcc.texturing.data_costs.photometric_outliers`).
        Default :attr:`TextureSettings.outlier_removal` (``"median"``) when ``images`` are
        given, else ``"none"``.
    **options
        Method options (``"mrf"``: ``smoothness``, ``max_data_cost``, ``n_sweeps``,
        ``adjacency``, ``mesh``); unknown ones raise :class:`~o3d_seqcc.errors.InputError` (a ``TypeError``).

    Returns
    -------
    (F,) int64
        Selected view index per face, always a view where the face is usable; ``-1`` where the
        face is usable in no view (counted and logged).

    Raises
    ------
    InputError
        Unknown method or option (the message lists the valid ones; an unknown option's is also a
        ``TypeError``); no face is usable in any view (wrong cameras or mesh, or filters too strict); ``"gmi"``
        or outlier removal without ``images``.

    Examples
    --------
    >>> import tempfile, o3d_seqcc as sc
    >>> room = sc.make_synthetic_scene(tempfile.mkdtemp() + '/room', n_views=3, width=96, height=72, seed=1,
    ...                                seen_only=True)
    >>> vis = sc.compute_visibility(room.scene)
    >>> labels = sc.select_views(vis, method='largest-area')
    >>> labels.shape == (len(vis.mesh.faces),), int(labels.max()) <= 2
    (True, True)
    """
    from .data_costs import score_visibility

    SELECTION_METHODS.check_options(method, options)  # an unknown method or option: InputError with the valid names
    term = (TextureSettings.data_term if images is not None else "area") if data_term is None else data_term
    term = {"log-area": "area", "log-area-cos": "area-cos"}.get(term, term)
    if outlier_removal is None:
        outlier_removal = TextureSettings.outlier_removal if images is not None else "none"
    n_usable = int(visibility.usable_counts().sum())
    if visibility.n_faces == 0 or not n_usable:
        raise InputError(
            f"no face of the mesh is usable in any of the {visibility.n_views} views (outside every image, occluded, "
            "depth-inconsistent or too oblique): check that the mesh and the cameras are in the same coordinates "
            "(extrinsic = world-to-camera), or relax the visibility filters"
        )
    if method == "mrf":
        options["data_term"] = term
    if (method == "mrf" and term == "gmi") or outlier_removal != "none":
        visibility = score_visibility(visibility, images, data_term=term if method == "mrf" else "area",
                                      outlier_removal=outlier_removal)
    elif term not in ("area", "area-cos", "gmi"):
        raise ValueError(f"unknown data_term {data_term!r}; valid: 'area', 'area-cos', 'gmi'")
    labels = np.asarray(SELECTION_METHODS[method](visibility, seed=seed, **options), dtype=np.int64)
    n_unseen = int(np.count_nonzero(labels < 0))
    if n_unseen:
        logger.info("select_views(%s): %d of %d faces are seen by no view", method, n_unseen, len(labels))
    return labels
