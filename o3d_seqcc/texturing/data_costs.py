"""How much a photo shows of a face: the data term of the view selection (issue 19).

After mvs-texturing's ``calculate_data_costs`` (Waechter et al. 2014), on the (colour-corrected)
photos and the sparse usable (view, face) incidences of a
:class:`~o3d_seqcc.visibility.Visibility`:

- :func:`face_view_statistics`: per incidence, the **GMI** (gradient magnitude integrated over
  the face's projection: the mean Sobel magnitude of the photo's luminance at the pixel centres
  inside the projected triangle, times its area in px^2; a face covering no pixel centre reads
  the magnitude at its centroid) and the face's mean colour in the photo. One task per view on
  local threads, each photo read once; the sums over a triangle are exact integer sums of a
  row-wise cumulative sum along its scanline spans (the pixels of
  :func:`~o3d_seqcc.texturing.bake.row_spans`), one channel at a time, so the cost is the number
  of projected rows, not pixels;
- the photometric outliers (:mod:`~o3d_seqcc.texturing.outliers`): per face, the views whose mean
  colour is far from the consensus of the others (the CIE Lab of the colours is converted in the
  view's task);
- :class:`ScoredVisibility`: a visibility whose usable incidences carry that quality and lack
  the outliers, what the selection methods read (:mod:`~o3d_seqcc.texturing.selection`).

Nothing here is dense in views x faces: every array is one entry per usable incidence.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any, NamedTuple, Sequence

import numpy as np

from ..errors import InputError
from ..imaging.arrays import img_as_float, img_as_uint8, sample_bilinear
from .outliers import colour_lab, photometric_outliers
from .settings import DATA_TERMS, OUTLIER_REMOVALS, TextureSettings

__all__ = ["DATA_TERMS", "OUTLIER_REMOVALS", "ScoredVisibility", "face_view_statistics", "gradient_magnitude",
           "photometric_outliers", "score_visibility"]

logger = logging.getLogger(__name__)


#: integer scale of the channels summed exactly in int32 (values in [0, 6) -> < 2^16 per pixel)
_QUANT = 10000.0
#: scanline spans (rows of projected triangles) handled per step by the data costs
SPAN_ROWS = 1 << 19
#: rows of a photo converted to float and grey at a time
GREY_ROWS = 256


def _grey(image: np.ndarray) -> np.ndarray:
    """(H, W) float32 luminance (OpenCV's RGB -> grey) of an RGB image, float32 in [0, 1] or any dtype."""
    import cv2

    img = np.asarray(image)
    img = img if img.dtype == np.float32 else img_as_float(img).astype(np.float32)
    return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img


def _sobel_magnitude(grey: np.ndarray) -> np.ndarray:
    """(H, W) float32 Sobel gradient magnitude over 8 of a float32 grey image (see :func:`gradient_magnitude`)."""
    import cv2

    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3, borderType=cv2.BORDER_REPLICATE)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3, borderType=cv2.BORDER_REPLICATE)
    # numpy, not cv2.magnitude: OpenCV's SIMD rows fuse the multiply-add and its scalar row tails do not, and its
    # threads split the rows differently from call to call: the last bit of a few texels changed between runs
    np.multiply(gx, gx, out=gx)
    np.multiply(gy, gy, out=gy)
    gx += gy
    del gy
    np.sqrt(gx, out=gx)
    gx /= np.float32(8.0)
    return gx


def gradient_magnitude(image: np.ndarray) -> np.ndarray:
    """(H, W) float32 Sobel gradient magnitude of the luminance of an RGB image scaled to [0, 1].

    The 3 x 3 Sobel operator (borders replicated) over 8 (its weights' sum), so a step of height
    1 reads about 1.
    """
    return _sobel_magnitude(_grey(image))


#: every uint8 level as a float32 in [0, 1] (level / 255 in float32, as the data costs scale their photos)
_UNIT = np.arange(256, dtype=np.float32) / np.float32(255.0)


def _level_magnitude(image: np.ndarray) -> np.ndarray:
    """:func:`gradient_magnitude` of an (H, W, 3) uint8 photo as ``image.astype(float32) / 255``, without that
    float copy: the grey image is made :data:`GREY_ROWS` rows at a time (OpenCV converts row by row, so the
    pixels are the whole image's), and freed before the Sobel magnitude is complete."""
    import cv2

    grey = np.empty(image.shape[:2], dtype=np.float32)
    for r in range(0, len(grey), GREY_ROWS):
        f = image[r:r + GREY_ROWS].astype(np.float32)
        f /= np.float32(255.0)
        cv2.cvtColor(f, cv2.COLOR_RGB2GRAY, dst=grey[r:r + GREY_ROWS])
    return _sobel_magnitude(grey)


def _sample_levels(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(n, 3) ``sample_bilinear(image.astype(float32) / 255, x, y)`` of an (H, W, 3) uint8 photo, from its levels
    (:data:`_UNIT`): the same arithmetic at the four corners, without the float copy of the photo."""
    h, w = image.shape[:2]
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, w - 1.0)
    y = np.clip(np.asarray(y, dtype=np.float64), 0.0, h - 1.0)
    x0, y0 = np.floor(x).astype(np.intp), np.floor(y).astype(np.intp)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]

    def at(yy: np.ndarray, xx: np.ndarray) -> np.ndarray:
        return _UNIT[image[yy, xx]].astype(np.float64)

    top = at(y0, x0) * (1.0 - fx) + at(y0, x1) * fx
    bot = at(y1, x0) * (1.0 - fx) + at(y1, x1) * fx
    return top * (1.0 - fy) + bot * fy


class _Spans(NamedTuple):
    """The pixel centres inside k triangles, one scanline span per (triangle, row).

    ``tri`` (t,) the triangles with rows, in the order of their spans; ``offsets`` (t,) the first
    span of each; ``start`` / ``stop`` (rows,) int64 flat indices ``y * (W + 1) + x`` of a span's
    ends in a row-wise cumulative sum with a leading zero column (``start == stop``: empty);
    ``count`` (k,) int64 pixel centres per triangle.
    """

    tri: np.ndarray
    offsets: np.ndarray
    start: np.ndarray
    stop: np.ndarray
    count: np.ndarray


def _spans(tri: np.ndarray, height: int, width: int, *, chunk: int = SPAN_ROWS) -> _Spans:
    """The spans of :func:`~o3d_seqcc.texturing.bake.row_spans` (the same arithmetic per row: the same
    pixels), without its barycentric rows. Each edge of a triangle bounds its rows on the left
    (``A_i > 1e-15``), on the right (``A_i < -1e-15``) or is flat (a test per row); the triangles
    are handled in groups of one pattern of the three, so that a row computes its own bounds only.

    Parameters
    ----------
    tri : (k, 3, 2) float64
        Triangles in pixel coordinates (x right, y down, centres at integers).
    height, width : int
        Image size (spans are clipped to it).
    chunk : int
        Rows handled per step (bounds the per-row float64 temporaries).
    """
    p = np.asarray(tri, dtype=np.float64)
    ax, ay, bx, by, cx, cy = p[:, 0, 0], p[:, 0, 1], p[:, 1, 0], p[:, 1, 1], p[:, 2, 0], p[:, 2, 1]
    d = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)  # bake._area2 / _edge_functions, term for term
    ok = np.abs(d) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, d, 1.0), 0.0)
    A = ((by - cy) * inv, (cy - ay) * inv, (ay - by) * inv)
    B = ((cx - bx) * inv, (ax - cx) * inv, (bx - ax) * inv)
    C = ((bx * cy - cx * by) * inv, (cx * ay - ax * cy) * inv, (ax * by - bx * ay) * inv)
    y0 = np.maximum(np.ceil(np.minimum(np.minimum(ay, by), cy) - 1e-9), 0).astype(np.int64)
    y1 = np.minimum(np.floor(np.maximum(np.maximum(ay, by), cy) + 1e-9), height - 1).astype(np.int64)
    xlo = np.maximum(np.minimum(np.minimum(ax, bx), cx) - 1e-9, 0.0)
    xhi = np.minimum(np.maximum(np.maximum(ax, bx), cx) + 1e-9, width - 1.0)
    ny = np.where(ok, np.maximum(y1 - y0 + 1, 0), 0)
    has = np.flatnonzero(ny > 0)
    # the kind of every edge: 0 left bound, 1 right bound, 2 flat, 3 NaN (no effect, as in row_spans)
    code = np.zeros(len(has), dtype=np.uint8)
    for j in range(3):
        a = A[j][has]
        kind = (a < -1e-15).view(np.uint8) + 2 * (np.abs(a) <= 1e-15).view(np.uint8) + 3 * np.isnan(a).view(np.uint8)
        code += kind << (2 * j)
    order = has[np.argsort(code, kind="stable")]  # the triangles grouped by the kinds of their edges (a radix sort)
    bounds = np.cumsum(np.bincount(code, minlength=64))
    total = int(ny[has].sum())
    tri_of, offsets, count_of = np.empty(len(has), np.int64), np.empty(len(has), np.int64), np.empty(len(has), np.int64)
    start, stop = np.empty(total, np.int64), np.empty(total, np.int64)
    eps = 1e-7
    done = done_t = 0
    for cd in np.flatnonzero(np.diff(bounds, prepend=0)).tolist():
        group = order[(bounds[cd - 1] if cd else 0):bounds[cd]]
        kinds = [(cd >> (2 * j)) & 3 for j in range(3)]
        ends = np.cumsum(ny[group])
        lo_t = 0
        while lo_t < len(group):
            base = ends[lo_t - 1] if lo_t else 0
            hi_t = max(int(np.searchsorted(ends, base + chunk, side="right")), lo_t + 1)
            t = group[lo_t:hi_t]
            nyt = ny[t]
            first = np.cumsum(nyt) - nyt
            rows = int(first[-1] + nyt[-1])
            k = np.zeros(rows, dtype=np.intp)  # the triangle (in t) of every span: gathers, not np.repeat (slow)
            k[first[1:]] = 1
            np.cumsum(k, out=k)
            yi = (y0[t] - first)[k] + np.arange(rows)  # the row of every span
            y = yi.astype(np.float64)

            def r(j: int) -> np.ndarray:
                return B[j][t][k] * y + C[j][t][k]

            lo = xlo[t][k]
            hi = xhi[t][k]
            for j in range(3):
                if kinds[j] < 2:
                    bound = (-eps - r(j)) / A[j][t][k]
                    (np.maximum if kinds[j] == 0 else np.minimum)(lo if kinds[j] == 0 else hi, bound,
                                                                   out=lo if kinds[j] == 0 else hi)
            xs = np.ceil(lo).astype(np.int64)
            n = np.floor(hi).astype(np.int64) - xs + 1
            np.maximum(n, 0, out=n)
            for j in range(3):
                if kinds[j] == 2:
                    n[r(j) < -eps] = 0
            xs[n == 0] = 0
            sl = slice(done, done + rows)
            np.multiply(yi, width + 1, out=start[sl])
            start[sl] += xs
            np.add(start[sl], n, out=stop[sl])
            ts = slice(done_t, done_t + len(t))
            tri_of[ts], offsets[ts], count_of[ts] = t, first + done, np.add.reduceat(n, first)
            done += rows
            done_t += len(t)
            lo_t = hi_t
    count = np.zeros(len(p), dtype=np.int64)
    count[tri_of] = count_of
    return _Spans(tri_of, offsets, start, stop, count)


def _span_sums(spans: _Spans, q: np.ndarray) -> np.ndarray:
    """(k,) int64 exact sums of an (H, W) int32 channel over the spans of every triangle."""
    h, w = q.shape
    cum = np.zeros((h, w + 1), dtype=np.int32)
    np.cumsum(q, axis=1, dtype=np.int32, out=cum[:, 1:])  # row sums <= 6e4 x W: exact for W < 35k
    del q
    cum = cum.reshape(-1)
    out = np.zeros(len(spans.count), dtype=np.int64)
    if len(spans.tri):
        seg = cum[spans.stop] - cum[spans.start]
        out[spans.tri] = np.add.reduceat(seg, spans.offsets, dtype=np.int64)
    return out


def _quantise(x: np.ndarray) -> np.ndarray:
    """float32 values clipped to [0, 6] as int32 multiples of 1 / :data:`_QUANT` (rounded); ``x`` is overwritten."""
    np.clip(x, 0.0, 6.0, out=x)
    x *= _QUANT
    np.rint(x, out=x)
    return x.astype(np.int32)


#: the quantised value of every uint8 level
_LEVELS = _quantise(_UNIT.copy())


def _view_means(image: np.ndarray, tri: np.ndarray, *, gmi: bool, colour: bool
                ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Mean gradient magnitude and mean RGB of one photo over the pixel centres inside each projected triangle.

    Parameters
    ----------
    image : (H, W, 3) uint8
    tri : (k, 3, 2) float64
        The triangles in pixel coordinates.

    Returns
    -------
    gmi : (k,) float64 or None
        Mean Sobel magnitude of the photo as float32 / 255 (:func:`gradient_magnitude`).
    colour : (k, 3) float64 or None
        Mean RGB in [0, 1].

    Every channel is quantised to int32 multiples of 1 / :data:`_QUANT` and summed exactly along the
    spans (:func:`_span_sums`); a triangle covering no pixel centre reads its centroid (bilinear). One
    (H, W) channel and its cumulative sum are alive at a time; the photo is never copied as float.
    """
    h, w = image.shape[:2]
    spans = _spans(tri, h, w)
    denom = _QUANT * np.maximum(spans.count, 1)
    empty = spans.count == 0
    cen = tri[empty].mean(axis=1) if empty.any() else None
    g = c = None
    if gmi:
        mag = _level_magnitude(image)
        at_centre = sample_bilinear(mag, cen[:, 0], cen[:, 1]) if cen is not None else None
        g = _span_sums(spans, _quantise(mag)) / denom
        del mag
        if cen is not None:
            g[empty] = at_centre
    if colour:
        import cv2

        c = np.empty((len(tri), 3))
        for j in range(3):  # OpenCV's table lookup: a third of numpy's gather from the strided channel
            c[:, j] = _span_sums(spans, cv2.LUT(np.ascontiguousarray(image[..., j]), _LEVELS)) / denom
        if cen is not None:
            c[empty] = _sample_levels(image, cen[:, 0], cen[:, 1])
    return g, c


class _Statistics(NamedTuple):
    """What :func:`_statistics` computed for every usable incidence (None where not asked for)."""

    gmi: np.ndarray | None  # (nnz,) float64
    colour: np.ndarray | None  # (nnz, 3) float32
    lab: np.ndarray | None  # (nnz, 3) float64


def _statistics(visibility: Any, images: Sequence[np.ndarray], indptr: np.ndarray, faces: np.ndarray,
                area: np.ndarray, *, gmi: bool, colour: bool, lab: bool) -> _Statistics:
    """GMI, mean colour and the colour's CIE Lab of every usable incidence (:func:`face_view_statistics`).

    ``colour`` keeps the float32 colours (the Gaussian outlier tests), ``lab`` their CIE Lab
    (:func:`~o3d_seqcc.texturing.outliers.colour_lab`: the median test), converted in each view's task.
    """
    from .._shared.parallel import LocalExecutor

    nnz = len(faces)
    out_g = np.zeros(nnz) if gmi else None
    out_c = np.zeros((nnz, 3), dtype=np.float32) if colour else None
    out_l = np.zeros((nnz, 3)) if lab else None
    mesh_faces = np.asarray(visibility.mesh.faces)

    def one(v: int) -> None:
        # each view writes its own slice of the outputs: the same numbers for any number of threads
        a, b = int(indptr[v]), int(indptr[v + 1])
        img = img_as_uint8(images[v], where=f"image of view {v}")
        fs = np.asarray(faces[a:b], dtype=np.int64)
        tri = visibility.vertex_uv(v, mesh_faces[fs].reshape(-1)).reshape(-1, 3, 2).astype(np.float64)
        mg, mc = _view_means(img, tri, gmi=gmi, colour=colour or lab)
        del img
        if gmi:
            out_g[a:b] = mg * np.nan_to_num(np.asarray(area[a:b], dtype=np.float64), nan=0.0)
        if colour or lab:
            mc = mc.astype(np.float32)
            if colour:
                out_c[a:b] = mc
            if lab:
                out_l[a:b] = colour_lab(mc)

    # one task per view with incidences, on local threads (OpenCV's filters and numpy's sums, gathers and sorts
    # release the GIL): the images are read by the tasks, at most one per thread at a time
    views = [v for v in range(len(indptr) - 1) if indptr[v + 1] > indptr[v]]
    LocalExecutor().map(one, views, desc="data costs", unit="view")
    return _Statistics(out_g, out_c, out_l)


def face_view_statistics(visibility: Any, images: Sequence[np.ndarray], indptr: np.ndarray, faces: np.ndarray,
                         area: np.ndarray, *, gmi: bool = True, colour: bool = False
                         ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """GMI and mean colour of every usable incidence (see the module docstring).

    Parameters
    ----------
    visibility : Visibility
        ``vertex_uv(v, ids)`` and ``mesh.faces``.
    images : sequence of (H_v, W_v, 3) arrays
        One per view (the corrected photos), uint8 / uint16 / float in [0, 1]; ``images[v]`` is
        read once, for the views with incidences only.
    indptr, faces, area : arrays
        The usable incidences, view-major (``usable_entries()``): (V+1,), (nnz,), (nnz,) px^2.
    gmi, colour : bool
        What to compute.

    Returns
    -------
    gmi : (nnz,) float64 or None
        Mean gradient magnitude x projected area.
    colour : (nnz, 3) float32 or None
        Mean RGB in [0, 1].
    """
    st = _statistics(visibility, images, indptr, faces, area, gmi=gmi, colour=colour, lab=False)
    return st.gmi, st.colour


@dataclass(frozen=True, eq=False)
class ScoredVisibility:
    """A visibility whose usable incidences carry a quality and lack the photometric outliers.

    Read by the selection methods through ``usable_entries()`` (the kept incidences, view-major)
    and ``entry_quality`` (aligned with them); ``mesh``, ``n_views``, ``n_faces`` and
    ``face_uv`` are the underlying visibility's.
    """

    visibility: Any
    indptr: np.ndarray
    faces: np.ndarray
    area: np.ndarray
    cos_angle: np.ndarray
    entry_quality: np.ndarray
    data_term: str
    stats: dict = field(default_factory=dict)

    @property
    def mesh(self) -> Any:
        return self.visibility.mesh

    @property
    def n_views(self) -> int:
        return int(self.visibility.n_views)

    @property
    def n_faces(self) -> int:
        return int(self.visibility.n_faces)

    def usable_entries(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self.indptr, self.faces, self.area, self.cos_angle

    def usable_counts(self) -> np.ndarray:
        return np.diff(self.indptr)

    def usable_faces(self, v: int) -> np.ndarray:
        return self.faces[self.indptr[v]:self.indptr[v + 1]].astype(np.int64)

    def usable_area(self, v: int) -> np.ndarray:
        return np.asarray(self.area[self.indptr[v]:self.indptr[v + 1]], np.float32)

    def vertex_projection(self, v: int, vertex_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.visibility.vertex_projection(v, vertex_ids)

    def face_uv(self, selection: np.ndarray) -> np.ndarray:
        return self.visibility.face_uv(selection)

    def to_dense(self, *, projections: bool = True):
        """The kept incidences as dense arrays (``valid = usable``; tests and figures only)."""
        from ..visibility.dense import DenseVisibility

        V, F = self.n_views, self.n_faces
        view = np.repeat(np.arange(V), np.diff(self.indptr))
        usable = np.zeros((V, F), bool)
        usable[view, self.faces] = True
        area, cos = np.zeros((V, F), np.float32), np.zeros((V, F), np.float32)
        area[view, self.faces], cos[view, self.faces] = self.area, self.cos_angle
        base = self.visibility.to_dense(projections=projections)
        no = np.zeros((V, F), bool)
        return DenseVisibility(valid=usable, occluded=no, depth_inconsistent=no, oblique=no, usable=usable, area=area,
                               cos_angle=cos, uv=base.uv, depth=base.depth)


def score_visibility(visibility: Any, images: Sequence[np.ndarray] | None, *, data_term: str = TextureSettings.data_term,
                     outlier_removal: str = "none") -> ScoredVisibility:
    """The usable incidences of ``visibility`` with their quality (``data_term``) and without outliers.

    Parameters
    ----------
    visibility : Visibility
        ``usable_entries()``, ``vertex_uv``, ``mesh``.
    images : sequence of (H, W, 3) arrays or None
        The (corrected) photos, one per view; needed for ``"gmi"`` and outlier removal.
    data_term : {"area", "area-cos", "gmi"}
        Quality of an incidence: projected area (px^2), area x cosine of the viewing angle, or
        GMI (:func:`face_view_statistics`).
    outlier_removal : {"none", "median", "gauss-clamping", "gauss-damping"}

    Returns
    -------
    ScoredVisibility
        ``stats``: the data term, outlier-removal counts and time.

    Raises
    ------
    InputError
        ``images`` missing where needed, or not one per view.
    ValueError
        Unknown data term or outlier removal (the message lists the valid ones).
    """
    if data_term not in DATA_TERMS:
        raise ValueError(f"unknown data_term {data_term!r}; valid: {', '.join(map(repr, DATA_TERMS))}")
    if outlier_removal not in OUTLIER_REMOVALS:
        raise ValueError(f"unknown outlier_removal {outlier_removal!r}; valid: {', '.join(map(repr, OUTLIER_REMOVALS))}")
    need = data_term == "gmi" or outlier_removal != "none"
    if need and images is None:
        raise InputError(f"data_term={data_term!r} / outlier_removal={outlier_removal!r} read the photos: pass images= "
                         "(one per view), or use data_term='area' and outlier_removal='none'")
    if need and len(images) != visibility.n_views:
        raise InputError(f"{len(images)} images given for {visibility.n_views} views")
    t = time.perf_counter()
    indptr, faces, area, cos = visibility.usable_entries()
    median = outlier_removal == "median"
    st = (_statistics(visibility, images, indptr, faces, area, gmi=data_term == "gmi",
                      colour=outlier_removal != "none" and not median, lab=median) if need else None)
    if data_term == "gmi":
        quality = st.gmi
    else:
        quality = np.nan_to_num(np.asarray(area, dtype=np.float64), nan=0.0)
        if data_term == "area-cos":
            quality *= np.clip(np.nan_to_num(np.asarray(cos, dtype=np.float64)), 0.0, 1.0)
    stats: dict[str, Any] = {"data_term": data_term, "outlier_removal": outlier_removal}
    if outlier_removal != "none":
        weight, ost = photometric_outliers(faces, st.colour, method=outlier_removal, lab=st.lab)
        del st
        stats.update(ost)
        quality *= weight
        keep = weight > 0
        if not keep.all():
            kept_before = np.concatenate([[0], np.cumsum(keep)])
            indptr = kept_before[indptr]  # the kept incidences before each view's first
            faces, area, cos, quality = faces[keep], area[keep], cos[keep], quality[keep]
        logger.info("outlier removal (%s): %d of %d faces tested, %d views dropped on %d faces", outlier_removal,
                    ost["faces_tested"], visibility.n_faces, ost["incidences_dropped"], ost["faces_with_outliers"])
    stats["time_s"] = time.perf_counter() - t
    return ScoredVisibility(visibility=visibility, indptr=np.asarray(indptr, np.int64), faces=faces, area=area,
                            cos_angle=cos, entry_quality=np.asarray(quality, dtype=np.float64), data_term=data_term,
                            stats=stats)
