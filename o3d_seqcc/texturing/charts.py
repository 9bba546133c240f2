"""Charts of the texture atlas: which faces share a parametrisation, and their UVs (paper 3.8, issue 13).

A chart is a set of faces with one continuous parametrisation, packed as one piece
(:mod:`~o3d_seqcc.texturing.packing`) and welded inside (its faces share their vertices):

- **image charts** (:func:`image_charts`): connected regions of faces textured from one view;
  the UVs are the vertices' pixel coordinates in that view (``visibility.face_uv``), so a texel
  is a photo pixel at one texel per pixel and a face's texture is its image-space footprint;
- **absorbed unseen faces**: an edge-connected component of faces seen by no view joins the
  image chart with which it shares the most vertices when that chart's view projects all its
  vertices in front of the camera and inside the chart's footprint (its bounding box grown by
  its own size): the component is welded to the chart, its UVs are that projection, and its
  texels get the fallback colours (:mod:`~o3d_seqcc.texturing.fallback`) where no seen face
  covers them (faces seen from behind or edge-on in that view get few or no texels of their
  own and show the chart's photo around them: they are seen by no camera);
- **merged tiny charts**: a chart of at most ``merge_faces`` faces joins the larger
  neighbouring chart it shares most vertices with when that chart's view sees each of its
  faces (``usable``: unoccluded, front-facing, not oblique) with at least half the projected
  area of the face's own view. Only the UVs move (the host view's projection, welded with the
  host); every face is still **sampled from its own view** by the bake, so the texture does
  not change, the atlas loses a chart's gutter and the mesh loses the chart's seam vertices;
- **fallback region**: the unseen components left, each projected on its best-fit plane (or
  parametrised by xatlas where that projection folds), at the median photo density.

All UVs are in "source pixels" (photo pixels for image charts, the same scale for the
fallback region), so that one texel-density factor (texels per source pixel) applies to the
whole atlas.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._shared.sets import unique
from ..geometry.meshops import weld_vertices
from .settings import VisibilityLike

__all__ = ["ChartSet", "build_charts", "image_charts"]

logger = logging.getLogger(__name__)

#: absorbed unseen components must project inside the host chart's bounding box grown by this fraction
ABSORB_MARGIN = 1.0
#: a merged tiny chart's faces need at least this fraction of their own view's projected area in the host view:
#: 0.81 keeps them at 0.9 texels per pixel of their own photo or more (issue 35; 0.5 let them fall to 0.71)
MERGE_MIN_AREA_RATIO = 0.81
#: fallback-region density: this fraction of the median photo density (pixels per world unit)
FALLBACK_DENSITY = 1.0


@dataclass
class ChartSet:
    """Charts of a mesh and their welded output vertices.

    Attributes
    ----------
    faces : (F, 3) int64
        Output vertex ids of every input face (input face order).
    vertex_index : (M,) int64
        Input vertex of every output vertex.
    uv : (M, 2) float64
        Chart coordinates in source pixels (x right, y down).
    face_chart : (F,) int64
        Chart of every face, ``0 .. n_charts - 1``; image charts first (``< n_image``).
    n_image : int
        Number of image charts (with their absorbed and merged faces).
    level_chart : (F,) int64
        Connected same-view region of every seen face (the charts of the seam leveling; merged
        tiny charts keep their own), -1 for unseen faces.
    stats : dict
    """

    faces: np.ndarray
    vertex_index: np.ndarray
    uv: np.ndarray
    face_chart: np.ndarray
    n_image: int
    level_chart: np.ndarray
    stats: dict = field(default_factory=dict)

    @property
    def n_charts(self) -> int:
        return int(self.face_chart.max()) + 1 if len(self.face_chart) else 0


def _tri_area2(p: np.ndarray) -> np.ndarray:
    """Signed doubled area of (n, 3, 2) triangles."""
    return (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1])


def _components(mask: np.ndarray, adjacency: np.ndarray) -> np.ndarray:
    """Edge-connected components of the faces in ``mask``: (F,) id ``0..n-1``, -1 outside the mask."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    F = len(mask)
    e = adjacency[mask[adjacency[:, 0]] & mask[adjacency[:, 1]]]
    _, comp = connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(F, F)), directed=False)
    out = np.full(F, -1, dtype=np.int64)
    if mask.any():
        out[mask] = np.unique(comp[mask], return_inverse=True)[1].reshape(-1)
    return out


def image_charts(faces: np.ndarray, labels: np.ndarray, adjacency: np.ndarray) -> np.ndarray:
    """Connected same-view regions: (F,) int64 chart id ``0..n-1`` of every seen face, -1 for unseen ones.

    Parameters
    ----------
    faces : (F, 3) int array
    labels : (F,) int array
        View of every face, -1 = seen by no view.
    adjacency : (E, 2) int array
        Faces sharing an edge.
    """
    labels = np.asarray(labels, dtype=np.int64)
    adjacency = np.asarray(adjacency, dtype=np.int64).reshape(-1, 2)
    same = labels[adjacency[:, 0]] == labels[adjacency[:, 1]]
    return _components(labels >= 0, adjacency[same])


def _weld_position_normal(wpos: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Ids merging vertices with the same welded position AND normal (flat-shaded split meshes stay flat)."""
    qn = np.round(np.asarray(normals, dtype=np.float64) * 1e4).astype(np.int64)
    order = np.lexsort((qn[:, 2], qn[:, 1], qn[:, 0], wpos))
    key = np.stack([wpos, qn[:, 0], qn[:, 1], qn[:, 2]], axis=1)[order]
    new = np.r_[True, (key[1:] != key[:-1]).any(axis=1)] if len(key) else np.zeros(0, dtype=bool)
    out = np.empty(len(wpos), dtype=np.int64)
    out[order] = np.cumsum(new) - 1
    return out


def _group_pairs(a: np.ndarray, b: np.ndarray, n_b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unique (a, b) pairs with their multiplicity, sorted by a then by multiplicity (descending)."""
    key, cnt = np.unique(a * n_b + b, return_counts=True)
    pa, pb = key // n_b, key % n_b
    o = np.lexsort((pb, -cnt, pa))
    return pa[o], pb[o], cnt[o]


def _rank_in_group(g: np.ndarray) -> np.ndarray:
    """0, 1, 2, ... within runs of equal values of a sorted array."""
    start = np.r_[0, np.flatnonzero(g[1:] != g[:-1]) + 1]
    sizes = np.diff(np.r_[start, len(g)])
    return np.arange(len(g)) - np.repeat(start, sizes)


def _shared_vertex_pairs(owner_a: np.ndarray, wf: np.ndarray, face_b: np.ndarray, mask_a: np.ndarray,
                         mask_b: np.ndarray, n_b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(a, b, count): groups ``owner_a`` of the faces in ``mask_a`` and charts ``face_b`` of the faces in
    ``mask_b`` sharing ``count`` welded vertices (``wf`` (F, 3)), best first within each a."""
    na = int(owner_a.max()) + 2 if len(owner_a) else 1
    ka = unique(wf[mask_a].reshape(-1) * na + np.repeat(owner_a[mask_a], 3))
    va = np.stack([ka // na, ka % na], axis=1)
    if owner_a is face_b and mask_a is mask_b:  # the same (vertex, group) pairs, in the same (lexicographic) order
        vb = va
    else:
        kb = unique(wf[mask_b].reshape(-1) * (n_b + 1) + np.repeat(face_b[mask_b], 3))
        vb = np.stack([kb // (n_b + 1), kb % (n_b + 1)], axis=1)
    st = np.searchsorted(vb[:, 0], va[:, 0], "left")
    n = np.searchsorted(vb[:, 0], va[:, 0], "right") - st
    rep = np.repeat(np.arange(len(va)), n)
    idx = np.repeat(st, n) + (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n))
    a, b = va[rep, 1], vb[idx, 1]
    keep = a != b if owner_a is face_b else np.ones(len(a), dtype=bool)
    return _group_pairs(a[keep], b[keep], max(n_b, 1))


def _absorb_unseen(chart: np.ndarray, chart_view: np.ndarray, labels: np.ndarray, wf: np.ndarray,
                   adjacency: np.ndarray, visibility: VisibilityLike, fuv_seen: np.ndarray,
                   rounds: int = 4) -> tuple[np.ndarray, int]:
    """Unseen components joined to an image chart (see the module docstring); returns the new chart per face."""
    unseen = labels < 0
    comp = _components(unseen, adjacency)
    n_comp = int(comp.max()) + 1
    out = chart.copy()
    if n_comp == 0 or len(chart_view) == 0:
        return out, 0
    seen = ~unseen
    n_ch = len(chart_view)
    pc, pch, _ = _shared_vertex_pairs(comp, wf, chart, unseen, seen, n_ch)
    rank = _rank_in_group(pc)
    # host footprints: bounding boxes of the charts' seen faces in their views, grown by ABSORB_MARGIN
    p = fuv_seen[seen].reshape(-1, 2)
    cc = np.repeat(chart[seen], 3)
    lo = np.full((n_ch, 2), np.inf)
    hi = np.full((n_ch, 2), -np.inf)
    np.minimum.at(lo, cc, p)
    np.maximum.at(hi, cc, p)
    grow = (hi - lo) * ABSORB_MARGIN + 1.0
    lo, hi = lo - grow, hi + grow
    best = np.full(n_comp, -1, dtype=np.int64)
    fu = np.flatnonzero(unseen)
    for r in range(rounds):
        sel = (rank == r) & (best[pc] < 0)
        if not sel.any():
            break
        cand = np.full(n_comp, -1, dtype=np.int64)
        cand[pc[sel]] = pch[sel]
        fc = cand[comp[fu]]
        alt = np.full(len(labels), -1, dtype=np.int64)
        alt[fu] = np.where(fc >= 0, chart_view[np.maximum(fc, 0)], -1)
        q = visibility.face_uv(alt)[fu]  # (n, 3, 2), NaN behind the camera
        inside = np.isfinite(q).all(axis=(1, 2))
        c_ = np.maximum(fc, 0)
        inside &= (q >= lo[c_][:, None]).all(axis=(1, 2)) & (q <= hi[c_][:, None]).all(axis=(1, 2))
        has = fc >= 0
        bad = np.bincount(comp[fu][has], weights=~inside[has], minlength=n_comp)
        tried = np.zeros(n_comp, dtype=bool)
        tried[comp[fu][has]] = True
        ok = tried & (bad == 0)
        best[ok] = cand[ok]
    out[fu] = best[comp[fu]]
    return out, int(np.count_nonzero(best >= 0))


def _usable_at(visibility: VisibilityLike, views: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pointwise ``usable[views, faces]`` (bool) and ``area[views, faces]`` (float64, 0 where not usable), looked
    up in each view's usable face ids (ascending) and areas: no (V, F) array."""
    views, faces = np.asarray(views, np.int64).reshape(-1), np.asarray(faces, np.int64).reshape(-1)
    ok, area = np.zeros(len(faces), bool), np.zeros(len(faces), np.float64)
    order = np.argsort(views, kind="stable")
    bounds = np.searchsorted(views[order], np.arange(visibility.n_views + 1))
    for v in np.flatnonzero(np.diff(bounds)):
        idx = order[bounds[v]:bounds[v + 1]]
        ids, a = visibility.usable_faces(int(v)), visibility.usable_area(int(v))
        if len(ids):
            pos = np.minimum(np.searchsorted(ids, faces[idx]), len(ids) - 1)
            ok[idx] = hit = ids[pos] == faces[idx]
            area[idx] = np.where(hit, a[pos], 0.0)
    return ok, area


def _merge_tiny(chart: np.ndarray, chart_view: np.ndarray, labels: np.ndarray, wf: np.ndarray,
                visibility: VisibilityLike, own_area: np.ndarray, max_faces: int, rounds: int = 3) -> tuple[np.ndarray, int]:
    """Charts of <= ``max_faces`` faces moved into a larger neighbour's parametrisation (module docstring)."""
    ch = chart.copy()
    n_ch = len(chart_view)
    merged = 0
    for _ in range(rounds):
        m = ch >= 0
        size = np.bincount(ch[m], minlength=n_ch)
        t_, c_, _cnt = _shared_vertex_pairs(ch, wf, ch, m, m, n_ch)
        same_view = chart_view[t_] == chart_view[c_]  # charts of one view touching at a vertex: always mergeable
        sel = ((size[t_] <= max_faces) | same_view) & ((size[c_] > size[t_]) | (same_view & (c_ < t_)))
        t_, c_ = t_[sel], c_[sel]
        if len(t_) == 0:
            break
        # every face of the tiny chart t must be fine in c's view
        fm = np.flatnonzero(m)
        order = fm[np.argsort(ch[fm], kind="stable")]
        cs = ch[order]
        st = np.searchsorted(cs, t_, "left")
        n = np.searchsorted(cs, t_, "right") - st
        rep = np.repeat(np.arange(len(t_)), n)
        f = order[np.repeat(st, n) + (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n))]
        v = chart_view[c_[rep]]
        seen_f = labels[f] >= 0
        ok_f = np.zeros(len(f), dtype=bool)
        if seen_f.any():
            fs, vs = f[seen_f], v[seen_f]
            use, area = _usable_at(visibility, vs, fs)
            ok_f[seen_f] = use & (area >= MERGE_MIN_AREA_RATIO * own_area[fs])
        ok = np.bincount(rep, weights=~ok_f & seen_f, minlength=len(t_)) == 0
        ok &= np.bincount(rep, weights=seen_f, minlength=len(t_)) == n  # tiny charts of seen faces only
        t_, c_ = t_[ok], c_[ok]
        first = np.r_[True, t_[1:] != t_[:-1]] if len(t_) else np.zeros(0, dtype=bool)
        t_, c_ = t_[first], c_[first]  # best host per tiny chart (pairs are sorted by shared vertices)
        keep = ~np.isin(c_, t_)  # a host does not move in the same round
        t_, c_ = t_[keep], c_[keep]
        if len(t_) == 0:
            break
        mp = np.arange(n_ch)
        mp[t_] = c_
        ch = np.where(ch >= 0, mp[np.maximum(ch, 0)], -1)
        merged += len(t_)
    return ch, merged


def _migrate_faces(chart: np.ndarray, chart_view: np.ndarray, labels: np.ndarray, adjacency: np.ndarray,
                   visibility: VisibilityLike, own_area: np.ndarray, tiny: int, rounds: int = 3) -> tuple[np.ndarray, int]:
    """Seen faces that share two or three edges with another chart, or any edge when their chart
    has at most ``tiny`` faces, move into that chart's parametrisation where its view sees them
    (see the module docstring): chart borders lose their notches, tiny charts dissolve."""
    ch = chart.copy()
    n_ch = len(chart_view)
    moved = 0
    f_, g_ = np.r_[adjacency[:, 0], adjacency[:, 1]], np.r_[adjacency[:, 1], adjacency[:, 0]]
    for r in range(rounds):
        m = (ch[f_] >= 0) & (ch[g_] >= 0) & (ch[f_] != ch[g_]) & (labels[f_] >= 0)
        fa, cb, cnt = _group_pairs(f_[m], ch[g_[m]], n_ch)
        size = np.bincount(ch[ch >= 0], minlength=n_ch)
        need = np.where(size[ch[fa]] <= tiny, 1, 3 if r == 0 else 2)
        first = np.r_[True, fa[1:] != fa[:-1]] if len(fa) else np.zeros(0, dtype=bool)
        sel = first & (cnt >= need) & (size[cb] > size[ch[fa]])
        fa, cb = fa[sel], cb[sel]
        if len(fa) == 0:
            continue
        v = chart_view[cb]
        use, area = _usable_at(visibility, v, fa)
        ok = use & (area >= MERGE_MIN_AREA_RATIO * own_area[fa])
        ch[fa[ok]] = cb[ok]
        moved += int(ok.sum())
    return ch, moved


def _planar_param(verts: np.ndarray, faces: np.ndarray, wid: np.ndarray, comp: np.ndarray, scale: float):
    """Projection of each component on its best-fit plane, welded inside a component.

    Returns corner UVs (f, 3, 2) (world units x ``scale``), corner vertex ids (f, 3) local to
    these faces, and (n_comp,) bool: the projection has no flipped or degenerate face.
    """
    nc = int(comp.max()) + 1
    nw = int(wid.max()) + 1
    key = comp[:, None] * nw + wid[faces]
    uk, inv = np.unique(key.reshape(-1), return_inverse=True)
    vid = inv.reshape(-1, 3)
    vcomp = uk // nw
    P = np.zeros((len(uk), 3))
    P[vid.reshape(-1)] = verts[faces.reshape(-1)]
    cnt = np.bincount(vcomp, minlength=nc).astype(np.float64)
    mean = np.stack([np.bincount(vcomp, weights=P[:, k], minlength=nc) for k in range(3)], axis=1) / cnt[:, None]
    Q = P - mean[vcomp]
    C = np.zeros((nc, 3, 3))
    for i in range(3):
        for j in range(3):
            C[:, i, j] = np.bincount(vcomp, weights=Q[:, i] * Q[:, j], minlength=nc)
    fn = np.cross(verts[faces[:, 1]] - verts[faces[:, 0]], verts[faces[:, 2]] - verts[faces[:, 0]])
    nsum = np.stack([np.bincount(comp, weights=fn[:, k], minlength=nc) for k in range(3)], axis=1)
    # rounded to 1e-6 of each component's spread: float64 noise (a scene 1e7 m from the origin) must not turn the
    # axes of a nearly round component (the packing reacts to any change)
    q = 1e-6 * np.maximum(np.trace(C, axis1=1, axis2=2), 1e-300)[:, None, None]
    _, V = np.linalg.eigh(np.round(C / q) * q)
    e0, e1 = V[:, :, 2], V[:, :, 1].copy()  # the two largest principal axes
    flip = (np.cross(e0, e1) * nsum).sum(axis=1) < 0  # keep the faces' winding (counter-clockwise)
    e1[flip] *= -1.0
    uv = np.stack([(Q * e0[vcomp]).sum(axis=1), (Q * e1[vcomp]).sum(axis=1)], axis=1) * float(scale)
    uv = np.round(uv * 8.0) / 8.0  # source pixels to 1/8, as Visibility.face_uv
    bad = np.bincount(comp, weights=_tri_area2(uv[vid]) <= 1e-9, minlength=nc) > 0
    return uv[vid], vid, ~bad


def _xatlas_param(verts: np.ndarray, faces: np.ndarray, wid: np.ndarray, scale: float):
    """xatlas's own charts of a sub-mesh: corner UVs (f, 3, 2) at ``scale`` per world unit, corner
    vertex ids (f, 3) local to these faces, chart per face, number of charts."""
    import xatlas

    uw, inv = np.unique(wid[faces].reshape(-1), return_inverse=True)
    lf = inv.reshape(-1, 3)
    first = np.zeros(len(uw), dtype=np.int64)
    first[inv.reshape(-1)] = faces.reshape(-1)
    a = xatlas.Atlas()
    local = verts[first] - verts[first].mean(axis=0)  # xatlas is float32: a local frame for far-away scenes,
    q = 1e-6 * max(float(np.ptp(local, axis=0).max()), 1e-300)  # rounded so float64 noise there changes nothing
    local = np.round(local / q) * q
    a.add_mesh(np.ascontiguousarray(local, dtype=np.float32), np.ascontiguousarray(lf, dtype=np.uint32))
    po = xatlas.PackOptions()
    po.texels_per_unit = float(scale)
    po.resolution = 0
    po.padding = 1
    a.generate(xatlas.ChartOptions(), po)
    _, ind, uv = a[0]
    if ind.shape != faces.shape:  # pragma: no cover - xatlas dropped faces: one planar chart per face instead
        cuv, cvid, _ = _planar_param(verts, faces, wid, np.arange(len(faces)), scale)
        return cuv, cvid, np.arange(len(faces)), len(faces)
    _, chart_of_v = a.get_mesh_vertex_assignment(0)
    ch = chart_of_v[ind[:, 0]].astype(np.int64)
    ch[ch >= np.iinfo(np.uint32).max] = 0
    corner_uv = (uv.astype(np.float64) * [a.width, a.height])[ind]
    return corner_uv, ind.astype(np.int64), ch, max(int(a.chart_count), 1)


def build_charts(
    verts: np.ndarray, faces: np.ndarray, normals: np.ndarray, labels: np.ndarray, fuv: np.ndarray,
    visibility: VisibilityLike, adjacency: np.ndarray, *, wpos: np.ndarray | None = None, merge_faces: int = 3,
) -> ChartSet:
    """Charts, welded output vertices and chart UVs of a view selection (see the module docstring).

    Parameters
    ----------
    verts : (N, 3) float64
    faces : (F, 3) int64
    normals : (N, 3) float64
        Unit vertex normals (vertices are welded inside a chart when position and normal agree).
    labels : (F,) int64
        Selected view of every face, -1 = unseen.
    fuv : (F, 3, 2) float64
        ``visibility.face_uv(labels)``: every face's corners in its own view.
    visibility : Visibility
        ``face_uv`` (other views' projections for absorbing and merging), ``usable`` and
        ``area`` (read at the (view, face) pairs of merge candidates only).
    adjacency : (E, 2) int64
        Faces sharing an edge.
    wpos : (N,) int64, optional
        Welded vertex ids (:func:`o3d_seqcc.geometry.meshops.weld_vertices`), computed when omitted.
    merge_faces : int, default 3
        Charts of at most this many faces are merged into a neighbour's parametrisation (0: off).

    Returns
    -------
    ChartSet
    """
    F = len(faces)
    seen = labels >= 0
    wpos = weld_vertices(verts) if wpos is None else np.asarray(wpos, dtype=np.int64)
    wf = wpos[faces]
    wid = _weld_position_normal(wpos, normals)
    level = image_charts(faces, labels, adjacency)
    n_level = int(level.max()) + 1
    chart_view = np.zeros(n_level, dtype=np.int64)
    chart_view[level[seen]] = labels[seen]
    p3 = verts[faces]
    area3 = 0.5 * np.linalg.norm(np.cross(p3[:, 1] - p3[:, 0], p3[:, 2] - p3[:, 0]), axis=1)
    chart, n_absorbed = _absorb_unseen(level, chart_view, labels, wf, adjacency, visibility, fuv)
    own_area = np.zeros(F)
    own_area[seen] = 0.5 * np.abs(_tri_area2(fuv[seen]))
    n_merged = 0
    if merge_faces > 0 and n_level > 1:
        chart, n_merged = _merge_tiny(chart, chart_view, labels, wf, visibility, own_area, int(merge_faces))
        chart, n_moved = _migrate_faces(chart, chart_view, labels, adjacency, visibility, own_area, int(merge_faces))
        logger.info("charts: %d faces moved across chart borders", n_moved)
    # image charts (compact ids), parametrised by their view's projection
    fi = np.flatnonzero(chart >= 0)
    used, chart_i = np.unique(chart[fi], return_inverse=True)
    chart_i = chart_i.reshape(-1)
    pview = np.full(F, -1, dtype=np.int64)
    pview[fi] = chart_view[used][chart_i]
    puv = visibility.face_uv(pview)
    nw = int(wid.max()) + 1
    keys, inv = np.unique((chart_i[:, None] * nw + wid[faces[fi]]).reshape(-1), return_inverse=True)
    new_faces = np.zeros((F, 3), dtype=np.int64)
    new_faces[fi] = inv.reshape(-1, 3)
    v_orig = [np.zeros(len(keys), dtype=np.int64)]
    v_orig[0][inv.reshape(-1)] = faces[fi].reshape(-1)
    uv = [np.zeros((len(keys), 2))]
    uv[0][inv.reshape(-1)] = puv[fi].reshape(-1, 2)
    face_chart = np.full(F, -1, dtype=np.int64)
    face_chart[fi] = chart_i
    n_image = len(used)
    # fallback region: the unseen components left
    fu = np.flatnonzero(chart < 0)
    stats: dict[str, Any] = {"image_charts": n_image, "absorbed_components": n_absorbed,
                             "absorbed_faces": int(np.count_nonzero(~seen & (chart >= 0))),
                             "merged_tiny_charts": n_merged, "fallback_region_faces": int(len(fu)),
                             "fallback_charts": 0}
    if len(fu):
        good = seen & (own_area > 0) & (area3 > 0)
        px_per_unit = float(np.median(np.sqrt(own_area[good] / area3[good]))) if good.any() else 1.0
        scale = px_per_unit * FALLBACK_DENSITY
        comp = _components(chart < 0, adjacency)[fu]
        cuv, cvid, okc = _planar_param(verts, faces[fu], wid, comp, scale)
        use_p = okc[comp]
        nfv, n_fb = 0, 0
        fb_chart = np.zeros(len(fu), dtype=np.int64)
        if use_p.any():
            _, cvid_p = np.unique(cvid[use_p], return_inverse=True)
            cvid[use_p] = cvid_p.reshape(-1, 3)
            fb_chart[use_p] = np.unique(comp[use_p], return_inverse=True)[1].reshape(-1)
            nfv = int(cvid_p.max()) + 1
            n_fb = int(fb_chart[use_p].max()) + 1
        if (~use_p).any():
            xuv, xvid, xch, nx = _xatlas_param(verts, faces[fu[~use_p]], wid, scale)
            cuv[~use_p], cvid[~use_p] = xuv, xvid + nfv
            fb_chart[~use_p] = n_fb + xch
            nfv += int(xvid.max()) + 1
            n_fb += nx
        base = len(keys)
        new_faces[fu] = base + cvid
        vo = np.zeros(nfv, dtype=np.int64)
        vo[cvid.reshape(-1)] = faces[fu].reshape(-1)
        ufb = np.zeros((nfv, 2))
        ufb[cvid.reshape(-1)] = cuv.reshape(-1, 2)
        v_orig.append(vo)
        uv.append(ufb)
        face_chart[fu] = n_image + fb_chart
        stats.update(fallback_charts=n_fb, fallback_px_per_unit=scale)
    stats["charts"] = int(face_chart.max()) + 1
    logger.info("charts: %d image charts (%d unseen components absorbed, %d tiny charts merged), %d fallback charts "
                "for %d faces", n_image, n_absorbed, n_merged, stats["fallback_charts"], len(fu))
    return ChartSet(faces=new_faces, vertex_index=np.concatenate(v_orig), uv=np.concatenate(uv), face_chart=face_chart,
                    n_image=n_image, level_chart=level, stats=stats)
