"""Edge summaries: each graph edge's colours reduced to matched per-channel quantiles.

The first step of ``method="seqcc-global"`` (:mod:`~o3d_seqcc.correction.methods.seqcc_global`): for
**every** edge of the colour-correction graph (not only the path tree) the colours at the
pair's mappings, wrong correspondences dropped (the joint rule of
:func:`~o3d_seqcc.correction.methods.seqcc.colour_inliers`), are summarised per channel by their matched
quantiles ``(Q_a(p), Q_b(p))`` -- the JIH's quantile-paired marginals, which misregistration by
a few pixels does not flatten (:mod:`o3d_seqcc.correction.cmf`). The joint solves of
:mod:`~o3d_seqcc.correction.methods.joint_curves` work on these summaries only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ...mappings.pairs import BATCH_PAIRS, LazyPairs, thinned_many
from ..._shared.parallel import LocalExecutor, current as current_executor
from .value_space import histogram_normalisers_from_colours, map_rows

__all__ = ["SATURATION", "TRIM", "EdgeObservations", "edge_observations", "edge_quantiles", "rank_inliers"]

#: quantile levels this close to 0 or 1 are left out of the edge summaries
TRIM = 0.005
#: values within this of 0 or 1 are censored (clipped by the camera) and not used as observations
SATURATION = 1.5 / 255
#: values within this of 0 or 1 are a photo's clipped end levels (:func:`clipped_ends`)
CLIPPED = 0.5 / 255


def _sorted_quantiles(sorted_rows: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Quantiles at levels ``q`` of each row of an ascending (C, n) array, plotting positions
    ``(i + 0.5) / n`` (the same as ``np.interp(q, (arange(n) + 0.5) / n, row)``); (C, len(q))."""
    n = sorted_rows.shape[1]
    pos = np.clip(np.asarray(q, dtype=np.float64) * n - 0.5, 0.0, n - 1.0)
    i0 = np.minimum(np.floor(pos).astype(np.int64), max(n - 2, 0))
    t = pos - i0 if n > 1 else np.zeros(pos.size)
    i1 = np.minimum(i0 + 1, n - 1)
    return sorted_rows[:, i0] * (1.0 - t) + sorted_rows[:, i1] * t


def edge_quantiles(ca: np.ndarray, cb: np.ndarray, *, levels: int = 64, trim: float = TRIM) -> tuple[np.ndarray, np.ndarray]:
    """Matched per-channel quantiles of two views' colours at a pair's mappings.

    Parameters
    ----------
    ca, cb : (n, 3) float arrays in [0, 1]
        Colours of the two views at the same mappings (n >= 1).
    levels : int, default 64
        Number of quantile levels, evenly spaced in ``[trim, 1 - trim]``.
    trim : float, default :data:`TRIM`

    Returns
    -------
    qa, qb : (3, levels) float64
        ``qa[c, i]`` and ``qb[c, i]`` are the same quantile of channel c in the two views
        (plotting positions ``(i + 0.5) / n``, as :func:`o3d_seqcc.correction.cmf.quantile_samples`).
    """
    ca = np.asarray(ca, dtype=np.float64)
    cb = np.asarray(cb, dtype=np.float64)
    if ca.shape != cb.shape or ca.ndim != 2 or ca.shape[1] != 3 or len(ca) == 0:
        raise InputError(f"edge_quantiles: need two (n, 3) colour arrays of the same shape, n >= 1; got {ca.shape} and {cb.shape}")
    q = np.linspace(trim, 1.0 - trim, int(levels))
    return _sorted_quantiles(np.sort(ca.T, axis=1), q), _sorted_quantiles(np.sort(cb.T, axis=1), q)


def _median_rows(x: np.ndarray) -> np.ndarray:
    """``np.median(x, axis=1)`` of a finite (C, m) array, m >= 1: the same partition and mean of the middle
    two, without np.median's checks (a third of an edge summary's time)."""
    h = x.shape[1] // 2
    if x.shape[1] % 2:
        return np.partition(x, h, axis=1)[:, h]
    part = np.partition(x, (h - 1, h), axis=1)
    return np.mean(part[:, h - 1 : h + 1], axis=1)


def _rank_inliers(ca: np.ndarray, cb: np.ndarray, order_a: np.ndarray, sorted_b: np.ndarray, *, k: float) -> np.ndarray:
    """:func:`o3d_seqcc.correction.methods.seqcc.colour_inliers` with the pair's empirical quantile-quantile
    curve as the prediction: each mapping's colour in view a is mapped, channel by channel, to
    the value of view b of the same rank (no lookup table to build or interpolate). Same rule:
    residuals in robust sigmas (1.4826 MAD, at least 1/255), joint norm <= ``k * sqrt(3)``.
    Channels are rows: ``ca``, ``cb`` (3, n), ``order_a`` their argsort along the rows, ``sorted_b`` sorted."""
    n = ca.shape[1]
    rank = np.empty_like(order_a)
    np.put_along_axis(rank, order_a, np.arange(n)[None, :], axis=1)
    r = cb - np.take_along_axis(sorted_b, rank, axis=1)
    sub = r[:, :: max(1, n // 2000)]  # the centre and scale from ~2000 of them (4x faster, same threshold)
    med = _median_rows(sub)[:, None]
    mad = 1.4826 * _median_rows(np.abs(sub - med))
    z = (r - med) / np.maximum(mad, np.float32(1.0 / 255))[:, None]
    z *= z
    return np.sqrt((z[0] + z[1]) + z[2]) <= k * np.sqrt(3.0)


#: :func:`rank_inliers` ranks values on this many bins of [0, 1] (a quarter of an 8-bit level): values in one bin
#: are tied
RANK_BINS = 1024


class _TiedRanks:
    """The bins of one (C, n) set of values in [0, 1] (:data:`RANK_BINS`, values in one bin tied), so that the
    mid-rank of every value among any subset of them costs a bincount (:meth:`among`)."""

    def __init__(self, rows: np.ndarray) -> None:
        self.group = np.clip(np.rint(np.asarray(rows, dtype=np.float64) * (RANK_BINS - 1)), 0, RANK_BINS - 1).astype(np.int64)
        self.flat = (self.group + (np.arange(rows.shape[0]) * RANK_BINS)[:, None]).ravel()

    def among(self, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(mid, half)`` (C, n): each value's mid-rank CDF position among the values where ``keep`` (n,), and half
        the share its tied values take there."""
        C = self.group.shape[0]
        cnt = np.bincount(self.flat, weights=np.tile(keep, C).astype(np.float64),
                          minlength=C * RANK_BINS).reshape(C, RANK_BINS)
        hi = np.cumsum(cnt, axis=1).ravel()
        scale = 1.0 / (2.0 * max(int(keep.sum()), 1))
        hi_v = hi[self.flat].reshape(self.group.shape)
        lo_v = hi_v - cnt.ravel()[self.flat].reshape(self.group.shape)
        return (lo_v + hi_v) * scale, (hi_v - lo_v) * scale


def rank_inliers(ca: np.ndarray, cb: np.ndarray, *, k: float = 3.0, rounds: int = 5) -> np.ndarray:
    """Mappings whose two colours hold the same rank in their views, jointly over the channels, iterated.

    Each mapping's residual is, per channel, the difference of its colour's mid-rank position (the empirical
    CDF) in view b and in view a, among the mappings kept so far, less the half-widths of the two values' tied
    ranks (a level of an 8-bit photo holds a range of ranks): a monotone change of either view's values (a
    camera's exposure, white balance, gamma or tone curve) does not move it, so the same mappings are kept
    whatever the cameras did. Residuals are centred and scaled per channel by their median and 1.4826 MAD over
    all the mappings (at least 0.001: a scale taken over the inliers shrank every round and never settled) and
    summed in quadrature; a mapping is an outlier when that norm exceeds
    ``k * sqrt(3)`` (the rule of :func:`o3d_seqcc.correction.methods.seqcc.colour_inliers`). The first round
    ranks among all mappings; each further round among the last round's inliers, every mapping measured again
    (one dropped too early can come back), until at most one in a thousand changes. An occluder that one view shows
    over a tenth of the pair's surface shifts every rank above its colour in the first round; among the inliers
    it stands out.

    Parameters
    ----------
    ca, cb : (3, n) float arrays
        The two views' colours at the pair's mappings, channels as rows.
    k : float, default 3.0
        Robust sigmas (> 0).
    rounds : int, default 5
        Rounds after the first (>= 0).

    Returns
    -------
    (n,) bool
        Inliers; all true when fewer than 10 mappings would be kept.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> a = rng.uniform(0.1, 0.9, (3, 4000))
    >>> b = a ** 2.2  # another camera: a gamma
    >>> b[:, :400] = 0.3  # an occluder in view b over a tenth of the pairs
    >>> keep = rank_inliers(a, b)
    >>> bool(keep[:400].mean() < 0.5), bool(keep[400:].mean() > 0.95)
    (True, True)
    """
    ca = np.asarray(ca)
    cb = np.asarray(cb)
    n = ca.shape[1]
    keep = np.ones(n, dtype=bool)
    if n < 10:
        return keep
    both = _TiedRanks(np.concatenate([ca, cb]))  # view a's channels, then view b's
    C = ca.shape[0]
    for _ in range(1 + int(rounds)):
        pos, half = both.among(keep)
        pa, pb, ha, hb = pos[:C], pos[C:], half[:C], half[C:]
        # within the two values' tied ranks the residual is 0: quantisation, not a wrong mapping
        r = np.sign(pb - pa) * np.maximum(np.abs(pb - pa) - (ha + hb), 0.0)
        sub = r[:, :: max(1, n // 2000)]
        med = _median_rows(sub)[:, None]
        mad = 1.4826 * _median_rows(np.abs(sub - med))
        z = (r - med) / np.maximum(mad, 1e-3)[:, None]
        z *= z
        new = np.sqrt((z[0] + z[1]) + z[2]) <= float(k) * np.sqrt(3.0)
        if new.sum() < 10:
            break
        changed = int(np.count_nonzero(new != keep))
        keep = new
        if changed <= n // 1000:  # settled (a few mappings on the threshold may swap for ever)
            break
    return keep


class _PlaneValues:
    """``[c]``: channel ``c``'s values at some pixels, gathered from its plane through the level table when asked."""

    def __init__(self, planes: list[np.ndarray], table: np.ndarray, idx: np.ndarray) -> None:
        self.planes, self.table, self.idx = planes, table, idx

    def __getitem__(self, c: int) -> np.ndarray:
        return np.take(self.table, np.take(self.planes[c], self.idx))


def _bilinear_rows(values, shape: tuple[int, int], uv: np.ndarray, interpolation: str) -> np.ndarray:
    """(n, 2) pixel positions -> (3, n) float32 colours, channels as rows (contiguous for the edge summaries' sorts).

    ``values(idx)[c]``: the float32 values of channel ``c`` at the flat pixel indices ``idx``. Bilinear weights
    and products in float32, as :func:`o3d_seqcc.imaging.arrays.sample_colors` on a float32 image (its sorts
    are twice as fast as float64's).
    """
    H, W = shape
    x = np.clip(uv[:, 0], 0.0, W - 1.0)
    y = np.clip(uv[:, 1], 0.0, H - 1.0)
    if interpolation == "nearest":
        xi = np.minimum(np.floor(x + 0.5).astype(np.int64), W - 1)
        yi = np.minimum(np.floor(y + 0.5).astype(np.int64), H - 1)
        got = values(yi * W + xi)
        return np.stack([got[c] for c in range(3)])
    x0 = np.floor(x).astype(np.int64)
    y0 = np.floor(y).astype(np.int64)
    i00 = y0 * W + x0
    i01 = i00 + (x0 < W - 1)
    down = np.where(y0 < H - 1, W, 0)
    c00, c01, c10, c11 = (values(i) for i in (i00, i01, i00 + down, i01 + down))
    fx = (x - x0).astype(np.float32)
    fy = (y - y0).astype(np.float32)
    gx, gy = 1.0 - fx, 1.0 - fy
    out = np.empty((3, len(uv)), np.float32)
    for c in range(3):
        top = c00[c] * gx + c01[c] * fx
        bot = c10[c] * gx + c11[c] * fx
        np.add(top * gy, bot * fy, out=out[c])
    return out


def _sample_image(img: np.ndarray, uv: np.ndarray, interpolation: str) -> np.ndarray:
    """:func:`_bilinear_rows` of an (H, W, 3) image: float images as float32; uint8 / uint16 photos through a
    table of ``float32(level / scale)`` (float64 division, as :func:`~o3d_seqcc.imaging.arrays.img_as_float` then
    a float32 copy do), so every value, and every bilinear weight and product after it, is bit for bit that of
    the float32 copy of ``img_as_float(img)``, which is never made (24 + 12 bytes per pixel). A photo sampled
    at as many points as half its pixels is read through its channel planes (contiguous gathers), a larger
    one (6 MP at a few edges' mappings) pixel by pixel, without copying it."""
    from ...imaging.arrays import dtype_scale

    img = np.asarray(img)
    H, W = img.shape[:2]
    if img.dtype not in (np.uint8, np.uint16):
        flat = np.ascontiguousarray(img, dtype=np.float32).reshape(-1, 3)
        return _bilinear_rows(lambda idx: np.take(flat, idx, axis=0).T, (H, W), uv, interpolation)
    table = (np.arange(np.iinfo(img.dtype).max + 1, dtype=np.float64) / dtype_scale(img.dtype)).astype(np.float32)
    if 2 * len(uv) >= H * W:
        planes = [np.ascontiguousarray(img[..., c]).reshape(-1) for c in range(3)]
        return _bilinear_rows(lambda idx: _PlaneValues(planes, table, idx), (H, W), uv, interpolation)
    flat = np.ascontiguousarray(img).reshape(-1, 3)
    return _bilinear_rows(lambda idx: np.take(table, np.take(flat, idx, axis=0).T), (H, W), uv, interpolation)


def _sample_view_task(item: tuple[int, list], images, interpolation: str, source=None) -> np.ndarray:
    """One view's task: read its image once and sample it at every position its edges need -> (3, n) float32.

    ``item`` is ``(v, parts)``, one part per edge in order: its (m, 2) positions in ``v``, or, with ``source``
    (the lazy pairs' :class:`~o3d_seqcc.mappings.pairs.PairSource`), where its picked mappings lie (``(face,
    point)``, :meth:`~o3d_seqcc.mappings.pairs.PairSource.locate_batch`), projected here into ``v``
    (:meth:`~o3d_seqcc.mappings.pairs.PairSource.points`: the same values), so no edge's positions are held
    beyond its view's task. ``images`` is the context's float sequence; over uint8 / uint16 photos
    (:class:`~o3d_seqcc.imaging.sequences.FloatImages`) the photo itself is sampled (the same values, no float
    copy of the photo).
    """
    from ...imaging.sequences import FloatImages

    v, parts = item
    if source is None:
        uv = np.concatenate(parts) if parts else np.zeros((0, 2))
    else:
        bounds = np.concatenate([[0], np.cumsum([len(face) for face, _ in parts])]).astype(np.int64)
        uv = source.points(np.full(len(parts), v, np.int64), bounds, np.concatenate([f for f, _ in parts]),
                           np.concatenate([p for _, p in parts]))
    if isinstance(images, FloatImages):
        raw = np.asarray(images.images[v])
        if raw.dtype in (np.uint8, np.uint16) and raw.ndim == 3 and raw.shape[2] == 3:
            return _sample_image(raw, uv, interpolation)
    return _sample_image(images[v], uv, interpolation)


def clipped_ends(sa: np.ndarray, sb: np.ndarray) -> np.ndarray:
    """What each side's clipped end levels hide, from an edge's two sorted (3, n) colour rows.

    Where view a clipped a channel (values within :data:`CLIPPED` of 1, or of 0), its pixels hold one level
    for a range of true values. Matched by rank, as the quantile summaries are, those pixels are the other
    view's same share of its highest (lowest) values; the middle of that range, the other view's quantile at
    ``1 - share / 2`` (``share / 2``), is what the clipped level stands for (the median of the hidden values:
    what a correction should map the clipped level to; it is equivariant to either view's monotone change).

    Returns
    -------
    (2, 3, 2, 2) float64
        ``[side, channel, end, (share, other)]``: side 0 is view a, 1 view b; end 0 the low end, 1 the high end;
        the share of the side's values at that end level and the other side's value in the middle of their ranks.
    """
    out = np.zeros((2, 3, 2, 2))
    n = sa.shape[1]
    if n == 0:
        return out
    for side, (own, other) in enumerate(((sa, sb), (sb, sa))):
        lo = (own <= CLIPPED).sum(axis=1) / n
        hi = (own >= 1.0 - CLIPPED).sum(axis=1) / n
        out[side, :, 0, 0], out[side, :, 1, 0] = lo, hi
        out[side, :, 0, 1] = _sorted_quantiles_each(other, lo / 2.0)
        out[side, :, 1, 1] = _sorted_quantiles_each(other, 1.0 - hi / 2.0)
    return out


def _sorted_quantiles_each(sorted_rows: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(C,) the quantile at level ``q[c]`` of each ascending row ``c`` of a (C, n) array (plotting positions)."""
    return np.array([_sorted_quantiles(sorted_rows[c : c + 1], np.array([q[c]]))[0, 0] for c in range(len(q))])


def _summary_task(item: tuple[np.ndarray, np.ndarray], q: np.ndarray, outlier_k: float | None,
                  outlier_rounds: int | None = None):
    """One edge's task: (ca, cb) float32 colours, channels as rows (3, n) -> (qa (3, P), qb (3, P), n kept,
    :func:`clipped_ends` (2, 3, 2, 2)). ``outlier_rounds`` None: the one-pass rule in view b's values
    (:func:`_rank_inliers`); an integer: :func:`rank_inliers` with that many further rounds."""
    ca, cb = item
    if outlier_k is not None and ca.shape[1] >= 10 and outlier_rounds is not None:
        keep = rank_inliers(ca, cb, k=float(outlier_k), rounds=int(outlier_rounds))
        if 10 <= keep.sum() < len(keep):
            ca, cb = ca[:, keep], cb[:, keep]
        sa, sb = np.sort(ca, axis=1), np.sort(cb, axis=1)
    elif outlier_k is not None and ca.shape[1] >= 10:
        sb = np.sort(cb, axis=1)
        oa = np.argsort(ca, axis=1)
        sa = np.take_along_axis(ca, oa, axis=1)
        keep = _rank_inliers(ca, cb, oa, sb, k=float(outlier_k))
        if 10 <= keep.sum() < len(keep):
            # view a's kept values stay in sorted order: filter each channel's sorted list
            sa = np.stack([sa[c][keep[oa[c]]] for c in range(3)])
            sb = np.sort(cb[:, keep], axis=1)
    else:
        sa, sb = np.sort(ca, axis=1), np.sort(cb, axis=1)
    return _sorted_quantiles(sa, q), _sorted_quantiles(sb, q), sa.shape[1], clipped_ends(sa, sb)


@dataclass(frozen=True, eq=False)
class EdgeObservations:
    """Quantile summaries of the graph's edges.

    Attributes
    ----------
    a, b : (E,) int64
        The two views of each edge.
    qa, qb : (E, 3, P) float64 in [0, 1]
        Matched quantiles of each channel in view a and view b (:func:`edge_quantiles`), in the
        views' own values or, with ``normalisers``, in the normalised values.
    n : (E,) int64
        Number of mappings used per edge (after the outlier pass).
    normalisers : (V, 3, L) float64 or None
        The per-view tables the colours went through before they were summarised
        (:func:`~o3d_seqcc.correction.methods.value_space.histogram_normalisers_from_colours`, or :meth:`through`); None:
        the views' own values.
    seen : (2, E, 3, P) bool or None
        Which quantiles of view a (``seen[0]``) and of view b (``seen[1]``) are not censored (clipped by the
        camera), when they were summarised in other values than the views' own (:meth:`through`); None: the
        quantiles more than :data:`SATURATION` from 0 and 1.
    clipped : (E, 2, 3, 2, 2) float64 or None
        Per edge, :func:`clipped_ends` of its colours in the views' own values (the same in every value space).
    """

    a: np.ndarray
    b: np.ndarray
    qa: np.ndarray
    qb: np.ndarray
    n: np.ndarray
    normalisers: np.ndarray | None = None
    seen: np.ndarray | None = None
    clipped: np.ndarray | None = None

    def __post_init__(self) -> None:
        e = len(self.a)
        if not (len(self.b) == len(self.n) == e and self.qa.shape == self.qb.shape and self.qa.shape[:2] == (e, 3)):
            raise InputError(
                f"EdgeObservations: inconsistent shapes a {np.shape(self.a)}, b {np.shape(self.b)}, n {np.shape(self.n)}, "
                f"qa {np.shape(self.qa)}, qb {np.shape(self.qb)}; need (E,), (E,), (E,), (E, 3, P), (E, 3, P)"
            )

    def subset(self, keep: np.ndarray) -> "EdgeObservations":
        """These summaries of the edges where ``keep`` (E,) bool is true."""
        keep = np.asarray(keep, dtype=bool)
        return EdgeObservations(a=self.a[keep], b=self.b[keep], qa=self.qa[keep], qb=self.qb[keep], n=self.n[keep],
                                normalisers=self.normalisers, seen=None if self.seen is None else self.seen[:, keep],
                                clipped=None if self.clipped is None else self.clipped[keep])

    def through(self, normalisers: np.ndarray) -> "EdgeObservations":
        """These summaries with every view's values through its monotone (3, L) table ``normalisers[v]`` (the
        quantiles of ``T(X)`` are ``T`` of the quantiles of ``X``); what was censored stays censored."""
        if self.normalisers is not None:
            raise InputError("EdgeObservations.through: these summaries are normalised already")
        norm = np.asarray(normalisers, dtype=np.float64)
        grid = np.linspace(0.0, 1.0, norm.shape[2])

        def mapped(views: np.ndarray, q: np.ndarray) -> np.ndarray:
            out = np.empty_like(q)
            for v in np.unique(views):
                sel = views == v
                for c in range(3):
                    out[sel, c] = np.interp(q[sel, c], grid, norm[v, c])
            return out

        seen = np.stack([np.stack(self.observed(c), axis=0) for c in range(3)], axis=2)  # (2, E, 3, P)
        return EdgeObservations(a=self.a, b=self.b, qa=mapped(self.a, self.qa), qb=mapped(self.b, self.qb), n=self.n,
                                normalisers=norm, seen=seen, clipped=self.clipped)

    def observed(self, c: int) -> tuple[np.ndarray, np.ndarray]:
        """(E, P) masks of channel ``c``'s quantiles of view a and of view b that are not censored."""
        if self.seen is not None:
            return self.seen[0, :, c, :], self.seen[1, :, c, :]
        out = []
        for q in (self.qa[:, c, :], self.qb[:, c, :]):
            out.append((q > SATURATION) & (q < 1.0 - SATURATION))
        return out[0], out[1]


def edge_observations(
    ctx,
    edges: list[tuple[int, int]],
    *,
    levels: int = 64,
    max_mappings: int | None = 8000,
    outlier_k: float | None = 3.0,
    outlier_rounds: int | None = None,
    normalise_to: int | None = None,
    n_jobs: int | None = None,
) -> EdgeObservations | tuple[EdgeObservations, EdgeObservations]:
    """Quantile summaries of the colours at the mappings of ``edges`` (see the module docstring).

    Parameters
    ----------
    ctx : o3d_seqcc.correction.CorrectionContext
        Gives the images (float, [0, 1]), the mappings and the colour sampling.
    edges : list of (int, int)
        View pairs with mappings.
    levels : int, default 64
        Quantile levels per edge and channel.
    max_mappings : int or None, default 8000
        Use at most this many mappings per edge, evenly strided over the pair's list (None:
        all). A quantile of 8000 samples is within ~0.3 % of the distribution of all of them;
        the cap keeps the cost linear in the number of edges, not in the number of mappings.
    outlier_k : float or None, default 3.0
        Drop mappings whose colours disagree with the pair's quantile-quantile curve by more
        than this many robust sigmas jointly over the channels
        (:func:`o3d_seqcc.correction.methods.seqcc.colour_inliers`); None keeps all.
    outlier_rounds : int or None, default None
        None: that rule in one pass, the residuals in view b's values against the pair's quantile-quantile curve;
        an integer: :func:`rank_inliers` (the same rule on the colours' ranks, which no monotone change of either
        view moves) with this many further rounds among the inliers.
    normalise_to : int or None, default None
        A view index: also summarise the same colours with every other view's through its histogram normaliser
        toward that view (:func:`~o3d_seqcc.correction.methods.value_space.histogram_normalisers_from_colours`),
        before that summary's outlier pass, so that it does not move with any view's monotone change of its
        values; the normalisers are kept in its :attr:`EdgeObservations.normalisers`, what was censored in its
        :attr:`EdgeObservations.seen`.
        Threads of the local executor (joblib semantics: None = the active
        ``joblib.parallel_config`` or 1, -1 = all cores). The colours are sampled by one task
        per view on the active executor (:mod:`o3d_seqcc._shared.parallel`: its image read once, at
        every position its edges need, then released; on a Dask cluster the workers read it);
        the per-edge summaries run in local threads.

    Returns
    -------
    EdgeObservations, or (own, normalised) EdgeObservations with ``normalise_to``
    """
    E, P = len(edges), int(levels)
    q = np.linspace(TRIM, 1.0 - TRIM, P)

    def pick(n: int) -> np.ndarray | None:
        if max_mappings is None or n <= int(max_mappings):
            return None
        return (np.arange(int(max_mappings)) * (n / float(max_mappings))).astype(np.int64)

    # what each edge samples in its two views, only the strided max_mappings of a pair: with lazy pairs where they
    # lie (the pairs located in batches on local threads, where the lazy pairs live), projected by each view's
    # task; otherwise their positions
    ex = current_executor(n_jobs)
    local_jobs = n_jobs if not isinstance(ex, LocalExecutor) else ex.n_jobs
    keys = [(min(int(a), int(b)), max(int(a), int(b))) for a, b in edges]
    pairs_map = ctx.mappings.pairs
    source = getattr(pairs_map, "source", None) if isinstance(pairs_map, LazyPairs) else None
    parts: dict[int, list] = {}
    sizes = []
    if source is not None and hasattr(source, "locate_batch"):
        for k in keys:
            if k not in pairs_map:
                raise KeyError(k)
        batches = [keys[i : i + BATCH_PAIRS] for i in range(0, len(keys), BATCH_PAIRS)]
        located = LocalExecutor(local_jobs).imap(source.locate_batch, batches, pick, desc="edge mappings", unit="batch")
        for (a, b), (_, face, point) in zip(edges, (x for part in located for x in part)):
            parts.setdefault(int(a), []).append((face, point))
            parts.setdefault(int(b), []).append((face, point))
            sizes.append(len(face))
    else:
        source = None
        for (a, b), (_, pm) in zip(edges, thinned_many(pairs_map, keys, pick, n_jobs=local_jobs)):
            uva, uvb = (pm.uv_a, pm.uv_b) if int(a) <= int(b) else (pm.uv_b, pm.uv_a)
            parts.setdefault(int(a), []).append(np.asarray(uva, dtype=np.float64).reshape(-1, 2))
            parts.setdefault(int(b), []).append(np.asarray(uvb, dtype=np.float64).reshape(-1, 2))
            sizes.append(len(uva))
    # one task per view: its image read once, sampled at all its edges' positions, released
    views = sorted(parts)
    sampled = ex.map(_sample_view_task, [(v, parts.pop(v)) for v in views], ex.share(ctx.images), ctx.interpolation,
                     None if source is None else ex.share(source), desc="sample views", unit="view")
    offset = {v: 0 for v in views}
    colours: dict[int, np.ndarray] = dict(zip(views, sampled))
    pairs: list[tuple[np.ndarray, np.ndarray]] = []
    for (a, b), m in zip(edges, sizes):  # each edge's colours, channels as rows (3, m)
        a, b = int(a), int(b)
        pairs.append((colours[a][:, offset[a] : offset[a] + m], colours[b][:, offset[b] : offset[b] + m]))
        offset[a] += m
        offset[b] += m
    local = LocalExecutor(local_jobs)
    arr = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    live = [i for i in range(E) if pairs[i][0].shape[1]]

    def summarise(items: list) -> EdgeObservations:
        # the per-edge summaries: numpy's sorts, gathers and medians release the GIL, local threads
        qa, qb, ns = np.zeros((E, 3, P)), np.zeros((E, 3, P)), np.zeros(E, dtype=np.int64)
        clipped = np.zeros((E, 2, 3, 2, 2))
        for i, (qa_i, qb_i, n_i, clip_i) in zip(live, local.map(_summary_task, [items[i] for i in live], q, outlier_k, outlier_rounds,
                                                       desc="edge summaries", unit="edge")):
            qa[i], qb[i], ns[i], clipped[i] = qa_i, qb_i, n_i, clip_i
        return EdgeObservations(a=arr[:, 0].copy(), b=arr[:, 1].copy(), qa=qa, qb=qb, n=ns, clipped=clipped)

    own = summarise(pairs)
    if normalise_to is None:
        return own
    n_views = len(ctx.images)
    norm = histogram_normalisers_from_colours(colours, reference=int(normalise_to), n_views=n_views,
                                              lut_size=ctx.lut_size)
    mapped = {v: map_rows(norm[v], c) for v, c in colours.items()}
    offset = {v: 0 for v in views}
    normed = []
    for (a, b), m in zip(edges, sizes):
        a, b = int(a), int(b)
        normed.append((mapped[a][:, offset[a] : offset[a] + m], mapped[b][:, offset[b] : offset[b] + m]))
        offset[a] += m
        offset[b] += m
    out = summarise(normed)
    # censored where the view's own value is: a quantile at or below the table's value at the censoring threshold
    grid = np.linspace(0.0, 1.0, norm.shape[2])
    seen = np.ones((2, E, 3, P), dtype=bool)
    for side, (views_, qs) in enumerate(((out.a, out.qa), (out.b, out.qb))):
        for v in np.unique(views_):
            sel = views_ == v
            for c in range(3):
                own_c = colours[int(v)][c]
                lo = np.interp(SATURATION, grid, norm[v, c]) if (own_c <= SATURATION).any() else -np.inf
                hi = np.interp(1.0 - SATURATION, grid, norm[v, c]) if (own_c >= 1.0 - SATURATION).any() else np.inf
                seen[side, sel, c] = (qs[sel, c] > lo) & (qs[sel, c] < hi)
    return own, EdgeObservations(a=out.a, b=out.b, qa=out.qa, qb=out.qb, n=out.n, normalisers=norm, seen=seen,
                                 clipped=own.clipped)

