"""Baking into the mesh's own texture coordinates (``uv="keep"``, issue 35).

Game and web pipelines often bring their own UV layout (an artist's unwrap, a lightmap layout, a
mesh from Blender). :func:`bake_own_uv` fills that layout from the photos with the same colour
correction, view selection and seam leveling as the atlas of :func:`~o3d_seqcc.texturing.bake_texture`,
and returns the input mesh's topology and UVs unchanged with a new texture:

1. **UVs of the faces the visibility split** (:func:`split_corner_uv`): a part of an input face
   takes the UVs of its corners' barycentric points in that face, so every part rasterises inside
   its parent's UV triangle;
2. **the page** (:func:`own_uv_page`): one square page (the UV square), its side chosen so that the
   median photo pixel of the seen faces gets ``texels_per_pixel`` texels (1: as sharp as the photos),
   a multiple of 4 (a power of two with ``power_of_two``), never above ``atlas_size`` (a budget: the
   density is then lowered, with a warning giving the factor);
3. **the layout's problems, reported** (:func:`uv_problems`): faces whose UV area is zero (they get
   no texel of their own), faces mirrored against the layout's majority orientation, and faces whose
   texels another face also covers (overlapping or mirrored-and-stacked islands: the face drawn
   last wins there);
4. **the bake**: every texel inside a face samples its selected photo at the same barycentric
   point of the face's projection; gutters of ``padding`` texels continue the nearest face's map;
   the global seam leveling's per-corner offsets (regions: connected same-view faces, since a
   view change inside a UV island is a seam of the texture too), the local leveling along region
   borders, and a pull-push fill of the texels no face reaches.

Within a triangle the photo is sampled affinely, as in the atlas bake.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any, Sequence

import numpy as np

from ..errors import InputError, warn
from ..geometry.meshops import vertex_normals, weld_vertices
from ..imaging.sequences import LRUCache, default_cache_bytes
from .atlas import _check, _regions, _texel_pass, _threads, corner_additions, owner_canvas
from .bake import rasterize_owner, release_free_memory
from .charts import image_charts
from .fill import push_pull_fill
from .leveling import local_seam_leveling
from .memory import texture_memory
from .packing import BLOCK, MAX_AUTO_ATLAS_SIZE
from .settings import TextureSettings, VisibilityLike
from .textured_mesh import TexturedMesh

__all__ = ["bake_own_uv", "own_uv_page", "split_corner_uv", "uv_problems"]

logger = logging.getLogger(__name__)

#: the page side gives this share of the photo pixels the seen faces cover ``texels_per_pixel`` texels or more
#: (their median: the pixel-weighted median of the faces' needs). Measured (``benchmarks/own_uv.py``, the
#: xatlas-unwrapped room): 0.5 -> 2708^2, gradient similarity of the renders to the photos 0.910 (the atlas's
#: 0.955); 0.75 -> 3224^2, 0.926; 0.9 -> 3612^2, 0.935: the rest is the second resampling a layout whose texel
#: grid is not the photo's pixel grid costs, which density does not buy back
PIXEL_SHARE = 0.5

def _area2(p: np.ndarray) -> np.ndarray:
    """Signed doubled area of (n, 3, 2) triangles."""
    return (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1])


def check_corner_uv(corner_uv: Any, n_faces: int, *, where: str = "the mesh") -> np.ndarray:
    """(F, 3, 2) float64 texture coordinates of every face corner, checked: the shape, finite, inside the UV square.

    Raises
    ------
    InputError
        Another shape, non-finite values, or coordinates outside [0, 1] (tiled / UDIM layouts), naming ``where``.
    """
    uv = np.asarray(corner_uv, dtype=np.float64)
    if uv.shape != (n_faces, 3, 2):
        raise InputError(f"{where}: texture coordinates of shape {uv.shape} for {n_faces} faces; uv='keep' needs one "
                         "(u, v) per face corner")
    if not np.isfinite(uv).all():
        raise InputError(f"{where}: texture coordinates that are not finite; fix the UV layout or drop uv='keep'")
    tol = 1e-6
    out = (uv < -tol) | (uv > 1 + tol)
    if out.any():
        bad = np.flatnonzero(out.any(axis=(1, 2)))
        raise InputError(f"{where}: {len(bad)} faces (e.g. {bad[:5].tolist()}) have texture coordinates outside "
                         "[0, 1] (a tiled or UDIM layout): uv='keep' bakes one page over the UV square; pack the "
                         "layout into [0, 1] (Blender: UV > Pack Islands) or drop uv='keep' for a new atlas")
    return np.clip(uv, 0.0, 1.0)


def split_corner_uv(vertices: np.ndarray, faces: np.ndarray, parent: np.ndarray | None, input_vertices: np.ndarray,
                    input_faces: np.ndarray, corner_uv: np.ndarray) -> np.ndarray:
    """UVs of the corners of the faces the visibility split: each corner's barycentric point in its input face.

    Parameters
    ----------
    vertices, faces : (N', 3) float, (F', 3) int
        The split mesh (:attr:`Visibility.mesh <o3d_seqcc.visibility.Visibility.mesh>`).
    parent : (F',) int or None
        Input face of every split face (None: the faces are the input's).
    input_vertices, input_faces : (N, 3) float, (F, 3) int
    corner_uv : (F, 3, 2) float
        The input faces' corner UVs.

    Returns
    -------
    (F', 3, 2) float64
    """
    faces = np.asarray(faces, dtype=np.int64)
    if parent is None:
        if len(faces) != len(corner_uv):
            raise InputError(f"{len(faces)} faces but texture coordinates for {len(corner_uv)}")
        return np.asarray(corner_uv, dtype=np.float64)
    parent = np.asarray(parent, dtype=np.int64)
    tri = np.asarray(input_vertices, dtype=np.float64)[np.asarray(input_faces, dtype=np.int64)[parent]]  # (F', 3, 3)
    p = np.asarray(vertices, dtype=np.float64)[faces]  # (F', 3 corners, 3)
    a, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    d = p - a[:, None]
    g11, g12, g22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    det = g11 * g22 - g12 * g12
    det = np.where(np.abs(det) > 1e-300, det, 1e-300)
    r1, r2 = (d * e1[:, None]).sum(2), (d * e2[:, None]).sum(2)
    b1 = (g22[:, None] * r1 - g12[:, None] * r2) / det[:, None]
    b2 = (g11[:, None] * r2 - g12[:, None] * r1) / det[:, None]
    bary = np.stack([1.0 - b1 - b2, b1, b2], axis=2)  # (F', 3 corners, 3 weights)
    return np.einsum("fkw,fwd->fkd", bary, np.asarray(corner_uv, dtype=np.float64)[parent])


def own_uv_page(corner_uv: np.ndarray, fuv: np.ndarray, seen: np.ndarray, s: TextureSettings) -> tuple[int, float,
                                                                                                        float]:
    """The page side for a UV layout: ``(side, texels_per_pixel, density_scale)``.

    The side gives the seen faces (with UV and photo area) ``s.texels_per_pixel`` texels per photo pixel (1 for
    ``"auto"``) at the median photo pixel (:data:`PIXEL_SHARE`: half the pixels they cover get as many or more), rounded up to a multiple of 4 (a power of two with ``s.power_of_two``), at most
    ``s.atlas_size`` (or :data:`~o3d_seqcc.texturing.packing.MAX_AUTO_ATLAS_SIZE` for ``"auto"``; a budget that
    lowers the density: ``density_scale`` < 1, with a warning).
    """
    req = 1.0 if isinstance(s.texels_per_pixel, str) else float(s.texels_per_pixel)
    a_uv = np.abs(_area2(np.asarray(corner_uv, dtype=np.float64)))
    a_px = np.abs(_area2(np.asarray(fuv, dtype=np.float64)))
    ok = seen & (a_uv > 1e-14) & (a_px > 1e-9) & np.isfinite(a_px)
    if not ok.any():
        raise InputError("uv='keep': no seen face has both a UV area and an area in its photo: the layout is "
                         "degenerate (every UV triangle a point or a line)")
    need = np.sqrt(a_px[ok] / a_uv[ok])  # each face's page side at one texel per photo pixel
    o = np.argsort(need)
    cum = np.cumsum(a_px[ok][o])
    ratio = float(need[o][np.searchsorted(cum, PIXEL_SHARE * cum[-1])])
    want = max(BLOCK, req * ratio)
    limit = MAX_AUTO_ATLAS_SIZE if isinstance(s.atlas_size, str) else int(s.atlas_size)
    if s.power_of_two:
        side = 1 << max(2, math.ceil(math.log2(want)))
        top = 1 << int(math.floor(math.log2(limit)))
    else:
        side = int(BLOCK * math.ceil(want / BLOCK))
        top = int(BLOCK * (limit // BLOCK))
    if side <= top:
        return side, side / ratio, 1.0
    t = top / ratio
    msg = (f"uv='keep': the layout needs a {side}x{side} page for {req:g} texels per pixel; the {top}x{top} page "
           f"(atlas_size) holds {t:.3g}: density scaled by {t / req:.3f} (a larger atlas_size keeps it)")
    warn(msg)
    return top, t, t / req


def uv_problems(txy: np.ndarray, faces: np.ndarray, height: int, width: int, *, islands: np.ndarray | None = None,
                threads: int = 1) -> dict:
    """What a UV layout does that a bake has to know: zero-area, mirrored and overlapping faces.

    Parameters
    ----------
    txy : (M, 2) float
        Texel coordinates (x right, y down, texel centres at integers).
    faces : (F, 3) int
        Faces over ``txy``.
    height, width : int
        The page.
    islands : (F,) int, optional
        UV island of every face (faces connected through shared corners); default one island.
    threads : int, default 1
        Of the rasterisation.

    Returns
    -------
    dict
        ``zero_area_faces`` (UV area below 1e-9 texels: no texel of their own), ``mirrored_faces`` (UV winding
        opposite the majority of their island, by area: a fold or a flipped face inside an island; a whole
        island mirrored against the surface is no problem for a bake unless it is stacked on another, which
        ``overlapping_faces`` finds), ``overlapping_faces`` (faces with a texel another face also
        covers: the first and the last drawn there, from two rasterisations in opposite orders) and
        ``overlapping_texels``; ``examples``: up to 5 face ids of each.
    """
    faces = np.asarray(faces, dtype=np.int64)
    a = _area2(np.asarray(txy, dtype=np.float64)[faces])
    zero = np.abs(a) < 2e-9
    isl = np.zeros(len(faces), dtype=np.int64) if islands is None else np.asarray(islands, dtype=np.int64)
    n_isl = int(isl.max()) + 1 if len(isl) else 0
    pos = np.bincount(isl, weights=np.where(zero, 0.0, a.clip(0)), minlength=n_isl)
    neg = np.bincount(isl, weights=np.where(zero, 0.0, (-a).clip(0)), minlength=n_isl)
    major = np.where(pos >= neg, 1.0, -1.0)[isl]
    mirrored = ~zero & (np.sign(a) != major)
    # drawn in one order and in the other: a texel two faces cover has another owner each time
    order = np.arange(len(faces))
    first = rasterize_owner(txy, faces, height, width, order=order[::-1], threads=threads)
    last = rasterize_owner(txy, faces, height, width, order=order, threads=threads)
    shared = np.flatnonzero(first != last)
    fa, fb = first[shared].astype(np.int64), last[shared].astype(np.int64)
    del first, last
    # two faces with an edge in common (two corners at the same UVs) both hold a texel centre on that edge: a tie
    # of the rasterisation, not an overlap (a face folded over its edge neighbour turns over: ``mirrored``); three
    # corners in common is a face stacked on another
    t = np.asarray(txy, dtype=np.float64)[faces]
    same = (t[fa][:, :, None, :] == t[fb][:, None, :, :]).all(axis=3).any(axis=2).sum(axis=1)
    real = same != 2
    shared, fa, fb = shared[real], fa[real], fb[real]
    over = np.zeros(len(faces), dtype=bool)
    over[fa] = True
    over[fb] = True
    return {"zero_area_faces": int(zero.sum()), "mirrored_faces": int(mirrored.sum()),
            "overlapping_faces": int(over.sum()), "overlapping_texels": int(len(shared)),
            "examples": {"zero_area": np.flatnonzero(zero)[:5].tolist(), "mirrored": np.flatnonzero(mirrored)[:5].tolist(),
                         "overlapping": np.flatnonzero(over)[:5].tolist()}}


def _output_vertices(input_faces: np.ndarray, corner_uv: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray,
                                                                                               np.ndarray]:
    """The input topology with one UV per vertex: ``(vertex_index, faces, uv)``.

    A vertex keeps its index and the UV of its first corner; corners with another UV (an OBJ's seams) get a
    copy of the vertex, appended after the input's vertices (so a mesh with one UV per vertex, a PLY or a GLB,
    comes back with its vertices in their order).
    """
    f = np.asarray(input_faces, dtype=np.int64).reshape(-1)
    uv = np.asarray(corner_uv, dtype=np.float64).reshape(-1, 2)
    first = np.full(n_vertices, -1, dtype=np.int64)
    order = np.arange(len(f))[::-1]
    first[f[order]] = order  # the first corner of every vertex (written last)
    base_uv = np.zeros((n_vertices, 2))
    used = first >= 0
    base_uv[used] = uv[first[used]]
    other = np.flatnonzero((uv != base_uv[f]).any(axis=1))
    vertex_index = np.arange(n_vertices, dtype=np.int64)
    out_f = f.copy()
    out_uv = base_uv
    if len(other):
        key = np.concatenate([f[other, None].astype(np.float64), uv[other]], axis=1)
        uniq, inv = np.unique(key, axis=0, return_inverse=True)
        vertex_index = np.r_[vertex_index, uniq[:, 0].astype(np.int64)]
        out_uv = np.r_[base_uv, uniq[:, 1:]]
        out_f[other] = n_vertices + inv.reshape(-1)
    return vertex_index, out_f.reshape(-1, 3), out_uv


def _islands(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(F,) UV island of every face: faces connected through shared (vertex, UV) corners."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    F = len(faces)
    rows = np.repeat(np.arange(F), 3)
    g = coo_matrix((np.ones(3 * F), (rows, faces.reshape(-1))), shape=(F, n_vertices)).tocsr()
    _, comp = connected_components(g @ g.T, directed=False)
    return np.unique(comp, return_inverse=True)[1].reshape(-1).astype(np.int64)


def bake_own_uv(
    mesh: Any,
    views_images: Sequence[np.ndarray],
    visibility: VisibilityLike,
    selection: np.ndarray,
    *,
    input_mesh: Any,
    corner_uv: np.ndarray,
    parent: np.ndarray | None = None,
    settings: TextureSettings | None = None,
    adjacency: np.ndarray | None = None,
) -> TexturedMesh:
    """Bake the photos into ``input_mesh``'s own UV layout (see the module docstring).

    Parameters
    ----------
    mesh : Mesh
        The mesh the visibility and the selection are on (split where faces were partly seen).
    views_images : sequence of (H_v, W_v, 3) arrays
        One image per view (the corrected photos).
    visibility : Visibility
    selection : (F',) int array
        View of every face of ``mesh`` (-1: unseen, fallback colour).
    input_mesh : Mesh
        The mesh as read (``vertices``, ``faces``, ``vertex_normals``): the output's topology.
    corner_uv : (F, 3, 2) float
        Its texture coordinates per face corner, OBJ convention (origin bottom-left, v up), in [0, 1].
    parent : (F',) int, optional
        Input face of every face of ``mesh`` (:attr:`Visibility.parent_faces`); None when they are the input's.
    settings : TextureSettings, optional
        ``texels_per_pixel``, ``atlas_size`` (a budget), ``power_of_two``, ``padding``, the leveling and fallback
        options; the atlas's packing options do not apply.
    adjacency : (E, 2) int array, optional
        Face adjacency of ``mesh``.

    Returns
    -------
    TexturedMesh
        ``input_mesh``'s faces and UVs (per face corner: positions and UVs equal to the input's; vertices in the
        input's order, with copies appended where a vertex has several UVs), one page; ``face_view``: the view of
        each input face's largest part; ``stats``: as :func:`~o3d_seqcc.texturing.bake_texture`'s where they
        apply, ``uv: "keep"`` and ``uv_layout`` (:func:`uv_problems`).

    Raises
    ------
    InputError
        Texture coordinates of another shape, not finite or outside [0, 1]; what
        :func:`~o3d_seqcc.texturing.bake_texture` rejects.
    """
    from ..geometry.meshops import face_adjacency

    s = settings or TextureSettings()
    t0 = time.perf_counter()
    in_v = np.asarray(input_mesh.vertices, dtype=np.float64)
    in_f = np.asarray(input_mesh.faces, dtype=np.int64)
    cuv0 = check_corner_uv(corner_uv, len(in_f))
    verts, faces, labels, fuv = _check(mesh, views_images, visibility, selection)
    adjacency = face_adjacency(faces, verts) if adjacency is None else np.asarray(adjacency, dtype=np.int64).reshape(-1, 2)
    if parent is not None and len(parent) != len(faces):
        raise InputError(f"parent has {len(parent)} entries for {len(faces)} faces")
    cuv = split_corner_uv(verts, faces, parent, in_v, in_f, cuv0)
    seen = labels >= 0
    side, tpp, scale = own_uv_page(cuv, fuv, seen, s)
    W = H = side
    # texel coordinates of every corner of the (split) faces: one vertex per corner
    txy = np.stack([cuv[..., 0] * W - 0.5, (1.0 - cuv[..., 1]) * H - 0.5], axis=-1).reshape(-1, 2)
    cf = np.arange(3 * len(faces), dtype=np.int64).reshape(-1, 3)
    vertex_index, out_f, out_uv = _output_vertices(in_f, cuv0, len(in_v))  # the output: the input's topology, UVs
    islands = _islands(out_f, len(vertex_index))
    problems = uv_problems(np.stack([cuv0[..., 0] * W - 0.5, (1.0 - cuv0[..., 1]) * H - 0.5], -1).reshape(-1, 2),
                           np.arange(3 * len(in_f)).reshape(-1, 3), H, W, islands=islands, threads=_threads())
    for what in ("zero_area", "mirrored", "overlapping"):
        n = problems[f"{what}_faces"]
        if n:
            logger.warning("uv='keep': %d face(s) with %s UVs (e.g. %s)%s", n, what.replace("_", " "),
                           problems["examples"][what], ": the face drawn last wins on shared texels"
                           if what == "overlapping" else "")
    threads = _threads()
    wpos = weld_vertices(verts)
    wf = wpos[faces]
    region_chart = image_charts(faces, labels, adjacency)  # connected same-view faces: the leveling's regions
    n_regions = int(region_chart.max()) + 1 if len(region_chart) else 0
    cache = LRUCache(default_cache_bytes())
    add, lev_stats, n_unseen = corner_additions(views_images, faces, labels, fuv, wf, region_chart, adjacency, s,
                                                cache, threads)
    owner = owner_canvas(txy, cf, seen, H, W, int(s.padding), threads)
    tex = np.zeros((H, W, 3), dtype=np.uint8)
    _texel_pass(tex, owner, txy, cf, labels, fuv, views_images, add, tpp, cache, threads)
    del cache, add
    written = owner != -1
    n_texels = int(np.count_nonzero(written))
    local_stats = None
    if s.local_leveling and int(s.padding) >= 1:
        face_chart = np.where(seen, region_chart, n_regions)
        region = _regions(owner, face_chart, n_regions)
        del owner
        tex, local_stats = local_seam_leveling(tex, region.reshape(H, W), txy, cf, face_chart, labels, adjacency, wf,
                                               band=int(s.local_band), copy=False)
        del region
    owner = None
    release_free_memory()
    if s.fill_background and not written.all():
        push_pull_fill(tex, written.reshape(H, W), copy=False, threads=threads)
    normals = np.asarray(input_mesh.vertex_normals, dtype=np.float64) if getattr(input_mesh, "vertex_normals", None) \
        is not None else vertex_normals(in_v, in_f, None)
    area = 0.5 * np.abs(_area2(np.asarray(fuv, dtype=np.float64)))
    area = np.where(seen & np.isfinite(area), area, -1.0)
    par = np.arange(len(faces)) if parent is None else np.asarray(parent, dtype=np.int64)
    face_view = np.full(len(in_f), -1, dtype=np.int64)
    order = np.argsort(area, kind="stable")  # the largest part's view written last
    face_view[par[order]] = np.where(seen, labels, -1)[order]
    tri = 0.5 * np.abs(_area2(np.stack([cuv0[..., 0] * W, cuv0[..., 1] * H], -1)))
    a_uv = 0.5 * np.abs(_area2(cuv * [W, H]))
    sized = seen & (area > 1e-6)
    face_tpp = np.sqrt(a_uv[sized] / area[sized]) if sized.any() else np.ones(1)
    t_end = time.perf_counter()
    stats = {
        "uv": "keep", "atlas_size": W, "page_width": W, "page_height": H, "requested_atlas_size": s.atlas_size,
        "pages": 1, "power_of_two": bool(s.power_of_two),
        "texture_memory": texture_memory(W, H, [float(tri.sum() / (W * H))]),
        "texels_per_pixel": float(tpp), "density_scale": float(scale), "padding": int(s.padding),
        "face_texels_per_pixel": {"min": float(face_tpp.min()), "p1": float(np.percentile(face_tpp, 1)),
                                  "median": float(np.median(face_tpp)),
                                  "below_1": float(np.mean(face_tpp < 0.999 * tpp))},
        "coverage": float(tri.sum() / (W * H)), "utilization": float(n_texels / (W * H)),
        "charts": int(n_regions), "uv_islands": int(islands.max()) + 1 if len(islands) else 0, "unseen_faces": n_unseen, "vertices_in": int(len(in_v)),
        "vertices_out": int(len(vertex_index)), "uv_layout": problems, "leveling": lev_stats,
        "local_leveling": local_stats, "time_total_s": t_end - t0,
    }
    logger.info("bake_own_uv: %dx%d page at %.3g texels/pixel (median pixel), coverage %.0f%%, %d UV islands, "
                "%d zero-area / %d mirrored / %d overlapping faces, in %.2f s", W, H, tpp, 100 * stats["coverage"],
                stats["uv_islands"], problems["zero_area_faces"], problems["mirrored_faces"],
                problems["overlapping_faces"], stats["time_total_s"])
    return TexturedMesh(
        vertices=in_v[vertex_index], faces=out_f, uv=out_uv, texture=np.ascontiguousarray(tex),
        normals=normals[vertex_index], face_view=face_view, vertex_index=vertex_index, face_chart=islands, pages=1,
        stats=stats,
    )
