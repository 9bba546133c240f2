"""Chart packing with xatlas, the atlas sized to the charts or under a budget (issues 13, 19).

The charts (:mod:`~o3d_seqcc.texturing.charts`) are given to xatlas as a *UV mesh*
(``xatlas.Atlas.add_uv_mesh`` with one material per chart, so that charts are kept as they are
and never merged), whose parametric area is its UV area: xatlas places every chart (turned by
90 degrees where that packs better, never by another angle: ``rotate_charts_to_axis`` off) at
``padding`` texels from the others (the texels bilinear filtering reads included,
``resolution`` = the page size).

**The texel grid is the photo's pixel grid.** xatlas moves a chart by a fractional offset and
stretches it to whole texels, so its texture coordinates would put every texel between four
photo pixels. Only its placement is kept: every chart's texel coordinates are recomputed as
``t * uv + o`` (``uv`` with x and y swapped where xatlas turned the chart) with an integer
offset ``o`` per chart, as close to xatlas's placement as rounding allows (within a texel: xatlas
is given ``padding + 1`` so that the gap between charts stays ``2 * padding``). At one texel per
pixel (``t = 1``) a texel centre is then a pixel centre and the bake copies the photo
(:mod:`~o3d_seqcc.texturing.bake`).

Size (:func:`pack_charts`): with ``atlas_size="auto"`` (the default) the atlas is sized to the
charts at their photos' resolution (``texels_per_pixel="auto"``: exactly 1, or the number
asked). By default (``power_of_two=False``) it is one page cut to them: the rectangle their
placement without a size limit reaches, with their gutters, each side rounded up to a multiple of
4 (:func:`tight_side`, as block compression needs), and no xatlas call but that placement's. With
``power_of_two=True`` it is the smallest square power-of-two page that holds them
(``shrink_to_fit``: or the one below it at a density at most that share lower, with a warning).
Up to :data:`MAX_AUTO_ATLAS_SIZE`; beyond that, as many square pages of that size as needed. An
integer ``atlas_size`` N is a budget, a maximum: the page is the smallest that holds the charts at
the asked density within N x N (never raised to fill the page: a texel between photo pixels
blurs the photo once more in every render); when even N cannot hold the charts at that density,
``overflow="scale"`` lowers the density (a warning gives the factor; the page then cut to the
charts unless ``power_of_two``) and ``overflow="pages"`` keeps it and writes several N x N
pages. Charts are never resized silently: a chart xatlas would have to shrink to fit a page
lowers the density of the whole atlas instead (with a warning).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, warn
from .blocks import pack_with_block
from .settings import TextureSettings

__all__ = ["MAX_AUTO_ATLAS_SIZE", "Packing", "pack_charts"]

logger = logging.getLogger(__name__)

#: ``atlas_size="auto"``: the largest page; more pages of this side beyond it
MAX_AUTO_ATLAS_SIZE = 8192
#: ``pack_effort``: xatlas's own placement search, or every position (``bruteForce``)
PACK_EFFORTS = ("fast", "best")
#: page sides are multiples of this (BC / ASTC 4x4 / ETC block compression)
BLOCK = 4
#: xatlas's marker of an unassigned vertex / chart
_NONE = np.iinfo(np.uint32).max


@dataclass
class Packing:
    """Where every output vertex lies in the atlas.

    Attributes
    ----------
    txy : (M, 2) float64
        Texel coordinates in the vertex's page (x right, y down, texel centres at integers).
    page : (M,) int64
        Page of every vertex.
    width, height : int
        Size of every page in texels: square pages (powers of two, or under a budget with several
        pages), or one page cut to its charts (``power_of_two=False``: sides multiples of 4).
    pages : int
    texels_per_pixel : float
        The density used: atlas texels per source pixel.
    requested : float
        The density asked for (1.0 for ``"auto"``: the photos' resolution).
    scale : float
        ``texels_per_pixel / requested`` when the budget forced the density down, else 1.0.
    utilization : list of float
        xatlas's share of every page taken by charts with their padding.
    log : list of str
        The packing attempts.
    """

    txy: np.ndarray
    page: np.ndarray
    width: int
    height: int
    pages: int
    texels_per_pixel: float
    requested: float
    scale: float = 1.0
    utilization: list = field(default_factory=list)
    log: list = field(default_factory=list)

    @property
    def size(self) -> int:
        """The larger side of a page (what an ``atlas_size`` budget bounds)."""
        return max(self.width, self.height)


def tight_side(extent: float, padding: int) -> int:
    """A page side that holds charts reaching texel coordinate ``extent`` (centres at integers) and their
    gutters (``padding`` + the texel bilinear filtering reads): a multiple of 4, as block compression needs."""
    return int(BLOCK * math.ceil((float(extent) + int(padding) + 2.0) / BLOCK))


class _Packer:
    """xatlas calls on one UV mesh (kept across attempts)."""

    def __init__(self, uv: np.ndarray, faces: np.ndarray, chart: np.ndarray, padding: int, *,
                 effort: str = "fast") -> None:
        self.brute_force = effort == "best"
        self.uv64 = np.asarray(uv, dtype=np.float64)
        self.uv = np.ascontiguousarray(uv, dtype=np.float32)
        self.faces = np.ascontiguousarray(faces, dtype=np.uint32)
        self.chart = np.ascontiguousarray(chart, dtype=np.uint32).reshape(-1, 1)
        self.padding = int(padding)
        p = self.uv64[np.asarray(faces)]
        a2 = np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
        self.n_charts = int(np.asarray(chart).max()) + 1
        self.chart_area = np.bincount(np.asarray(chart), weights=0.5 * a2, minlength=self.n_charts)
        self.vertex_chart = np.full(len(uv), -1, dtype=np.int64)
        self.vertex_chart[np.asarray(faces, dtype=np.int64)] = np.asarray(chart, dtype=np.int64)[:, None]
        self.log: list[str] = []

    def pack(self, t: float, resolution: int):
        import xatlas

        a = xatlas.Atlas()
        a.add_uv_mesh(self.uv, self.faces, self.chart)
        po = xatlas.PackOptions()
        po.texels_per_unit = float(t)
        po.resolution = int(resolution)
        po.padding = self.padding + 1 if self.padding > 0 else 0  # + the texel the grid alignment may move a chart
        po.bilinear = True
        po.blockAlign = False
        po.rotate_charts = True  # by 90 degrees (xatlas swaps x and y): the texel grid stays the pixel grid
        po.rotate_charts_to_axis = False  # any other angle would resample every texel
        po.bruteForce = self.brute_force  # "best": every position tried (Fountain 300k: 1.5 -> 7.7 s, +10 % coverage)
        a.generate(xatlas.ChartOptions(), po)
        return a

    def shrunk(self, a, t: float) -> bool:
        """Whether xatlas shrank a chart to fit a page (its packed area is below t^2 x its area)."""
        _, ind, uv = a[0]
        w = np.asarray([a.width, a.height], dtype=np.float64)
        p = uv.astype(np.float64)[ind] * w
        a2 = np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
        got = np.bincount(self.chart.reshape(-1)[: len(ind)], weights=0.5 * a2, minlength=self.n_charts)
        want = self.chart_area * t * t
        big = want > 4.0
        return bool(np.any(got[big] < 0.97 * want[big]))

    def largest_chart(self, t: float) -> float:
        """An upper bound of the side of any chart's packed image at density ``t`` (texels: its extent, xatlas's
        half-texel offset and padding on both sides, rounding)."""
        return float(self._spans().max(initial=0.0)) * t + self._margin()

    def _margin(self) -> float:
        return 2 * (self.padding + 1) + 3

    def boxes_side(self, t: float) -> float:
        """The side of a square as large as the charts' padded bounding boxes at density ``t`` (texels)."""
        span = self._spans() * t + self._margin()
        return math.sqrt(float(np.sum(span[:, 0] * span[:, 1])))

    def _spans(self) -> np.ndarray:
        """(C, 2) extent of every chart in uv units (0 for a chart with no vertex)."""
        if not hasattr(self, "_span"):
            vc = self.vertex_chart
            ok = vc >= 0
            lo = np.full((self.n_charts, 2), np.inf)
            hi = np.full((self.n_charts, 2), -np.inf)
            np.minimum.at(lo, vc[ok], self.uv64[ok])
            np.maximum.at(hi, vc[ok], self.uv64[ok])
            self._span = np.where(np.isfinite(hi - lo), hi - lo, 0.0)
        return self._span

    def unlimited(self, t: float, *, start: int | None = None):
        """The charts at density ``t`` without a size limit: ``(atlas, width, height, R)`` or None.

        xatlas given a page limit places every chart where it would without one, as long as no chart's search
        reaches the limit (its random candidate positions are drawn up to the atlas's current extents plus one,
        clamped to the limit minus the chart's size): packed on a power-of-two page ``R`` with room for the
        unlimited packing's extents plus the largest chart, the placement is the unlimited one, and its texel
        coordinates are exact (``uv * R``). ``width`` and ``height`` are the unlimited packing's extents (xatlas's
        ``atlasSizes`` less the padding: the ceiling of its largest texel coordinates). None when R would have to
        exceed 2**15 (the caller packs without a limit instead).

        The first ``R`` tried is the smallest that holds the charts' padded bounding boxes side by side (1.1 x the
        square root of their total area) plus the largest chart; a placement that came close to its limit is
        packed again on a page twice as large (``start``: the first ``R`` tried instead, a power of two). xatlas's
        time grows with ``R`` (Fountain 300k: 1.2 s at 4096, 1.8 s at 32768) while the placement does not change.
        """
        side = self.largest_chart(t)
        need = 1.1 * self.boxes_side(t) + side + 1
        R = 1 << max(4, math.ceil(math.log2(max(need, 1.0)))) if start is None else int(start)
        while R <= 2**15:
            a = self.pack(t, R)
            if a.atlas_count == 1:
                _, _, uv = a[0]
                page, _ = a.get_mesh_vertex_assignment(0)
                tc = uv[page < _NONE].astype(np.float64) * R
                if not len(tc):
                    return None
                W, H = (int(math.ceil(float(v))) for v in tc.max(axis=0))
                if max(W, H) + 1 + side <= R:
                    return a, W, H, R
            logger.debug("packing: a %dx%d page is too small to read the unlimited placement off; twice that", R, R)
            R *= 2
        return None

    def attempt(self, t: float, size: int, packed=None):
        """xatlas's packing on a page of side ``size`` (``packed``: that packing, made elsewhere) and whether it holds
        every chart on one page at density ``t``."""
        a = self.pack(t, size) if packed is None else packed
        ok = a.atlas_count == 1 and not self.shrunk(a, t)
        self.log.append(f"t={t:.4f} S={size}: {a.atlas_count} page(s){'' if ok or a.atlas_count > 1 else ', chart shrunk'}")
        return a, ok


class _OnPage:
    """An xatlas packing made on a larger page ``R``, read as the same placement on a page of side ``size``: what
    xatlas gives when it packs on that page (uv = texel coordinates / size in float32, utilization = the same count
    of used texels over size^2)."""

    def __init__(self, big, R: int, size: int) -> None:
        self._big, self._R, self.width, self.height, self.atlas_count = big, int(R), int(size), int(size), 1
        vmap, ind, uv = big[0]
        tc = uv * np.float32(R)  # exact: R is a power of two
        self._mesh = (vmap, ind, (tc / np.float32(size)).astype(np.float32))

    def __getitem__(self, i: int):
        return self._mesh

    def get_mesh_vertex_assignment(self, i: int):
        return self._big.get_mesh_vertex_assignment(i)

    def get_utilization(self, i: int) -> float:
        count = np.float32(self._big.get_utilization(i)) * np.float32(self._R * self._R)  # exact: R^2 a power of two
        return float(count / np.float32(self.width * self.height))


def _sizes(atlas_size: int, power_of_two: bool, side: float) -> list[int]:
    """Candidate page sides <= atlas_size, ascending (powers of two, or multiples of 4 from ``side`` up)."""
    if power_of_two:
        return [1 << k for k in range(3, 31) if (1 << k) <= atlas_size] or [int(atlas_size)]
    out, s = [], max(8.0, float(side))
    while s < atlas_size:
        out.append(int(4 * math.ceil(s / 4)))
        s *= 1.05
    return sorted(set(x for x in out if x < atlas_size)) + [int(atlas_size)]


def _chart_ranges(values: np.ndarray, order: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-chart minimum and maximum of (M, k) ``values`` (vertices sorted by chart: ``order``, ``starts``)."""
    v = values[order]
    return np.minimum.reduceat(v, starts, axis=0), np.maximum.reduceat(v, starts, axis=0)


def _aligned(pk: _Packer, txy: np.ndarray, placed: np.ndarray, t: float, size: int) -> np.ndarray:
    """Texel coordinates ``t * uv + o`` per chart (x and y swapped where xatlas turned it), ``o`` integer.

    ``txy`` (M, 2): xatlas's coordinates (texel centres at integers) where ``placed``; charts with
    no placed vertex keep them.
    """
    vc = pk.vertex_chart
    sel = np.flatnonzero(placed & (vc >= 0))
    out = txy.copy()
    if len(sel) == 0:
        return out
    order = np.argsort(vc[sel], kind="stable")
    cs = vc[sel][order]
    starts = np.flatnonzero(np.r_[True, cs[1:] != cs[:-1]])
    charts = cs[starts]
    uv = pk.uv64 * t
    q = txy[sel]
    spread = []
    for src in (uv[sel], uv[sel][:, ::-1]):
        lo, hi = _chart_ranges(q - src, order, starts)
        spread.append((hi - lo).sum(axis=1))
    swap_c = np.zeros(pk.n_charts, dtype=bool)
    swap_c[charts] = spread[1] < spread[0] - 1e-6
    has = np.zeros(pk.n_charts, dtype=bool)
    has[charts] = True
    allv = np.flatnonzero((vc >= 0) & has[np.maximum(vc, 0)])
    src_all = np.where(swap_c[vc[allv]][:, None], uv[allv][:, ::-1], uv[allv])
    src = np.where(swap_c[vc[sel]][:, None], uv[sel][:, ::-1], uv[sel])
    dlo, dhi = _chart_ranges(q - src, order, starts)
    o = np.rint(0.5 * (dlo + dhi))
    # keep the chart inside its page (xatlas's placement may touch the page border)
    o2 = np.argsort(vc[allv], kind="stable")
    ca = vc[allv][o2]
    st2 = np.flatnonzero(np.r_[True, ca[1:] != ca[:-1]])
    slo, shi = _chart_ranges(src_all, o2, st2)
    pos = np.searchsorted(charts, ca[st2])  # the same charts, in the same (ascending) order
    o = o[pos]
    o = np.minimum(np.maximum(o, np.ceil(-0.5 - slo - 1e-9)), np.floor(size - 0.5 - shi + 1e-9))
    off = np.zeros((pk.n_charts, 2))
    off[ca[st2]] = o
    out[allv] = src_all + off[vc[allv]]
    return out


def _result(a, pk: _Packer, t: float, requested: float, size: int, *, tight: bool = False) -> Packing:
    """The :class:`Packing` of xatlas's ``a`` on pages of side ``size``; ``tight``: one page cut to its charts and
    their gutters (:func:`tight_side`, at most ``size``), the placement unchanged."""
    _, ind, uv = a[0]
    page, _ = a.get_mesh_vertex_assignment(0)
    page = page.astype(np.int64)
    txy = uv.astype(np.float64) * [a.width, a.height] - 0.5
    bad = page >= _NONE
    txy = _aligned(pk, txy, ~bad & np.isfinite(txy).all(axis=1), t, size)
    if bad.any():  # vertices of faces xatlas ignored (zero UV area): their chart's page, else a placed vertex's
        vc = pk.vertex_chart
        cpage = np.full(pk.n_charts, -1, dtype=np.int64)
        ok = ~bad & (vc >= 0)
        cpage[vc[ok]] = page[ok]
        fix = bad & (vc >= 0)
        fix[fix] = cpage[vc[fix]] >= 0
        page[fix] = cpage[vc[fix]]
        bad &= ~fix
        faces = pk.faces.astype(np.int64)
        for j in range(3):  # 3 corner slots, vectorised over faces
            fv = faces[:, j]
            m = bad[fv]
            if m.any():
                o1, o2 = faces[m, (j + 1) % 3], faces[m, (j + 2) % 3]
                other = np.where(~bad[o1], o1, o2)
                txy[fv[m]] = txy[other]
                page[fv[m]] = page[other]
        page[page >= _NONE] = 0
        txy[~np.isfinite(txy).all(axis=1)] = 0.0
    width = height = int(size)
    util = [float(a.get_utilization(i)) for i in range(a.atlas_count)]
    if tight and a.atlas_count == 1 and len(txy):
        width, height = (min(int(size), tight_side(float(txy[:, k].max()), pk.padding)) for k in (0, 1))
        util = [util[0] * size * size / (width * height)]
        pk.log.append(f"page cut to its charts: {width}x{height}")
    return Packing(txy=txy, page=page, width=width, height=height, pages=int(a.atlas_count), texels_per_pixel=float(t),
                   requested=float(requested), scale=float(t / requested) if t < requested * 0.999 else 1.0,
                   utilization=util, log=pk.log)


def pack_charts(
    uv: np.ndarray, faces: np.ndarray, chart: np.ndarray, *, atlas_size: int | str = TextureSettings.atlas_size,
    texels_per_pixel: float | str = TextureSettings.texels_per_pixel, overflow: str = TextureSettings.overflow,
    padding: int = TextureSettings.padding, power_of_two: bool = TextureSettings.power_of_two,
    shrink_to_fit: float = TextureSettings.shrink_to_fit, small_charts: int = TextureSettings.small_charts,
    small_padding: int = TextureSettings.small_padding, pack_effort: str = TextureSettings.pack_effort,
) -> Packing:
    """Pack charts into pages sized to them or of at most ``atlas_size`` (see the module docstring).

    Parameters
    ----------
    uv : (M, 2) float
        Chart coordinates in source pixels (pixel centres at integers).
    faces : (F, 3) int
        Faces over ``uv``.
    chart : (F,) int
        Chart of every face (``0 .. C-1``); a chart is packed as one piece.
    atlas_size : int or "auto", default "auto"
        ``"auto"``: pages sized to the charts (up to :data:`MAX_AUTO_ATLAS_SIZE`, then more pages);
        an integer: the largest page side N (a budget).
    texels_per_pixel : float or "auto", default "auto"
        Density; ``"auto"``: 1, the photos' resolution (lowered only by a budget with
        ``overflow="scale"``).
    overflow : {"scale", "pages"}, default "scale"
        Under a budget, when the charts do not fit one N x N page at the density (always
        ``"pages"`` with ``atlas_size="auto"``).
    padding : int, default 4
        Texels between a chart and its neighbours' padding (the gap between two charts is
        twice this).
    power_of_two : bool, default False
        Square pages whose side is a power of two; False: one page cut to the charts, its sides
        multiples of 4 (several square pages when they need more than ``atlas_size`` or
        :data:`MAX_AUTO_ATLAS_SIZE`).
    shrink_to_fit : float, default 0.0
        With ``power_of_two``: the largest density reduction (a share, < 0.5) accepted to keep the
        charts on the power of two below the one they need at the asked density (a warning gives
        the factor; ``stats["density_scale"]`` records it). 0: never.
    small_charts : int, default 16
        Charts of at most this many texels on their longer side are packed together in one block
        at ``small_padding`` (:func:`~o3d_seqcc.texturing.blocks.pack_with_block`); 0: each on its own.
    small_padding : int, default 1
        The gutters inside that block.
    pack_effort : {"fast", "best"}, default "fast"
        xatlas's placement search, or every candidate position (``bruteForce``: measured on
        Fountain 300k's charts, coverage 41.8 -> 46.2 %, packing 1.5 -> 7.7 s).

    Returns
    -------
    Packing
        ``txy``: ``t * uv + o`` per chart (x and y swapped in charts xatlas turned), ``o`` integer.

    Raises
    ------
    InputError
        A density that is not positive; with ``overflow="scale"``, charts whose gutters alone do
        not fit the largest atlas.
    """
    return pack_with_block(uv, faces, chart, _pack_charts, small_charts=int(small_charts),
                           small_padding=int(small_padding), atlas_size=atlas_size, texels_per_pixel=texels_per_pixel,
                           overflow=overflow, padding=padding, power_of_two=power_of_two, shrink_to_fit=shrink_to_fit,
                           pack_effort=pack_effort)


def _pack_charts(uv, faces, chart, *, atlas_size, texels_per_pixel, overflow, padding, power_of_two,
                 shrink_to_fit=TextureSettings.shrink_to_fit, pack_effort=TextureSettings.pack_effort,
                 speculate=None) -> Packing:
    """:func:`pack_charts`; ``speculate(packer, t, N, power_of_two)``, given a spare core: the page a sure second
    xatlas call will pack, packed in a child process from the start, or None
    (:func:`~o3d_seqcc.texturing.packing_child.speculative_page`): the same packing sooner."""
    auto = isinstance(texels_per_pixel, str)
    req = 1.0 if auto else float(texels_per_pixel)
    if not req > 0:
        raise InputError(f"texels_per_pixel must be > 0 or 'auto', got {texels_per_pixel!r}")
    sized = isinstance(atlas_size, str)  # "auto": sized to the charts, pages beyond the largest
    if sized:
        overflow = "pages"
    N = MAX_AUTO_ATLAS_SIZE if sized else int(atlas_size)
    if pack_effort not in PACK_EFFORTS:
        raise InputError(f"pack_effort must be one of {', '.join(PACK_EFFORTS)}, got {pack_effort!r}")
    pk = _Packer(uv, faces, chart, padding, effort=pack_effort)
    spec = speculate(pk, req, N, power_of_two) if speculate is not None else None
    try:
        return _pack_sized(pk, req, N, overflow, power_of_two, padding, spec, shrink_to_fit)
    finally:
        if spec is not None:
            spec.cancel()


def _shrunk_onto(pk: _Packer, req: float, size: int, start: float, most: float) -> Packing | None:
    """The charts on a page of side ``size`` at a density reduced by at most ``most`` (from ``start`` down in steps
    of 1 %), with a warning giving the factor; None when even that density does not fit."""
    t = min(req, start)
    while t >= req * (1.0 - most) - 1e-12:
        a, ok = pk.attempt(t, size)
        if ok:
            msg = (f"shrink_to_fit: the charts take a {size}x{size} page at {t:.3g} texels per pixel (density scaled "
                   f"by {t / req:.3f} from {req:g}) instead of a page of twice that side")
            warn(msg)
            return _result(a, pk, t, req, size)
        t *= 0.99
    pk.log.append(f"shrink_to_fit: no {size}x{size} page within {most:.0%} of {req:g} texels per pixel")
    return None


def _pack_sized(pk: _Packer, req: float, N: int, overflow: str, power_of_two: bool, padding: int, spec,
                shrink_to_fit: float = TextureSettings.shrink_to_fit) -> Packing:
    # the charts at the asked density without a size limit (its placement serves any page it fits, see unlimited)
    free = pk.unlimited(req)
    if free is None:
        tight = pk.pack(req, 0)
        tw, th = tight.width, tight.height
    else:
        big, tw, th, R = free
    area_1 = tw * th / (req * req)  # atlas texels they take per unit density^2
    pk.log.append(f"t={req:g}: {tw}x{th} without a size limit")
    sizes = _sizes(N, power_of_two, math.sqrt(area_1) * req / 0.98)
    N = sizes[-1]  # the largest page allowed (a power of two by default)

    def fill(size: int) -> float:  # the density that fills a page of this side (estimate)
        return math.sqrt(size * size / area_1) * 0.98

    if not power_of_two:  # one page cut to the charts: their placement without a limit, no other xatlas call
        side = tight_side(max(tw, th), padding)
        if side <= N:
            a = _OnPage(big, R, side) if free is not None else tight
            if not pk.shrunk(a, req):
                pk.log.append(f"t={req:.4f}: the unlimited placement")
                logger.info("packing: the charts' own page at %.3g texels per pixel", req)
                return _result(a, pk, req, req, side, tight=True)
    k = next((i for i, s_ in enumerate(sizes) if fill(s_) >= req), len(sizes) - 1)
    if power_of_two and shrink_to_fit > 0 and 0 < k and fill(sizes[k - 1]) >= req * (1.0 - shrink_to_fit):
        smaller = _shrunk_onto(pk, req, sizes[k - 1], fill(sizes[k - 1]), shrink_to_fit)
        if smaller is not None:
            return smaller
    t = min(req, fill(sizes[k]))
    for _ in range(60):
        if t < req * 0.999 and k == len(sizes) - 1 and overflow == "pages":
            break
        if free is not None and t == req and max(tw, th) + 1 + pk.largest_chart(t) <= sizes[k]:
            a = _OnPage(big, R, sizes[k])  # the placement xatlas makes on this page: the unlimited one
            ok = not pk.shrunk(a, t)
            pk.log.append(f"t={t:.4f} S={sizes[k]}: 1 page(s){'' if ok else ', chart shrunk'}")
        elif spec is not None and t == req and spec.size == sizes[k]:
            a, ok = pk.attempt(t, sizes[k], spec.result())  # the same xatlas call, made beside the unlimited one
            spec = None
        else:
            a, ok = pk.attempt(t, sizes[k])
        if ok:
            if t < req * 0.999:
                msg = (f"the charts do not fit a {N}x{N} atlas at {req:g} texels per pixel: density scaled by "
                       f"{t / req:.3f} to {t:.3g} texels per pixel (a larger atlas_size, or overflow='pages', "
                       "keeps it)")
                logger.warning(msg)
                warn(msg)
            logger.info("packing: %dx%d atlas at %.3g texels per pixel (%d attempts)", sizes[k], sizes[k], t,
                        len(pk.log) - 1)
            return _result(a, pk, t, req, sizes[k], tight=not power_of_two)
        # the next try: several pages -> shrink by their total use, else a few percent
        used = sum(a.get_utilization(i) for i in range(a.atlas_count))
        shrink = float(np.clip(math.sqrt(0.95 / used), 0.5, 0.95)) if a.atlas_count > 1 and used > 0 else 0.95
        if k < len(sizes) - 1:
            k += 1
            t = req
        elif overflow == "pages":
            break
        else:
            t *= shrink
        if t < 1e-3:
            break
    if overflow != "pages":
        raise InputError(
            f"could not pack {pk.n_charts} charts into a {N}x{N} atlas even at {t:.2g} texels per pixel: their gutters "
            f"({2 * int(padding)} texels between charts) alone need more room; use a larger atlas_size, a smaller "
            "padding, or overflow='pages'")
    # overflow="pages": the asked density in as many N x N pages as needed
    t = req
    for _ in range(60):
        a = pk.pack(t, N)
        if not pk.shrunk(a, t):
            break
        t *= 0.95
    pk.log.append(f"t={t:.4f} S={N}: {a.atlas_count} page(s)")
    if t < req * 0.999:
        warn(f"the largest chart does not fit a {N}x{N} page at {req:g} texels per pixel: density scaled by "
             f"{t / req:.3f} to {t:.3g}")
    logger.info("packing: %d pages of %dx%d at %.3g texels per pixel", a.atlas_count, N, N, t)
    return _result(a, pk, t, req, N)
