"""Seam metric of a textured mesh: colour jumps across the edges between faces.

None of the paper's tools measures texture seams, so this module does (issue 5). For every
*interior* edge of a mesh (an edge shared by exactly two faces once vertices are merged by
position, so that an edge between two UV charts counts as interior), both adjacent faces are
sampled just inside the edge -- a fixed distance in texture space, half a texel by default --
each in its **own** texture coordinates, and the colours are compared with CIEDE2000 (sRGB ->
CIE Lab, D65). Edges inside a chart (same texture coordinates on both sides) are continuous by
construction and count 0, so the metric measures seams, not the photo's own texture gradient
(which would reward blurred textures). A seam between two charts textured from differently
exposed photos gives the colour difference of the photos. See :func:`seam_metric`.

Works on any textured OBJ / GLB (ours or another tool's) read by trimesh, and on meshes with
per-vertex colours (colours interpolated at the sample points).
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from ..imaging.arrays import delta_e_2000
from ..geometry.meshops import edge_topology, weld_vertices
from ..texturing.textured_mesh import TexturedMesh, load_textured_mesh, sample_texture

__all__ = ["SeamReport", "SelectionSeams", "mip_bleed", "photo_colors", "seam_metric", "selection_seams", "selection_seams_of"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class SeamReport:
    """Summary of the seam metric.

    Attributes
    ----------
    n_edges : int
        Number of interior edges measured (edges shared by exactly two faces).
    mean : float
        Mean over edges of the per-edge CIEDE2000 (each edge averaged over its samples).
    median : float
        Median per-edge CIEDE2000.
    p99 : float
        99th percentile of the per-edge CIEDE2000.
    frac_above_5 : float
        Fraction of edges whose CIEDE2000 exceeds 5 (a clearly visible seam), in [0, 1].
    n_boundary_edges : int
        Edges with one adjacent face (not measured).
    n_nonmanifold_edges : int
        Edges with more than two adjacent faces (not measured).
    n_seam_edges : int
        Interior edges on a UV seam (different texture coordinates on the two sides); the
        others are inside a chart and count as 0.
    seam_mean : float
        Mean CIEDE2000 over the UV-seam edges only (0 when there is none).
    offset : float
        The sampling distance from the edge, in texels.
    per_edge : (n_edges,) float64 array or None
        Per-edge CIEDE2000 when requested (``keep_per_edge=True``).
    edges : (n_edges, 2) int64 array or None
        The merged-vertex ids of each measured edge (with ``keep_per_edge=True``).
    is_seam : (n_edges,) bool array or None
        Which measured edges are UV seams (with ``keep_per_edge=True``).
    """

    n_edges: int
    mean: float
    median: float
    p99: float
    frac_above_5: float
    n_boundary_edges: int = 0
    n_nonmanifold_edges: int = 0
    n_seam_edges: int = 0
    seam_mean: float = 0.0
    offset: float = 0.5
    per_edge: np.ndarray | None = field(default=None, repr=False)
    edges: np.ndarray | None = field(default=None, repr=False)
    is_seam: np.ndarray | None = field(default=None, repr=False)

    def to_dict(self) -> dict[str, Any]:
        """The scalar fields as a JSON-friendly dict (no per-edge arrays)."""
        d = asdict(self)
        d.pop("per_edge")
        d.pop("edges")
        d.pop("is_seam")
        return d


def _face_samples(
    uvpts: np.ndarray, corners: np.ndarray, corner_lo: np.ndarray, corner_hi: np.ndarray, t: np.ndarray,
    offset: float, max_weight: float = 1.0 / 3.0,
) -> np.ndarray:
    """Barycentric weights (E, S, 3) of points along an edge, moved ``offset`` units inward.

    ``uvpts`` are the per-vertex coordinates in which distances are measured (texture
    coordinates in texels). A point at parameter ``t`` on the edge (A at the ``corner_lo``
    corner, B at ``corner_hi``) is moved along the inward normal of the edge, in the face's own
    coordinates, by ``offset`` (capped at ``max_weight`` times the face's altitude over the edge
    so that the point stays well inside thin faces): the weight of the opposite corner is
    ``min(offset / altitude, max_weight)`` and the point is P(t) + w (O - F), F the foot of the
    altitude from the opposite corner O.
    """
    E, S = len(corner_lo), len(t)
    opposite = 3 - corner_lo - corner_hi
    rows = np.arange(E)
    A = uvpts[corners[rows, corner_lo]]
    B = uvpts[corners[rows, corner_hi]]
    O = uvpts[corners[rows, opposite]]
    ab = B - A
    L2 = np.einsum("ij,ij->i", ab, ab)
    ao = O - A
    t_o = np.divide(np.einsum("ij,ij->i", ao, ab), L2, out=np.full(E, 0.5), where=L2 > 0)
    cross = np.abs(ab[:, 0] * ao[:, 1] - ab[:, 1] * ao[:, 0]) if uvpts.shape[1] == 2 else np.linalg.norm(np.cross(ab, ao), axis=1)
    L = np.sqrt(L2)
    alt = np.divide(cross, L, out=np.zeros(E), where=L > 0)
    wo = np.where(alt > 0, np.minimum(np.divide(offset, alt, out=np.full(E, np.inf), where=alt > 0), max_weight), 0.0)
    w_lo = (1.0 - t)[None, :] - (wo * (1.0 - t_o))[:, None]
    w_hi = t[None, :] - (wo * t_o)[:, None]
    w_o = np.broadcast_to(wo[:, None], (E, S))
    w = np.stack([w_lo, w_hi, w_o], axis=-1)
    # very obtuse faces: keep the point inside the face
    w = np.clip(w, 0.0, None)
    w /= w.sum(axis=-1, keepdims=True)
    out = np.zeros((E, S, 3))
    r, c = rows[:, None], np.arange(S)[None, :]
    out[r, c, corner_lo[:, None]] = w[..., 0]
    out[r, c, corner_hi[:, None]] = w[..., 1]
    out[r, c, opposite[:, None]] = w[..., 2]
    return out


def _colors_at(tm: TexturedMesh, faces: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Colours (E*S, 3) in [0, 1] at barycentric points (E, S, 3) of faces (E,)."""
    corners = tm.faces[faces]  # (E, 3)
    if tm.has_texture:
        uv = np.einsum("esk,ekd->esd", bary, tm.uv[corners]).reshape(-1, 2)
        return sample_texture(tm.texture, uv)
    return np.einsum("esk,ekd->esd", bary, tm.vertex_colors[corners]).reshape(-1, 3)


def _is_continuous(tm: TexturedMesh, fa, ca0, ca1, fb, cb0, cb1, tol: float) -> np.ndarray:
    """(E,) bool: both faces carry the same texture coordinates (or vertex colours) at both ends."""
    if tm.has_texture:
        h, w = tm.texture.shape[:2]
        attr = tm.uv * np.array([w, h], dtype=np.float64)  # texels
    else:
        attr = tm.vertex_colors * 255.0
    fa_c, fb_c = tm.faces[fa], tm.faces[fb]
    r = np.arange(len(fa))
    d0 = np.abs(attr[fa_c[r, ca0]] - attr[fb_c[r, cb0]]).max(axis=1)
    d1 = np.abs(attr[fa_c[r, ca1]] - attr[fb_c[r, cb1]]).max(axis=1)
    return (d0 <= tol) & (d1 <= tol)


def seam_metric(
    mesh_or_path: Any,
    *,
    offset: float = 0.5,
    samples_per_edge: int = 4,
    merge_tol: float | None = None,
    continuity_tol: float = 0.01,
    keep_per_edge: bool = False,
) -> SeamReport:
    """Seam metric: CIEDE2000 across every interior edge of a textured mesh.

    Definition (tool-agnostic: it only reads positions, texture coordinates and the texture
    image, so it applies to any textured OBJ/GLB). For each edge shared by exactly two faces
    (after merging vertices by position):

    - if both faces carry the **same texture coordinates** at both ends of the edge (within
      ``continuity_tol`` texels), the texture is continuous across it by construction (an edge
      inside a chart): a renderer shows no seam there, and its value is 0 -- the limit of the
      sampling below as the offset goes to 0, where both sides read the same texel;
    - otherwise (a UV seam: the faces lie in different charts, possibly from different images)
      take ``samples_per_edge`` points evenly spaced along the edge (``t = (k + 0.5) / S``),
      move each ``offset`` **texels** inward, perpendicular to the edge in each face's **own**
      texture coordinates (capped at a third of the face's altitude in texels, so thin faces are
      not crossed), look both textures up there (bilinear) and average the CIEDE2000 of the
      pairs (sRGB -> CIE Lab D65).

    "Just inside" is thus a fixed distance in texture space: at half a texel, the bilinear
    lookup reads texels whose centres lie at most half a texel outside the face, so a chart's
    gutter hardly leaks in, and the photo's own gradient across the seam contributes over one
    texel at most. Meshes with per-vertex colours are sampled on the edge itself (an edge
    whose two faces share the colours at both ends scores 0).

    Parameters
    ----------
    mesh_or_path : path-like, trimesh.Trimesh or TexturedMesh
        A textured OBJ/GLB (or a mesh with vertex colours).
    offset : float, default 0.5
        Distance of the samples from the edge, in texels of the texture image (> 0).
    samples_per_edge : int, default 4
        Points per edge (>= 1).
    merge_tol : float, optional
        Vertices closer than this (grid rounding) are the same position. Default: 1e-6 x the
        bounding-box diagonal.
    continuity_tol : float, default 0.01
        Texture coordinates closer than this (in texels; 0-255 units for vertex colours) are
        the same: the edge is inside a chart.
    keep_per_edge : bool, default False
        Keep the per-edge values (``per_edge``, ``edges``, ``is_seam``) in the report.

    Returns
    -------
    SeamReport
        ``mean``, ``median``, ``p99``, ``frac_above_5`` over all interior edges (edges inside a
        chart count as 0); ``n_seam_edges`` and ``seam_mean`` over the UV-seam edges alone.

    Raises
    ------
    InputError
        No texture / vertex colours, a non-positive offset, or no interior edge (e.g. a
        triangle soup whose vertices do not coincide).

    Examples
    --------
    >>> import tempfile, o3d_seqcc as sc
    >>> room = sc.make_synthetic_scene(tempfile.mkdtemp() + '/room', n_views=3, width=96, height=72, seed=1,
    ...                                seen_only=True)
    >>> tm = sc.pipeline.texture(room.scene, atlas_size=512, seams=False).textured
    >>> report = sc.seam_metric(tm)  # CIEDE2000 across the interior edges
    >>> report.n_edges > 0, 0 <= report.mean < 20
    (True, True)
    """
    if not float(offset) > 0.0:
        raise InputError(f"offset must be > 0 (texels inward from the edge), got {offset}")
    samples_per_edge = int(samples_per_edge)
    if samples_per_edge < 1:
        raise InputError(f"samples_per_edge must be >= 1, got {samples_per_edge}")
    tm = load_textured_mesh(mesh_or_path)
    diag = float(np.linalg.norm(np.ptp(tm.vertices, axis=0)))
    tol = float(merge_tol) if merge_tol is not None else max(diag * 1e-6, 1e-12)
    topo = edge_topology(weld_vertices(tm.vertices, tol=tol)[tm.faces])
    fa, ca0, ca1, fb, cb0, cb1 = (topo.face_a, topo.corner_a0, topo.corner_a1, topo.face_b, topo.corner_b0,
                                  topo.corner_b1)
    edges, n_bnd, n_nm = topo.edges, topo.n_boundary, topo.n_nonmanifold
    if len(fa) == 0:
        raise InputError(
            "the mesh has no interior edge (no edge shared by two faces after merging vertices within "
            f"{tol:g}); is it a triangle soup? pass a larger merge_tol"
        )
    seam = ~_is_continuous(tm, fa, ca0, ca1, fb, cb0, cb1, float(continuity_tol))
    de = np.zeros(len(fa))
    if seam.any():
        t = (np.arange(samples_per_edge) + 0.5) / samples_per_edge
        if tm.has_texture:
            h, w = tm.texture.shape[:2]
            pts, off = tm.uv * np.array([w, h], dtype=np.float64), float(offset)
        else:
            pts, off = tm.vertices, 0.0
        s_ = np.flatnonzero(seam)
        col_a = _colors_at(tm, fa[s_], _face_samples(pts, tm.faces[fa[s_]], ca0[s_], ca1[s_], t, off))
        col_b = _colors_at(tm, fb[s_], _face_samples(pts, tm.faces[fb[s_]], cb0[s_], cb1[s_], t, off))
        de[s_] = delta_e_2000(col_a, col_b).reshape(len(s_), samples_per_edge).mean(axis=1)
    n_seam = int(seam.sum())
    logger.info("seam metric: %d interior edges (%d on UV seams), %d boundary, %d non-manifold",
                len(de), n_seam, n_bnd, n_nm)
    return SeamReport(
        n_edges=int(len(de)),
        mean=float(de.mean()),
        median=float(np.median(de)),
        p99=float(np.percentile(de, 99)),
        frac_above_5=float(np.mean(de > 5.0)),
        n_boundary_edges=n_bnd,
        n_nonmanifold_edges=n_nm,
        n_seam_edges=n_seam,
        seam_mean=float(de[seam].mean()) if n_seam else 0.0,
        offset=float(offset),
        per_edge=de if keep_per_edge else None,
        edges=edges if keep_per_edge else None,
        is_seam=seam if keep_per_edge else None,
    )


def _box_chain(img: np.ndarray, levels: int) -> list[np.ndarray]:
    """Mip levels 0..levels of an image, each texel the mean of a 2 x 2 block of the level below."""
    out = [img.astype(np.float64)]
    for _ in range(levels):
        a = out[-1]
        a = a[: a.shape[0] - a.shape[0] % 2, : a.shape[1] - a.shape[1] % 2]
        out.append(0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2]))
    return out


def mip_bleed(mesh_or_path: Any, *, levels: tuple[int, ...] = (1, 2, 3), reach: float | None = None,
              seen_only: bool = True) -> dict[int, dict[str, float]]:
    """Colour bleeding into each face at mip levels 1-3 (box-filtered chain), in CIEDE2000.

    A renderer minifying the atlas reads level k of its mip chain, where a texel is the mean of
    a 2^k x 2^k block of the atlas: near a chart's border that block mixes in the gutter, the
    background or the next chart, unless the gutter continues the chart's content. For every
    face, at its centroid and at its corners moved a third of the way to the centroid (its
    footprint), the bilinear lookup in level k is compared with the same lookup in a level k
    built from the face's **own chart** only (each level-k texel the mean of the level-0 texels
    of its block that belong to the chart: the chart's faces and its gutter; taps whose block
    holds none are dropped and the weights renormalised). The bleed of a face is the largest
    CIEDE2000 over its points.

    Parameters
    ----------
    mesh_or_path : TexturedMesh or path
        With ``face_chart`` (a :func:`~o3d_seqcc.texturing.bake_texture` result); a file gives
        every connected UV island its own chart.
    levels : tuple of int, default (1, 2, 3)
    reach : float, optional
        Texels outside the faces that belong to their chart (its gutter: the nearest face's);
        default ``stats["padding"] + 1`` (5 for the default padding).
    seen_only : bool, default True
        Only faces textured from a photo (``face_view >= 0``).

    Returns
    -------
    dict
        Level -> ``mean``, ``p99``, ``max``, ``share_gt1``, ``share_gt2`` (fractions of faces),
        ``faces``.
    """
    from ..texturing.bake import gutter_texels, rasterize_faces

    tm = load_textured_mesh(mesh_or_path)
    if not tm.has_texture:
        raise InputError("mip_bleed needs a textured mesh")
    H, W = tm.texture.shape[:2]
    faces = np.asarray(tm.faces)
    chart = tm.face_chart
    if chart is None:  # UV islands: faces sharing texture coordinates
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
        _, chart = connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(tm.uv),) * 2),
                                        directed=False)
        chart = chart[faces[:, 0]]
    if reach is None:
        reach = float(tm.stats.get("padding", 4)) + 1.0
    txy = tm.texel_xy()
    idx, face, _ = rasterize_faces(txy, faces, H, W)
    gidx, gface = gutter_texels(idx, face, H, W, reach)
    owner = np.full(H * W, -1, dtype=np.int64)
    owner[idx] = chart[face]
    owner[gidx] = chart[gface]
    owner = owner.reshape(H, W)
    fsel = np.arange(len(faces)) if not seen_only or tm.face_view is None else np.flatnonzero(tm.face_view >= 0)
    p = txy[faces[fsel]]
    c = p.mean(axis=1, keepdims=True)
    pts = np.concatenate([c, p + (c - p) / 3.0], axis=1)  # (n, 4, 2)
    X, Y = pts[..., 0].reshape(-1), pts[..., 1].reshape(-1)
    ch = np.repeat(chart[fsel], 4)
    tex = tm.texture.astype(np.float64)
    chain = _box_chain(tex, max(levels))
    out: dict[int, dict[str, float]] = {}
    for k in levels:
        L = chain[k]
        n = 2 ** k
        xk, yk = (X + 0.5) / n - 0.5, (Y + 0.5) / n - 0.5
        x0, y0 = np.floor(xk).astype(np.int64), np.floor(yk).astype(np.int64)
        fx, fy = xk - x0, yk - y0
        plain = np.zeros((len(X), 3))
        own = np.zeros((len(X), 3))
        wsum = np.zeros(len(X))
        for dy, dx, w in ((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)), (1, 0, (1 - fx) * fy), (1, 1, fx * fy)):
            xi = np.clip(x0 + dx, 0, L.shape[1] - 1)
            yi = np.clip(y0 + dy, 0, L.shape[0] - 1)
            plain += w[:, None] * L[yi, xi]
            acc = np.zeros((len(X), 3))
            cnt = np.zeros(len(X))
            for by in range(n):  # the level-0 block of this level-k texel
                for bx in range(n):
                    Y0 = np.clip(yi * n + by, 0, H - 1)
                    X0 = np.clip(xi * n + bx, 0, W - 1)
                    m = owner[Y0, X0] == ch
                    acc += m[:, None] * tex[Y0, X0]
                    cnt += m
            has = cnt > 0
            own += (w * has)[:, None] * (acc / np.maximum(cnt, 1)[:, None])
            wsum += w * has
        ok = wsum > 1e-9
        own[ok] /= wsum[ok, None]
        own[~ok] = plain[~ok]
        dmax = delta_e_2000(np.clip(plain / 255.0, 0, 1), np.clip(own / 255.0, 0, 1)).reshape(-1, 4).max(axis=1)
        out[k] = {"mean": float(dmax.mean()), "p99": float(np.percentile(dmax, 99)), "max": float(dmax.max()),
                  "share_gt1": float((dmax > 1).mean()), "share_gt2": float((dmax > 2).mean()), "faces": int(len(dmax))}
    return out


def photo_colors(views: Any, points: np.ndarray, view_ids: np.ndarray, *image_sets: Any) -> Any:
    """Colours of 3-D points in the photos that texture them: point ``i`` in ``images[view_ids[i]]``.

    Each point is projected by its view's camera (once, whatever the number of image sets) and
    the image looked up bilinearly, clamped at the border (the definition of
    :func:`o3d_seqcc.imaging.arrays.sample_bilinear`, by OpenCV's ``remap``: weights in 1/32 pixel).
    Every image needed is read once.

    Parameters
    ----------
    views : sequence of View
        The cameras (``scene.views``).
    points : (n, 3) float
        World coordinates.
    view_ids : (n,) int
        View of each point; negative entries get NaN.
    *image_sets : sequences of (H, W, 3) arrays
        One or more sets of one image per view (e.g. the photos and the corrected images); a
        lazy sequence is read only at the views in ``view_ids``.

    Returns
    -------
    (n, 3) float64, or a list of them (one per image set when several are given)
        sRGB in [0, 1].
    """
    import cv2

    from ..geometry.camera import project_points
    from ..imaging.arrays import dtype_scale, sample_colors

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    vid = np.asarray(view_ids, dtype=np.int64).reshape(-1)
    outs = [np.full((len(pts), 3), np.nan) for _ in image_sets]
    order = np.argsort(vid, kind="stable")
    bounds = np.searchsorted(vid[order], np.arange(len(views) + 1))
    for v in range(len(views)):
        idx = order[bounds[v]:bounds[v + 1]]
        if len(idx) == 0:
            continue
        uv, _ = project_points(pts[idx], views[v].intrinsic, views[v].extrinsic)
        n = len(idx)
        bands = None
        for images, out in zip(image_sets, outs):
            img = np.asarray(images[v])
            if n < img.shape[0] * img.shape[1] // 20:  # a few points: numpy, without a float copy of the image
                out[idx] = sample_colors(img, np.nan_to_num(uv)) / dtype_scale(img.dtype)
                continue
            if bands is None:
                bands = _remap_bands(uv, *img.shape[:2])
            col = np.empty((n, img.shape[2]), dtype=np.float32)
            for r0, r1, which, maps in bands:  # a float copy of a band of rows at a time, not of the whole image
                part = cv2.remap(img[r0:r1].astype(np.float32), maps[0], maps[1], cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_REPLICATE)
                col[which] = part.reshape(-1, img.shape[2])[:len(which)]
            out[idx] = col.astype(np.float64) / dtype_scale(img.dtype)
    outs = [np.clip(o, 0.0, 1.0) for o in outs]
    return outs[0] if len(outs) == 1 else outs


#: image rows converted to float32 at a time by :func:`photo_colors` (OpenCV's remap reads them)
REMAP_BAND_ROWS = 128


def _remap_bands(uv: np.ndarray, h: int, w: int, k: int = 4096) -> list[tuple[int, int, np.ndarray, tuple]]:
    """The points ``uv`` (n, 2), clamped to the image, grouped by bands of :data:`REMAP_BAND_ROWS` rows:
    ``(r0, r1, which, (map_x, map_y))`` per band, the maps relative to row ``r0`` in rows of ``k``.

    OpenCV's bilinear remap reads the rows of a point's 1/32-pixel position and the next one: at
    most ``floor(y) + 2``, all inside the band's rows ``r0 .. r1`` (two beyond the band), so every
    point's value is the one the whole image gives (the same weights, the same pixels; the image's
    own last rows are the band's, with the same border).
    """
    x = np.clip(np.nan_to_num(uv[:, 0], nan=0.0), 0.0, w - 1.0).astype(np.float32)
    y = np.clip(np.nan_to_num(uv[:, 1], nan=0.0), 0.0, h - 1.0).astype(np.float32)
    band = np.floor(y).astype(np.int64) // REMAP_BAND_ROWS
    order = np.argsort(band, kind="stable")
    starts = np.searchsorted(band[order], np.arange(band.max(initial=0) + 2))
    out = []
    for b in np.flatnonzero(np.diff(starts)):
        which = order[starts[b]:starts[b + 1]]
        r0 = int(b) * REMAP_BAND_ROWS
        r1 = min(h, r0 + REMAP_BAND_ROWS + 2)
        m = len(which)
        pad = (-m) % k
        maps = tuple(np.concatenate([a, np.zeros(pad, np.float32)]).reshape(-1, min(k, m + pad))
                     for a in (x[which], y[which] - np.float32(r0)))  # exact: r0 is an integer below y
        out.append((r0, r1, which, maps))
    return out


@dataclass(frozen=True, eq=False)
class SelectionSeams:
    """The colour steps in the photos across the edges where the per-face selection changes photo.

    Attributes
    ----------
    delta_e : (n,) float64
        CIEDE2000 between the two photos' colours on each such edge (mean of its samples).
    segments : (n, 2, 3) float64
        The edges' end points (world coordinates), for drawing.
    faces : (n, 2) int64
        The two faces of each edge.
    """

    delta_e: np.ndarray
    segments: np.ndarray
    faces: np.ndarray

    def summary(self) -> dict[str, float]:
        """``n_edges``, ``mean``, ``median``, ``p90``, ``frac_above_5`` (JSON types; zeros when no edge)."""
        d = self.delta_e
        if len(d) == 0:
            return {"n_edges": 0, "mean": 0.0, "median": 0.0, "p90": 0.0, "frac_above_5": 0.0}
        return {"n_edges": int(len(d)), "mean": float(d.mean()), "median": float(np.median(d)),
                "p90": float(np.percentile(d, 90)), "frac_above_5": float((d > 5).mean())}


def selection_seams(
    vertices: np.ndarray, faces: np.ndarray, selection: np.ndarray, views: Any, images: Any, *,
    samples_per_edge: int = 3,
) -> SelectionSeams:
    """The colour step each selection seam shows before any atlas or seam leveling.

    For every interior edge whose two faces are textured from different photos, points along
    the edge are looked up in both photos (:func:`photo_colors`) and compared with CIEDE2000:
    what a viewer would see across the edge if each face showed its photo as it is. A colour
    correction that makes the photos agree lowers it; seam leveling, which hides the steps
    after the fact, does not enter (compare :func:`seam_metric` of the finished texture).

    Parameters
    ----------
    vertices : (N, 3) float
    faces : (F, 3) int
        The scene's mesh (coincident vertices are merged to find the edges).
    selection : (F,) int
        View per face, -1 = seen by no view (edges to such faces are skipped).
    views : sequence of View
    images : sequence of (H, W, 3) arrays
        One per view (e.g. the photos, or the corrected images).
    samples_per_edge : int, default 3

    Returns
    -------
    SelectionSeams
    """
    return selection_seams_of(vertices, faces, selection, views, {"images": images},
                              samples_per_edge=samples_per_edge)["images"]


def selection_seams_of(
    vertices: np.ndarray, faces: np.ndarray, selection: np.ndarray, views: Any, image_sets: dict[str, Any], *,
    samples_per_edge: int = 3,
) -> dict[str, SelectionSeams]:
    """:func:`selection_seams` in several image sets at once (e.g. the photos and the corrected images).

    The seam edges and their sample points are found once and projected once per view, and each
    view's images of every set are read together (:func:`photo_colors`); each set's result is the
    one :func:`selection_seams` gives for it.

    Parameters
    ----------
    vertices, faces, selection, views, samples_per_edge
        As :func:`selection_seams`.
    image_sets : dict
        Name -> one image per view.

    Returns
    -------
    dict
        Name -> :class:`SelectionSeams`.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    sel = np.asarray(selection, dtype=np.int64).reshape(-1)
    if len(sel) != len(f):
        raise InputError(f"selection has {len(sel)} entries for {len(f)} faces")
    topo = edge_topology(weld_vertices(v)[f])
    a, b = sel[topo.face_a], sel[topo.face_b]
    k = np.flatnonzero((a >= 0) & (b >= 0) & (a != b))
    fa, fb = topo.face_a[k], topo.face_b[k]
    p0 = v[f[fa, topo.corner_a0[k]]]
    p1 = v[f[fa, topo.corner_a1[k]]]
    s = max(int(samples_per_edge), 1)
    t = (np.arange(s) + 0.5) / s
    pts = (p0[:, None] * (1.0 - t)[None, :, None] + p1[:, None] * t[None, :, None]).reshape(-1, 3)
    names = list(image_sets)
    cols = photo_colors(views, np.concatenate([pts, pts]), np.concatenate([np.repeat(a[k], s), np.repeat(b[k], s)]),
                        *(image_sets[n] for n in names))  # each image read once for both sides
    segments, pair = np.stack([p0, p1], axis=1), np.stack([fa, fb], axis=1)
    out = {}
    for name, both in zip(names, cols if len(names) > 1 else [cols]):
        ca, cb = both[:len(pts)], both[len(pts):]
        de = delta_e_2000(ca, cb).reshape(-1, s).mean(axis=1) if len(k) else np.zeros(0)
        out[name] = SelectionSeams(delta_e=de, segments=segments, faces=pair)
    return out
