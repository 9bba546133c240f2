"""Today's bake (main 89e7de7, before issue 13), frozen for comparison: shelf-packed chart rectangles copied
pixel for pixel from the photos (no rotation, no xatlas), fallback blocks per unseen face.

``bake_shelf(mesh, images, visibility, selection, atlas_size=..., adjacency=...)`` returns a
:class:`o3d_seqcc.texturing.TexturedMesh` as ``bake_texture`` did on main (atlas grown 2x while the
charts do not fit). Used by ``benchmarks/atlas.py`` to measure the shelf bake and the xatlas bake in the
same process; the library itself no longer has the shelf packer (issue 13: it measured worse on coverage,
GLB size, vertices and budget, see the benchmark's table). Only library helpers that issue 13 kept
unchanged are imported (seam_leveling_offsets, _rasterize_uv, _seam_edge_corners, _propagate, _check, pull-push
fill, weld / adjacency / normals); the local
seam leveling is main's, copied here.
"""
# ruff: noqa
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from o3d_seqcc.errors import InputError
from o3d_seqcc.imaging.arrays import img_as_uint8, sample_bilinear
from o3d_seqcc.geometry.meshops import face_adjacency, vertex_normals, weld_vertices
from o3d_seqcc.texturing.atlas import _check  # unchanged since 89e7de7: shared, not copied
from o3d_seqcc.texturing.fallback import _propagate
from o3d_seqcc.texturing.leveling import _rasterize_uv, _seam_edge_corners, seam_leveling_offsets
from o3d_seqcc.texturing.textured_mesh import TexturedMesh
from o3d_seqcc.texturing.bake import push_pull_fill

logger = logging.getLogger("benchmarks.shelf_bake")
LEVELING_SMOOTHNESS = 0.03
FALLBACK_GREY = (128, 128, 128)


@dataclass(frozen=True)
class ShelfSettings:
    """main 89e7de7's TextureSettings fields that the shelf bake reads (same defaults)."""

    atlas_size: int = 2048
    padding: int = 4
    texel_scale: float = 1.0
    overflow: str = "grow"
    max_atlas_size: int = 16384
    fill_background: bool = True
    leveling: bool = True
    leveling_smoothness: float = LEVELING_SMOOTHNESS
    local_leveling: bool = True
    local_band: int = 8
    fallback: str = "smooth"

def leveling_corner_offsets(
    images: list[np.ndarray],
    fuv: np.ndarray,
    verts: np.ndarray,
    faces: np.ndarray,
    labels: np.ndarray,
    face_chart: np.ndarray,
    *,
    smoothness: float,
    radius: int = 2,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Seam-leveling offsets (F, 3 corners, 3 channels), 0-255 units, 0 for unseen faces.

    ``f`` at each corner is the mean of its selected image over a (2 radius + 1)^2 pixel
    neighbourhood of the corner's projection (3 x 3 bilinear taps ``radius`` pixels apart),
    which is robust to noise and to sub-pixel registration errors.
    """
    seen = np.flatnonzero(labels >= 0)
    F3 = len(seen) * 3
    f = np.zeros((F3, 3))
    lab_c = np.repeat(labels[seen], 3)
    corner_uv = fuv[seen].reshape(-1, 2)
    vid = faces[seen].reshape(-1)
    d = np.array([-float(radius), 0.0, float(radius)])  # 3 x 3 bilinear taps spanning the neighbourhood
    dx, dy = np.meshgrid(d, d)
    for v in np.unique(lab_c):
        idx = np.flatnonzero(lab_c == v)
        p = corner_uv[idx]
        f[idx] = sample_bilinear(images[v], p[:, 0:1] + dx.ravel()[None], p[:, 1:2] + dy.ravel()[None]).mean(axis=1)
    group = weld_vertices(verts)[vid]
    chart = np.repeat(face_chart[seen], 3)
    g, stats = seam_leveling_offsets(f, np.arange(F3).reshape(-1, 3), group, vertex_chart=chart, smoothness=smoothness)
    out = np.zeros((len(faces), 3, 3))
    out[seen] = g.reshape(-1, 3, 3)
    return out, stats


def apply_corner_offsets(
    tex: np.ndarray, region: np.ndarray, txy: np.ndarray, faces: np.ndarray, corner_offsets: np.ndarray,
    face_chart: np.ndarray, *, fill_iters: int,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Add per-face-corner offsets (F, 3, 3), interpolated barycentrically, to the atlas.

    ``region`` (S, S) int: chart id of every texel to level (-1 = leave). Texels inside a face
    (rasterised) get the interpolated offset; the others (gutters) the mean offset of their
    chart, blended towards the nearest faces' offsets over ``fill_iters`` texels by masked 3 x 3
    dilations, so bilinear filtering and the first mip levels see a continuous offset field.
    """
    import cv2

    t0 = time.perf_counter()
    rows = np.flatnonzero((region >= 0).any(axis=1))
    if len(rows) == 0:
        return tex.copy(), {"texels_in_faces": 0, "time_raster_s": 0.0, "time_apply_s": 0.0}
    full = tex
    R = int(rows[-1]) + 1  # charts are packed from the top: work on the rows that hold them
    region, tex = region[:R], tex[:R]
    S = tex.shape[1]
    tidx, tface, bary = _rasterize_uv(txy, faces, region >= 0)
    t1 = time.perf_counter()
    n_ch = int(max(region.max(), face_chart.max())) + 1
    csum = np.zeros((n_ch, 3))
    np.add.at(csum, face_chart, corner_offsets.mean(axis=1))
    ccnt = np.bincount(face_chart, minlength=n_ch).astype(np.float64)
    cmean = (csum / np.maximum(ccnt, 1.0)[:, None]).astype(np.float32)
    off = np.zeros((R * S, 3), dtype=np.float32)
    flat_region = region.reshape(-1)
    inr = np.flatnonzero(flat_region >= 0)
    off[inr] = cmean[flat_region[inr]]
    off[tidx] = np.einsum("nk,nkc->nc", bary, corner_offsets[tface]).astype(np.float32)
    have = np.zeros(R * S, dtype=np.float32)
    have[tidx] = 1.0
    todo = inr[have[inr] == 0]
    for _ in range(int(fill_iters)):
        if len(todo) == 0:
            break
        ssum = cv2.boxFilter((off * have[:, None]).reshape(R, S, 3), -1, (3, 3), normalize=False,
                             borderType=cv2.BORDER_CONSTANT).reshape(-1, 3)
        cnt = cv2.boxFilter(have.reshape(R, S), -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT).reshape(-1)
        c = cnt[todo]
        sel = c > 0
        ids = todo[sel]
        off[ids] = ssum[ids] / c[sel][:, None]
        have[ids] = 1.0
        todo = todo[~sel]
    out = full.copy()
    flat = out[:R].reshape(-1, 3)
    flat[inr] = np.clip(np.rint(flat[inr].astype(np.float32) + off[inr]), 0, 255).astype(np.uint8)
    return out, {"texels_in_faces": int(len(tidx)), "time_raster_s": t1 - t0, "time_apply_s": time.perf_counter() - t0}


def _face_colors(
    images: list[np.ndarray], fuv: np.ndarray, faces: np.ndarray, labels: np.ndarray, adjacency: np.ndarray, *,
    offsets: np.ndarray | None = None, iters: int = 64,
) -> np.ndarray:
    """(F, 3) colours (0-255): the selected image at the centroid projection for seen faces (plus
    ``offsets`` (F, 3) when given), the mean of the neighbours for unseen ones."""
    col = np.zeros((len(faces), 3))
    known = labels >= 0
    for v in np.unique(labels[known]):
        sel = np.flatnonzero(labels == v)
        c = fuv[sel].mean(axis=1)
        img = images[v]
        xi = np.clip(np.rint(c[:, 0]).astype(np.int64), 0, img.shape[1] - 1)
        yi = np.clip(np.rint(c[:, 1]).astype(np.int64), 0, img.shape[0] - 1)
        col[sel] = img[yi, xi]
    if offsets is not None:
        col[known] = np.clip(col[known] + offsets[known], 0.0, 255.0)
    return _propagate(col, known, adjacency, iters=iters)


def _corner_colors(
    images: list[np.ndarray], fuv: np.ndarray, verts: np.ndarray, faces: np.ndarray, labels: np.ndarray, *,
    corner_offsets: np.ndarray | None = None, iters: int = 256,
) -> np.ndarray:
    """(F, 3, 3) colour of every face corner (0-255): per welded vertex, the mean of the seen
    faces' corners at it (selected image at its projection, plus ``corner_offsets``), propagated
    along mesh edges to vertices with no seen face around them."""
    wv = weld_vertices(verts)
    n_w = int(wv.max()) + 1 if len(wv) else 0
    seen = np.flatnonzero(labels >= 0)
    col_c = np.zeros((len(seen), 3, 3))
    for v in np.unique(labels[seen]):
        sel = labels[seen] == v
        p = fuv[seen[sel]]  # (n, 3, 2)
        col_c[sel] = sample_bilinear(images[v], p[..., 0], p[..., 1])
    if corner_offsets is not None:
        col_c += corner_offsets[seen]
    w_ids = wv[faces[seen]].reshape(-1)
    cnt = np.bincount(w_ids, minlength=n_w).astype(np.float64)
    col = np.stack([np.bincount(w_ids, weights=col_c.reshape(-1, 3)[:, c], minlength=n_w) for c in range(3)], axis=1)
    known = cnt > 0
    col[known] /= cnt[known, None]
    e = wv[faces][:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    col = _propagate(col, known, e[e[:, 0] != e[:, 1]], iters=iters)
    return np.clip(col[wv[faces]], 0.0, 255.0)


def fallback_blocks(
    images: list[np.ndarray], fuv: np.ndarray, verts: np.ndarray, faces: np.ndarray, labels: np.ndarray,
    adjacency: np.ndarray, *, fallback: str, pad: int, corner_offsets: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Texel blocks of the faces seen by no view.

    Parameters
    ----------
    images : list of (H, W, 3) uint8
    fuv : (F, 3, 2) float
        Projection of every face's corners in its selected view (NaN for unseen faces).
    verts : (N, 3) float, faces : (F, 3) int, labels : (F,) int (-1 = unseen)
    adjacency : (E, 2) int
        Face pairs sharing an edge.
    fallback : {"smooth", "flat"}
    pad : int
        Texels around the colour ramp of a block.
    corner_offsets : (F, 3, 3) float or None
        Seam-leveling offsets of the seen faces' corners.

    Returns
    -------
    blocks : (n_blocks, blk, blk, 3) uint8
    block_of_face : (F,) int64
        Block of every unseen face, -1 for seen faces.
    corner_xy : (3, 2) float64
        The texel of each face corner inside its block.
    """
    unseen = np.flatnonzero(labels < 0)
    block_of_face = np.full(len(faces), -1, dtype=np.int64)
    if fallback == "flat":
        blk = 2 * pad + 1
        corner_xy = np.full((3, 2), float(pad))
        if len(unseen) == 0:
            return np.zeros((0, blk, blk, 3), np.uint8), block_of_face, corner_xy
        cols = _face_colors(images, fuv, faces, labels, adjacency,
                            offsets=None if corner_offsets is None else corner_offsets.mean(axis=1))
        c8 = np.clip(np.rint(cols[unseen]), 0, 255).astype(np.uint8)
        rgb, inv = np.unique(c8, axis=0, return_inverse=True)
        block_of_face[unseen] = inv.reshape(-1)
        return np.broadcast_to(rgb[:, None, None, :], (len(rgb), blk, blk, 3)).copy(), block_of_face, corner_xy
    legs = 8  # corners at (pad, pad), (pad + 8, pad), (pad, pad + 8): a gentle ramp per texel
    blk = legs + 2 * pad + 1
    corner_xy = np.array([[pad, pad], [pad + legs, pad], [pad, pad + legs]], dtype=np.float64)
    if len(unseen) == 0:
        return np.zeros((0, blk, blk, 3), np.uint8), block_of_face, corner_xy
    cc = _corner_colors(images, fuv, verts, faces, labels, corner_offsets=corner_offsets)[unseen]
    t = (np.arange(blk, dtype=np.float64) - pad) / legs
    tx, ty = t[None, :, None], t[:, None, None]  # block[y, x] = c0 + (c1 - c0) x + (c2 - c0) y
    c0, c1, c2 = (cc[:, k][:, None, None, :] for k in range(3))
    blocks = c0 + (c1 - c0) * tx[None] + (c2 - c0) * ty[None]
    block_of_face[unseen] = np.arange(len(unseen))
    return np.clip(np.rint(blocks), 0, 255).astype(np.uint8), block_of_face, corner_xy
def local_seam_leveling(
    tex: np.ndarray, region: np.ndarray, txy: np.ndarray, new_faces: np.ndarray, face_chart: np.ndarray,
    labels: np.ndarray, adjacency: np.ndarray, wf: np.ndarray, *, band: int, smooth_iters: int = 1,
    step: float = 0.5, inset: float = 0.5,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Local seam leveling (after Waechter et al. 2014, simplified); see :func:`o3d_seqcc.texturing.bake_texture`.

    Along every seam edge (adjacent faces in two different charts, at least one of them seen)
    the atlas is sampled in both charts at points ``step`` texels apart. A seen chart's target
    is the mean of the two colours (``d = (other - own) / 2``), or the other side's colour when
    that is a fallback (unseen) face, which is not changed (``d = other - own``). ``d`` is
    splatted (bilinear weights) onto the texels around the edge in the chart's rectangle,
    extended into the chart by ``ceil(band / 2)`` steps of masked 5 x 5 normalised convolution (a
    front that never crosses into another chart's rectangle: a two-texel ring inside every
    rectangle is a barrier), smoothed by ``smooth_iters`` masked 3 x 3 averages, faded out with
    the distance to the nearest border texel (smoothstep from 1 within one texel of the
    border to 0 at ``band + 1`` texels) and added to the texture. Whole-atlas OpenCV filters,
    no per-texel Python.
    """
    import cv2

    t0 = time.perf_counter()
    stats: dict[str, Any] = {"band": int(band), "seam_edges": 0, "mean_abs_diff": 0.0, "texels_changed": 0,
                             "mean_abs_offset": 0.0}
    seen = labels >= 0
    fp, fq = adjacency[:, 0], adjacency[:, 1]
    seam = (seen[fp] | seen[fq]) & (face_chart[fp] != face_chart[fq])
    pairs = adjacency[seam]
    rows_used = np.flatnonzero((region >= 0).any(axis=1))
    if len(pairs) == 0 or len(rows_used) == 0 or band < 1:
        stats["time_s"] = time.perf_counter() - t0
        return tex, stats
    R = int(rows_used[-1]) + 1
    S = tex.shape[1]
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
            sgn = np.sign(((third - e2[:, 0]) * nvec).sum(axis=1))
            pts_ += (float(inset) * sgn[:, None] * nvec)[eid]
    diff = sample_bilinear(tex, pb[:, 0], pb[:, 1]) - sample_bilinear(tex, pa[:, 0], pa[:, 1])  # other - own, for p
    both = (seen[pairs[:, 0]] & seen[pairs[:, 1]])[eid]
    share = np.where(both, 0.5, 1.0)[:, None]
    stats["seam_edges"] = int(len(pairs))
    stats["mean_abs_diff"] = float(np.abs(diff).mean())
    # splat d onto the 4 bilinear neighbours of every sample, on both sides (fallback sides fall outside the domain)
    own_seen = np.concatenate([seen[pairs[:, 0]][eid], seen[pairs[:, 1]][eid]])
    pts = np.concatenate([pa, pb])[own_seen]
    dv = np.concatenate([share * diff, -share * diff])[own_seen]
    x0 = np.clip(np.floor(pts[:, 0]).astype(np.int64), 0, S - 2)
    y0 = np.clip(np.floor(pts[:, 1]).astype(np.int64), 0, R - 2)
    fx = np.clip(pts[:, 0] - x0, 0.0, 1.0)
    fy = np.clip(pts[:, 1] - y0, 0.0, 1.0)
    base = y0 * S + x0
    idx = np.concatenate([base, base + 1, base + S, base + S + 1])
    w = np.concatenate([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy])
    wsum = np.bincount(idx, weights=w, minlength=R * S).reshape(R, S)
    # domain: texels of seen-chart rectangles minus a two-texel ring inside every rectangle
    reg = region[:R]
    edge = np.zeros((R, S), dtype=np.uint8)
    edge[1:] |= reg[1:] != reg[:-1]
    edge[:-1] |= reg[:-1] != reg[1:]
    edge[:, 1:] |= reg[:, 1:] != reg[:, :-1]
    edge[:, :-1] |= reg[:, :-1] != reg[:, 1:]
    edge = cv2.dilate(edge, np.ones((3, 3), np.uint8))
    dom = ((reg >= 0) & (edge == 0)).astype(np.float32)
    seed = ((wsum > 1e-6) & (dom > 0)).astype(np.float32)
    inv_w = np.divide(seed, wsum, out=np.zeros((R, S)), where=wsum > 1e-6)
    P = [np.ascontiguousarray((np.bincount(idx, weights=w * np.tile(dv[:, c], 4), minlength=R * S).reshape(R, S)
                               * inv_w).astype(np.float32)) for c in range(3)]  # value x known
    K = seed
    bc = cv2.BORDER_CONSTANT
    for _ in range((int(band) + 1) // 2):  # extension front, two texels per step
        c = cv2.boxFilter(K, -1, (5, 5), normalize=False, borderType=bc)
        upd = cv2.multiply(cv2.subtract(dom, K), cv2.threshold(c, 1e-3, 1.0, cv2.THRESH_BINARY)[1])
        f = cv2.divide(upd, cv2.max(c, 1e-3))  # upd is 0 where c is
        P = [cv2.add(p, cv2.multiply(cv2.boxFilter(p, -1, (5, 5), normalize=False, borderType=bc), f)) for p in P]
        K = cv2.add(K, upd)
    free = cv2.subtract(K, seed)  # extended, non-seed texels
    keep = cv2.subtract(np.float32(1.0) + np.zeros_like(free), free)
    for _ in range(int(smooth_iters)):  # masked smoothing of the extended values (seeds fixed)
        c = cv2.boxFilter(K, -1, (3, 3), normalize=False, borderType=bc)
        f = cv2.divide(free, cv2.max(c, 1e-3))  # c >= 1 where free
        P = [cv2.add(cv2.multiply(p, keep), cv2.multiply(cv2.boxFilter(p, -1, (3, 3), normalize=False, borderType=bc), f))
             for p in P]
    dist = cv2.distanceTransform((seed == 0).astype(np.uint8), cv2.DIST_L2, 3)
    tt = np.clip(1.0 - (dist - 1.0) / float(band), 0.0, 1.0)
    fall = (tt * tt * (3.0 - 2.0 * tt) * K).astype(np.float32)  # P holds value x known, K in {0, 1}
    off = cv2.merge([cv2.multiply(p, fall) for p in P])
    touched = fall > 0
    out = tex.copy()
    sub = out[:R]
    sub[touched] = np.clip(np.rint(sub[touched].astype(np.float32) + off[touched]), 0, 255).astype(np.uint8)
    stats["texels_changed"] = int(np.count_nonzero(touched))
    stats["mean_abs_offset"] = float(np.abs(off[touched]).mean()) if touched.any() else 0.0
    stats["time_s"] = time.perf_counter() - t0
    return out, stats


def shelf_pack(w: np.ndarray, h: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Shelf packing of rectangles into a strip of ``width``; returns x, y and total height.

    Rectangles are sorted by height (then width, then index, deterministic), filled left to
    right in shelves; one Python iteration per shelf, vectorised within a shelf.
    """
    n = len(w)
    x = np.zeros(n, dtype=np.int64)
    y = np.zeros(n, dtype=np.int64)
    if n == 0:
        return x, y, 0
    order = np.lexsort((np.arange(n), -w, -h))
    ws, hs = w[order], h[order]
    cw = np.cumsum(ws)
    k, top = 0, 0
    while k < n:
        base = cw[k - 1] if k else 0
        j = int(np.searchsorted(cw, base + width, side="right"))
        j = max(j, k + 1)  # a rectangle wider than the strip still gets its own shelf
        idx = order[k:j]
        x[idx] = cw[k:j] - ws[k:j] - base
        y[idx] = top
        top += int(hs[k])
        k = j
    return x, y, top


@dataclass
class _Charts:
    """Charts of a selection: seen components first, then fallback blocks."""

    face_chart: np.ndarray  # (F,) int64
    chart_view: np.ndarray  # (C,) int64, n_views = fallback block
    n_seen: int
    blocks: np.ndarray  # (B, blk, blk, 3) uint8
    block_xy: np.ndarray  # (3, 2) corner texels inside a block
    corner_offsets: np.ndarray | None  # (F, 3, 3) global leveling offsets
    leveling: dict | None


@dataclass
class _Layout:
    """Where every chart rectangle sits: in its (scaled) source image and in the atlas."""

    size: int
    scale: float
    grew: bool
    fac: np.ndarray  # (V, 2) scaled / original image size
    x0: np.ndarray  # (C, 2) top-left of the rectangle in its scaled source
    wh: np.ndarray  # (C, 2) rectangle size
    px: np.ndarray  # (C,) atlas position
    py: np.ndarray


def _make_charts(images, fuv, verts, faces, labels, adjacency, s: ShelfSettings) -> _Charts:
    """Charts = connected components of same-view faces; leveling offsets; fallback blocks."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    seen = labels >= 0
    same = (labels[adjacency[:, 0]] == labels[adjacency[:, 1]]) & (labels[adjacency[:, 0]] >= 0)
    e = adjacency[same]
    _, comp = connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(faces),) * 2),
                                   directed=False)
    corner_off = lev_stats = None
    if s.leveling:
        t = time.perf_counter()
        corner_off, lev_stats = leveling_corner_offsets(images, fuv, verts, faces, labels, comp,
                                                        smoothness=float(s.leveling_smoothness))
        lev_stats["time_solve_s"] = time.perf_counter() - t
    blocks, fb_of_face, fb_xy = fallback_blocks(images, fuv, verts, faces, labels, adjacency, fallback=s.fallback,
                                                pad=min(int(s.padding), 1), corner_offsets=corner_off)
    n_unseen = int(np.count_nonzero(~seen))
    if n_unseen:
        logger.info("bake_texture: %d faces seen by no view get a %s fallback colour (%d blocks)", n_unseen,
                    s.fallback, len(blocks))
    seen_comp, chart_seen = np.unique(comp[seen], return_inverse=True)
    face_chart = np.empty(len(faces), dtype=np.int64)
    face_chart[seen] = chart_seen.reshape(-1)
    face_chart[~seen] = len(seen_comp) + fb_of_face[~seen]
    chart_view = np.full(len(seen_comp) + len(blocks), len(images), dtype=np.int64)  # n_views = fallback colours
    chart_view[face_chart[seen]] = labels[seen]
    return _Charts(face_chart, chart_view, len(seen_comp), blocks, fb_xy, corner_off, lev_stats)


def _layout(images, fuv, labels, ch: _Charts, s: ShelfSettings) -> _Layout:
    """Chart rectangles in their scaled sources and their atlas positions (retrying on overflow)."""
    seen = labels >= 0
    fs = np.flatnonzero(seen)
    n_charts = len(ch.chart_view)
    blk = ch.blocks.shape[1]
    padding = int(s.padding)
    size, scale, grew = int(s.atlas_size), float(s.texel_scale), False
    img_wh = np.array([[im.shape[1], im.shape[0]] for im in images], dtype=np.float64)
    for _attempt in range(64):
        fac = np.maximum(1, np.rint(img_wh * scale)) / img_wh  # exact per-image resize factors
        suv = (fuv[fs] + 0.5) * fac[labels[fs]][:, None, :] - 0.5
        lo = np.full((n_charts, 2), np.inf)
        hi = np.full((n_charts, 2), -np.inf)
        np.minimum.at(lo, ch.face_chart[fs], suv.min(axis=1))
        np.maximum.at(hi, ch.face_chart[fs], suv.max(axis=1))
        x0 = np.zeros((n_charts, 2), dtype=np.int64)
        x1 = np.zeros((n_charts, 2), dtype=np.int64)
        x0[:ch.n_seen] = np.floor(lo[:ch.n_seen]).astype(np.int64) - padding
        x1[:ch.n_seen] = np.ceil(hi[:ch.n_seen]).astype(np.int64) + padding
        x0[ch.n_seen:], x1[ch.n_seen:] = 0, blk - 1  # fallback blocks: blk x blk
        wh = x1 - x0 + 1
        px, py, height = shelf_pack(wh[:, 0], wh[:, 1], size)
        if wh[:, 0].max() <= size and height <= size:
            return _Layout(size, scale, grew, fac, x0, wh, px, py)
        need_area = float((wh[:, 0] * wh[:, 1]).sum())
        if s.overflow == "error":
            raise InputError(
                f"the charts do not fit a {size}x{size} atlas at texel_scale {scale:g} (they need about "
                f"{int(np.ceil(np.sqrt(need_area)))}^2 texels, widest chart {int(wh[:, 0].max())}); use a larger "
                "atlas_size (--atlas-size), a smaller texel_scale, or overflow='grow'/'scale'"
            )
        if s.overflow == "grow":
            if size * 2 > s.max_atlas_size:
                raise InputError(
                    f"the charts do not fit a {size}x{size} atlas at texel_scale {scale:g} and growing it would exceed "
                    f"max_atlas_size={s.max_atlas_size}; use overflow='scale' or a smaller texel_scale"
                )
            size, grew = size * 2, True
            logger.warning("bake_texture: charts do not fit, atlas grown to %dx%d", size, size)
        else:
            scale *= float(np.clip(min(np.sqrt(size * size / need_area) * 0.9, size / wh[:, 0].max()), 0.3, 0.97))
            if scale < 1e-3:
                break
            logger.info("bake_texture: charts do not fit, texel_scale reduced to %.3f", scale)
    raise InputError(
        f"could not pack {n_charts} charts into a {size}x{size} atlas even with texel_scale {scale:.2g}: their "
        f"gutters alone ({2 * padding + 1}^2 texels per chart) need more room; use a larger atlas_size or a "
        "smaller padding"
    )


def _gather(images, ch: _Charts, lay: _Layout, padding: int, want_region: bool):
    """Copy every chart rectangle from its padded (scaled) source into the atlas, texel for texel."""
    import cv2

    size = lay.size
    margin = int(padding) + 2
    blk = ch.blocks.shape[1]
    srcs = []
    for im, f in zip(images, lay.fac):
        ww, hh = int(round(im.shape[1] * f[0])), int(round(im.shape[0] * f[1]))
        if (ww, hh) != (im.shape[1], im.shape[0]):
            im = cv2.resize(im, (ww, hh), interpolation=cv2.INTER_AREA if lay.scale < 1 else cv2.INTER_LINEAR)
        srcs.append(cv2.copyMakeBorder(im, margin, margin, margin, margin, cv2.BORDER_REPLICATE))
    # fallback block k is at x = k * blk of one row of blocks
    fb_img = ch.blocks.transpose(1, 0, 2, 3).reshape(blk, -1, 3) if len(ch.blocks) else np.zeros((1, 1, 3), np.uint8)
    srcs.append(cv2.copyMakeBorder(fb_img, margin, margin, margin, margin, cv2.BORDER_REPLICATE))
    sh = np.array([s.shape[0] for s in srcs], dtype=np.int64)
    sw = np.array([s.shape[1] for s in srcs], dtype=np.int64)
    soff = np.r_[0, np.cumsum(sh * sw)[:-1]]
    flat = np.concatenate([s.reshape(-1, 3) for s in srcs], axis=0)
    n_charts = len(ch.chart_view)
    sx0 = lay.x0.copy()
    sx0[ch.n_seen:, 0] = np.arange(len(ch.blocks)) * blk
    sx0[ch.n_seen:, 1] = 0
    sx0 += margin
    sx1 = sx0 + lay.wh - 1
    cv_ = ch.chart_view
    out_of = (sx0[:, 0] < 0) | (sx0[:, 1] < 0) | (sx1[:, 0] >= sw[cv_]) | (sx1[:, 1] >= sh[cv_])
    if out_of.any():
        bad = np.flatnonzero(np.isin(ch.face_chart, np.flatnonzero(out_of)))
        raise InputError(
            f"{len(bad)} faces (e.g. {bad[:5].tolist()}) are assigned to views in which they project outside the "
            "image: select only usable views (select_views does)"
        )
    area_c = lay.wh[:, 0] * lay.wh[:, 1]
    start = np.r_[0, np.cumsum(area_c)[:-1]]
    cid = np.repeat(np.arange(n_charts), area_c)
    local = np.arange(int(area_c.sum()), dtype=np.int64) - start[cid]
    ly, lx = np.divmod(local, lay.wh[cid, 0])
    del local
    src_idx = (soff[cv_] + sx0[:, 1] * sw[cv_] + sx0[:, 0])[cid] + ly * sw[cv_][cid] + lx
    dst_idx = (lay.py * size + lay.px)[cid] + ly * size + lx
    del lx, ly
    tex = np.zeros((size * size, 3), dtype=np.uint8)
    tex[dst_idx] = flat[src_idx]
    covered = np.zeros(size * size, dtype=bool)
    covered[dst_idx] = True
    region = None
    if want_region:  # chart id of every texel of a seen chart's rectangle (fallback blocks are not leveled)
        region = np.full(size * size, -1, dtype=np.int32)
        region[dst_idx] = cid.astype(np.int32)
        region[region >= ch.n_seen] = -1
        region = region.reshape(size, size)
    return tex.reshape(size, size, 3), covered.reshape(size, size), region


def _output_vertices(fuv, faces, ch: _Charts, lay: _Layout, n_vertices: int):
    """Vertices duplicated per chart: new faces, original vertex ids, texel coordinates."""
    keys, inv = np.unique((ch.face_chart[:, None] * n_vertices + faces).reshape(-1), return_inverse=True)
    new_faces = inv.reshape(-1, 3).astype(np.int64)
    v_chart, v_orig = keys // n_vertices, keys % n_vertices
    txy = np.empty((len(keys), 2))
    pos = np.stack([lay.px, lay.py], axis=1)
    seen_faces = np.flatnonzero(ch.face_chart < ch.n_seen)
    corners = new_faces[seen_faces].reshape(-1)  # every corner of a seen face: its view's projection of the vertex
    cview = np.repeat(ch.chart_view[ch.face_chart[seen_faces]], 3)
    suv = (fuv[seen_faces].reshape(-1, 2) + 0.5) * lay.fac[cview] - 0.5
    txy[corners] = suv - lay.x0[v_chart[corners]] + pos[v_chart[corners]]
    fbf = np.flatnonzero(ch.face_chart >= ch.n_seen)
    for j in range(3):  # fallback faces: their corners' texels in their blocks
        txy[new_faces[fbf, j]] = pos[ch.face_chart[fbf]] + ch.block_xy[j]
    return new_faces, v_orig.astype(np.int64), txy


def bake_shelf(mesh: Any, views_images: Sequence[np.ndarray], visibility: Any, selection: np.ndarray, *,
               adjacency: np.ndarray | None = None, **options: Any) -> TexturedMesh:
    """main 89e7de7's ``bake_texture`` (options: the :class:`ShelfSettings` fields)."""
    return _bake(mesh, views_images, visibility, selection, ShelfSettings(**options), adjacency, lambda _name: None)


def _bake(mesh, views_images, visibility, selection, s: ShelfSettings, adjacency, step) -> TexturedMesh:
    t0 = time.perf_counter()
    step("charts")
    verts, faces, labels, fuv = _check(mesh, views_images, visibility, selection)
    images = [img_as_uint8(im, where=f"image of view {i}") for i, im in enumerate(views_images)]
    adjacency = face_adjacency(faces, verts) if adjacency is None else np.asarray(adjacency, dtype=np.int64).reshape(-1, 2)
    ch = _make_charts(images, fuv, verts, faces, labels, adjacency, s)
    step("pack")
    lay = _layout(images, fuv, labels, ch, s)
    t_pack = time.perf_counter()
    step("copy texels")
    tex, covered, region = _gather(images, ch, lay, int(s.padding), s.leveling or s.local_leveling)
    t_bake = time.perf_counter()
    new_faces, v_orig, txy = _output_vertices(fuv, faces, ch, lay, len(verts))
    seen = labels >= 0
    lev_stats = ch.leveling
    step("seam leveling")
    if s.leveling:
        fs = np.flatnonzero(seen)
        tex, st = apply_corner_offsets(tex, region, txy, new_faces[fs], ch.corner_offsets[fs], ch.face_chart[fs],
                                       fill_iters=2)
        lev_stats.update(st, smoothness=float(s.leveling_smoothness))
        logger.info("bake_texture: seam leveling, %d seam pairs, mean |offset| %.1f levels, step %.1f -> %.1f, %.2f s",
                    lev_stats["seam_pairs"], lev_stats["mean_abs_offset"], lev_stats["seam_step_before"],
                    lev_stats["seam_step_after"], lev_stats["time_solve_s"] + lev_stats["time_apply_s"])
    local_stats = None
    step("local seam leveling")
    if s.local_leveling and int(s.padding) < 1:
        logger.warning("bake_texture: local seam leveling needs padding >= 1 (got %d): skipped", int(s.padding))
    elif s.local_leveling:
        tex, local_stats = local_seam_leveling(tex, region, txy, new_faces, ch.face_chart, labels, adjacency,
                                               weld_vertices(verts)[faces], band=int(s.local_band))
        logger.info("bake_texture: local seam leveling, %d seam edges, mean step %.1f levels, %d texels, %.2f s",
                    local_stats["seam_edges"], local_stats["mean_abs_diff"], local_stats["texels_changed"],
                    local_stats["time_s"])
    step("gutters")
    if s.fill_background and not covered.all():
        tex = push_pull_fill(tex, covered)
    t_end = time.perf_counter()
    size = lay.size
    stats = {
        "atlas_size": size, "requested_atlas_size": int(s.atlas_size), "grew": lay.grew, "texel_scale": lay.scale,
        "charts": int(ch.n_seen), "fallback_charts": int(len(ch.blocks)), "fallback": s.fallback,
        "unseen_faces": int(np.count_nonzero(~seen)), "vertices_out": int(len(v_orig)),
        "utilization": float(covered.mean()), "packer": "shelf", "leveling": lev_stats, "local_leveling": local_stats,
        "time_pack_s": t_pack - t0, "time_bake_s": t_bake - t_pack, "time_total_s": t_end - t0,
    }
    logger.info("bake_texture: %d charts, %dx%d atlas (scale %.3g, %.0f%% used) in %.2f s",
                ch.n_seen, size, size, lay.scale, 100 * stats["utilization"], stats["time_total_s"])
    normals = vertex_normals(verts, faces, getattr(mesh, "vertex_normals", None))[v_orig]
    return TexturedMesh(
        vertices=verts[v_orig], faces=new_faces,
        uv=np.stack([(txy[:, 0] + 0.5) / size, 1.0 - (txy[:, 1] + 0.5) / size], axis=1),
        texture=tex, normals=normals, face_view=np.where(seen, labels, -1), vertex_index=v_orig,
        face_chart=ch.face_chart, stats=stats,
    )
