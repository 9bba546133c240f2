"""Photometric outliers: per face, the views whose colour is far from the consensus of its views (issue 19).

So that a pedestrian or a car the mesh does not hold, seen in one or two photos, does not texture
the wall behind it (texrecon's ``--outlier_removal``, and a robust alternative), from the mean
colour of every usable (view, face) incidence (:func:`~o3d_seqcc.texturing.data_costs.face_view_statistics`):

- ``"median"`` (default): the distance to the per-channel median of the face's CIE Lab colours;
  the faces seen by the same number of views are tested together, as one block sorted along its
  rows (no loop over faces);
- ``"gauss-clamping"`` / ``"gauss-damping"`` (texrecon): an iterated multivariate Gaussian of the
  faces' YCbCr colours, vectorised over all faces at once (segment sums over the incidences).

Every array is one entry per incidence (or per face): nothing is dense in views x faces.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..imaging.arrays import rgb_to_lab
from .settings import OUTLIER_REMOVALS

__all__ = ["DAMPING_FACTOR", "GAUSS_REJECTION", "MEDIAN_MAD_FACTOR", "MEDIAN_MIN_DELTA_E", "MIN_COVARIANCE", "MIN_INLIERS",
           "OUTLIER_ITERATIONS", "colour_lab", "photometric_outliers"]


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


def colour_lab(colour: np.ndarray) -> np.ndarray:
    """(n, 3) float64 CIE Lab of (n, 3) RGB colours in [0, 1] (:func:`~o3d_seqcc.imaging.arrays.rgb_to_lab` of them
    as float64, clipped to [0, 1]), the same bits for any part of the rows as for all of them (the data cost tasks
    convert them view by view): a single row is converted as two (the 1-row matrix product rounds apart)."""
    x = np.clip(np.asarray(colour, dtype=np.float64), 0.0, 1.0)
    if len(x) == 1:
        return rgb_to_lab(np.repeat(x, 2, axis=0))[:1]
    return rgb_to_lab(x)


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


def _median_outliers(face: np.ndarray, lab: np.ndarray, n_faces: int) -> np.ndarray:
    """Incidences whose Lab colour is more than max(:data:`MEDIAN_MIN_DELTA_E`, :data:`MEDIAN_MAD_FACTOR`
    x the face's median distance) from the per-channel median of the face's views (faces of >= 3 views).

    ``face`` (m,) int ids in ``[0, n_faces)``, ``lab`` (m, 3) float64; returns (m,) bool. The faces
    seen by the same number n of views are tested together as an (f, n) block per channel: sorted
    along its rows, the medians are their middle values (one task per distinct count, never a loop
    over faces).
    """
    from .._shared.parallel import LocalExecutor

    count = np.bincount(face, minlength=n_faces)
    order = np.argsort(face, kind="stable")  # the incidences face by face
    ptr = np.zeros(n_faces + 1, dtype=np.int64)
    np.cumsum(count, out=ptr[1:])
    drop = np.zeros(len(face), dtype=bool)

    def block(n: int) -> None:
        idx = order[ptr[np.flatnonzero(count == n)][:, None] + np.arange(n)]  # (f, n) incidences
        lo, hi = (n - 1) // 2, n // 2
        sq = None
        for c in range(3):  # per channel: its median (the middle one or two), the squared distances summed in order
            x = lab[idx, c]
            srt = np.sort(x, axis=1)
            x -= 0.5 * (srt[:, lo] + srt[:, hi])[:, None]
            x *= x
            sq = x if sq is None else sq + x
        d = np.sqrt(sq)  # np.linalg.norm of the (f, n, 3) differences, term for term
        ds = np.sort(d, axis=1)
        dmed = 0.5 * (ds[:, lo] + ds[:, hi])
        drop[idx] = d > np.maximum(MEDIAN_MIN_DELTA_E, MEDIAN_MAD_FACTOR * dmed)[:, None]

    # the blocks on local threads (numpy's gathers and sorts release the GIL), each writing its own incidences
    LocalExecutor().map(block, np.unique(count[count >= 3]).tolist(), desc="outliers", unit="block")
    return drop


def photometric_outliers(face: np.ndarray, colour: np.ndarray | None, *, method: str = "median",
                         lab: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, Any]]:
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
        Mean RGB in [0, 1] of the face in the incidence's view (may be None for ``"median"`` with ``lab``).
    method : {"median", "gauss-clamping", "gauss-damping"}
    lab : (m, 3) float64, optional
        ``"median"``: the colours' CIE Lab (:func:`colour_lab`), when already converted.

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
    face = np.asarray(face)
    m = len(face)
    weight = np.ones(m)
    if m == 0:
        return weight, {"faces_tested": 0, "incidences_dropped": 0, "faces_with_outliers": 0}
    seg = face if face.min() >= 0 else np.unique(face, return_inverse=True)[1].reshape(-1)
    nf = int(seg.max()) + 1
    if method == "median":
        if lab is None:
            lab = rgb_to_lab(np.clip(np.asarray(colour, dtype=np.float64), 0.0, 1.0))
        drop = _median_outliers(seg, lab, nf)
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
