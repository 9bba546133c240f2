"""Colour correction of all views toward a reference (paper 3.3-3.7, Table 1).

:func:`correct` is the one entry point: it computes the filtered pairwise mappings (unless
given), builds the colour-correction graph and the Dijkstra paths to the reference
(:mod:`o3d_seqcc.correction.graph`), runs a method from the registry :data:`METHODS` and applies the
per-view transforms it returns. The methods, one module per family:

- :mod:`~o3d_seqcc.correction.methods.seqcc_global`: ``"seqcc-global"`` (:data:`DEFAULT_METHOD`:
  ``seqcc``'s sequential estimate refined jointly over every graph edge, curves continued over
  the whole value range; its steps in :mod:`~o3d_seqcc.correction.methods.edge_summaries` and
  :mod:`~o3d_seqcc.correction.methods.joint_curves`);
- :mod:`~o3d_seqcc.correction.methods.seqcc`: ``"seqcc"`` (the paper's #7, contrast-keeping CMF fit)
  and ``"seqcc-joint"`` (the paper's literal joint-histogram regression);
- :mod:`~o3d_seqcc.correction.methods.pairwise`: ``"none"``, ``"reinhard"``, ``"root-polynomial"``,
  ``"vandermonde"`` (#1-#4, per path edge);
- :mod:`~o3d_seqcc.correction.methods.global_methods`: ``"gain-compensation"``,
  ``"histogram-matching"`` (#5-#6, over all pairs at once).

Its options and their defaults are :class:`~o3d_seqcc.correction.settings.CorrectionSettings`.
Unknown method names raise ``InputError`` (a ``ValueError``) listing the valid ones; unknown
options ``TypeError``.
"""

from __future__ import annotations

import logging
import time
from typing import Sequence

import numpy as np

from ..errors import InputError, warn
from .graph import (
    build_graph,
    check_t_npm,
    choose_reference,
    correction_paths,
    graph_edges,
    resolve_t_npm,
    t_npm_units,
)
from ..imaging.sequences import FloatImages, ImageSequence, image_dtypes
from ..scene import resolve_view
from .methods import METHODS, available_methods, register_method
from .settings import CorrectionSettings
from .base import (
    DEFAULT_METHOD,
    CorrectedImages,
    CorrectionContext,
    CorrectionResult,
    FunctionTransform,
    IdentityTransform,
    LutTransform,
    Transform,
    apply_transform,
)
from .._shared.lazy import lazy_exports

__all__ = ["DEFAULT_METHOD", "METHODS", "CorrectedImages", "CorrectionContext", "CorrectionResult", "CorrectionSettings",
           "FunctionTransform",
           "IdentityTransform", "LutTransform", "Transform", "apply_transform", "available_methods", "check_method",
           "correct", "register_method"]

logger = logging.getLogger(__name__)


def check_method(method: str, *, t_npm: int | str | None = None) -> None:
    """Raise ``InputError`` for an unknown ``method`` (listing the valid names) or a ``t_npm`` that is neither
    ``"auto"`` nor a positive integer (None: not checked)."""
    METHODS.check(method)
    if t_npm is not None:
        check_t_npm(t_npm)


def _check_images(images: Sequence[np.ndarray], names: list[str], sizes: list[tuple[int, int]] | None) -> list[np.ndarray]:
    if len(images) != len(names):
        raise InputError(f"got {len(images)} images for {len(names)} views; give one per view")
    out = []
    for k, (name, img) in enumerate(zip(names, images)):
        img = np.asarray(img)
        if img.ndim == 2 or (img.ndim == 3 and img.shape[2] == 1):
            raise InputError(f"view {name!r}: image is grey-scale; colour correction needs RGB (H, W, 3) images")
        if img.ndim != 3 or img.shape[2] != 3:
            raise InputError(f"view {name!r}: image has shape {img.shape}; expected (H, W, 3) RGB (drop an alpha channel)")
        if sizes is not None and img.shape[:2] != (sizes[k][1], sizes[k][0]):
            raise InputError(
                f"view {name!r}: image is {img.shape[1]}x{img.shape[0]} but the scene says {sizes[k][0]}x{sizes[k][1]}"
            )
        if not (img.dtype in (np.uint8, np.uint16) or np.issubdtype(img.dtype, np.floating)):
            raise InputError(f"view {name!r}: image dtype {img.dtype} unsupported; use uint8, uint16 or float [0, 1]")
        out.append(img)
    return out


def correct(
    scene=None,
    *,
    mappings=None,
    images: Sequence[np.ndarray] | None = None,
    settings: CorrectionSettings | None = None,
    **options,
) -> CorrectionResult:
    """Colour-correct all views toward a reference view.

    Parameters
    ----------
    scene : o3d_seqcc.Scene, optional
        The scene; may be omitted when both ``images`` and ``mappings`` are given (views are
        then named by ``mappings.view_names`` or their index).
    mappings : Mappings or {"surface", "vertices", "dense"}, optional
        Precomputed filtered mappings (:class:`~o3d_seqcc.mappings.Mappings`), or the mapping
        mode to compute them with (``compute_mappings(scene, mappings=...)``); default the
        settings' ``mappings`` mode.
    images : list of (H, W, 3) arrays or ImageSequence, optional
        Images to correct instead of the scene's files (uint8, uint16 or float [0, 1]). A lazy
        :class:`~o3d_seqcc.imaging.sequences.ImageSequence` (e.g. ``SceneImages(scene.views)``) is read
        view by view when needed, and the result's ``images`` are then lazy too
        (:class:`~o3d_seqcc.correction.base.CorrectedImages`).
    settings : CorrectionSettings, optional
        Reference, method, ``t_npm``, seed, interpolation, graph weight and method options;
        default :class:`~o3d_seqcc.correction.settings.CorrectionSettings` (its attributes
        document each option and its default).
    **options
        Fields of :class:`~o3d_seqcc.correction.settings.CorrectionSettings` changed from
        ``settings`` (``reference``, ``method``, ``t_npm``, ``seed``, ``interpolation``,
        ``graph_weight``; None: the settings' value); any other name is an option of the method
        (e.g. seqcc: ``cmf="csvr"``, ``cmf_options={...}``, ``bits``), added to its
        ``method_options``: unknown names raise ``TypeError``.

    Returns
    -------
    CorrectionResult
        Corrected images in the input dtypes; inputs are not modified. Per-edge fits run on the
        active executor (:mod:`o3d_seqcc._shared.parallel`: threads, or a Dask cluster).

    Raises
    ------
    InputError
        Unknown method or option (lists the valid ones; an unknown option's error is also a
        ``TypeError``) or other option value, unknown reference (lists the valid names), no edge
        left at ``t_npm`` (says the largest pair count), a reference without edges, images not
        matching the scene, neither a scene nor images and mappings.

    Examples
    --------
    >>> import tempfile, o3d_seqcc as sc
    >>> room = sc.make_synthetic_scene(tempfile.mkdtemp() + '/room', n_views=3, width=96, height=72, seed=1,
    ...                                seen_only=True)
    >>> res = sc.correct(room.scene, method='reinhard', reference='v00')
    >>> len(res.images), res.reference, res.images[0].dtype
    (3, 0, dtype('uint8'))
    """
    if isinstance(mappings, str):
        options["mappings"], mappings = mappings, None
    fields = set(CorrectionSettings.field_names()) - {"method_options"}
    given = {k: options.pop(k) for k in list(options) if k in fields}
    if options:  # the method's own options, on top of the settings' (method_options= replaces them)
        base = given.get("method_options") or (settings.method_options if settings is not None else {})
        given["method_options"] = {**base, **options}
    cs = CorrectionSettings.resolve(settings, given, where="correct")
    reference, method, t_npm, seed = cs.reference, cs.method, cs.t_npm, cs.seed
    interpolation, graph_weight, options = cs.interpolation, cs.graph_weight, cs.method_options
    fn = METHODS[method]
    METHODS.check_options(method, options)
    if scene is None:
        if images is None or mappings is None:
            raise InputError("correct() needs a scene, or both images= and mappings=")
        names = list(getattr(mappings, "view_names", ()) or ()) or [str(i) for i in range(len(images))]
        sizes = None
    else:
        names = list(scene.names)
        sizes = [(v.width, v.height) for v in scene.views]
    n = len(names)
    if reference != "auto":
        resolve_view(names, reference)  # a wrong name fails before any heavy work
    timings: dict[str, float] = {}

    t0 = time.perf_counter()
    lazy = isinstance(images, ImageSequence)
    if lazy:  # read when a task needs them (each view checks its own file)
        raw = images
        if len(raw) != n:
            raise InputError(f"got {len(raw)} images for {n} views; give one per view")
    else:
        raw = [v.load_image() for v in scene.views] if images is None else _check_images(images, names, sizes)
    fimgs = FloatImages(raw)  # float images converted on access, least recently used dropped
    lut_size = 256 if all(dt == np.uint8 for dt in image_dtypes(raw)) else 4096
    timings["load_images"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    if mappings is None:
        from ..mappings.compute import compute_mappings

        mappings = compute_mappings(scene, mappings=cs.mappings)
    if getattr(mappings, "n_views", n) != n:
        raise InputError(f"mappings are for {mappings.n_views} views but there are {n}; recompute them")
    timings["mappings"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    counts = {k: int(v) for k, v in dict(mappings.counts).items()}
    if sizes is None and not lazy:
        sizes = [(int(np.shape(im)[1]), int(np.shape(im)[0])) for im in raw]
    t_eff, t_how = resolve_t_npm(t_npm, mappings, image_sizes=sizes)
    unit = t_npm_units(getattr(mappings, "mode", "vertices"))
    graph = build_graph(counts, n, t_npm=t_eff, weight=graph_weight)
    needs_graph = METHODS.info(method).get("needs_graph", True)
    if needs_graph and graph.number_of_edges() == 0:
        best = max(counts.items(), key=lambda kv: kv[1], default=None)
        if best is None or best[1] == 0:
            raise InputError("no view pair shares any pairwise mapping: the views do not overlap on the mesh")
        (a, b), nmax = best
        what = "px of shared surface" if unit == "px" else "mappings"
        raise InputError(
            f"no view pair has t_npm={t_eff} or more {what} ({t_how}; the largest count is {nmax}, between "
            f"{names[a]!r} and {names[b]!r}); lower t_npm to at most {nmax}"
        )
    if reference == "auto":
        ref = choose_reference(graph)
        logger.info("reference='auto': chose view %d (%s)", ref, names[ref])
    else:
        ref = resolve_view(names, reference)
    if needs_graph and graph.degree(ref) == 0:
        own = {(b if a == ref else a): c for (a, b), c in counts.items() if ref in (a, b) and c > 0}
        hint = ""
        if own:
            other, c = max(own.items(), key=lambda kv: kv[1])
            hint = f" (its largest pair count is {c} {unit}, with {names[other]!r}, below t_npm={t_eff})"
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
        warn(msg)
    timings["graph"] = time.perf_counter() - t0

    ctx = CorrectionContext(
        images=fimgs, mappings=mappings, reference=ref, t_npm=t_eff, seed=int(seed), graph=graph, paths=paths,
        lut_size=lut_size, interpolation=interpolation,
    )
    t0 = time.perf_counter()
    transforms = list(fn(ctx, **options))
    if len(transforms) != n:
        raise RuntimeError(f"method {method!r} returned {len(transforms)} transforms for {n} views")
    timings["fit"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    out = CorrectedImages(raw, transforms) if lazy else [apply_transform(tr, img) for img, tr in zip(raw, transforms)]
    timings["apply"] = time.perf_counter() - t0
    timings["total"] = float(sum(timings.values()))
    settings = {"t_npm": t_npm if t_npm == "auto" else int(t_npm), "seed": int(seed), "interpolation": interpolation, "graph_weight": graph_weight,
                "options": dict(options)}
    return CorrectionResult(
        images=out, transforms=transforms, reference=ref, paths=paths, unreachable=unreachable,
        graph_edges=graph_edges(graph), timings=timings, method=method, t_npm=t_eff,
        edge_luts=dict(sorted(ctx.edge_luts.items())), settings=settings,
        edge_residuals=dict(sorted(ctx.edge_residuals.items())),
    )

# the names the other stages use, imported from their modules on first use
__getattr__, __dir__ = lazy_exports(__name__, {
    # used by the other stages and the pipeline (tests/test_layout.py: nothing else is imported across)
    **dict.fromkeys(("OUT_OF_LINE_LEVELS", "OUT_OF_LINE_RATIO"), "base"),
    **dict.fromkeys(("PAPER_T_NPM", "WEIGHTS", "build_graph", "choose_reference", "mappings_summary",
                     "resolve_t_npm"), "graph"),
    "joint_histogram": "jih",
    "compose_luts": "luts",
    **dict.fromkeys(("colour_inliers", "quantile_luts"), "methods.seqcc"),
})
