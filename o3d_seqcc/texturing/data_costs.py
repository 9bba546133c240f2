"""How much a photo shows of a face: the data term of the view selection, photometric outliers (issue 19).

After mvs-texturing's ``calculate_data_costs`` (Waechter et al. 2014), on the (colour-corrected)
photos and the sparse usable (view, face) incidences of a
:class:`~o3d_seqcc.visibility.Visibility`:

- :func:`face_view_statistics`: per incidence, the **GMI** (gradient magnitude integrated over
  the face's projection: the mean Sobel magnitude of the photo's luminance at the pixel centres
  inside the projected triangle, times its area in px^2; a face covering no pixel centre reads
  the magnitude at its centroid) and the face's mean colour in the photo. One pass over the views,
  each photo read once; the sums over a triangle are differences of row-wise cumulative sums
  along its scanline spans (:func:`~o3d_seqcc.texturing.bake.row_spans`), so the cost is the
  number of projected rows, not pixels;
- :func:`photometric_outliers`: per face, the views whose mean colour is far from the
  consensus of the others, so that a pedestrian or a car the mesh does not hold, seen in one or
  two photos, does not texture the wall behind it: ``"median"`` (robust: the distance to the
  per-channel median of the face's CIE Lab colours) or texrecon's ``--outlier_removal`` (an
  iterated multivariate Gaussian of the faces' YCbCr colours; ``"gauss-clamping"`` drops the
  views below its rejection threshold, ``"gauss-damping"`` scales their quality by the
  Gaussian). Vectorised over all faces at once (segment sums and sorts over the incidences);
- :class:`ScoredVisibility`: a visibility whose usable incidences carry that quality and lack
  the outliers, what the selection methods read (:mod:`~o3d_seqcc.texturing.selection`).

Nothing here is dense in views x faces: every array is one entry per usable incidence.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..errors import InputError
from ..imaging.arrays import img_as_float, img_as_uint8, rgb_to_lab, sample_bilinear
from .bake import row_spans
from .settings import DATA_TERMS, OUTLIER_REMOVALS, TextureSettings

__all__ = ["DATA_TERMS", "OUTLIER_REMOVALS", "ScoredVisibility", "face_view_statistics", "gradient_magnitude",
           "photometric_outliers", "score_visibility"]

logger = logging.getLogger(__name__)


#: texrecon's constants: rejection threshold of the unnormalised Gaussian, covariance below which
#: the iteration stops, iterations, fewest inliers for a face to be tested
GAUSS_REJECTION = 6e-3
MIN_COVARIANCE = 5e-4
OUTLIER_ITERATIONS = 10
MIN_INLIERS = 4
#: gauss-damping widens the final Gaussian by 1 / this (texrecon's 0.2)
DAMPING_FACTOR = 0.2
#: "median": a view's colour of a face is an outlier beyond this CIE Lab distance from the median of its views ...
MEDIAN_MIN_DELTA_E = 20.0
#: ... and beyond this many times the face's median distance
MEDIAN_MAD_FACTOR = 3.0
#: integer scale of the channels summed exactly in int32 (values in [0, 6) -> < 2^16 per pixel)
_QUANT = 10000.0


def gradient_magnitude(image: np.ndarray) -> np.ndarray:
    """(H, W) float32 Sobel gradient magnitude of the luminance of an RGB image scaled to [0, 1].

    The 3 x 3 Sobel operator (borders replicated) over 8 (its weights' sum), so a step of height
    1 reads about 1.
    """
    import cv2

    img = np.asarray(image)
    img = img if img.dtype == np.float32 else img_as_float(img).astype(np.float32)
    grey = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3, borderType=cv2.BORDER_REPLICATE)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3, borderType=cv2.BORDER_REPLICATE)
    # numpy, not cv2.magnitude: OpenCV's SIMD rows fuse the multiply-add and its scalar row tails do not, and its
    # threads split the rows differently from call to call: the last bit of a few texels changed between runs
    mag = np.multiply(gx, gx)
    mag += gy * gy
    return np.sqrt(mag, out=mag) / np.float32(8.0)


def _triangle_means(tri: np.ndarray, channels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean of (H, W, C) float32 ``channels`` (values in [0, 6)) over the pixel centres inside each
    (n, 3, 2) triangle, and their number; triangles covering no centre read their centroid (bilinear)."""
    h, w, c = channels.shape
    q = np.rint(np.clip(channels, 0.0, 6.0) * _QUANT).astype(np.int32)
    cum = np.zeros((h, w + 1, c), dtype=np.int32)
    np.cumsum(q, axis=1, out=cum[:, 1:])  # row sums <= 6e4 x W: exact for W < 35k
    del q
    sums = np.zeros((len(tri), c), dtype=np.int64)
    count = np.zeros(len(tri), dtype=np.int64)
    for k, y, xs, n, _, _ in row_spans(tri, h, w):
        m = n > 0
        k, yy, x0, x1 = k[m], y[m].astype(np.int64), xs[m], xs[m] + n[m]
        seg = cum[yy, x1].astype(np.int64) - cum[yy, x0]  # (rows, C) exact sums over the spans
        for j in range(c):
            sums[:, j] += np.bincount(k, weights=seg[:, j], minlength=len(tri)).astype(np.int64)
        count += np.bincount(k, weights=n[m], minlength=len(tri)).astype(np.int64)
    mean = sums / (_QUANT * np.maximum(count, 1))[:, None]
    empty = count == 0
    if empty.any():
        cen = tri[empty].mean(axis=1)
        mean[empty] = sample_bilinear(channels, cen[:, 0], cen[:, 1]).reshape(-1, c)
    return mean, count


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
    from .._shared.parallel import LocalExecutor

    nnz = len(faces)
    out_g = np.zeros(nnz) if gmi else None
    out_c = np.zeros((nnz, 3), dtype=np.float32) if colour else None
    mesh_faces = np.asarray(visibility.mesh.faces)

    def one(v: int) -> None:
        # each view writes its own slice of the outputs: the same numbers for any number of threads
        a, b = int(indptr[v]), int(indptr[v + 1])
        img = img_as_uint8(images[v], where=f"image of view {v}").astype(np.float32) / np.float32(255.0)
        fs = np.asarray(faces[a:b], dtype=np.int64)
        tri = visibility.vertex_uv(v, mesh_faces[fs].reshape(-1)).reshape(-1, 3, 2).astype(np.float64)
        parts = ([gradient_magnitude(img)[..., None]] if gmi else []) + ([img[..., :3]] if colour else [])
        del img
        mean, _ = _triangle_means(tri, np.concatenate(parts, axis=2) if len(parts) > 1 else parts[0])
        if gmi:
            out_g[a:b] = mean[:, 0] * np.asarray(area[a:b], dtype=np.float64)
        if colour:
            out_c[a:b] = mean[:, 1 if gmi else 0:]

    # one task per view with incidences, on local threads (OpenCV's filters and numpy's cumulative sums and
    # bincounts release the GIL): the images are read by the tasks, at most one per thread at a time
    views = [v for v in range(len(indptr) - 1) if indptr[v + 1] > indptr[v]]
    LocalExecutor().map(one, views, desc="data costs", unit="view")
    return out_g, out_c


def _rgb_to_ycbcr(rgb: np.ndarray) -> np.ndarray:
    """(n, 3) RGB in [0, 1] -> YCbCr (ITU-R BT.601, full range, in [0, 1])."""
    m = np.array([[0.299, 0.587, 0.114], [-0.168736, -0.331264, 0.5], [0.5, -0.418688, -0.081312]])
    return rgb @ m.T + [0.0, 0.5, 0.5]


def _moments(x: np.ndarray, w: np.ndarray, seg: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Weighted sums per segment of (m, 3) ``x`` -> (n, 3) and of its outer products -> (n, 3, 3)."""
    s1 = np.stack([np.bincount(seg, weights=x[:, i] * w, minlength=n) for i in range(3)], axis=1)
    s2 = np.zeros((n, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            s2[:, i, j] = s2[:, j, i] = np.bincount(seg, weights=x[:, i] * x[:, j] * w, minlength=n)
    return s1, s2


def _mahalanobis2(d: np.ndarray, inv: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """``d_k^T inv[seg_k] d_k`` for (m, 3) ``d`` without an (m, 3, 3) gather."""
    out = np.zeros(len(d))
    for i in range(3):
        for j in range(3):
            out += inv[seg, i, j] * d[:, i] * d[:, j]
    return out


def _median_outliers(seg: np.ndarray, lab: np.ndarray, nf: int) -> np.ndarray:
    """Incidences whose Lab colour is more than max(:data:`MEDIAN_MIN_DELTA_E`, :data:`MEDIAN_MAD_FACTOR`
    x the face's median distance) from the per-channel median of the face's views (faces of >= 3 views)."""
    m = len(seg)
    order = np.lexsort((np.arange(m), seg))
    s = seg[order]
    start = np.r_[0, np.flatnonzero(s[1:] != s[:-1]) + 1]
    n = np.diff(np.r_[start, m])
    med = np.zeros((nf, 3))
    for c in range(3):  # per-channel medians: sort within faces, average the middle one or two
        o = np.lexsort((lab[order, c], s))
        vals = lab[order, c][o]
        lo = start + (n - 1) // 2
        hi = start + n // 2
        med[s[start], c] = 0.5 * (vals[lo] + vals[hi])
    d = np.linalg.norm(lab - med[seg], axis=1)
    dmed = np.zeros(nf)
    o = np.lexsort((d[order], s))
    dv = d[order][o]
    dmed[s[start]] = 0.5 * (dv[start + (n - 1) // 2] + dv[start + n // 2])
    many = np.zeros(nf, dtype=bool)
    many[s[start]] = n >= 3
    return many[seg] & (d > np.maximum(MEDIAN_MIN_DELTA_E, MEDIAN_MAD_FACTOR * dmed[seg]))


def photometric_outliers(face: np.ndarray, colour: np.ndarray, *, method: str = "median"
                         ) -> tuple[np.ndarray, dict[str, Any]]:
    """Per-incidence weight from the consensus of each face's colours (texrecon's outlier removal).

    ``"median"``: per face seen by at least 3 views, the per-channel median of their CIE Lab
    colours is the consensus, and a view is dropped when its colour is more than
    :data:`MEDIAN_MIN_DELTA_E` from it and more than :data:`MEDIAN_MAD_FACTOR` times the face's
    median distance (robust: a passer-by in 2 of 5 photos is dropped, where the Gaussian of all
    five is wide enough to keep it).

    texrecon's ``"gauss-clamping"`` / ``"gauss-damping"``: per face with at least
    :data:`MIN_INLIERS` views: starting from all of them, the inliers'
    mean and covariance (YCbCr) define an unnormalised Gaussian; the views where it is at least
    :data:`GAUSS_REJECTION` are the next inliers; :data:`OUTLIER_ITERATIONS` times, stopping
    early when fewer than :data:`MIN_INLIERS` remain or the covariance is singular (the face is
    left as it is) or when every covariance entry is below :data:`MIN_COVARIANCE` (the
    non-inliers are dropped). Then ``"gauss-clamping"`` drops the views below the threshold and
    ``"gauss-damping"`` multiplies each view's quality by the Gaussian widened by
    1 / :data:`DAMPING_FACTOR`. The sample covariance bounds a view's squared Mahalanobis
    distance by (n - 1)^2 / n, so with fewer than 12 views (threshold 2 ln(1 / 6e-3) = 10.2) not
    even a single outlier is found: the reason for ``"median"``.

    Parameters
    ----------
    face : (m,) int
        Face of every incidence.
    colour : (m, 3) float
        Mean RGB in [0, 1] of the face in the incidence's view.
    method : {"median", "gauss-clamping", "gauss-damping"}

    Returns
    -------
    weight : (m,) float64
        0 = drop, else the factor on the quality (1 for clamping's inliers).
    stats : dict
        ``faces_tested``, ``incidences_dropped``, ``faces_with_outliers``.
    """
    if method not in OUTLIER_REMOVALS or method == "none":
        raise ValueError(f"unknown outlier removal {method!r}; valid: "
                         f"{', '.join(repr(m) for m in OUTLIER_REMOVALS if m != 'none')}")
    face = np.asarray(face, dtype=np.int64)
    m = len(face)
    weight = np.ones(m)
    if m == 0:
        return weight, {"faces_tested": 0, "incidences_dropped": 0, "faces_with_outliers": 0}
    _, seg = np.unique(face, return_inverse=True)
    seg = seg.reshape(-1)
    nf = int(seg.max()) + 1
    if method == "median":
        drop = _median_outliers(seg, rgb_to_lab(np.clip(np.asarray(colour, dtype=np.float64), 0.0, 1.0)), nf)
        weight[drop] = 0.0
        return weight, {"faces_tested": int(np.count_nonzero(np.bincount(seg, minlength=nf) >= 3)),
                        "incidences_dropped": int(drop.sum()),
                        "faces_with_outliers": int(len(np.unique(seg[drop]))) if drop.any() else 0}
    x = _rgb_to_ycbcr(np.asarray(colour, dtype=np.float64))
    inl = np.ones(m, dtype=bool)
    active = np.bincount(seg, minlength=nf) >= MIN_INLIERS  # faces still iterating
    tested = active.copy()
    final = np.zeros(nf, dtype=bool)  # faces whose result is decided by the final Gaussian
    drop = np.zeros(m, dtype=bool)
    mean = np.zeros((nf, 3))
    inv = np.zeros((nf, 3, 3))
    for it in range(OUTLIER_ITERATIONS):
        w = (inl & active[seg]).astype(np.float64)
        cnt = np.bincount(seg, weights=w, minlength=nf)
        active &= cnt >= MIN_INLIERS
        if not active.any():
            break
        s1, s2 = _moments(x, w, seg, nf)
        n_ = np.maximum(cnt, 2.0)
        mu = s1 / n_[:, None]
        cov = (s2 - n_[:, None, None] * mu[:, :, None] * mu[:, None, :]) / (n_ - 1.0)[:, None, None]
        small = active & (np.abs(cov).reshape(nf, 9).max(axis=1) < MIN_COVARIANCE)
        drop |= small[seg] & ~inl  # converged: keep only the inliers
        active &= ~small
        det = np.linalg.det(cov)
        scale = np.abs(cov).reshape(nf, 9).max(axis=1)
        singular = active & ~(np.abs(det) > 1e-12 * np.maximum(scale, 1e-300) ** 3)
        active &= ~singular
        ok = np.flatnonzero(active)
        mean[ok] = mu[ok]
        inv[ok] = np.linalg.inv(cov[ok])
        g = np.exp(-0.5 * _mahalanobis2(x - mean[seg], inv, seg))
        upd = active[seg]
        inl = np.where(upd, g >= GAUSS_REJECTION, inl)
        if it == OUTLIER_ITERATIONS - 1:
            final = active.copy()
    if final.any():
        sel = final[seg]
        factor = 1.0 if method == "gauss-clamping" else DAMPING_FACTOR
        g = np.exp(-0.5 * factor * _mahalanobis2(x[sel] - mean[seg[sel]], inv, seg[sel]))
        if method == "gauss-clamping":
            drop[np.flatnonzero(sel)[g < GAUSS_REJECTION]] = True
        else:
            weight[sel] = g
    weight[drop] = 0.0
    stats = {"faces_tested": int(tested.sum()), "incidences_dropped": int(drop.sum()),
             "faces_with_outliers": int(len(np.unique(seg[drop]))) if drop.any() else 0}
    return weight, stats


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
    area64 = np.nan_to_num(np.asarray(area, dtype=np.float64), nan=0.0)
    gmi, colour = (face_view_statistics(visibility, images, indptr, faces, area64, gmi=data_term == "gmi",
                                        colour=outlier_removal != "none") if need else (None, None))
    if data_term == "gmi":
        quality = gmi
    elif data_term == "area-cos":
        quality = area64 * np.clip(np.nan_to_num(np.asarray(cos, dtype=np.float64)), 0.0, 1.0)
    else:
        quality = area64
    stats: dict[str, Any] = {"data_term": data_term, "outlier_removal": outlier_removal}
    if outlier_removal != "none":
        weight, ost = photometric_outliers(faces, colour, method=outlier_removal)
        stats.update(ost)
        quality = quality * weight
        keep = weight > 0
        if not keep.all():
            view = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
            indptr = np.concatenate([[0], np.cumsum(np.bincount(view[keep], minlength=len(indptr) - 1))]).astype(np.int64)
            faces, area, cos, quality = faces[keep], area[keep], cos[keep], quality[keep]
        logger.info("outlier removal (%s): %d of %d faces tested, %d views dropped on %d faces", outlier_removal,
                    ost["faces_tested"], visibility.n_faces, ost["incidences_dropped"], ost["faces_with_outliers"])
    stats["time_s"] = time.perf_counter() - t
    return ScoredVisibility(visibility=visibility, indptr=np.asarray(indptr, np.int64), faces=faces, area=area,
                            cos_angle=cos, entry_quality=np.asarray(quality, dtype=np.float64), data_term=data_term,
                            stats=stats)
