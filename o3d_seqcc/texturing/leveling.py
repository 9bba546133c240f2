"""Seam leveling (beyond the paper, after Waechter et al. 2014, "Let There Be Color!").

Global (:func:`seam_leveling_offsets`, :func:`corner_colors`, :func:`solve_corner_offsets`):
the colour correction leaves small per-chart colour offsets that show as steps at chart seams.
Additive per-vertex-per-chart offsets are solved for in a sparse least-squares problem (equal
colours on both sides of every seam vertex, smooth offsets inside charts) and the bake adds
their barycentric interpolation to every texel of a face (:mod:`~o3d_seqcc.texturing.atlas`).
Only a low-frequency field is added, so the texture keeps its detail.

Local (:func:`local_seam_leveling`, after the same paper's local Poisson editing, simplified):
what the global leveling leaves (colour differences that vary along a seam) is removed in a thin
strip along every chart border: both sides of every seam edge are sampled, each side's border is
moved to their mean, and the difference fades out smoothly into the chart (masked normalised
convolution on the whole atlas).

Atlas-space arrays: ``txy`` (M, 2) texel coordinates of the output vertices (x right, y down,
texel centres at integers), ``region`` (S, S) int32 chart id of every texel to level (-1 =
leave).
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np

from ..errors import InputError
from .._shared.sets import unique
from ..imaging.arrays import sample_bilinear
from .settings import LEVELING_SMOOTHNESS

logger = logging.getLogger(__name__)

#: unknowns up to which :func:`seam_leveling_offsets` factors its system (SuperLU); above, conjugate gradients.
#: The factors grow faster than the unknowns (760 MB for 772k unknowns, 1.4 GB of RSS while factoring, on a
#: 2.2M-face street), the iterative solve's memory is the matrix's (issue 36)
DIRECT_MAX_UNKNOWNS = 500_000
#: relative residual at which the conjugate gradients stop: offsets within 1e-4 levels of the direct solve's
#: (5e-5 at most on the 772k-unknown street, 0.0064 at 1e-6)
CG_RTOL = 1e-8

__all__ = ["corner_colors", "local_seam_leveling", "seam_leveling_offsets", "solve_corner_offsets"]


def _vertex_pairs_by_group(group: np.ndarray, members: np.ndarray) -> np.ndarray:
    """All pairs (i, j), i != j unordered, of ``members`` that share a ``group`` id -> (P, 2)."""
    if len(members) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    order = members[np.argsort(group[members], kind="stable")]
    gs = group[order]
    out = []
    d = 1
    while d < len(order):
        same = gs[d:] == gs[:-d]
        if not same.any():
            break
        out.append(np.stack([order[:-d][same], order[d:][same]], axis=1))
        d += 1
    return np.concatenate(out) if out else np.zeros((0, 2), dtype=np.int64)


def seam_leveling_offsets(
    colors: np.ndarray,
    faces: np.ndarray,
    vertex_group: np.ndarray,
    *,
    face_mask: np.ndarray | None = None,
    vertex_chart: np.ndarray | None = None,
    smoothness: float = LEVELING_SMOOTHNESS,
    regularizer: float = 1e-4,
    huber: float = 30.0,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Per-vertex additive colour offsets that cancel colour steps at chart seams.

    Vertices are split per chart (one copy of a 3D vertex per chart that uses it); copies of
    the same 3D vertex share a ``vertex_group``. Solves, per colour channel, the sparse
    least-squares problem (Waechter et al. 2014, global seam leveling)::

        min_g  sum_{copies i, j of one vertex} w_ij ((f_i + g_i) - (f_j + g_j))^2
             + smoothness * sum_{edges (i, j) of a face} (g_i - g_j)^2
             + regularizer * sum_i g_i^2

    through its normal equations (a sparse SPD system: SuperLU with a minimum-degree ordering of
    ``A^T + A`` and symmetric pivoting, ``scipy.sparse.linalg.splu``, a third less fill than
    ``spsolve``'s default column ordering; above :data:`DIRECT_MAX_UNKNOWNS` unknowns, whose factors
    would outgrow the mesh, Jacobi-preconditioned conjugate gradients to :data:`CG_RTOL`).
    ``w_ij = min(1, huber / |f_i - f_j|)`` (one Huber reweighting) limits the pull of seams
    whose two sides show different things (registration errors, occlusions).

    Parameters
    ----------
    colors : (M, 3) float array
        ``f``: the colour of every vertex copy in its own chart (e.g. a small neighbourhood
        average of the texture), in 0-255 units.
    faces : (F, 3) int array
        Faces over the vertex copies (a face never mixes charts).
    vertex_group : (M,) int array
        Id of the 3D vertex each copy belongs to.
    face_mask : (F,) bool array, optional
        Faces taking part (default all); vertices of other faces get offset 0.
    vertex_chart : (M,) int array, optional
        Chart of every copy. When given, copies with the same chart and group (meshes stored
        with split vertices) are one unknown (their colours averaged), so that the smoothness
        term links the faces of a chart; without it every copy is its own unknown.
    smoothness : float, default :data:`LEVELING_SMOOTHNESS` (0.03)
        Weight of the intra-chart smoothness term (larger = smoother, lower-frequency offsets;
        on fountain 0.03 leaves slightly smaller seams than 0.1, and clearly smaller than 0.3 or 1).
    regularizer : float, default 1e-4
        Pull of every offset towards 0 (fixes the free constant of each connected group). With
        ``smoothness`` it sets how far into a chart an offset reaches before fading: about
        ``sqrt(smoothness / regularizer)`` edges (17 with the defaults).
    huber : float, default 30.0
        Colour difference (0-255 units, Euclidean RGB) above which a seam pair is down-weighted.

    Returns
    -------
    offsets : (M, 3) float64
        ``g``, in the units of ``colors``.
    stats : dict
        ``seam_pairs``, ``mean_abs_offset``, ``max_abs_offset``, ``seam_step_before`` and
        ``seam_step_after`` (mean Euclidean RGB step over seam pairs).
    """
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    f = np.asarray(colors, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    grp = np.asarray(vertex_group, dtype=np.int64)
    M = len(f)
    if f.shape != (M, 3) or grp.shape != (M,):
        raise InputError(f"colors must be (M, 3) and vertex_group (M,), got {f.shape} and {grp.shape}")
    if vertex_chart is not None:
        ch = np.asarray(vertex_chart, dtype=np.int64)
        if ch.shape != (M,):
            raise InputError(f"vertex_chart must be ({M},), got {ch.shape}")
        gmax = int(grp.max()) + 1 if M else 1
        ukeys, node = np.unique(ch * gmax + grp, return_inverse=True)
        node = node.reshape(-1)
        cnt = np.bincount(node, minlength=len(ukeys)).astype(np.float64)
        fn = np.stack([np.bincount(node, weights=f[:, c], minlength=len(ukeys)) for c in range(3)], axis=1)
        fn /= cnt[:, None]
        g_n, stats = seam_leveling_offsets(fn, node[faces], ukeys % gmax, face_mask=face_mask, smoothness=smoothness,
                                           regularizer=regularizer, huber=huber)
        return g_n[node], stats
    if smoothness < 0 or regularizer <= 0:
        raise ValueError(f"smoothness must be >= 0 and regularizer > 0, got {smoothness}, {regularizer}")
    fm = faces if face_mask is None else faces[np.asarray(face_mask, dtype=bool)]
    used = np.zeros(M, dtype=bool)
    used[fm.reshape(-1)] = True
    pairs = _vertex_pairs_by_group(grp, np.flatnonzero(used))
    diff = f[pairs[:, 0]] - f[pairs[:, 1]] if len(pairs) else np.zeros((0, 3))
    step = np.linalg.norm(diff, axis=1)
    w = np.minimum(1.0, float(huber) / np.maximum(step, 1e-12)) if len(pairs) else np.zeros(0)
    e = np.concatenate([fm[:, [0, 1]], fm[:, [1, 2]], fm[:, [2, 0]]])
    e.sort(axis=1)
    e = e[e[:, 0] != e[:, 1]]
    key = unique(e[:, 0] * np.int64(max(M, 1)) + e[:, 1])  # the unique rows in their lexicographic order
    e = np.stack([key // max(M, 1), key % max(M, 1)], axis=1)
    ii = np.r_[pairs[:, 0], e[:, 0]]
    jj = np.r_[pairs[:, 1], e[:, 1]]
    ww = np.r_[w, np.full(len(e), float(smoothness))]
    W = sp.coo_matrix((ww, (ii, jj)), shape=(M, M))
    W = (W + W.T).tocsr()
    L = sp.diags(np.asarray(W.sum(axis=1)).ravel() + float(regularizer)) - W
    b = np.zeros((M, 3))
    if len(pairs):
        np.add.at(b, pairs[:, 0], -w[:, None] * diff)
        np.add.at(b, pairs[:, 1], w[:, None] * diff)
    if M <= DIRECT_MAX_UNKNOWNS:
        # SPD: minimum degree on A^T + A, diagonal pivots (186 MB -> 131 MB of factors at 189k unknowns, 300k faces)
        lu = splu(L.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        g = np.asarray(lu.solve(b), dtype=np.float64).reshape(M, 3)
        del lu
    else:
        g = _solve_cg(L.tocsr(), b)
    g[~used] = 0.0
    after = (f + g)[pairs[:, 0]] - (f + g)[pairs[:, 1]] if len(pairs) else np.zeros((0, 3))
    stats = {
        "seam_pairs": int(len(pairs)),
        "mean_abs_offset": float(np.abs(g[used]).mean()) if used.any() else 0.0,
        "max_abs_offset": float(np.abs(g).max()) if M else 0.0,
        "seam_step_before": float(step.mean()) if len(pairs) else 0.0,
        "seam_step_after": float(np.linalg.norm(after, axis=1).mean()) if len(pairs) else 0.0,
    }
    return g, stats


def _solve_cg(L, b: np.ndarray) -> np.ndarray:
    """(M, 3) float64 solution of the SPD system ``L g = b``, channel by channel, by Jacobi-preconditioned
    conjugate gradients to :data:`CG_RTOL` (memory: the matrix and a few (M,) vectors)."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import cg

    t0 = time.perf_counter()
    pre = sp.diags(1.0 / L.diagonal())
    g = np.zeros(b.shape, dtype=np.float64)
    for c in range(b.shape[1]):
        if not np.any(b[:, c]):
            continue
        g[:, c], info = cg(L, b[:, c], rtol=CG_RTOL, atol=0.0, M=pre, maxiter=20 * int(np.sqrt(len(b))) + 1000)
        if info > 0:
            logger.warning("seam leveling: conjugate gradients stopped short of %.0e after %d iterations (channel %d)",
                           CG_RTOL, info, c)
    logger.info("seam leveling: %d unknowns solved by conjugate gradients in %.1f s", len(b), time.perf_counter() - t0)
    return g


def _rasterize_uv(txy: np.ndarray, faces: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Face id and barycentric weights of the texels in ``mask`` (texel centres at integers).

    Ray casting on the UV mesh ``(x, y, 0)`` with rays along -z through the texel centres
    (Open3D ``RaycastingScene``). Returns the flat indices of the texels that hit a face, their
    face (index into ``faces``) and (n, 3) barycentric weights.
    """
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    v3 = np.zeros((len(txy), 3), dtype=np.float32)
    v3[:, :2] = txy
    scene.add_triangles(o3d.core.Tensor(v3), o3d.core.Tensor(np.ascontiguousarray(faces, dtype=np.uint32)))
    idx = np.flatnonzero(mask.reshape(-1))
    ty, tx = np.divmod(idx, mask.shape[1])
    rays = np.zeros((len(idx), 6), dtype=np.float32)
    rays[:, 0] = tx
    rays[:, 1] = ty
    rays[:, 2] = 1.0
    rays[:, 5] = -1.0
    ans = scene.cast_rays(o3d.core.Tensor(rays))
    prim = ans["primitive_ids"].numpy()
    hit = prim != np.iinfo(np.uint32).max
    uvs = ans["primitive_uvs"].numpy()[hit].astype(np.float64)
    bary = np.stack([1.0 - uvs[:, 0] - uvs[:, 1], uvs[:, 0], uvs[:, 1]], axis=1)
    return idx[hit], prim[hit].astype(np.int64), bary


def corner_colors(image: np.ndarray, corner_uv: np.ndarray, *, radius: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Colours of one view at face corners: the neighbourhood mean the leveling compares, and the point value.

    Parameters
    ----------
    image : (H, W, 3) array
    corner_uv : (n, 2) float
        Pixel coordinates (centres at integers).
    radius : int, default 2
        The mean is over a (2 radius + 1)^2 pixel neighbourhood (3 x 3 bilinear taps ``radius``
        pixels apart): robust to noise and to sub-pixel registration errors.

    Returns
    -------
    mean : (n, 3) float64
        Neighbourhood mean (0-255 units).
    point : (n, 3) float64
        Bilinear value at the corner.
    """
    d = np.array([-float(radius), 0.0, float(radius)])
    dx, dy = np.meshgrid(d, d)
    taps = sample_bilinear(image, corner_uv[:, 0:1] + dx.ravel()[None], corner_uv[:, 1:2] + dy.ravel()[None])
    return taps.mean(axis=1), taps[:, 4]


def solve_corner_offsets(
    f: np.ndarray, wf: np.ndarray, labels: np.ndarray, face_chart: np.ndarray, *, smoothness: float,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Seam-leveling offsets of every face corner (:func:`seam_leveling_offsets` on the charts' corners).

    Parameters
    ----------
    f : (F, 3, 3) float
        Colour of every face corner in its chart (:func:`corner_colors` ``mean``, 0-255 units);
        rows of unseen faces are ignored.
    wf : (F, 3) int
        Welded vertex id of every face corner (:func:`o3d_seqcc.geometry.meshops.weld_vertices`).
    labels : (F,) int
        View of every face, -1 = unseen (offset 0).
    face_chart : (F,) int
        Chart of every seen face (charts are leveled against each other at shared vertices).
    smoothness : float

    Returns
    -------
    offsets : (F, 3 corners, 3 channels) float64
    stats : dict
        :func:`seam_leveling_offsets`'s.
    """
    seen = np.flatnonzero(labels >= 0)
    F3 = len(seen) * 3
    group = np.asarray(wf)[seen].reshape(-1)
    chart = np.repeat(face_chart[seen], 3)
    g, stats = seam_leveling_offsets(np.asarray(f, dtype=np.float64)[seen].reshape(-1, 3),
                                     np.arange(F3).reshape(-1, 3), group, vertex_chart=chart, smoothness=smoothness)
    out = np.zeros((len(labels), 3, 3))
    out[seen] = g.reshape(-1, 3, 3)
    return out, stats


def _seam_edge_corners(wf: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Corner indices (0..2) of the shared edge of each adjacent face pair.

    ``wf`` (F, 3): welded vertex id of every face corner; ``pairs`` (E, 2): faces sharing an
    edge. Returns ``cp`` and ``cq``, both (E, 2) int64: the corners of face ``pairs[:, 0]`` /
    ``pairs[:, 1]`` at the two shared vertices, in the same vertex order.
    """
    wp = wf[pairs[:, 0]]
    wq = wf[pairs[:, 1]]
    match = wp[:, :, None] == wq[:, None, :]  # (E, 3, 3)
    ip = match.any(axis=2)
    cp = np.argsort(~ip, axis=1, kind="stable")[:, :2].astype(np.int64)
    rows = np.arange(len(pairs))[:, None]
    cq = np.argmax(match[rows, cp], axis=2).astype(np.int64)
    return cp, cq


def _reciprocal(box: np.ndarray) -> np.ndarray:
    """(n,) float32 ``1 / max(box, 1e-3)`` of small integer box sums, as ``cv2.divide`` gives it on float32 planes."""
    import cv2

    b = np.ascontiguousarray(box, dtype=np.float32).reshape(-1, 1)
    return cv2.divide(np.ones_like(b), cv2.max(b, 1e-3)).reshape(-1)


#: rows per band of :func:`_box_at`'s box filters
BOX_BAND_ROWS = 512


def _box_at(plane: np.ndarray, k: int, idx: np.ndarray) -> np.ndarray:
    """``cv2.boxFilter(plane, -1, (k, k), normalize=False, borderType=BORDER_CONSTANT)`` at the ascending flat
    indices ``idx`` only, filtered in bands of :data:`BOX_BAND_ROWS` rows with ``k // 2`` rows of the plane
    above and below each (a box sum reads its k x k neighbourhood only: the whole plane's values, without an
    atlas-sized output plane)."""
    import cv2

    R, S = plane.shape
    h = k // 2
    out = np.empty(len(idx), dtype=plane.dtype)
    cuts = np.searchsorted(idx, np.arange(0, R + BOX_BAND_ROWS, BOX_BAND_ROWS) * S)
    for b, r0 in enumerate(range(0, R, BOX_BAND_ROWS)):
        i0, i1 = cuts[b], cuts[b + 1]
        if i0 == i1:
            continue
        a, z = max(0, r0 - h), min(R, r0 + BOX_BAND_ROWS + h)
        box = cv2.boxFilter(plane[a:z], -1, (k, k), normalize=False, borderType=cv2.BORDER_CONSTANT)
        out[i0:i1] = box.reshape(-1)[idx[i0:i1] - a * S]
    return out


def local_seam_leveling(
    tex: np.ndarray, region: np.ndarray, txy: np.ndarray, new_faces: np.ndarray, face_chart: np.ndarray,
    labels: np.ndarray, adjacency: np.ndarray, wf: np.ndarray, *, band: int, smooth_iters: int = 1,
    step: float = 0.5, inset: float = 0.5, passes: int = 2, copy: bool = True,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Local seam leveling (after Waechter et al. 2014, simplified); see :func:`o3d_seqcc.texturing.bake_texture`.

    Along every seam edge (adjacent faces in two different charts, at least one of them seen)
    the atlas is sampled in both charts at points ``step`` texels apart, ``inset`` texels inside
    each face (at most a third of its altitude: thin faces are not crossed). A seen chart's
    target is the mean of the two colours (``d = (other - own) / 2``), or the other side's colour
    when that is a fallback (unseen) face, which is not changed (``d = other - own``). ``d`` is
    splatted (bilinear weights) onto the texels around the edge in the chart's region, extended
    into the chart by ``ceil(band / 2)`` steps of masked 5 x 5 normalised convolution (a front
    that never crosses into another chart's region: a two-texel ring inside every region is a
    barrier), smoothed by ``smooth_iters`` masked 3 x 3 averages, faded out with the distance to
    the nearest border texel (smoothstep from 1 within one texel of the border to 0 at
    ``band + 1`` texels) and added to the texture. ``passes`` repeats the whole on the result
    (where a thin chart has seams with several charts the seeds of one pass are averaged; a
    second pass removes most of what is left; the geometry is computed once). Whole-atlas OpenCV
    filters, no per-texel Python. ``region`` holds the chart of every texel to level (faces and
    their gutters), -1 elsewhere. The texture is changed in a copy (``copy=False``: in place, for a
    caller that drops the original).
    """
    import cv2

    t0 = time.perf_counter()
    stats: dict[str, Any] = {"band": int(band), "passes": int(passes), "seam_edges": 0, "mean_abs_diff": 0.0,
                             "texels_changed": 0, "mean_abs_offset": 0.0}
    seen = labels >= 0
    fp, fq = adjacency[:, 0], adjacency[:, 1]
    seam = (seen[fp] | seen[fq]) & (face_chart[fp] != face_chart[fq])
    pairs = adjacency[seam]
    rows_used = np.flatnonzero((region >= 0).any(axis=1))
    if len(pairs) == 0 or len(rows_used) == 0 or band < 1 or passes < 1:
        stats["time_s"] = time.perf_counter() - t0
        return tex, stats
    R = int(rows_used[-1]) + 1
    W = tex.shape[1]
    # the planes below span the columns of the regions (+ a margin the splats and filters never reach past): beyond
    # them every plane is 0 (no region), which is what the constant border of the filters reads
    S = min(W, int(np.flatnonzero((region[:R] >= 0).any(axis=0))[-1]) + 9)
    cp, cq = _seam_edge_corners(wf, pairs)
    ea = txy[new_faces[pairs[:, 0:1], cp]]  # (E, 2 endpoints, 2 xy) in the texels of face p's chart
    eb = txy[new_faces[pairs[:, 1:2], cq]]
    length = np.maximum(np.linalg.norm(ea[:, 1] - ea[:, 0], axis=1), np.linalg.norm(eb[:, 1] - eb[:, 0], axis=1))
    n = np.clip(np.ceil(length / float(step)).astype(np.int64), 1, 4096)
    eid = np.repeat(np.arange(len(pairs)), n)
    start = np.r_[0, np.cumsum(n)[:-1]]
    t = ((np.arange(int(n.sum())) - start[eid]) + 0.5) / n[eid]
    pa = ea[eid, 0] + (ea[eid, 1] - ea[eid, 0]) * t[:, None]
    pb = eb[eid, 0] + (eb[eid, 1] - eb[eid, 0]) * t[:, None]
    if inset > 0:  # move the samples ``inset`` texels into their own face (where seams are seen and measured)
        for e2, cc, col, pts_ in ((ea, cp, 0, pa), (eb, cq, 1, pb)):
            third = txy[new_faces[pairs[:, col], 3 - cc.sum(axis=1)]]  # the face's corner off the edge
            dvec = e2[:, 1] - e2[:, 0]
            nvec = np.stack([-dvec[:, 1], dvec[:, 0]], axis=1)
            nvec /= np.maximum(np.linalg.norm(nvec, axis=1), 1e-12)[:, None]
            h = ((third - e2[:, 0]) * nvec).sum(axis=1)  # signed altitude of the third corner
            # by ``inset`` texels but at most a third of the altitude: beyond a thin face lie other charts
            d_in = np.sign(h) * np.minimum(float(inset), np.abs(h) / 3.0)
            pts_ += (d_in[:, None] * nvec)[eid]
    # both seen: each side moves half-way; a fallback (unseen) side does not move, the seen side takes the whole step
    share = np.where(seen[pairs[:, 0]] & seen[pairs[:, 1]], 0.5, 1.0)[eid, None]
    own_seen = np.concatenate([seen[pairs[:, 0]][eid], seen[pairs[:, 1]][eid]])
    pts = np.concatenate([pa, pb])[own_seen]
    x0 = np.clip(np.floor(pts[:, 0]).astype(np.int64), 0, S - 2)
    y0 = np.clip(np.floor(pts[:, 1]).astype(np.int64), 0, R - 2)
    fx = np.clip(pts[:, 0] - x0, 0.0, 1.0)
    fy = np.clip(pts[:, 1] - y0, 0.0, 1.0)
    base = y0 * S + x0
    uniq, inv = np.unique(np.concatenate([base, base + 1, base + S, base + S + 1]), return_inverse=True)
    inv = inv.reshape(-1)
    w = np.concatenate([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy])
    wsum = np.bincount(inv, weights=w, minlength=len(uniq))
    stats["seam_edges"] = int(len(pairs))
    # domain: texels of seen-chart regions minus a two-texel ring inside every region
    reg = region[:R, :S]
    edge = np.zeros((R, S), dtype=np.uint8)
    edge[1:] |= reg[1:] != reg[:-1]
    edge[:-1] |= reg[:-1] != reg[1:]
    edge[:, 1:] |= reg[:, 1:] != reg[:, :-1]
    edge[:, :-1] |= reg[:, :-1] != reg[:, 1:]
    edge = cv2.dilate(edge, np.ones((3, 3), np.uint8))
    # the domain, the seeds and the front are 0 / 1 planes and their 5 x 5 / 3 x 3 box sums small
    # integers: held as uint8 (exact, a quarter of float32's bytes); the factors of the front's
    # steps (1 / box sum) are divided as float32 at the texels that use them
    dom = ((reg >= 0) & (edge == 0)).astype(np.uint8)
    del edge
    is_seed = (wsum > 1e-6) & (dom.reshape(-1)[uniq] > 0)
    seed = np.zeros(R * S, dtype=np.uint8)
    seed[uniq[is_seed]] = 1
    seed = seed.reshape(R, S)
    # the extension front and the smoothing do not depend on the values: their factors serve every pass
    bc = cv2.BORDER_CONSTANT
    # (held sparse: each factor is 0, or 1 for ``keep``, off the few texels a step reaches, where it changes nothing)
    K = seed.copy()
    c, upd = np.empty_like(seed), np.empty_like(seed)
    grow = []
    for _ in range((int(band) + 1) // 2):  # two texels per step
        cv2.boxFilter(K, -1, (5, 5), dst=c, normalize=False, borderType=bc)
        cv2.subtract(dom, K, dst=upd)  # K lies inside dom: 0 or 1
        upd[c == 0] = 0
        ring = np.flatnonzero(upd)
        grow.append((ring, _reciprocal(c.reshape(-1)[ring])))  # upd / box5(K), upd = 1 on the ring
        cv2.add(K, upd, dst=K)
    del dom, c, upd
    free = cv2.subtract(K, seed)  # extended, non-seed texels (0 or 1): keep = 1 - free, smooth = free / box(K)
    ext = np.flatnonzero(free)
    keep = (np.float32(1.0) - free.reshape(-1)[ext].astype(np.float32)).astype(np.float32)
    smooth = _reciprocal(cv2.boxFilter(K, -1, (3, 3), normalize=False, borderType=bc).reshape(-1)[ext])
    del free
    dist = cv2.distanceTransform((seed == 0).astype(np.uint8), cv2.DIST_L2, 3)
    del seed
    # fall = tt * tt * (3 - 2 tt) * K with tt = clip(1 - (dist - 1) / band, 0, 1): zero off K, so made at K's texels
    kidx = np.flatnonzero(K)
    del K
    tt = dist.reshape(-1)[kidx]
    del dist  # of the atlas-sized planes only the passes' buffer stays
    tt -= 1.0
    tt /= float(band)
    np.subtract(1.0, tt, out=tt)
    np.clip(tt, 0.0, 1.0, out=tt)
    fall = tt * tt
    fall *= 3.0 - 2.0 * tt
    del tt
    pos = fall > 0
    touched = kidx[pos]  # ascending flat indices
    fall_t = fall[pos].astype(np.float32, copy=False)[:, None]
    del kidx, fall, pos
    out = tex.copy() if copy else tex
    sub = out[:R]
    flat_sub = sub.reshape(-1, 3)
    touched_w = touched // S * W + touched % S  # the texture's flat indices (its rows are W long)
    total = np.zeros((len(touched), 3), dtype=np.float32)
    seeds = uniq[is_seed]
    p = np.zeros((R, S), dtype=np.float32)  # one buffer for every channel and pass: set at the seeds, reset after
    flat = p.reshape(-1)
    for k in range(int(passes)):
        diff = sample_bilinear(sub, pb[:, 0], pb[:, 1]) - sample_bilinear(sub, pa[:, 0], pa[:, 1])  # other - own (p)
        if k == 0:
            stats["mean_abs_diff"] = float(np.abs(diff).mean())
        dv = np.concatenate([share * diff, -share * diff])[own_seen]
        vals = np.stack([np.bincount(inv, weights=w * np.tile(dv[:, c], 4), minlength=len(uniq)) for c in range(3)], 1)
        off = np.zeros((len(fall_t), 3), dtype=np.float32)
        for c in range(3):  # one channel at a time (single-channel factors, no merges)
            flat[seeds] = vals[is_seed, c] / wsum[is_seed]
            for ring, g in grow:  # p += box5(p) * g
                flat[ring] += _box_at(p, 5, ring) * g
            for _ in range(int(smooth_iters)):  # masked smoothing of the extended values (seeds fixed)
                box = _box_at(p, 3, ext)
                flat[ext] = flat[ext] * keep + box * smooth  # p * keep + box3(p) * smooth
            off[:, c] = flat[touched]
            flat[seeds] = 0.0  # what the channel set: the seeds and the extended texels (the rings among them)
            flat[ext] = 0.0
        off *= fall_t
        flat_sub[touched_w] = np.clip(np.rint(flat_sub[touched_w].astype(np.float32) + off), 0, 255).astype(np.uint8)
        total += off
    stats["texels_changed"] = int(len(touched))
    stats["mean_abs_offset"] = float(np.abs(total).mean()) if len(touched) else 0.0
    stats["time_s"] = time.perf_counter() - t0
    return out, stats
