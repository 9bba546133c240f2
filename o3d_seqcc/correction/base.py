"""The correction framework: colour transforms, the context a method sees.

A correction method is ``fn(ctx: CorrectionContext, **options) -> list[Transform]`` (one
transform per view); the method modules (:mod:`~o3d_seqcc.correction.methods`) import this module,
and their table :data:`~o3d_seqcc.correction.methods.METHODS` names each one (written out there,
extended with :func:`~o3d_seqcc.correction.register_method`). Views without a path to the
reference keep an :class:`IdentityTransform`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Sequence

import numpy as np

from .luts import compose_luts
from ..errors import InputError
from ..imaging.arrays import img_as_dtype, img_as_float, sample_colors
from ..imaging.sequences import ImageSequence, LRUCache, default_cache_bytes, image_dtypes
from .._shared.parallel import current as current_executor

__all__ = [
    "DEFAULT_METHOD",
    "COLOUR_CACHE_BYTES",
    "OUT_OF_LINE_LEVELS",
    "OUT_OF_LINE_RATIO",
    "CorrectedImages",
    "CorrectionContext",
    "CorrectionResult",
    "FunctionTransform",
    "IdentityTransform",
    "LutTransform",
    "Transform",
    "apply_transform",
    "fit_context",
    "lut_per_path",
    "path_steps",
    "sequential",
]

logger = logging.getLogger(__name__)

#: method of :func:`o3d_seqcc.correction.correct` (and every entry point) when none is given: the
#: measured best (README, ``benchmarks/table2.py``); ``"seqcc"`` is the paper's
DEFAULT_METHOD = "seqcc-global"
#: a view whose edges still differ by more than this many 8-bit levels (root mean square of their matched
#: quantiles, on average over its edges) after the correction, and by more than :data:`OUT_OF_LINE_RATIO` times
#: the median view's, is reported as not brought in line (Fountain 300k: views 3.0-7.0, median 4.6)
OUT_OF_LINE_LEVELS = 2.0
OUT_OF_LINE_RATIO = 1.5
#: byte budget of a context's cache of the colours sampled at each pair's mappings
COLOUR_CACHE_BYTES = 64 * 2**20


def _check_float_image(img: np.ndarray) -> np.ndarray:
    img = np.asarray(img, dtype=np.float64)
    if img.ndim < 1 or img.shape[-1] != 3:
        raise ValueError(f"expected (..., 3) colours in [0, 1], got shape {img.shape}")
    return img


@dataclass(frozen=True, eq=False)
class LutTransform:
    """Per-channel lookup tables.

    Attributes
    ----------
    lut : (3, L) float64 in [0, 1]
        ``lut[c, i]`` is the output of channel c for input ``i / (L - 1)``; values in between
        are interpolated linearly.
    """

    lut: np.ndarray

    def __post_init__(self) -> None:
        lut = np.array(self.lut, dtype=np.float64, copy=True)
        if lut.ndim != 2 or lut.shape[0] != 3 or lut.shape[1] < 2:
            raise ValueError(f"LutTransform.lut must be (3, L) with L >= 2, got {lut.shape}")
        if not np.all(np.isfinite(lut)):
            raise ValueError("LutTransform.lut contains NaN/inf")
        lut = np.clip(lut, 0.0, 1.0)
        lut.setflags(write=False)
        object.__setattr__(self, "lut", lut)

    def apply(self, img: np.ndarray) -> np.ndarray:
        """(..., 3) float in [0, 1] -> (..., 3) float64 in [0, 1]."""
        img = _check_float_image(img)
        grid = np.linspace(0.0, 1.0, self.lut.shape[1])
        out = np.empty(img.shape, dtype=np.float64)
        for c in range(3):
            out[..., c] = np.interp(img[..., c], grid, self.lut[c])
        return out

    def level_tables(self, dtype: np.dtype | type) -> np.ndarray:
        """(3, 256) uint8 or (3, 65536) uint16: every integer level of ``dtype`` through the transform,
        ``img_as_dtype(apply(level / top))`` (computed once per dtype)."""
        dtype = np.dtype(dtype)
        cache = self.__dict__.setdefault("_level_tables", {})  # not a field: frozen, compared by identity
        if dtype not in cache:
            top = np.iinfo(dtype).max
            levels = np.arange(top + 1, dtype=np.float64) / float(top)
            grid = np.linspace(0.0, 1.0, self.lut.shape[1])
            cache[dtype] = np.stack([img_as_dtype(np.interp(levels, grid, self.lut[c]), dtype) for c in range(3)])
        return cache[dtype]

    def apply_levels(self, img: np.ndarray) -> np.ndarray:
        """(H, W, 3) uint8/uint16 -> same dtype, equal to ``img_as_dtype(apply(img_as_float(img)))``.

        Tabulates the transform once per integer level (256 or 65536, :meth:`level_tables`) and looks
        every pixel up (OpenCV's ``LUT`` for uint8): no per-pixel interpolation.
        """
        img = np.asarray(img)
        if img.dtype not in (np.uint8, np.uint16) or img.ndim != 3 or img.shape[2] != 3:
            raise ValueError(f"apply_levels expects (H, W, 3) uint8/uint16, got {img.shape} {img.dtype}")
        tables = self.level_tables(img.dtype)
        if img.dtype == np.uint8 and img.size:
            import cv2

            return cv2.LUT(np.ascontiguousarray(img), np.ascontiguousarray(tables.T).reshape(1, 256, 3))
        out = np.empty_like(img)
        for c in range(3):
            out[..., c] = np.take(tables[c], img[..., c])
        return out


@dataclass(frozen=True, eq=False)
class FunctionTransform:
    """Any colour transform ``fn((..., 3) in [0, 1]) -> (..., 3)``; the output is clipped to [0, 1]."""

    fn: Callable[[np.ndarray], np.ndarray]

    def apply(self, img: np.ndarray) -> np.ndarray:
        """(..., 3) float in [0, 1] -> (..., 3) float64 in [0, 1] (NaN -> 0)."""
        img = _check_float_image(img)
        out = np.asarray(self.fn(img), dtype=np.float64)
        if out.shape != img.shape:
            raise ValueError(f"FunctionTransform changed the shape {img.shape} -> {out.shape}")
        return np.clip(np.nan_to_num(out, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)


@dataclass(frozen=True, eq=False)
class IdentityTransform:
    """Leaves the image unchanged."""

    def apply(self, img: np.ndarray) -> np.ndarray:
        """Returns a float64 copy of ``img``."""
        return np.array(_check_float_image(img), dtype=np.float64, copy=True)


Transform = LutTransform | FunctionTransform | IdentityTransform


def apply_transform(tr: Transform, img: np.ndarray) -> np.ndarray:
    """One view's corrected image in its input dtype (what :func:`~o3d_seqcc.correction.correct` returns).

    Identity: a copy; a lookup table on uint8 / uint16: :meth:`LutTransform.apply_levels`;
    otherwise the transform on the float image, converted back (rounded, clipped).
    """
    img = np.asarray(img)
    if isinstance(tr, IdentityTransform):
        return np.array(img, copy=True)
    if isinstance(tr, LutTransform) and img.dtype in (np.uint8, np.uint16):
        return tr.apply_levels(img)
    return img_as_dtype(tr.apply(img_as_float(img)), img.dtype)


class CorrectedImages(ImageSequence):
    """Lazy corrected images: ``images[v]`` is ``apply_transform(transforms[v], originals[v])``,
    computed on every access (nothing is kept)."""

    def __init__(self, originals, transforms: list) -> None:
        if len(originals) != len(transforms):
            raise ValueError(f"{len(originals)} images for {len(transforms)} transforms")
        self.originals = originals
        self.transforms = list(transforms)

    def __len__(self) -> int:
        return len(self.transforms)

    def _load(self, i: int) -> np.ndarray:
        return apply_transform(self.transforms[i], self.originals[i])

    def dtypes(self) -> list[np.dtype]:
        return image_dtypes(self.originals)


@dataclass(frozen=True, eq=False)
class CorrectionContext:
    """Everything a correction method sees.

    Attributes
    ----------
    images : list of (H, W, 3) float64 in [0, 1]
        The input images (do not modify).
    mappings : o3d_seqcc.mappings.Mappings
        Filtered pairwise mappings.
    reference : int
        Reference view index.
    t_npm : int
        Edge threshold actually used (in the units of ``mappings``).
    seed : int
        Seed for any randomness.
    graph : networkx.Graph or None
        Colour-correction graph.
    paths : dict[int, list[int]]
        ``view -> [view, ..., reference]``; unreachable views are absent.
    lut_size : int
        Lookup-table length suited to the input bit depth (256 for 8-bit, 4096 for 16-bit/float).
    interpolation : str
        Colour sampling at mappings ("bilinear" or "nearest").
    edge_luts : dict[(int, int), (3, L) array]
        Filled by :func:`lut_per_path`: the lookup table of every directed path edge
        ``(target, source)``, before composition (what the report plots, paper Figure 7).
    edge_residuals : dict[(int, int), (float, float)]
        Filled by the methods that measure it (``seqcc-global``): per graph edge ``(a, b)`` with
        ``a < b``, how far apart the pair's two photos are over their shared surface before and
        after the correction (root-mean-square difference of their matched quantiles, in 8-bit
        levels).
    """

    images: list
    mappings: Any
    reference: int
    t_npm: int
    seed: int = 0
    graph: Any = None
    paths: dict = field(default_factory=dict)
    lut_size: int = 256
    interpolation: str = "bilinear"
    edge_luts: dict = field(default_factory=dict)
    edge_residuals: dict = field(default_factory=dict)
    _cache: Any = field(default_factory=lambda: LRUCache(COLOUR_CACHE_BYTES), repr=False)

    def colors(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """Colours of pair (a, b) at its mappings: ``(ca, cb)``, each (n, 3) float64 in [0, 1].

        Either order of ``a`` and ``b`` works; results are cached (least recently used pairs
        dropped beyond :data:`COLOUR_CACHE_BYTES`). The pair's mappings are built and its two
        images read when first asked for.
        """
        a, b = int(a), int(b)
        key = (min(a, b), max(a, b))
        hit = self._cache.get(key)
        if hit is None:
            pm = self.mappings.pairs.get(key)
            if pm is None:
                raise InputError(f"no pairwise mappings between views {key[0]} and {key[1]}")
            c0 = sample_colors(self.images[key[0]], np.asarray(pm.uv_a), interpolation=self.interpolation)
            c1 = sample_colors(self.images[key[1]], np.asarray(pm.uv_b), interpolation=self.interpolation)
            hit = (c0, c1)
            self._cache[key] = hit
        c0, c1 = hit
        return (c0, c1) if a <= b else (c1, c0)

    def path_edges(self) -> list[tuple[int, int]]:
        """Directed edges ``(target, source)`` used by the paths, each once, in a stable order."""
        seen: dict[tuple[int, int], None] = {}
        for v in sorted(self.paths):
            p = self.paths[v]
            for t, s in zip(p[:-1], p[1:]):
                seen.setdefault((t, s), None)
        return list(seen)


@dataclass(frozen=True, eq=False)
class CorrectionResult:
    """Output of :func:`correct`.

    Attributes
    ----------
    images : list of (H, W, 3) arrays, or CorrectedImages
        Corrected images, each in its input dtype (uint8 / uint16 rounded and clipped); a lazy
        :class:`CorrectedImages` (computed on access) when the input images were a lazy
        :class:`~o3d_seqcc.imaging.sequences.ImageSequence`.
    transforms : list of transforms
        One per view (:class:`LutTransform`, :class:`FunctionTransform`, :class:`IdentityTransform`).
    reference : int
        Reference view index.
    paths : dict[int, list[int]]
        Correction path per reachable view.
    unreachable : list[int]
        Views without a path to the reference (left unchanged by path-based methods).
    graph_edges : list of dict
        ``{"a", "b", "n", "weight"}`` per graph edge.
    timings : dict[str, float]
        Seconds per stage.
    method : str
    t_npm : int
        Edge threshold used, in the units of the mappings (pixels of shared surface for surface
        mappings; see :func:`o3d_seqcc.correction.graph.resolve_t_npm`).
    edge_luts : dict[(int, int), (3, L) float64]
        Per directed path edge ``(target, source)``: the colour mapping function fitted on it
        (R, G, B lookup tables over L evenly spaced inputs), for the methods that compose lookup
        tables along the paths (``seqcc``, ``seqcc-joint``, ``vandermonde``); empty otherwise.
    edge_residuals : dict[(int, int), (float, float)]
        Per graph edge ``(a, b)``, ``a < b``: the pair's residual before and after the correction,
        in 8-bit levels (:attr:`CorrectionContext.edge_residuals`; ``seqcc-global``); empty for the
        methods that do not measure it.
    settings : dict
        The arguments of :func:`~o3d_seqcc.correction.correct` that, with the same images and
        mappings, give this result again: ``t_npm`` (as given: ``"auto"`` or a number), ``seed``,
        ``interpolation``, ``graph_weight`` and ``options`` (the method's).
    """

    images: list
    transforms: list
    reference: int
    paths: dict
    unreachable: list
    graph_edges: list
    timings: dict
    method: str
    t_npm: int = 400
    edge_luts: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)
    edge_residuals: dict = field(default_factory=dict)

    def out_of_line(self, *, levels: float = OUT_OF_LINE_LEVELS, ratio: float = OUT_OF_LINE_RATIO) -> list[int]:
        """Views the correction could not bring in line: those (but the reference) whose edges, after it, still
        differ on average by more than ``levels`` 8-bit levels and by more than ``ratio`` times the median view's
        average (real photos keep a few levels of residual everywhere: misregistration, view-dependent light);
        empty when the method measured no residuals."""
        total: dict[int, list[float]] = {}
        for (a, b), (_, after) in self.edge_residuals.items():
            total.setdefault(int(a), []).append(float(after))
            total.setdefault(int(b), []).append(float(after))
        means = {v: float(np.mean(r)) for v, r in total.items() if v != self.reference}
        if not means:
            return []
        bound = max(float(levels), float(ratio) * float(np.median(list(means.values()))))
        return sorted(v for v, m in means.items() if m > bound)


def _edge_task(edge: tuple[int, int], make_step: Callable[[int, int], Any]) -> Any:
    return make_step(*edge)


def path_steps(ctx: CorrectionContext, make_step: Callable[[int, int], Any], *, n_jobs: int | None = None) -> list[list | None]:
    """Per view, the per-edge steps ``make_step(t, s)`` along its path (each directed edge made
    once, even when several paths share it); None for the reference and unreachable views.

    One task per edge on the active executor (:mod:`o3d_seqcc._shared.parallel`): joblib threads
    (``n_jobs``, joblib semantics: None = the active ``joblib.parallel_config`` or 1, -1 = all
    cores; scikit-learn's SVR fit releases the GIL), or a Dask cluster, to which ``make_step``
    (with the context it closes over: the visibility records, the image references) is
    scattered once. Results come back in edge order, whatever finishes first.
    """
    paths = [ctx.paths.get(v) for v in range(len(ctx.images))]
    edges = list(dict.fromkeys((t, s) for p in paths if p is not None for t, s in zip(p[:-1], p[1:])))
    ex = current_executor(n_jobs)
    made = ex.map(_edge_task, edges, ex.share(make_step) if edges else None, desc="fit edges", unit="edge")
    cache = dict(zip(edges, made))
    logger.debug("fitted %d directed edge(s) for %d path(s)", len(cache), len(ctx.paths))
    return [
        None if p is None or len(p) < 2 else [cache[(t, s)] for t, s in zip(p[:-1], p[1:])] for p in paths
    ]


def lut_per_path(
    ctx: CorrectionContext,
    edge_lut: Callable[[int, int], np.ndarray],
    *,
    extrapolate: bool = False,
    n_jobs: int | None = None,
) -> list:
    """Compose per-edge (3, L) tables along every path into one table per view.

    The per-edge tables are also kept in ``ctx.edge_luts`` (``(target, source) -> (3, L)``).
    """
    steps = path_steps(ctx, edge_lut, n_jobs=n_jobs)
    for v, luts in enumerate(steps):
        p = ctx.paths.get(v) if luts else None
        for t, s, lut in zip(p[:-1], p[1:], luts) if p else ():
            ctx.edge_luts.setdefault((int(t), int(s)), np.asarray(lut, dtype=np.float64))
    return [
        IdentityTransform()
        if luts is None
        else LutTransform(
            np.stack([compose_luts([l[c] for l in luts], n_out=ctx.lut_size, extrapolate=extrapolate) for c in range(3)])
        )
        for luts in steps
    ]


class _BlurredImages(ImageSequence):
    """Lazy read-only sequence of Gaussian-blurred float images (blurred on access, LRU-cached)."""

    def __init__(self, images: Sequence[np.ndarray], sigma: float) -> None:
        self._images, self._sigma = images, float(sigma)
        self._cache = LRUCache(default_cache_bytes())

    def __len__(self) -> int:
        return len(self._images)

    def _load(self, i: int) -> np.ndarray:
        def blur() -> np.ndarray:
            import cv2

            s = self._sigma
            return cv2.GaussianBlur(np.asarray(self._images[i], dtype=np.float32), (0, 0), sigmaX=s, sigmaY=s,
                                    borderType=cv2.BORDER_REFLECT).astype(np.float64)

        return self._cache.get(i, blur)


def fit_context(ctx: CorrectionContext, blur: float) -> CorrectionContext:
    """``ctx`` whose colours are sampled from images blurred by ``blur`` px (0: ctx itself)."""
    if blur <= 0:
        return ctx
    return replace(ctx, images=_BlurredImages(ctx.images, blur), _cache=LRUCache(COLOUR_CACHE_BYTES))


def sequential(ctx: CorrectionContext, make_step: Callable[[int, int], Callable[[np.ndarray], np.ndarray]]) -> list:
    """FunctionTransforms applying per-edge colour transforms in order along each path."""

    def chain(steps: list) -> FunctionTransform:
        def fn(img: np.ndarray, steps=tuple(steps)) -> np.ndarray:
            shape = img.shape
            x = img.reshape(-1, 3)
            for st in steps:
                x = np.clip(st(x), 0.0, 1.0)
            return x.reshape(shape)

        return FunctionTransform(fn)

    return [IdentityTransform() if steps is None else chain(steps) for steps in path_steps(ctx, make_step)]
