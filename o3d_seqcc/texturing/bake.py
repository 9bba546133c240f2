"""Baking an atlas by sampling (issues 13, 19): texel -> face -> barycentric -> source pixel.

The atlas is *sampled*: every texel whose centre lies in a face's UV triangle
(:func:`rasterize_faces`) takes the colour of the face's own view at the point with the same
barycentric coordinates in the face's projection (:func:`sample_image`: Lanczos, clamped to
the neighbouring pixels' range; the projection is affine over a face, as the texture mapping
of a renderer). The packing puts every chart's texels on its photo's pixel grid
(:mod:`~o3d_seqcc.texturing.packing`), so at one texel per pixel that point is a pixel centre
and the texel a copy of the pixel: nothing is resampled, and a render from the photo's camera
gives the photo back. Faces of tiny charts merged into a neighbour's parametrisation, atlases
at another density and the fallback region are resampled. Texels of a chart's gutter
(:func:`gutter_texels`: within ``reach`` texels of a face) continue the nearest face's affine
map outside the triangle, so that they hold the photo's real content around the chart and
bilinear filtering and the first mip levels read nothing foreign; texels further away are
filled smoothly by :func:`~o3d_seqcc.texturing.fill.push_pull_fill`.

Texel coordinates: x right, y down, texel centres at integers; several square pages are
stacked vertically into one tall canvas (page p = rows ``p * S .. (p + 1) * S - 1``).
"""

from __future__ import annotations

import numpy as np

from .._shared.parallel import thread_map

__all__ = ["bary_coefficients", "barycentric", "edge_texels", "gutter_owner", "gutter_texels",
           "rasterize_faces", "rasterize_owner", "release_free_memory", "row_spans", "sample_image", "texel_bary"]


def _area2(p: np.ndarray) -> np.ndarray:
    return (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1])


def barycentric(txy: np.ndarray, faces: np.ndarray, face: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(n, 3) float64 barycentric coordinates of points (x, y) in the UV triangles of ``faces[face]``
    (negative outside the triangle; degenerate triangles give their first corner)."""
    p = txy[faces[face]]
    d = _area2(p)
    ok = np.abs(d) > 1e-12
    d = np.where(ok, d, 1.0)
    b, c = p[:, 1], p[:, 2]
    a = p[:, 0]
    l0 = ((b[:, 0] - x) * (c[:, 1] - y) - (c[:, 0] - x) * (b[:, 1] - y)) / d
    l1 = ((c[:, 0] - x) * (a[:, 1] - y) - (a[:, 0] - x) * (c[:, 1] - y)) / d
    out = np.stack([l0, l1, 1.0 - l0 - l1], axis=1)
    out[~ok] = (1.0, 0.0, 0.0)
    return out


def _edge_functions(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Barycentric coordinates as affine functions of the texel position: ``l_i = A_i x + B_i y + C_i``.

    ``p`` (F, 3, 2) triangles; returns A, B, C (F, 3) and the doubled signed area (F,) (faces
    with a near-zero area get zero coefficients).
    """
    d = _area2(p)
    ok = np.abs(d) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, d, 1.0), 0.0)
    a, b, c = p[:, 0], p[:, 1], p[:, 2]
    A = np.stack([b[:, 1] - c[:, 1], c[:, 1] - a[:, 1], a[:, 1] - b[:, 1]], axis=1) * inv[:, None]
    B = np.stack([c[:, 0] - b[:, 0], a[:, 0] - c[:, 0], b[:, 0] - a[:, 0]], axis=1) * inv[:, None]
    C = np.stack([b[:, 0] * c[:, 1] - c[:, 0] * b[:, 1], c[:, 0] * a[:, 1] - a[:, 0] * c[:, 1],
                  a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]], axis=1) * inv[:, None]
    return A, B, C, d


def row_spans(p: np.ndarray, height: int, width: int, *, chunk: int = 2_000_000, rows: tuple[int, int] | None = None):
    """Per triangle and canvas row, the span of texel (pixel) centres inside the triangle.

    The span of every row is solved from the three edge functions (no per-texel inside test),
    vectorised over all rows of a chunk of triangles.

    Parameters
    ----------
    p : (F, 3, 2) float64
        Triangles in canvas coordinates (x right, y down, centres at integers).
    height, width : int
        Canvas size (spans are clipped to it).
    chunk : int
        Texels (estimated from bounding boxes) handled per step.
    rows : (int, int), optional
        Only the canvas rows ``rows[0] <= y < rows[1]`` (each row's span is the same as without it).

    Yields
    ------
    k : (rows,) int64
        Triangle of every row (index into ``p``), ascending.
    y : (rows,) float64
        The row.
    xs, n : (rows,) int64
        First texel of the span and its length (0: no texel centre inside).
    A, r : (rows, 3) float64
        The barycentric coordinates on the row: ``l_i = A_i x + r_i``.
    """
    A, B, C, d = _edge_functions(p)
    lo_row, hi_row = (0, height) if rows is None else (max(0, int(rows[0])), min(height, int(rows[1])))
    y0 = np.maximum(np.ceil(p[:, :, 1].min(axis=1) - 1e-9), lo_row).astype(np.int64)
    y1 = np.minimum(np.floor(p[:, :, 1].max(axis=1) + 1e-9), hi_row - 1).astype(np.int64)
    xlo = np.maximum(p[:, :, 0].min(axis=1) - 1e-9, 0.0)
    xhi = np.minimum(p[:, :, 0].max(axis=1) + 1e-9, width - 1.0)
    ny = np.where(np.abs(d) > 1e-12, np.maximum(y1 - y0 + 1, 0), 0)
    est = np.cumsum(ny * np.maximum(np.ceil(xhi - xlo) + 1, 1))
    eps = 1e-7
    start = 0
    while start < len(p):
        base = est[start - 1] if start else 0
        end = max(int(np.searchsorted(est, base + chunk, side="right")), start + 1)
        k = np.repeat(np.arange(start, end), ny[start:end])  # one entry per (face, row)
        if len(k):
            y = (y0[k] + np.arange(len(k)) - np.repeat(np.cumsum(ny[start:end]) - ny[start:end], ny[start:end])).astype(np.float64)
            r = B[k] * y[:, None] + C[k]  # (rows, 3): l_i = A_i x + r_i on this row
            a = A[k]
            with np.errstate(divide="ignore", invalid="ignore"):
                bound = (-eps - r) / a
            lo = np.max(np.where(a > 1e-15, bound, -np.inf), axis=1)
            hi = np.min(np.where(a < -1e-15, bound, np.inf), axis=1)
            flat_bad = ((np.abs(a) <= 1e-15) & (r < -eps)).any(axis=1)
            xs = np.ceil(np.maximum(lo, xlo[k])).astype(np.int64)
            xe = np.floor(np.minimum(hi, xhi[k])).astype(np.int64)
            n = np.where(flat_bad, 0, np.maximum(xe - xs + 1, 0))
            yield k, y, xs, n, a, r
        start = end


def release_free_memory() -> None:
    """Give the C heap's free pages back to the system (glibc ``malloc_trim``; nothing elsewhere).

    Arrays below glibc's dynamic mmap threshold (up to 32 MB: the bake's per-chunk arrays) live
    in the heap, and once freed their pages stay counted in the process's RSS until trimmed:
    called where the bake drops many such arrays before making atlas-sized ones.
    """
    import ctypes
    import ctypes.util

    global _LIBC
    if _LIBC is None:
        name = ctypes.util.find_library("c")
        lib = ctypes.CDLL(name) if name else False
        _LIBC = lib if lib is not False and hasattr(lib, "malloc_trim") else False
    if _LIBC:
        _LIBC.malloc_trim(0)


_LIBC = None


#: canvas rows per band of :func:`rasterize_owner` on several threads
RASTER_BAND_ROWS = 256


def rasterize_owner(txy: np.ndarray, faces: np.ndarray, height: int, width: int, *,
                    order: np.ndarray | None = None, chunk: int = 2_000_000, threads: int = 1) -> np.ndarray:
    """The face whose UV triangle holds each texel centre: a canvas of face ids (the face drawn last wins).

    Scanline (:func:`row_spans`), vectorised over all rows of a chunk of triangles; each span is
    written as it comes, so the memory is the canvas (4 bytes per texel) and one chunk's spans.

    Parameters
    ----------
    txy : (M, 2) float
        Texel coordinates of the vertices (texel (X, Y) has its centre at (X, Y)).
    faces : (F, 3) int
    height, width : int
        Canvas size.
    order : (F,) int, optional
        Drawing order: where triangles overlap, the face drawn last keeps the texel.
    chunk : int
        Texels (estimated from bounding boxes) handled per vectorised step.
    threads : int
        Bands of :data:`RASTER_BAND_ROWS` rows drawn side by side (each band's texels by the faces
        that reach it, in the drawing order: the same canvas).

    Returns
    -------
    (height * width,) int32
        Face id per texel (row-major), -1 where no texel centre is inside a face.
    """
    if len(faces) >= 2**31 - 2:
        raise ValueError(f"{len(faces)} faces: face ids must fit int32")
    fo = np.arange(len(faces)) if order is None else np.asarray(order, dtype=np.int64)
    owner = np.full(height * width, -1, dtype=np.int32)
    if len(fo) == 0:
        return owner
    p = np.asarray(txy, dtype=np.float64)[np.asarray(faces)[fo]]
    fo32 = fo.astype(np.int32)

    def draw(q: np.ndarray, ids: np.ndarray, rows: tuple[int, int] | None) -> None:
        for k, y, xs, n, _, _ in row_spans(q, height, width, chunk=chunk, rows=rows):
            total = int(n.sum())
            if total == 0:
                continue
            first = y.astype(np.int64) * width + xs - (np.cumsum(n) - n)  # span start minus its offset in the run
            pos = np.repeat(first, n)
            pos += np.arange(total, dtype=np.int64)
            owner[pos] = np.repeat(ids[k], n)  # in drawing order: the last face written keeps a texel
            del pos

    if threads <= 1 or height <= RASTER_BAND_ROWS:
        draw(p, fo32, None)
        return owner
    ylo, yhi = p[:, :, 1].min(axis=1), p[:, :, 1].max(axis=1)

    def band(r0: int) -> None:
        r1 = r0 + RASTER_BAND_ROWS
        sel = np.flatnonzero((yhi + 1e-9 >= r0) & (ylo - 1e-9 <= r1 - 1))  # faces with a row in the band
        if len(sel):
            draw(p[sel], fo32[sel], (r0, r1))

    thread_map(band, range(0, height, RASTER_BAND_ROWS), threads, name="o3d_seqcc-raster")
    return owner


def bary_coefficients(txy: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, ...]:
    """The first two barycentric coordinates of every UV triangle as affine functions of the texel position.

    ``(A0, A1, B0, B1, C0, C1)``, each (F,) float64 contiguous: ``l_i = A_i x + (B_i y + C_i)``
    (:func:`_edge_functions`; zero for triangles of near-zero area), the form :func:`texel_bary` evaluates.
    """
    A, B, C, _ = _edge_functions(np.asarray(txy, dtype=np.float64)[np.asarray(faces)])
    return tuple(np.ascontiguousarray(m[:, i]) for m in (A, B, C) for i in (0, 1))[::1]


def texel_bary(txy: np.ndarray, faces: np.ndarray, face: np.ndarray, x: np.ndarray, y: np.ndarray, *,
               inside: np.ndarray | bool = True, coeffs: tuple | None = None) -> np.ndarray:
    """(n, 3) float32 barycentric coordinates of texel centres (x, y) in the UV triangles of ``faces[face]``.

    Texels ``inside`` their face (:func:`rasterize_owner`) get the row-span form of the
    rasterisation (``l_i = A_i x + (B_i y + C_i)`` from the face's edge functions), the others
    (under a thin face's edge, in a gutter) :func:`barycentric`'s: the float64 arithmetic the
    bake has always used, rounded to float32.

    Parameters
    ----------
    txy : (M, 2) float64
    faces : (F, 3) int
    face : (n,) int
    x, y : (n,) int or float
        Texel columns and rows.
    inside : (n,) bool or bool
        Which texels lie inside their face.
    coeffs : tuple, optional
        :func:`bary_coefficients` of ``txy, faces`` (computed when omitted).
    """
    face = np.asarray(face)
    n = len(face)
    out = np.empty((n, 3), dtype=np.float32)
    ins = np.broadcast_to(np.asarray(inside, dtype=bool), (n,))
    every = bool(ins.all())
    if every or ins.any():
        A0, A1, B0, B1, C0, C1 = bary_coefficients(txy, faces) if coeffs is None else coeffs
        sel = slice(None) if every else np.flatnonzero(ins)
        f = face[sel]
        xi = np.asarray(x, dtype=np.float64)[sel]
        yi = np.asarray(y, dtype=np.float64)[sel]
        l0 = B0[f] * yi
        l0 += C0[f]
        l0 += A0[f] * xi  # A x + (B y + C), as the row spans evaluate it
        l1 = B1[f] * yi
        l1 += C1[f]
        l1 += A1[f] * xi
        out[sel, 0] = l0
        out[sel, 1] = l1
        np.subtract(1.0, l0, out=l0)
        l0 -= l1
        out[sel, 2] = l0
    if not every:
        sel = np.flatnonzero(~ins)
        out[sel] = barycentric(txy, faces, face[sel], np.asarray(x, dtype=np.float64)[sel],
                               np.asarray(y, dtype=np.float64)[sel])
    return out


def rasterize_faces(txy: np.ndarray, faces: np.ndarray, height: int, width: int, *,
                    order: np.ndarray | None = None, chunk: int = 2_000_000,
                    compact: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Texels whose centre lies in a UV triangle, with their face and barycentric coordinates.

    :func:`rasterize_owner`'s canvas, listed: memory about 4 bytes per canvas texel plus the
    outputs.

    Parameters
    ----------
    txy : (M, 2) float
        Texel coordinates of the vertices (texel (X, Y) has its centre at (X, Y)).
    faces : (F, 3) int
    height, width : int
        Canvas size.
    order : (F,) int, optional
        Drawing order: where triangles overlap, the face drawn last keeps the texel.
    chunk : int
        Texels (estimated from bounding boxes) handled per vectorised step.
    compact : bool
        Return ``idx`` and ``face`` as int32 (when the canvas has fewer than 2**31 texels):
        the same values, half the bytes.

    Returns
    -------
    idx : (n,) int64 (int32 with ``compact``)
        Flat canvas indices (``y * width + x``), ascending, one per covered texel.
    face : (n,) int64 (int32 with ``compact``)
        Its face.
    bary : (n, 3) float32
        Its barycentric coordinates in the face (in [0, 1] up to rounding).
    """
    small = compact and height * width < 2**31 and len(faces) < 2**31
    itype = np.int32 if small else np.int64
    owner = rasterize_owner(txy, faces, height, width, order=order, chunk=chunk)
    cov = np.flatnonzero(owner >= 0)
    face = owner[cov]
    del owner
    if len(cov) == 0:
        return np.zeros(0, dtype=itype), np.zeros(0, dtype=itype), np.zeros((0, 3), dtype=np.float32)
    y, x = np.divmod(cov, width)
    bary = texel_bary(txy, faces, face, x, y)
    return cov.astype(itype, copy=False), face.astype(itype, copy=False), bary


#: edge samples made at a time by :func:`edge_texels` (about 40 bytes each in temporaries: 1M samples, 40 MB;
#: 4M held 100 MB more at the peak of Fountain 300k's rasterisation)
EDGE_SAMPLES = 1 << 20


def edge_texels(txy: np.ndarray, faces: np.ndarray, covered: np.ndarray | None, height: int, width: int, *,
                max_altitude: float = 2.0, step: float = 0.5,
                free: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Texels under the edges of thin faces that no face covers (conservative rasterisation).

    A texel belongs to a face when its centre is inside (:func:`rasterize_faces`), so a sliver
    (a UV triangle less than ``max_altitude`` texels thick) may own almost no texel and its
    gutter would not follow its length. Its edges are sampled every ``step`` texels and the
    texels under them that no face covers are given to it (first face wins, vectorised).

    ``covered`` lists the covered texels (flat indices); or give ``free`` instead, a (height *
    width,) bool canvas, True where no face covers the texel (a :func:`rasterize_owner` canvas
    ``== -1``).

    Returns
    -------
    idx : (m,) int64
        Flat canvas indices (ascending, none in ``covered``).
    face : (m,) int64
    """
    txy = np.asarray(txy, dtype=np.float64)
    p = txy[np.asarray(faces)]
    a2 = np.abs(_area2(p))
    e = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 0] - p[:, 2]], axis=1)  # (F, 3, 2)
    L = np.linalg.norm(e, axis=2)
    thin = np.flatnonzero(a2 <= max_altitude * np.maximum(L.max(axis=1), 1e-12))
    if len(thin) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    if free is None:
        free = np.ones(height * width, dtype=bool)
        free[covered] = False
    pe, ee = p[thin].reshape(-1, 2), e[thin].reshape(-1, 2)  # (3 per thin face) edge starts and vectors
    # an edge whose samples' texels (within the rounded box of its ends, a texel more for rounding) are all covered
    # gives nothing: left out
    lo, hi = np.rint(np.minimum(pe, pe + ee)) - 1, np.rint(np.maximum(pe, pe + ee)) + 1
    x0, x1 = (np.clip(v[:, 0], 0, width - 1).astype(np.int64) for v in (lo, hi))
    y0, y1 = (np.clip(v[:, 1], 0, height - 1).astype(np.int64) for v in (lo, hi))
    import cv2

    ry, rx = int(y1.max()) + 1, int(x1.max()) + 1  # the summed-area table over the edges' extent only
    acc = cv2.integral(np.ascontiguousarray(free.view(np.uint8).reshape(height, width)[:ry, :rx]),
                       sdepth=cv2.CV_32S if ry * rx < 2**31 else cv2.CV_64F)
    inside = acc[y1 + 1, x1 + 1] - acc[y0, x1 + 1] - acc[y1 + 1, x0] + acc[y0, x0]
    del acc
    keep = np.flatnonzero(inside > 0)
    if len(keep) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    pe, ee, fe = pe[keep], ee[keep], np.repeat(thin, 3)[keep]
    n = np.maximum(np.ceil(L[thin].reshape(-1)[keep] / step).astype(np.int64), 1) + 1  # samples per edge, ends included
    # the edges in runs of about EDGE_SAMPLES samples; the free texels they hit, in edge order
    ends = np.cumsum(n)
    cuts = np.unique(np.searchsorted(ends, np.arange(EDGE_SAMPLES, int(ends[-1]), EDGE_SAMPLES), side="right"))
    hit_idx, hit_face = [], []
    for s0, s1 in zip(np.r_[0, cuts], np.r_[cuts, len(n)]):
        if s1 <= s0:
            continue
        nn = n[s0:s1]
        # sample k of an edge at start + e * (k / (n - 1)), its values repeated from the edge's (no (samples, 2) gathers)
        k = np.arange(int(nn.sum()), dtype=np.float64)
        k -= np.repeat((np.cumsum(nn) - nn).astype(np.float64), nn)
        k /= np.repeat(np.maximum(nn - 1, 1).astype(np.float64), nn)
        idx = np.zeros(len(k), dtype=np.int64)
        for a, size, stride in ((0, width, 1), (1, height, width)):  # idx = y * width + x
            v = np.repeat(ee[s0:s1, a], nn)
            v *= k
            v += np.repeat(pe[s0:s1, a], nn)
            np.rint(v, out=v)
            np.clip(v, 0, size - 1, out=v)
            idx += v.astype(np.int64) * stride
            del v
        del k
        m = free[idx]
        hit_idx.append(idx[m])
        hit_face.append(np.repeat(fe[s0:s1], nn)[m])
        del idx, m
    idx, f = np.concatenate(hit_idx), np.concatenate(hit_face)
    del hit_idx, hit_face
    u, first = np.unique(idx, return_index=True)
    return u, f[first].astype(np.int64)


def gutter_texels(idx: np.ndarray, face: np.ndarray, height: int, width: int,
                  reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Texels outside every face within ``reach`` texels of one, and the face of the nearest covered texel.

    Parameters
    ----------
    idx, face : (n,) int
        Covered texels (ascending flat indices) and their faces (:func:`rasterize_faces`).
    reach : float
        Largest Euclidean distance (texels) of a gutter texel from a covered one.

    Returns
    -------
    gidx : (m,) int64
        Flat canvas indices of the gutter texels.
    gface : (m,) int64
        The face of their nearest covered texel.
    """
    import cv2

    if reach <= 0 or len(idx) == 0 or len(idx) == height * width:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    free = np.ones(height * width, dtype=np.uint8)
    free[idx] = 0
    dist, lab = cv2.distanceTransformWithLabels(free.reshape(height, width), cv2.DIST_L2, 5,
                                                labelType=cv2.DIST_LABEL_PIXEL)
    near = dist <= reach + 1e-3
    del dist
    near &= free.reshape(height, width) > 0
    del free
    gidx = np.flatnonzero(near.reshape(-1))
    del near
    # labels enumerate the zero (covered) pixels in raster order, i.e. the ascending idx
    return gidx, np.asarray(face)[lab.reshape(-1)[gidx] - 1].astype(np.int64)


#: rows of canvas above and below a band that its gutters' distance transform reads (the labels of texels within
#: ``reach`` of a face depend on the texels within a few ``reach`` of them only: the whole-canvas values)
GUTTER_MARGIN = 32
#: rows of canvas per band of :func:`gutter_owner`
GUTTER_BAND_ROWS = 512


def gutter_owner(owner: np.ndarray, height: int, width: int, reach: float, *,
                 threads: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """:func:`gutter_texels` of an owner canvas, in row bands (on ``threads`` threads).

    Parameters
    ----------
    owner : (height * width,) int32
        -1 at free texels; any other value marks a covered texel: its face ``f`` (>= 0), or
        ``-2 - f`` (a texel given to face ``f`` otherwise, e.g. under a thin face's edge).
    reach : float
        Largest Euclidean distance (texels) of a gutter texel from a covered one.
    threads : int
        Bands computed side by side (OpenCV releases the GIL).

    Returns
    -------
    gidx : (m,) int64
        Flat canvas indices of the gutter texels, ascending.
    gface : (m,) int64
        The face of their nearest covered texel: what :func:`gutter_texels` gives on the whole
        canvas (its chamfer distances and labels, computed on each band with
        :data:`GUTTER_MARGIN` rows of context above and below, the same within ``reach``).
    """
    import cv2

    if reach <= 0 or height * width == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    if reach + 2 > GUTTER_MARGIN / 4:
        raise ValueError(f"gutter reach {reach} needs a margin over {GUTTER_MARGIN} rows")
    grid = owner.reshape(height, width)

    def band(r0: int) -> tuple[np.ndarray, np.ndarray]:
        r1 = min(height, r0 + GUTTER_BAND_ROWS)
        a, b = max(0, r0 - GUTTER_MARGIN), min(height, r1 + GUTTER_MARGIN)
        sub = grid[a:b]
        free = (sub == -1).view(np.uint8)
        if not free.any() or free.all():
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        dist, lab = cv2.distanceTransformWithLabels(free, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
        core = slice(r0 - a, r1 - a)
        near = dist[core] <= reach + 1e-3
        near &= free[core] > 0
        loc = np.flatnonzero(near.reshape(-1))
        codes = sub.reshape(-1)
        cov = codes[codes != -1]  # the covered texels in raster order: what the labels enumerate
        f = cov[lab[core].reshape(-1)[loc] - 1].astype(np.int64)
        f = np.where(f < -1, -2 - f, f)
        return loc + r0 * width, f

    parts = thread_map(band, range(0, height, GUTTER_BAND_ROWS), threads, name="o3d_seqcc-gutters")
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def _remap(img: np.ndarray, mx: np.ndarray, my: np.ndarray, interpolation: int) -> np.ndarray:
    import cv2

    return cv2.remap(img, mx, my, interpolation, borderMode=cv2.BORDER_REPLICATE)


def sample_image(image: np.ndarray, x: np.ndarray, y: np.ndarray, *, density: float) -> np.ndarray:
    """(n, 3) float32 colours (0-255 units) of ``image`` at pixel coordinates (x, y), pixel centres at integers.

    Lanczos interpolation (OpenCV's 8 x 8 ``INTER_LANCZOS4``), clamped to the range of the 2 x 2
    pixels around the point (no ringing: a value never leaves what bilinear interpolation could
    give, yet keeps the photo's contrast where bilinear would average it away). At a pixel centre
    the result is that pixel, exactly: on an atlas aligned with the photo at one texel per pixel
    (:mod:`~o3d_seqcc.texturing.packing`) the bake copies the photo. Below one texel per pixel
    (``density`` < 1, an atlas budget too small for the photos) the image is first area-averaged
    to the atlas resolution, so that a texel integrates its footprint instead of aliasing.
    Outside the image the border pixels are repeated.
    """
    import cv2

    img = image
    if density < 0.999:
        h, w = img.shape[:2]
        nw, nh = max(1, int(round(w * density))), max(1, int(round(h * density)))
        img = cv2.resize(img, (nw, nh), interpolation=cv2.INTER_AREA)
        x = (x + 0.5) * (nw / w) - 0.5
        y = (y + 0.5) * (nh / h) - 0.5
    n = len(x)
    out = np.empty((n, 3), dtype=np.float32)
    # points at a pixel centre, as OpenCV's remap sees them (to 1/32 px: round(32 x) in float32): INTER_LANCZOS4 is
    # then the pixel itself (its only non-zero weight), which the 2 x 2 range keeps: read directly
    X = np.rint(np.asarray(x, dtype=np.float32) * np.float32(32)).astype(np.int64)
    Y = np.rint(np.asarray(y, dtype=np.float32) * np.float32(32)).astype(np.int64)
    at = ((X | Y) & 31) == 0
    h, w = img.shape[:2]
    sel = np.flatnonzero(at)
    out[sel] = img[np.clip(Y[sel] >> 5, 0, h - 1), np.clip(X[sel] >> 5, 0, w - 1)]
    del X, Y, sel
    rest = np.flatnonzero(~at)
    if len(rest) < n:
        if len(rest):
            out[rest] = _sample_lanczos(img, np.asarray(x)[rest], np.asarray(y)[rest])
        return out
    return _sample_lanczos(img, x, y)


def _sample_lanczos(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """:func:`sample_image`'s Lanczos, clamped to the 2 x 2 neighbourhood's range, at every point (float32 (n, 3))."""
    import cv2

    n = len(x)
    cols = 4096
    # the 2 x 2 neighbourhood's range: min / max filters (anchored at the top-left pixel) read at the floor
    k = np.ones((2, 2), np.uint8)
    lo_img = cv2.erode(img, k, anchor=(0, 0), borderType=cv2.BORDER_REPLICATE)
    hi_img = cv2.dilate(img, k, anchor=(0, 0), borderType=cv2.BORDER_REPLICATE)
    out = np.empty((n, 3), dtype=np.float32)
    step = SAMPLE_CHUNK
    for a in range(0, max(n, 1), step):  # every point on its own: chunks only bound the temporaries
        m = min(n, a + step) - a
        rows = max(1, -(-m // cols))
        mx = np.zeros(rows * cols, np.float32)
        my = np.zeros(rows * cols, np.float32)
        mx[:m], my[:m] = x[a:a + m], y[a:a + m]
        mx, my = mx.reshape(rows, cols), my.reshape(rows, cols)
        o = out[a:a + m]
        o[:] = _remap(img, mx, my, cv2.INTER_LANCZOS4).reshape(-1, 3)[:m]
        fx, fy = np.floor(mx), np.floor(my)
        lo = _remap(lo_img, fx, fy, cv2.INTER_NEAREST).reshape(-1, 3)[:m].astype(np.float32)
        hi = _remap(hi_img, fx, fy, cv2.INTER_NEAREST).reshape(-1, 3)[:m].astype(np.float32)
        np.clip(o, lo, hi, out=o)
    return out


#: points sampled per step by :func:`sample_image` (a multiple of its 4096-point map rows)
SAMPLE_CHUNK = 1 << 21
