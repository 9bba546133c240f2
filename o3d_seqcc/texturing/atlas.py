"""Texture-atlas baking: charts, xatlas packing, sampling bake, seam leveling (paper 3.8, issues 13, 19).

:func:`bake_texture` turns a per-face view selection into a textured mesh, in stages:

1. **charts** (:mod:`~o3d_seqcc.texturing.charts`): connected same-view regions, whose UVs are
   their vertices' pixel coordinates in the view (a face's texture is its image-space
   footprint, as the paper crops each face's projection from its selected photo); unseen faces
   welded into a neighbouring chart or into one shared fallback region; tiny charts merged
   into a neighbour's parametrisation;
2. **packing** (:mod:`~o3d_seqcc.texturing.packing`): xatlas places the charts (turned by 90
   degrees at most, at ``padding`` texels from each other) on one page cut to them at the photos'
   resolution, its sides multiples of 4 (or the smallest power-of-two square with
   ``power_of_two``; ``atlas_size="auto"``: up to 8192 x 8192, then more square pages; an
   integer is a budget: when it cannot hold them, the density is scaled down, logged
   with the factor, or several pages are written); every chart's texel grid is its photo's
   pixel grid, moved by whole texels;
3. **bake by sampling** (:mod:`~o3d_seqcc.texturing.bake`): every texel inside a face samples
   the face's own view at the same barycentric point of its projection (at one texel per pixel
   a pixel centre, so the texel is a copy of the photo's pixel; Lanczos, clamped, in tiny charts
   merged into a neighbour's parametrisation and at other densities); gutter texels continue
   the nearest face's map (real photo content around every chart, so bilinear filtering and
   mip levels 1-2 read no foreign colour); faces seen by no view get their fallback colours
   (:mod:`~o3d_seqcc.texturing.fallback`);
4. **seam leveling** (:mod:`~o3d_seqcc.texturing.leveling`): the global leveling's per-corner
   offsets are added to every face's texels, then the local leveling blends what is left along
   chart borders; the background is filled by pull-push.

Each view's image is read once (``images[v]`` in one loop over the views, which gathers
everything the bake needs from it), and the visibility only through ``face_uv`` and, for
merge candidates, ``usable`` / ``area`` at single (view, face) pairs.

Within a triangle UVs are interpolated affinely while the camera projection is projective: as
in the paper and mvs-texturing, the texture of a face is its image-space projection, which is
exact at the vertices and off by the perspective foreshortening across one face (negligible for
triangles small relative to their depth).
"""

from __future__ import annotations

import logging
import time
from typing import Any, Sequence

import numpy as np

from ..errors import InputError
from ..imaging.arrays import img_as_uint8
from ..geometry.meshops import face_adjacency, vertex_normals, weld_vertices
from .._shared.progress import steps
from .._shared.parallel import LocalExecutor, current as current_executor, thread_map
from ..imaging.sequences import LRUCache, default_cache_bytes
from .bake import (bary_coefficients, edge_texels, gutter_owner, rasterize_owner, release_free_memory, sample_image,
                   texel_bary)
from .charts import build_charts
from .fill import push_pull_fill
from .fallback import fallback_corner_colors
from .memory import texture_memory
from .leveling import corner_colors, local_seam_leveling, solve_corner_offsets
from .packing_child import pack_charts_beside
from .settings import TextureSettings, VisibilityLike
from .textured_mesh import TexturedMesh

__all__ = ["bake_texture", "push_pull_fill"]

logger = logging.getLogger(__name__)

#: canvas texels per band of the bake's passes over the atlas (a band's temporaries: about 80 bytes per written texel,
#: one band per thread at a time: 2 x 512k texels hold about 80 MB; 2M-texel bands held 220 MB more at the peak of
#: Fountain 300k's texel pass for no measurable speed)
_BAND_TEXELS = 1 << 19


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


def _groups(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stable order of ``keys`` and the start / end of each run of equal keys in it: (order, values, bounds)."""
    order = np.argsort(keys.astype(np.int32), kind="stable")
    ks = keys[order]
    cut = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]]) if len(ks) else np.zeros(0, dtype=np.int64)
    return order, ks[cut], np.r_[cut, len(ks)]


def _interp(b: np.ndarray, corner: np.ndarray) -> np.ndarray:
    """Barycentric interpolation: (n, 3) weights x (n, 3, c) corner values -> (n, c)."""
    return b[:, 0:1] * corner[:, 0] + b[:, 1:2] * corner[:, 1] + b[:, 2:3] * corner[:, 2]


def _clip_bary(b: np.ndarray) -> np.ndarray:
    b = np.clip(b, 0.0, None)
    return b / np.maximum(b.sum(axis=1, keepdims=True), 1e-12)


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
        [0, 1]; the atlas is uint8. ``views_images[v]`` is read once per view.
    visibility : Visibility
        ``face_uv(selection)``: the pixel coordinates of every face's corners in its view.
    selection : (F,) int array
        From :func:`~o3d_seqcc.texturing.select_views`; -1 = unseen face (fallback colour).
    settings : TextureSettings, optional
        Atlas, leveling and fallback options; default :class:`TextureSettings` (the command
        line's defaults: sized to the charts at the photos' resolution, 4 texels of padding,
        global and local seam leveling on).
    adjacency : (E, 2) int array, optional
        Face adjacency (:func:`o3d_seqcc.geometry.meshops.face_adjacency`), computed when omitted.
    **options
        Fields of :class:`TextureSettings` overriding ``settings`` (e.g. ``atlas_size=1024``,
        ``leveling=False``); unknown names raise ``TypeError``.

    Returns
    -------
    TexturedMesh
        UVs in the OBJ convention (origin bottom-left); with several pages, ``texture`` holds
        them stacked vertically (``pages``). ``stats``: ``atlas_size`` (page side),
        ``requested_atlas_size``, ``pages``, ``texels_per_pixel`` (atlas texels per photo pixel),
        ``face_texels_per_pixel`` (per seen face, the square root of its texel area over its
        area in its photo: ``min``, ``p1``, ``median`` and the share ``below_1`` below
        ``texels_per_pixel``; tiny charts merged into a neighbour's parametrisation may be
        smaller), ``density_scale`` (< 1 when the budget lowered the density), ``coverage`` (triangle texels / atlas texels),
        ``utilization`` (texels written: faces and their gutters / atlas texels), ``charts``
        (image charts), ``fallback_charts``, ``absorbed_faces``, ``merged_tiny_charts``,
        ``unseen_faces``, ``vertices_in``, ``vertices_out``, ``packer``, ``pack_log``,
        ``leveling`` / ``local_leveling`` (None or their statistics), timings ``time_*_s``.

    Raises
    ------
    InputError
        Selection / visibility / image shapes that do not match, a face assigned to a view where
        its vertices are not projected (NaN) or project outside the image, or a selection where
        no face is seen.

    Examples
    --------
    >>> import tempfile, o3d_seqcc as sc
    >>> room = sc.make_synthetic_scene(tempfile.mkdtemp() + '/room', n_views=3, width=96, height=72, seed=1,
    ...                                seen_only=True)
    >>> vis = sc.compute_visibility(room.scene)
    >>> photos = [v.load_image() for v in room.scene.views]
    >>> tm = sc.bake_texture(vis.mesh, photos, vis, sc.select_views(vis), atlas_size=512)
    >>> tm.texture.ndim, len(tm.faces) == len(vis.mesh.faces)
    (3, True)
    """
    s = (settings or TextureSettings()).updated(**options) if options else (settings or TextureSettings())
    with steps("bake", 7) as step:
        return _bake(mesh, views_images, visibility, selection, s, adjacency, step)


def _threads() -> int:
    """Threads for the bake's bands: the local executor's (``-j``), one under a Dask client (the bake runs here)."""
    ex = current_executor()
    return ex.threads() if isinstance(ex, LocalExecutor) else 1


def _corner_pass(views_images, faces: np.ndarray, labels: np.ndarray, fuv: np.ndarray, cache: LRUCache,
                 threads: int = 1):
    """Every seen face's corner colours in its view (the leveling's means and the point values), one task per view.

    Returns ``corner_mean``, ``corner_point`` (F, 3, 3) float64, NaN for unseen faces; the uint8 images read go
    into ``cache`` for the texel pass. ``threads`` views at a time (each view's values are its own).
    """
    F = len(labels)
    corner_mean = np.full((F, 3, 3), np.nan)
    corner_point = np.full((F, 3, 3), np.nan)
    f_order, f_views, f_bounds = _groups(labels)
    tasks = [(int(v), f_order[f_bounds[i]:f_bounds[i + 1]]) for i, v in enumerate(f_views) if v >= 0]

    def one(task):
        v, fs = task
        img = _image(views_images, v, cache)
        p = fuv[fs]
        h, w = img.shape[:2]
        out = (p[..., 0] < -1.0) | (p[..., 0] > w) | (p[..., 1] < -1.0) | (p[..., 1] > h)
        if out.any():
            bad = fs[out.any(axis=1)]
            raise InputError(f"{len(bad)} faces (e.g. {bad[:5].tolist()}) are assigned to view {v}, in which "
                             "they project outside the image: select only usable views (select_views does)")
        # a vertex's corners in one view are one projection: sampled once (the same numbers for each of its faces)
        _, first, back = np.unique(faces[fs].reshape(-1), return_index=True, return_inverse=True)
        m, pt = corner_colors(img, p.reshape(-1, 2)[first])
        return m[back.reshape(-1)], pt[back.reshape(-1)]

    for (v, fs), (m, pt) in zip(tasks, thread_map(one, tasks, threads, name="o3d_seqcc-corners")):
        corner_mean[fs], corner_point[fs] = m.reshape(-1, 3, 3), pt.reshape(-1, 3, 3)
    return corner_mean, corner_point


def _image(views_images, v: int, cache: LRUCache) -> np.ndarray:
    """View ``v``'s image as uint8, read once while it fits ``cache``."""
    return cache.get(v, lambda: img_as_uint8(views_images[v], where=f"image of view {v}"))


def _regions(owner: np.ndarray, face_chart: np.ndarray, n_image: int) -> np.ndarray:
    """(texels,) image chart of every written texel's face (the local leveling's regions), -1 elsewhere (free
    texels, the fallback region), in bands of :data:`_BAND_TEXELS`; int16 while the charts' ids fit it."""
    dtype = np.int16 if n_image < 2**15 else np.int32
    region = np.full(len(owner), -1, dtype=dtype)
    chart = np.where(face_chart < n_image, face_chart, -1).astype(dtype)
    for a in range(0, len(owner), _BAND_TEXELS):
        codes = owner[a:a + _BAND_TEXELS]
        loc = np.flatnonzero(codes != -1)
        c = codes[loc]
        region[loc + a] = chart[np.where(c >= 0, c, -2 - c)]
    return region


def _pixel_aligned(ctxy: np.ndarray, faces: np.ndarray, fuv: np.ndarray, density: float):
    """Faces whose texels are their photo's pixels moved by whole texels: ``(ok, ox, oy, swap, limit)``, (F,) each.

    Where a face's texel corners are its corners in its photo plus an integer offset (x and y swapped
    where xatlas turned the chart), the affine map of every one of its texels (inside, under its edges,
    in its gutter) to its photo is ``(X - ox, Y - oy)`` (swapped: ``(Y - oy, X - ox)``), an exact pixel
    centre: :func:`~o3d_seqcc.texturing.bake.sample_image` gives that pixel. The bake computes the
    source point in float32 (``bary @ corners``); ``limit`` bounds ``|b0| + |b1| + |b2|`` for which that
    rounding stays far below OpenCV's 1/32-pixel grid (the point is then read as the pixel, exactly
    as the sampling would): ``8192 / max |corner coordinate|``.
    """
    F = len(faces)
    none = np.zeros(F, dtype=bool)
    if density < 0.999 or F == 0:
        return none, None, None, None, None
    T = np.asarray(ctxy, dtype=np.float64)[faces]
    P = np.asarray(fuv, dtype=np.float64)
    ok_all = np.isfinite(P).all(axis=(1, 2)) & (np.abs(_edge_area(T)) > 1e-12)
    found = []
    for Q in (P, P[..., ::-1]):
        d = T - Q
        same = (d == d[:, :1]).all(axis=(1, 2)) & (d[:, 0] == np.round(d[:, 0])).all(axis=1)
        found.append((same & ok_all, d[:, 0]))
    (plain, dp), (turned, dt) = found
    ok = plain | turned
    swap = ~plain & turned
    o = np.where(plain[:, None], dp, dt)
    o = np.where(ok[:, None], o, 0.0).astype(np.int64)
    cmax = np.nan_to_num(np.abs(P).max(axis=(1, 2)), nan=np.inf)
    limit = (8192.0 / np.maximum(cmax, 1.0)).astype(np.float32)
    return ok, o[:, 0], o[:, 1], swap, limit


def _edge_area(p: np.ndarray) -> np.ndarray:
    return (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1])


def _texel_pass(tex: np.ndarray, owner: np.ndarray, ctxy: np.ndarray, faces: np.ndarray, labels: np.ndarray,
                fuv: np.ndarray, views_images, add: np.ndarray | None, density: float, cache: LRUCache,
                threads: int) -> None:
    """Every texel the owner canvas gives a face: its colour in the face's view plus the leveling offsets, into ``tex``.

    In bands of :data:`_BAND_TEXELS` texels (``threads`` side by side; each band's texels grouped by view). A
    texel inside its face samples the view at the barycentric point of its face's projection; one under a thin
    face's edge or in a gutter (``owner`` ``-2 - f``) continues the face's affine map there, and takes the
    offsets (``add`` (F, 3 corners, 3 channels): global leveling, fallback colours) at the nearest point of
    the face. Texels of pixel-aligned faces (:func:`_pixel_aligned`) read their pixel directly. Every texel's
    value is computed on its own, so the bands change no value.
    """
    H, S = tex.shape[:2]
    coeffs = bary_coefficients(ctxy, faces)
    fuv32 = fuv.astype(np.float32)
    key = labels.astype(np.int16 if labels.max(initial=0) < 2**15 else np.int32)
    aligned, ox, oy, swap, limit = _pixel_aligned(ctxy, faces, fuv, density)
    adds = None if add is None else [np.ascontiguousarray(add[:, i]) for i in range(3)]
    flat_tex = tex.reshape(-1, 3)
    rows = max(1, _BAND_TEXELS // max(S, 1))

    def band(r0: int) -> None:
        a, b = r0 * S, min(H, r0 + rows) * S
        codes = owner[a:b]
        loc = np.flatnonzero(codes != -1)
        if not len(loc):
            return
        c = codes[loc]
        inside = c >= 0
        f = np.where(inside, c, -2 - c).astype(np.intp)
        del c
        y, x = np.divmod(loc + a, S)
        bary = texel_bary(ctxy, faces, f, x, y, inside=inside, coeffs=coeffs)
        col = np.zeros((len(loc), 3), dtype=np.float32)
        order, views, bounds = _groups(key[f])
        for i, v in enumerate(views):
            if v < 0:  # unseen faces: their fallback colours below
                continue
            ts = order[bounds[i]:bounds[i + 1]]
            img = _image(views_images, int(v), cache)
            ft = f[ts]
            if aligned.any():
                fast = aligned[ft]
                fast &= np.abs(bary[ts]).sum(axis=1) <= limit[ft]
                tf, ff = ts[fast], ft[fast]
                X, Y = x[tf] - ox[ff], y[tf] - oy[ff]
                t = swap[ff]
                h, w = img.shape[:2]
                col[tf] = img[np.clip(np.where(t, X, Y), 0, h - 1), np.clip(np.where(t, Y, X), 0, w - 1)]
                ts, ft = ts[~fast], ft[~fast]
                del tf, ff, X, Y, t, fast
            if len(ts):
                src = _interp(bary[ts], fuv32[ft])
                col[ts] = sample_image(img, src[:, 0], src[:, 1], density=density)
        del order, x, y
        if adds is not None:
            ex = np.flatnonzero(~inside)
            bary[ex] = _clip_bary(bary[ex])  # under edges and in gutters: the nearest point of the face
            # col += b0 a0 + b1 a1 + b2 a2 (:func:`_interp`'s float32 operations, in place)
            acc = adds[0][f]
            acc *= bary[:, 0:1]
            tmp = adds[1][f]
            tmp *= bary[:, 1:2]
            acc += tmp
            np.take(adds[2], f, axis=0, out=tmp)
            tmp *= bary[:, 2:3]
            acc += tmp
            col += acc
            del acc, tmp
        np.rint(col, out=col)
        np.clip(col, 0, 255, out=col)
        flat_tex[loc + a] = col.astype(np.uint8)

    thread_map(band, range(0, H, rows), threads, name="o3d_seqcc-bake")


def corner_additions(views_images, faces: np.ndarray, labels: np.ndarray, fuv: np.ndarray, wf: np.ndarray,
                     level_chart: np.ndarray, adjacency: np.ndarray, s: TextureSettings, cache: LRUCache,
                     threads: int) -> tuple[np.ndarray | None, dict | None, int]:
    """What the texel pass adds per face corner: ``(add, leveling stats, unseen faces)``.

    ``add`` (F, 3 corners, 3 channels) float32: the global seam leveling's offsets (``s.leveling``, regions
    ``level_chart``) on seen faces, the fallback colours (``s.fallback``) on unseen ones (sampled as 0); None when
    there is neither. Every seen face's corner colours are read from its view (the images go into ``cache``).
    """
    corner_mean, corner_point = _corner_pass(views_images, faces, labels, fuv, cache, threads)
    seen = labels >= 0
    lev_stats = corner_off = None
    if s.leveling:
        corner_off, lev_stats = solve_corner_offsets(corner_mean, wf, labels, level_chart,
                                                     smoothness=float(s.leveling_smoothness))
        lev_stats["smoothness"] = float(s.leveling_smoothness)
        logger.info("bake: seam leveling, %d seam pairs, mean |offset| %.1f levels, step %.1f -> %.1f",
                    lev_stats["seam_pairs"], lev_stats["mean_abs_offset"], lev_stats["seam_step_before"],
                    lev_stats["seam_step_after"])
    del corner_mean  # (F, 3, 3) float64 arrays: each one 22 MB at 300k faces, dropped as soon as they are used
    n_unseen = int(np.count_nonzero(~seen))
    if corner_off is None and not n_unseen:
        return None, lev_stats, 0
    add = np.zeros((len(faces), 3, 3), dtype=np.float32)
    if corner_off is not None:
        add[seen] = corner_off[seen]
        if n_unseen:
            corner_point += corner_off  # the leveled corner colours the fallback starts from
        del corner_off
    if n_unseen:
        add[~seen] = fallback_corner_colors(corner_point, wf, labels, adjacency, fallback=s.fallback)[~seen]
        logger.info("bake: %d faces seen by no view get %s fallback colours", n_unseen, s.fallback)
    return add, lev_stats, n_unseen


def owner_canvas(txy: np.ndarray, faces: np.ndarray, seen: np.ndarray, height: int, width: int, padding: int,
                 threads: int) -> np.ndarray:
    """(height * width,) int32: the face of every texel, inside a face (the seen faces drawn last), under a thin
    face's edge or in a gutter of ``padding`` + 1 texels (``-2 - f``), -1 elsewhere."""
    owner = rasterize_owner(txy, faces, height, width, order=np.r_[np.flatnonzero(~seen), np.flatnonzero(seen)],
                            threads=threads)
    eidx, eface = edge_texels(txy, faces, None, height, width, free=owner == -1)  # slivers own the texels under edges
    owner[eidx] = -2 - eface.astype(np.int32)
    del eidx, eface
    if padding > 0:
        gidx, gface = gutter_owner(owner, height, width, float(padding) + 1.0, threads=threads)
        owner[gidx] = -2 - gface.astype(np.int32)
    return owner


def _bake(mesh, views_images, visibility, selection, s: TextureSettings, adjacency, step) -> TexturedMesh:
    t0 = time.perf_counter()
    step("charts")
    verts, faces, labels, fuv = _check(mesh, views_images, visibility, selection)
    adjacency = face_adjacency(faces, verts) if adjacency is None else np.asarray(adjacency, dtype=np.int64).reshape(-1, 2)
    normals = vertex_normals(verts, faces, getattr(mesh, "vertex_normals", None))
    wpos = weld_vertices(verts)
    wf = wpos[faces]
    cs = build_charts(verts, faces, normals, labels, fuv, visibility, adjacency, wpos=wpos,
                      merge_faces=int(s.merge_charts))
    t_charts = time.perf_counter()
    threads = _threads()
    # xatlas packs in a child process while the seam leveling is solved here (neither needs the other)
    packing = pack_charts_beside(cs.uv, cs.faces, cs.face_chart, beside=threads > 1, atlas_size=s.atlas_size,
                                 texels_per_pixel=s.texels_per_pixel, overflow=s.overflow, padding=int(s.padding),
                                 power_of_two=bool(s.power_of_two), shrink_to_fit=float(s.shrink_to_fit),
                                 small_charts=int(s.small_charts), small_padding=int(s.small_padding),
                                 pack_effort=s.pack_effort)
    step("seam leveling")
    seen = labels >= 0
    cache = LRUCache(default_cache_bytes())
    add, lev_stats, n_unseen = corner_additions(views_images, faces, labels, fuv, wf, cs.level_chart, adjacency, s,
                                                cache, threads)
    t_level = time.perf_counter()
    step("pack")
    pk = packing.result()
    W, Hp, P = pk.width, pk.height, pk.pages
    H = P * Hp
    ctxy = pk.txy.copy()
    ctxy[:, 1] += pk.page * Hp  # pages stacked vertically
    t_pack = time.perf_counter()
    step("rasterize")
    owner = owner_canvas(ctxy, cs.faces, seen, H, W, int(s.padding), threads)
    release_free_memory()
    t_raster = time.perf_counter()
    step("sample")
    tex = np.zeros((H, W, 3), dtype=np.uint8)
    _texel_pass(tex, owner, ctxy, cs.faces, labels, fuv, views_images, add, pk.texels_per_pixel, cache, threads)
    del cache, add
    written = owner != -1
    release_free_memory()
    t_sample = time.perf_counter()
    step("local seam leveling")
    local_stats = None
    n_texels = int(np.count_nonzero(written))
    if s.local_leveling and int(s.padding) < 1:
        logger.warning("bake_texture: local seam leveling needs padding >= 1 (got %d): skipped", int(s.padding))
    elif s.local_leveling:
        region = _regions(owner, cs.face_chart, cs.n_image)
        del owner
        tex, local_stats = local_seam_leveling(tex, region.reshape(H, W), ctxy, cs.faces, cs.face_chart, labels,
                                               adjacency, wf, band=int(s.local_band), copy=False)
        del region
        logger.info("bake_texture: local seam leveling, %d seam edges, mean step %.1f levels, %d texels, %.2f s",
                    local_stats["seam_edges"], local_stats["mean_abs_diff"], local_stats["texels_changed"],
                    local_stats["time_s"])
    t_local = time.perf_counter()
    step("gutters")
    owner = None  # the atlas-sized face canvas is done
    release_free_memory()
    if s.fill_background and not written.all():
        w2 = written.reshape(H, W)
        for p in range(P):  # page by page, in place
            push_pull_fill(tex[p * Hp:(p + 1) * Hp], w2[p * Hp:(p + 1) * Hp], copy=False, threads=threads)
    t_end = time.perf_counter()
    p2 = pk.txy[cs.faces]
    tri = 0.5 * np.abs((p2[:, 1, 0] - p2[:, 0, 0]) * (p2[:, 2, 1] - p2[:, 0, 1])
                       - (p2[:, 2, 0] - p2[:, 0, 0]) * (p2[:, 1, 1] - p2[:, 0, 1]))
    own = 0.5 * np.abs((fuv[:, 1, 0] - fuv[:, 0, 0]) * (fuv[:, 2, 1] - fuv[:, 0, 1])
                       - (fuv[:, 2, 0] - fuv[:, 0, 0]) * (fuv[:, 1, 1] - fuv[:, 0, 1]))
    sized = seen & (own > 1e-6)
    page_cover = np.bincount(pk.page[cs.faces[:, 0]], weights=tri, minlength=P) / (W * Hp)
    face_tpp = np.sqrt(tri[sized] / own[sized]) if sized.any() else np.ones(1)
    stats = {
        "atlas_size": max(W, Hp), "page_width": W, "page_height": Hp, "requested_atlas_size": s.atlas_size,
        "pages": P, "power_of_two": bool(s.power_of_two), "texture_memory": texture_memory(W, Hp, page_cover),
        "texels_per_pixel": pk.texels_per_pixel, "density_scale": pk.scale, "padding": int(s.padding),
        "face_texels_per_pixel": {"min": float(face_tpp.min()), "p1": float(np.percentile(face_tpp, 1)),
                                  "median": float(np.median(face_tpp)),
                                  "below_1": float(np.mean(face_tpp < 0.999 * pk.texels_per_pixel))},
        "coverage": float(tri.sum() / (P * W * Hp)), "utilization": float(n_texels / (P * W * Hp)),
        "charts": int(cs.n_image), "fallback_charts": int(cs.stats["fallback_charts"]),
        "absorbed_faces": int(cs.stats["absorbed_faces"]), "merged_tiny_charts": int(cs.stats["merged_tiny_charts"]),
        "fallback": s.fallback, "unseen_faces": n_unseen, "vertices_in": int(len(verts)),
        "vertices_out": int(len(cs.vertex_index)), "packer": "xatlas", "pack_log": list(pk.log),
        "xatlas_utilization": pk.utilization, "leveling": lev_stats, "local_leveling": local_stats,
        "time_charts_s": t_charts - t0, "time_leveling_s": t_level - t_charts, "time_pack_s": t_pack - t_level,
        "time_raster_s": t_raster - t_pack, "time_sample_s": t_sample - t_raster, "time_local_s": t_local - t_sample,
        "time_fill_s": t_end - t_local, "time_total_s": t_end - t0,
    }
    logger.info("bake_texture: %d charts, %d page(s) of %dx%d at %.3g texels/pixel, coverage %.0f%%, %d -> %d vertices "
                "in %.2f s", cs.n_image, P, W, Hp, pk.texels_per_pixel, 100 * stats["coverage"], len(verts),
                len(cs.vertex_index), stats["time_total_s"])
    v_orig = cs.vertex_index
    return TexturedMesh(
        vertices=verts[v_orig], faces=cs.faces,
        uv=np.stack([(pk.txy[:, 0] + 0.5) / W, 1.0 - (ctxy[:, 1] + 0.5) / H], axis=1),
        texture=np.ascontiguousarray(tex), normals=normals[v_orig], face_view=np.where(seen, labels, -1),
        vertex_index=v_orig, face_chart=cs.face_chart, pages=P, stats=stats,
    )
