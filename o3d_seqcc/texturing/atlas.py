"""Texture-atlas baking: charts cut from the selected photos, packed, leveled (paper 3.8).

:func:`bake_texture` builds a texture atlas whose charts are the image-space footprints of
connected same-view face regions ("the paper crops each face's projection from its selected
image"): a chart's UVs are its vertices' pixel coordinates in its view, so a chart is a
rectangle cut out of one (corrected) image at the image's own resolution and never mixes
images. The chart rectangles (footprint bounding box plus ``padding`` pixels of real image
content around it) are packed with a vectorised shelf packer, and the bake is an exact pixel
copy: with ``texel_scale=1`` a texel *is* a source pixel, so a renderer's bilinear texture lookup
equals bilinear sampling of the selected image at the projected point; other scales resample
the images once (area averaging down, bilinear up). Faces seen by no view get texel blocks
holding their fallback colours (:mod:`~o3d_seqcc.texturing.fallback`); seam leveling
(:mod:`~o3d_seqcc.texturing.leveling`) then removes the colour steps at chart borders.

Within a triangle UVs are interpolated affinely while the camera projection is projective: as
in the paper and mvs-texturing, the texture of a face is its image-space projection, which is
exact at the vertices and off by the perspective foreshortening across one face (negligible for
triangles small relative to their depth).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..errors import InputError
from ..imageops import img_as_uint8
from ..meshops import face_adjacency, vertex_normals, weld_vertices
from ..progress import steps
from .fallback import fallback_blocks
from .leveling import apply_corner_offsets, leveling_corner_offsets, local_seam_leveling
from .settings import TextureSettings, VisibilityLike
from .textured_mesh import TexturedMesh

__all__ = ["bake_texture", "push_pull_fill", "shelf_pack"]

logger = logging.getLogger(__name__)


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


def push_pull_fill(img: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Fill texels outside ``mask`` with smooth colours from the masked ones (pull-push).

    Pull: area-averaged pyramid of colour x coverage and coverage. Push: from the coarsest
    level up, ``filled = c + (1 - w) * upsampled`` (``c`` is the coverage-weighted colour mean,
    ``w`` the coverage), and at full resolution only the empty texels are replaced.

    Parameters
    ----------
    img : (H, W, 3) uint8
    mask : (H, W) bool
        Texels to keep.

    Returns
    -------
    (H, W, 3) uint8
        A new image.
    """
    import cv2

    m = mask.astype(np.float32)
    c = img.astype(np.float32)
    c *= m[..., None]
    levels = []
    while min(m.shape) > 1:
        hh, ww = (m.shape[0] + 1) // 2, (m.shape[1] + 1) // 2
        c = cv2.resize(c, (ww, hh), interpolation=cv2.INTER_AREA)
        m = cv2.resize(m, (ww, hh), interpolation=cv2.INTER_AREA)
        levels.append((c, m))
    c, m = levels[-1]
    filled = c / np.maximum(m, 1e-12)[..., None]
    for c, m in reversed(levels[:-1]):
        up = cv2.resize(filled, (m.shape[1], m.shape[0]), interpolation=cv2.INTER_LINEAR)
        filled = c + up * (1.0 - np.clip(m, 0.0, 1.0))[..., None]
    up = cv2.resize(filled, (mask.shape[1], mask.shape[0]), interpolation=cv2.INTER_LINEAR)
    out = img.copy()
    empty = ~mask
    out[empty] = np.clip(np.rint(up[empty]), 0, 255).astype(np.uint8)
    return out


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


def _check(mesh: Any, images: Sequence[np.ndarray], visibility: VisibilityLike, selection: np.ndarray):
    verts = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    labels = np.asarray(selection, dtype=np.int64).reshape(-1)
    n_views = visibility.n_views
    if len(labels) != len(faces) or visibility.n_faces != len(faces):
        raise InputError(f"selection has {len(labels)} entries and the visibility {visibility.n_faces} faces, but the "
                         f"mesh has {len(faces)} faces")
    if labels.size and (labels.max() >= n_views or labels.min() < -1):
        raise InputError(f"selection holds view indices outside -1..{n_views - 1}")
    if len(images) != n_views:
        raise InputError(f"{len(images)} images given for {n_views} views")
    if not (labels >= 0).any():
        raise InputError(
            "no face is seen by any view, so there is nothing to texture: check the mesh/camera registration "
            "or relax the visibility filters"
        )
    seen = labels >= 0
    fuv = visibility.face_uv(labels)
    if not np.isfinite(fuv[seen]).all():
        bad = np.flatnonzero(seen & ~np.isfinite(fuv).all(axis=(1, 2)))
        raise InputError(
            f"{len(bad)} faces (e.g. {bad[:5].tolist()}) are assigned to views where their vertices have no "
            "projection (NaN uv): select only usable views (select_views does)"
        )
    return verts, faces, labels, fuv


def _make_charts(images, fuv, verts, faces, labels, adjacency, s: TextureSettings) -> _Charts:
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


def _layout(images, fuv, labels, ch: _Charts, s: TextureSettings) -> _Layout:
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


def bake_texture(
    mesh: Any,
    views_images: Sequence[np.ndarray],
    visibility: VisibilityLike,
    selection: np.ndarray,
    *,
    settings: TextureSettings | None = None,
    adjacency: np.ndarray | None = None,
    **options: Any,
) -> TexturedMesh:
    """Bake a texture atlas from the selected view of every face.

    Parameters
    ----------
    mesh : Mesh
        ``vertices`` (N, 3), ``faces`` (F, 3), ``vertex_normals`` (N, 3).
    views_images : sequence of (H_v, W_v, 3) arrays
        One image per view (typically the colour-corrected ones), uint8, uint16 or float in
        [0, 1]; the atlas is uint8.
    visibility : Visibility
        ``face_uv(selection)``: the pixel coordinates of every face's corners in its view.
    selection : (F,) int array
        From :func:`~o3d_seqcc.texturing.select_views`; -1 = unseen face (fallback colour).
    settings : TextureSettings, optional
        Atlas, leveling and fallback options; default :class:`TextureSettings` (the command
        line's defaults: 2048 atlas, 4 texels of padding, global and local seam leveling on).
    adjacency : (E, 2) int array, optional
        Face adjacency (:func:`o3d_seqcc.meshops.face_adjacency`), computed when omitted.
    **options
        Fields of :class:`TextureSettings` overriding ``settings`` (e.g. ``atlas_size=1024``,
        ``leveling=False``); unknown names raise ``TypeError``.

    Returns
    -------
    TexturedMesh
        UVs in the OBJ convention (origin bottom-left). ``stats``: ``atlas_size``,
        ``requested_atlas_size``, ``grew``, ``texel_scale``, ``charts``, ``fallback_charts``,
        ``fallback``, ``unseen_faces``, ``vertices_out``, ``utilization`` (fraction of atlas
        texels inside a chart rectangle), ``packer``, ``leveling`` / ``local_leveling`` (None or
        their statistics: seam pairs or edges, offsets, steps before / after, timings), timings.

    Raises
    ------
    InputError
        Selection / visibility / image shapes that do not match, a face assigned to a view where
        its vertices are not projected (NaN), charts that do not fit with ``overflow="error"`` or
        beyond ``max_atlas_size``, or a selection where no face is seen.
    """
    s = (settings or TextureSettings()).updated(**options) if options else (settings or TextureSettings())
    with steps("bake", 6) as step:
        return _bake(mesh, views_images, visibility, selection, s, adjacency, step)


def _bake(mesh, views_images, visibility, selection, s: TextureSettings, adjacency, step) -> TexturedMesh:
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
