"""Sequential pairwise colour correction and the pairwise baselines (paper 3.7, Table 1).

:func:`correct` is the one entry point: it computes the filtered pairwise mappings (unless
given), builds the colour-correction graph and the Dijkstra paths to the reference
(:mod:`o3d_seqcc.graph`), runs a correction method from the registry :data:`METHODS` and
applies the per-view transforms it returns.

Methods (``method=``):

``"seqcc"`` (default, Table 1 #7)
    For every edge (target t -> source s) on a path: per-channel JIH of the colours at the
    pair's mappings (:mod:`o3d_seqcc.jih`) and a CMF fitted on it (:func:`o3d_seqcc.cmf.fit_cmf`,
    CSVR by default, fitted on the JIH's matched marginal quantiles with a contrast guard, so
    misregistered correspondences do not wash the images out). Each directed edge is fitted
    once, however many paths cross it. The CMFs
    along a view's path are composed as lookup tables in floating point
    (``E''' = f_FB(f_BC(f_CE(E)))``) and the image is transformed once (:class:`LutTransform`).
``"seqcc-joint"``
    ``seqcc`` with the paper's literal CMF input (regression on the JIH's joint observations,
    no contrast guard): higher pairwise scores at misregistered mappings, washed-out images
    (see :func:`_method_seqcc_joint`).
``"none"`` (#1)
    Identity.
``"reinhard"`` (#2, Reinhard et al. 2001)
    l-alpha-beta mean / standard deviation transfer, statistics of the colours at each pair's
    mappings, applied step by step along the path.
``"root-polynomial"`` (#3, Finlayson et al. 2015)
    Degree-2 root-polynomial regression: features ``r, g, b, sqrt(rg), sqrt(gb), sqrt(rb)`` ->
    3x6 matrix by least squares on the pair's colours, applied step by step along the path.
``"vandermonde"`` (#4, De Marchi)
    Per-channel cubic polynomial CMF by Vandermonde least squares, composed as lookup tables.

Global baselines (gain compensation, histogram matching) register themselves from
:mod:`o3d_seqcc.baselines` with :func:`register_method`.

A method is ``fn(ctx: CorrectionContext, **options) -> list[Transform]`` (one per view); views
without a path to the reference keep an :class:`IdentityTransform` (they are reported in
:attr:`CorrectionResult.unreachable`, never dropped).
"""

from __future__ import annotations

import importlib
import inspect
import logging
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from .cmf import compose_luts, fit_cmf
from .errors import InputError
from .graph import build_graph, choose_reference, correction_paths, graph_edges, scale_t_npm
from .jih import jih_samples, joint_histogram

__all__ = [
    "METHODS",
    "CorrectionContext",
    "CorrectionResult",
    "FunctionTransform",
    "IdentityTransform",
    "LutTransform",
    "available_methods",
    "correct",
    "register_method",
    "to_float",
    "from_float",
]

logger = logging.getLogger(__name__)

#: name -> ``fn(ctx, **options) -> list[Transform]``
METHODS: dict[str, Callable] = {}


def register_method(name: str, *, needs_graph: bool = True) -> Callable[[Callable], Callable]:
    """Decorator registering a correction method under ``name``.

    Parameters
    ----------
    name : str
        Name used with ``correct(..., method=name)``.
    needs_graph : bool, default True
        When True, :func:`correct` insists on a usable graph (at least one edge, a reference
        with an edge) and raises :class:`InputError` otherwise.
    """

    def deco(fn: Callable) -> Callable:
        fn.needs_graph = needs_graph  # type: ignore[attr-defined]
        METHODS[name] = fn
        return fn

    return deco


def available_methods() -> list[str]:
    """Sorted names of the registered methods (loads :mod:`o3d_seqcc.baselines` if present)."""
    _load_plugins()
    return sorted(METHODS)


def _load_plugins() -> None:
    try:
        importlib.import_module("o3d_seqcc.baselines")
    except ModuleNotFoundError as e:  # the module is optional; other import errors are real
        if e.name != "o3d_seqcc.baselines":
            raise


# --------------------------------------------------------------------------------------------
# transforms
# --------------------------------------------------------------------------------------------


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

    def apply_levels(self, img: np.ndarray) -> np.ndarray:
        """(H, W, 3) uint8/uint16 -> same dtype, equal to ``from_float(apply(to_float(img)))``.

        Tabulates the transform once per integer level (256 or 65536) and indexes: no per-pixel
        interpolation.
        """
        img = np.asarray(img)
        if img.dtype not in (np.uint8, np.uint16) or img.ndim != 3 or img.shape[2] != 3:
            raise ValueError(f"apply_levels expects (H, W, 3) uint8/uint16, got {img.shape} {img.dtype}")
        top = np.iinfo(img.dtype).max
        levels = np.arange(top + 1, dtype=np.float64) / float(top)
        grid = np.linspace(0.0, 1.0, self.lut.shape[1])
        out = np.empty_like(img)
        for c in range(3):
            table = from_float(np.interp(levels, grid, self.lut[c]), img.dtype)
            out[..., c] = table[img[..., c]]
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


# --------------------------------------------------------------------------------------------
# context and result
# --------------------------------------------------------------------------------------------


def to_float(img: np.ndarray) -> np.ndarray:
    """uint8 (/255), uint16 (/65535) or float [0, 1] (H, W, 3) -> float64 [0, 1]."""
    img = np.asarray(img)
    if img.dtype == np.uint8:
        return img.astype(np.float64) / 255.0
    if img.dtype == np.uint16:
        return img.astype(np.float64) / 65535.0
    if np.issubdtype(img.dtype, np.floating):
        return np.clip(np.nan_to_num(img.astype(np.float64), nan=0.0), 0.0, 1.0)
    raise InputError(f"images must be uint8, uint16 or float in [0, 1], got {img.dtype}")


def from_float(img: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """float [0, 1] -> ``dtype`` (uint8 / uint16 rounded and clipped; floats clipped)."""
    dtype = np.dtype(dtype)
    img = np.clip(np.nan_to_num(np.asarray(img, dtype=np.float64), nan=0.0), 0.0, 1.0)
    if dtype == np.uint8:
        return np.rint(img * 255.0).astype(np.uint8)
    if dtype == np.uint16:
        return np.rint(img * 65535.0).astype(np.uint16)
    return img.astype(dtype)


def _sample_bilinear(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    h, w = img.shape[:2]
    u = np.clip(np.asarray(uv[:, 0], dtype=np.float64), 0.0, w - 1.0)
    v = np.clip(np.asarray(uv[:, 1], dtype=np.float64), 0.0, h - 1.0)
    u0 = np.minimum(np.floor(u).astype(np.int64), w - 2) if w > 1 else np.zeros(u.shape, np.int64)
    v0 = np.minimum(np.floor(v).astype(np.int64), h - 2) if h > 1 else np.zeros(v.shape, np.int64)
    du, dv = (u - u0)[:, None], (v - v0)[:, None]
    u1, v1 = np.minimum(u0 + 1, w - 1), np.minimum(v0 + 1, h - 1)
    return (
        img[v0, u0] * (1 - du) * (1 - dv)
        + img[v0, u1] * du * (1 - dv)
        + img[v1, u0] * (1 - du) * dv
        + img[v1, u1] * du * dv
    ).astype(np.float64)


def _sample(img: np.ndarray, uv: np.ndarray, interpolation: str) -> np.ndarray:
    try:
        from .mappings import sample_colors
    except ImportError:  # mappings module not there yet: same bilinear sampling, locally
        return _sample_bilinear(img, uv)
    return np.asarray(sample_colors(img, uv, interpolation=interpolation), dtype=np.float64)


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
    _cache: dict = field(default_factory=dict, repr=False)

    def colors(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """Colours of pair (a, b) at its mappings: ``(ca, cb)``, each (n, 3) float64 in [0, 1].

        Either order of ``a`` and ``b`` works; results are cached.
        """
        a, b = int(a), int(b)
        key = (min(a, b), max(a, b))
        if key not in self._cache:
            pm = self.mappings.pairs.get(key)
            if pm is None:
                raise InputError(f"no pairwise mappings between views {key[0]} and {key[1]}")
            c0 = _sample(self.images[key[0]], np.asarray(pm.uv_a), self.interpolation)
            c1 = _sample(self.images[key[1]], np.asarray(pm.uv_b), self.interpolation)
            self._cache[key] = (c0, c1)
        c0, c1 = self._cache[key]
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
    images : list of (H, W, 3) arrays
        Corrected images, each in its input dtype (uint8 / uint16 rounded and clipped).
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
        Edge threshold used, in the units of the mappings (see :func:`o3d_seqcc.graph.scale_t_npm`).
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


# --------------------------------------------------------------------------------------------
# entry point
# --------------------------------------------------------------------------------------------


def _check_options(fn: Callable, method: str, options: dict) -> None:
    params = inspect.signature(fn).parameters
    if any(p.kind == inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    allowed = sorted(n for n, p in params.items() if p.kind == inspect.Parameter.KEYWORD_ONLY)
    bad = sorted(set(options) - set(allowed))
    if bad:
        raise TypeError(f"correct(method={method!r}) got unknown option(s) {bad}; valid: {allowed}")


def _resolve_reference(scene, graph, reference, names: list[str]) -> int:
    if isinstance(reference, str) and reference == "auto":
        ref = choose_reference(graph)
        logger.info("reference='auto': chose view %d (%s)", ref, names[ref])
        return ref
    if isinstance(reference, (int, np.integer)) and not isinstance(reference, bool):
        if not 0 <= int(reference) < len(names):
            raise InputError(f"reference index {reference} out of range 0..{len(names) - 1}")
        return int(reference)
    if isinstance(reference, str):
        if reference in names:
            return names.index(reference)
        if reference.isdigit() and int(reference) < len(names):
            return int(reference)
    raise InputError(f"unknown reference view {reference!r}; valid: 'auto' or one of: {', '.join(names)}")


def _check_images(images: Sequence[np.ndarray], scene) -> list[np.ndarray]:
    if len(images) != len(scene.views):
        raise InputError(f"got {len(images)} images for {len(scene.views)} views; give one per view")
    out = []
    for v, img in zip(scene.views, images):
        img = np.asarray(img)
        if img.ndim == 2 or (img.ndim == 3 and img.shape[2] == 1):
            raise InputError(f"view {v.name!r}: image is grey-scale; colour correction needs RGB (H, W, 3) images")
        if img.ndim != 3 or img.shape[2] != 3:
            raise InputError(
                f"view {v.name!r}: image has shape {img.shape}; expected (H, W, 3) RGB (drop an alpha channel)"
            )
        if img.shape[:2] != (v.height, v.width):
            raise InputError(
                f"view {v.name!r}: image is {img.shape[1]}x{img.shape[0]} but the scene says {v.width}x{v.height}"
            )
        if not (img.dtype in (np.uint8, np.uint16) or np.issubdtype(img.dtype, np.floating)):
            raise InputError(f"view {v.name!r}: image dtype {img.dtype} unsupported; use uint8, uint16 or float [0, 1]")
        out.append(img)
    return out


def correct(
    scene,
    *,
    reference: str | int = "auto",
    method: str = "seqcc",
    t_npm: int = 400,
    mappings=None,
    mappings_mode: str = "vertices",
    images: Sequence[np.ndarray] | None = None,
    seed: int = 0,
    interpolation: str = "bilinear",
    graph_weight: str = "paper",
    **options,
) -> CorrectionResult:
    """Colour-correct all views of a scene toward a reference view.

    Parameters
    ----------
    scene : o3d_seqcc.Scene
    reference : str or int, default "auto"
        View name, index, or ``"auto"`` (:func:`o3d_seqcc.graph.choose_reference`).
    method : str, default "seqcc"
        A name of :data:`METHODS` (see the module docstring).
    t_npm : int, default 400
        Minimum number of pairwise mappings for a graph edge, in vertex-mapping units (scaled
        for dense mappings by :func:`o3d_seqcc.graph.scale_t_npm`).
    mappings : o3d_seqcc.mappings.Mappings, optional
        Precomputed filtered mappings (default: ``compute_mappings(scene, mode=mappings_mode)``).
    mappings_mode : {"vertices", "dense"}, default "vertices"
    images : list of (H, W, 3) arrays, optional
        Images to correct instead of the scene's files (uint8, uint16 or float [0, 1]).
    seed : int, default 0
    interpolation : {"bilinear", "nearest"}, default "bilinear"
        Colour sampling at the mappings.
    graph_weight : {"paper", "log"}, default "paper"
        Edge weight formula (:func:`o3d_seqcc.graph.build_graph`).
    **options
        Options of the method (e.g. seqcc: ``cmf="csvr"``, ``cmf_options={...}``, ``bits``);
        unknown names raise ``TypeError``.

    Returns
    -------
    CorrectionResult
        Corrected images in the input dtypes; inputs are not modified.

    Raises
    ------
    ValueError
        Unknown method (lists the valid ones).
    TypeError
        Unknown option.
    InputError
        Unknown reference (lists the valid names), no edge left at ``t_npm`` (says the largest
        pair count), a reference without edges, images not matching the scene.
    """
    _load_plugins()
    if method not in METHODS:
        raise ValueError(f"unknown correction method {method!r}; valid: {', '.join(sorted(METHODS))}")
    fn = METHODS[method]
    _check_options(fn, method, options)
    names = list(scene.names)
    n = len(names)
    timings: dict[str, float] = {}

    t0 = time.perf_counter()
    if images is None:
        raw = [v.load_image() for v in scene.views]
    else:
        raw = _check_images(images, scene)
    fimgs = [to_float(im) for im in raw]
    lut_size = 256 if all(im.dtype == np.uint8 for im in raw) else 4096
    timings["load_images"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    if mappings is None:
        from .mappings import compute_mappings

        mappings = compute_mappings(scene, mode=mappings_mode)
    if getattr(mappings, "n_views", n) != n:
        raise InputError(f"mappings are for {mappings.n_views} views but the scene has {n}; recompute them")
    timings["mappings"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    counts = {k: int(v) for k, v in dict(mappings.counts).items()}
    t_eff = scale_t_npm(t_npm, mappings)
    graph = build_graph(counts, n, t_npm=t_eff, weight=graph_weight)
    needs_graph = getattr(fn, "needs_graph", True)
    if needs_graph and graph.number_of_edges() == 0:
        best = max(counts.items(), key=lambda kv: kv[1], default=None)
        if best is None or best[1] == 0:
            raise InputError("no view pair shares any pairwise mapping: the views do not overlap on the mesh")
        (a, b), nmax = best
        raise InputError(
            f"no view pair has t_npm={t_eff} or more mappings (the largest count is {nmax}, between "
            f"{names[a]!r} and {names[b]!r}); lower t_npm to at most {nmax}"
        )
    ref = _resolve_reference(scene, graph, reference, names)
    if needs_graph and graph.degree(ref) == 0:
        own = {(b if a == ref else a): c for (a, b), c in counts.items() if ref in (a, b) and c > 0}
        hint = ""
        if own:
            other, c = max(own.items(), key=lambda kv: kv[1])
            hint = f" (its largest pair count is {c}, with {names[other]!r}, below t_npm={t_eff})"
        raise InputError(
            f"reference view {names[ref]!r} has no edge in the colour-correction graph{hint}; "
            f"choose another reference (e.g. 'auto' -> {names[choose_reference(graph)]!r}) or lower t_npm"
        )
    paths = correction_paths(graph, ref)
    unreachable = [v for v in range(n) if v not in paths]
    if unreachable and needs_graph:
        msg = (
            f"{len(unreachable)} view(s) have no colour-correction path to the reference {names[ref]!r} and stay "
            f"unchanged: {', '.join(names[v] for v in unreachable)} (graph has several components; lower t_npm to join them)"
        )
        logger.warning(msg)
        warnings.warn(msg, stacklevel=2)
    timings["graph"] = time.perf_counter() - t0

    ctx = CorrectionContext(
        images=fimgs,
        mappings=mappings,
        reference=ref,
        t_npm=t_eff,
        seed=int(seed),
        graph=graph,
        paths=paths,
        lut_size=lut_size,
        interpolation=interpolation,
    )
    t0 = time.perf_counter()
    transforms = list(fn(ctx, **options))
    if len(transforms) != n:
        raise RuntimeError(f"method {method!r} returned {len(transforms)} transforms for {n} views")
    timings["fit"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    out = []
    for img, fimg, tr in zip(raw, fimgs, transforms):
        if isinstance(tr, IdentityTransform):
            out.append(np.array(img, copy=True))
        elif isinstance(tr, LutTransform) and img.dtype in (np.uint8, np.uint16):
            out.append(tr.apply_levels(img))
        else:
            out.append(from_float(tr.apply(fimg), img.dtype))
    timings["apply"] = time.perf_counter() - t0
    timings["total"] = float(sum(timings.values()))
    return CorrectionResult(
        images=out,
        transforms=transforms,
        reference=ref,
        paths=paths,
        unreachable=unreachable,
        graph_edges=graph_edges(graph),
        timings=timings,
        method=method,
        t_npm=t_eff,
    )


# --------------------------------------------------------------------------------------------
# methods
# --------------------------------------------------------------------------------------------


@register_method("none", needs_graph=False)
def _method_none(ctx: CorrectionContext) -> list:
    return [IdentityTransform() for _ in ctx.images]


def _path_steps(ctx: CorrectionContext, make_step: Callable[[int, int], Any], *, n_jobs: int | None = None) -> list[list | None]:
    """Per view, the per-edge steps ``make_step(t, s)`` along its path (each directed edge made
    once, even when several paths share it); None for the reference and unreachable views.

    The edges are fitted in joblib threads (``n_jobs``, joblib semantics: None = the active
    ``joblib.parallel_config`` or 1, -1 = all cores); scikit-learn's SVR fit releases the GIL.
    """
    from joblib import Parallel, delayed

    paths = [ctx.paths.get(v) for v in range(len(ctx.images))]
    edges = list(dict.fromkeys((t, s) for p in paths if p is not None for t, s in zip(p[:-1], p[1:])))
    made = Parallel(n_jobs=n_jobs, prefer="threads")(delayed(make_step)(t, s) for t, s in edges)
    cache = dict(zip(edges, made))
    logger.debug("fitted %d directed edge(s) for %d path(s)", len(cache), len(ctx.paths))
    return [
        None if p is None or len(p) < 2 else [cache[(t, s)] for t, s in zip(p[:-1], p[1:])] for p in paths
    ]


def _lut_per_path(
    ctx: CorrectionContext,
    edge_lut: Callable[[int, int], np.ndarray],
    *,
    extrapolate: bool = False,
    n_jobs: int | None = None,
) -> list:
    """Compose per-edge (3, L) tables along every path into one table per view."""
    return [
        IdentityTransform()
        if luts is None
        else LutTransform(
            np.stack([compose_luts([l[c] for l in luts], n_out=ctx.lut_size, extrapolate=extrapolate) for c in range(3)])
        )
        for luts in _path_steps(ctx, edge_lut, n_jobs=n_jobs)
    ]


class _BlurredImages:
    """Lazy read-only sequence of Gaussian-blurred float images (blurred on first access)."""

    def __init__(self, images: Sequence[np.ndarray], sigma: float) -> None:
        self._images, self._sigma, self._cache = images, float(sigma), {}

    def __len__(self) -> int:
        return len(self._images)

    def __getitem__(self, i: int) -> np.ndarray:
        if i not in self._cache:
            import cv2

            s = self._sigma
            self._cache[i] = cv2.GaussianBlur(
                np.asarray(self._images[i], dtype=np.float32), (0, 0), sigmaX=s, sigmaY=s, borderType=cv2.BORDER_REFLECT
            ).astype(np.float64)
        return self._cache[i]


def _fit_context(ctx: CorrectionContext, blur: float) -> CorrectionContext:
    """``ctx`` whose colours are sampled from images blurred by ``blur`` px (0: ctx itself)."""
    if blur <= 0:
        return ctx
    from dataclasses import replace

    return replace(ctx, images=_BlurredImages(ctx.images, blur), _cache={})


def quantile_luts(ct: np.ndarray, cs: np.ndarray, *, n_out: int = 256, levels: int = 256) -> np.ndarray:
    """Per-channel quantile-quantile curves: the target's quantiles mapped to the source's.

    The unweighted counterpart of :func:`o3d_seqcc.cmf.quantile_samples` (same levels, evenly
    spaced in ``[QUANTILE_TRIM, 1 - QUANTILE_TRIM]``, the same plotting positions ``(i + 0.5) /
    n``), on sorted columns instead of weighted sorts (~20x faster), with no regression and no
    guards: a numpy-only estimate of each channel's monotone photometric change.

    Parameters
    ----------
    ct, cs : (n, 3) float arrays in [0, 1]
        Target and source colours at the mappings (n >= 1).
    n_out : int, default 256
        Lookup-table length.
    levels : int, default 256
        Number of quantile levels.

    Returns
    -------
    numpy.ndarray
        (3, n_out) float64, monotone non-decreasing, flat beyond the outer quantiles.
    """
    from .cmf import QUANTILE_TRIM

    xs = np.sort(np.asarray(ct, dtype=np.float64), axis=0)
    ys = np.sort(np.asarray(cs, dtype=np.float64), axis=0)
    pos = (np.arange(len(xs)) + 0.5) / max(len(xs), 1)
    q = np.linspace(QUANTILE_TRIM, 1.0 - QUANTILE_TRIM, int(levels))
    grid = np.linspace(0.0, 1.0, int(n_out))
    out = np.empty((3, grid.size))
    for c in range(3):
        xq = np.interp(q, pos, xs[:, c])
        xq = np.maximum.accumulate(xq) + np.arange(q.size) * 1e-9  # strictly increasing for interp
        out[c] = np.interp(grid, xq, np.interp(q, pos, ys[:, c]))
    return out


def colour_inliers(ct: np.ndarray, cs: np.ndarray, lut: np.ndarray, *, k: float = 3.0) -> np.ndarray:
    """Mask of mappings whose colours agree with per-channel curves, jointly over the channels.

    The residual of every mapping's source colour against the target colour mapped by ``lut``
    is measured per channel in robust standard deviations (1.4826 MAD, at least 1/255) and
    summed in quadrature; a mapping is an outlier when that norm exceeds ``k * sqrt(3)``.
    Joint over the channels, so a wrong correspondence pairing two differently coloured
    surfaces (a maroon tile with grey stone) is caught even when each channel alone stays
    within its column's spread.

    Parameters
    ----------
    ct, cs : (n, 3) float arrays in [0, 1]
        Target and source colours at the mappings.
    lut : (3, L) float array
        Per-channel curves predicting the source colour from the target's (e.g.
        :func:`quantile_luts`).
    k : float, default 3.0

    Returns
    -------
    numpy.ndarray
        (n,) bool.
    """
    from .cmf import apply_lut

    ct = np.asarray(ct, dtype=np.float64)
    cs = np.asarray(cs, dtype=np.float64)
    if len(ct) < 10:
        return np.ones(len(ct), dtype=bool)
    r = cs - np.stack([apply_lut(lut[c], ct[:, c]) for c in range(3)], axis=1)
    med = np.median(r, axis=0)
    mad = 1.4826 * np.median(np.abs(r - med), axis=0)
    z = (r - med) / np.maximum(mad, 1.0 / 255)
    return np.sqrt((z**2).sum(1)) <= k * np.sqrt(3.0)


@register_method("seqcc")
def _method_seqcc(
    ctx: CorrectionContext,
    *,
    cmf: str = "csvr",
    cmf_options: dict | None = None,
    bits: int | None = None,
    jih_blur: float = 0.0,
    outlier_k: float | None = 3.0,
    n_jobs: int | None = None,
) -> list:
    """Sequential pairwise correction with JIH + CMF per path edge (paper 3.5-3.7).

    ``n_jobs`` (joblib semantics, threads): edges fitted in parallel; None = the active
    ``joblib.parallel_config`` or 1.

    Options: ``cmf`` (a :data:`o3d_seqcc.cmf.CMF_METHODS` name), ``cmf_options`` (passed to
    :func:`o3d_seqcc.cmf.fit_cmf`), ``bits`` (JIH bit depth; default 8 for 8-bit input, 10
    otherwise), ``jih_blur`` (default 0: Gaussian sigma in pixels applied to both images before
    their colours are sampled at the mappings for the JIH, e.g. about the registration error;
    it averages out the unrelated texture detail misregistration pairs. Off by default: with
    the default quantile pairing of :func:`o3d_seqcc.cmf.fit_cmf` misregistration no longer
    flattens the CMF (fountain: CIEDE2000 6.87 without, 6.82 with 2 px), while blurring before a
    non-linear tone curve does not commute with it (synthetic room, CIEDE2000 to ground truth
    1.49 -> 2.56 with 2 px)). The correction itself is applied to the unblurred images.
    ``outlier_k`` (default 3.0; None disables): mappings whose colours disagree with the edge's
    quantile-quantile curve (:func:`quantile_luts`) by more than ``outlier_k`` robust sigmas
    jointly over the three channels (:func:`colour_inliers`) are dropped before the JIH and the
    CMF fit. Wrong correspondences
    (occlusions the filters missed, gross misregistration) pair differently coloured surfaces;
    in a sparse tail of the value range a handful of them bend one channel's CMF and tint the
    shadows (fountain views 27-28 turned magenta). Measured (``benchmarks/table2.py``):
    synthetic room, CIEDE2000 to ground truth 1.06 -> 1.17 with clean correspondences and
    1.86 -> 1.69 with 0.5 deg pose error; fountain pairwise CIEDE2000 6.89 -> 6.86.
    """
    opts = dict(cmf_options or {})
    b = int(bits) if bits is not None else (8 if ctx.lut_size <= 256 else 10)
    if float(jih_blur) < 0:
        raise ValueError(f"jih_blur must be >= 0 (pixels), got {jih_blur}")
    if outlier_k is not None and not float(outlier_k) > 0:
        raise ValueError(f"outlier_k must be > 0 (robust sigmas) or None, got {outlier_k}")
    fctx = _fit_context(ctx, float(jih_blur))

    def fit(ct: np.ndarray, cs: np.ndarray) -> np.ndarray:
        jih = joint_histogram(ct, cs, bits=b)
        rows = []
        for c in range(3):
            x, y, w = jih_samples(jih[c])
            rows.append(fit_cmf(x, y, weights=w, method=cmf, n_out=ctx.lut_size, **opts))
        return np.stack(rows)

    def edge_lut(t: int, s: int) -> np.ndarray:
        ct, cs = fctx.colors(t, s)
        if outlier_k is None:
            return fit(ct, cs)
        # the outlier pass only needs the curve's shape: the quantile-quantile curve (numpy only)
        keep = colour_inliers(ct, cs, quantile_luts(ct, cs, n_out=ctx.lut_size), k=float(outlier_k))
        return fit(ct[keep], cs[keep])

    return _lut_per_path(ctx, edge_lut, extrapolate=not opts.get("clamp", True), n_jobs=n_jobs)


@register_method("seqcc-joint")
def _method_seqcc_joint(
    ctx: CorrectionContext,
    *,
    cmf: str = "csvr",
    cmf_options: dict | None = None,
    bits: int | None = None,
    jih_blur: float = 0.0,
    outlier_k: float | None = None,
    n_jobs: int | None = None,
) -> list:
    """``seqcc`` with the paper's literal CMF input: regression on the JIH's joint observations.

    Same as ``method="seqcc"`` with ``cmf_options={"pairing": "joint", "contrast_guard": None}``
    (further ``cmf_options`` override these) and without the outlier pass (``outlier_k=None``;
    the paper has none). The regression of the source value on the
    target value estimates the conditional mean, which on misregistered correspondences is
    flattened toward the mean (regression dilution) and compounds along the paths: it scores
    higher on pairwise PSNR / CIEDE2000 at those same correspondences, but washes the images
    out and moves them away from the true colours (``benchmarks/table2.py``: synthetic room with
    0.5 deg pose error (~2 px), CIEDE2000 to ground truth 10.5 uncorrected, seqcc 1.7,
    seqcc-joint 9.2 -- while its pairwise PSNR at the misregistered mappings is 3.8 dB higher).
    Kept for comparison with the paper.
    """
    opts = {"pairing": "joint", "contrast_guard": None, **dict(cmf_options or {})}
    return _method_seqcc(ctx, cmf=cmf, cmf_options=opts, bits=bits, jih_blur=jih_blur, outlier_k=outlier_k, n_jobs=n_jobs)


@register_method("vandermonde")
def _method_vandermonde(ctx: CorrectionContext, *, degree: int = 3) -> list:
    """Per-channel polynomial CMF (Vandermonde least squares, De Marchi), composed along paths."""

    def edge_lut(t: int, s: int) -> np.ndarray:
        ct, cs = ctx.colors(t, s)
        return np.stack(
            [
                fit_cmf(
                    ct[:, c], cs[:, c], method="polynomial", degree=degree, guard=False, pairing="joint", n_out=ctx.lut_size
                )
                for c in range(3)
            ]
        )

    return _lut_per_path(ctx, edge_lut)


def _sequential(ctx: CorrectionContext, make_step: Callable[[int, int], Callable[[np.ndarray], np.ndarray]]) -> list:
    """FunctionTransforms applying per-edge colour transforms in order along each path."""

    def chain(steps: list) -> FunctionTransform:
        def fn(img: np.ndarray, steps=tuple(steps)) -> np.ndarray:
            shape = img.shape
            x = img.reshape(-1, 3)
            for st in steps:
                x = np.clip(st(x), 0.0, 1.0)
            return x.reshape(shape)

        return FunctionTransform(fn)

    return [IdentityTransform() if steps is None else chain(steps) for steps in _path_steps(ctx, make_step)]


# Reinhard et al. 2001 l-alpha-beta
_RGB2LMS = np.array([[0.3811, 0.5783, 0.0402], [0.1967, 0.7244, 0.0782], [0.0241, 0.1288, 0.8444]])
_LMS2RGB = np.linalg.inv(_RGB2LMS)
_LMS2LAB = np.diag([1 / np.sqrt(3), 1 / np.sqrt(6), 1 / np.sqrt(2)]) @ np.array([[1, 1, 1], [1, 1, -2], [1, -1, 0]])
_LAB2LMS = np.linalg.inv(_LMS2LAB)
_LOG_EPS = 1.0 / 510.0  # half an 8-bit level: keeps log10 finite on black pixels


def rgb_to_lab_reinhard(rgb: np.ndarray) -> np.ndarray:
    """(n, 3) RGB in [0, 1] -> (n, 3) Reinhard l-alpha-beta (log10 LMS, decorrelated)."""
    lms = np.maximum(np.asarray(rgb, dtype=np.float64) @ _RGB2LMS.T, _LOG_EPS)
    return np.log10(lms) @ _LMS2LAB.T


def lab_reinhard_to_rgb(lab: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rgb_to_lab_reinhard` (not clipped)."""
    return (10.0 ** (np.asarray(lab, dtype=np.float64) @ _LAB2LMS.T)) @ _LMS2RGB.T


@register_method("reinhard")
def _method_reinhard(ctx: CorrectionContext) -> list:
    """Reinhard et al. (2001) mean/std transfer in l-alpha-beta, per path edge, sequentially."""

    def make_step(t: int, s: int):
        ct, cs = ctx.colors(t, s)
        lt, ls = rgb_to_lab_reinhard(ct), rgb_to_lab_reinhard(cs)
        mt, ms = lt.mean(0), ls.mean(0)
        st, ss = lt.std(0), ls.std(0)
        ratio = np.where(st > 1e-6, ss / np.where(st > 1e-6, st, 1.0), 1.0)

        def step(x: np.ndarray) -> np.ndarray:
            return lab_reinhard_to_rgb((rgb_to_lab_reinhard(x) - mt) * ratio + ms)

        return step

    return _sequential(ctx, make_step)


def root_polynomial_features(rgb: np.ndarray) -> np.ndarray:
    """(n, 3) RGB in [0, 1] -> (n, 6) degree-2 root-polynomial terms r, g, b, sqrt(rg), sqrt(gb), sqrt(rb)."""
    rgb = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, None)
    r, g, b = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    return np.stack([r, g, b, np.sqrt(r * g), np.sqrt(g * b), np.sqrt(r * b)], axis=1)


@register_method("root-polynomial")
def _method_root_polynomial(ctx: CorrectionContext) -> list:
    """Finlayson et al. (2015) degree-2 root-polynomial regression per path edge, sequentially."""

    def make_step(t: int, s: int):
        ct, cs = ctx.colors(t, s)
        M, *_ = np.linalg.lstsq(root_polynomial_features(ct), cs, rcond=None)  # (6, 3)

        def step(x: np.ndarray) -> np.ndarray:
            return root_polynomial_features(x) @ M

        return step

    return _sequential(ctx, make_step)
