"""The HTML report of a run, ``OUT/report.html``: the paper's figures for this run, in one file.

One self-contained page (images embedded as base64 PNG / JPEG, CSS inline, no external URL,
works offline) that ``run``, ``correct`` and ``texture`` (and so ``demo``) write into their
output folder, and that :func:`~o3d_seqcc.run_folder.read.regenerate_report` (``o3d-seqcc report RUN_DIR``) writes again
from an output folder. Sections, each only when the command produced its data:

- the textured model in an interactive 3D viewer (:mod:`o3d_seqcc.report.viewer`: the GLB
  inline, three.js bundled into the page; orbit, zoom, the texture corrected / as taken / the
  selection colours);
- what the correction changes (:mod:`o3d_seqcc.report.comparison`): one close-up of the model
  as written, with each face its photo corrected and as taken, and the selection seams on a
  colour scale of their step;
- the colour-correction graph with edge weights and the Dijkstra paths, reference marked
  (paper Figures 4-5), and the path edges as a table;
- the joint image histograms (JIH) and fitted colour mapping functions (CMF) of every path edge
  and channel (Figures 6-7): every edge of one path in full, all edges as thumbnails;
- the sequential steps of that path (Figure 8): the source view corrected step by step;
- a before / after grid of all views, reference marked (Figure 10);
- Table 2: PSNR / CIEDE2000 mean, weighted mean and std over the view pairs, before and after,
  with the contrast ratio (:func:`o3d_seqcc.evaluation.table2.before_after`);
- the per-face image selection with a legend (Figure 9);
- renders of the textured mesh from two views beside the photos (Figures 12-13);
- seam metric, timings and the run's settings.

At run time everything comes from memory: the page is drawn from the result objects the command
returns (:class:`~o3d_seqcc.report.inputs.PageInputs`: the images, the correction with its per-edge
lookup tables, the mappings, the selection, the textured mesh, the visibility's usable counts),
and no stage runs again (``tests/test_report_schema.py`` makes every stage raise while a run is
saved). :meth:`~o3d_seqcc.pipeline.RunResult.save` scores Table 2 on at most
:data:`METRICS_MAX_PER_PAIR` mappings per pair (all of them up to :data:`METRICS_ALL_UP_TO`; :func:`~o3d_seqcc.pipeline.run`
starts it in the background) and measures the selection seams' steps in a thread beside the export; the page then
draws the figures (the joint histograms with numpy and OpenCV, the graph as SVG text), the viewer's textures,
the close-ups and two ray-cast renders (selection.png is reused), reading each photo once.
:func:`~o3d_seqcc.run_folder.read.regenerate_report` (a folder, not a result) reloads the scene, recomputes only what the
folder does not hold (visibility, mappings and correction, with the settings ``report.json``
recorded: the per-edge CMFs are not saved) and reads the selection, the textured mesh and the
numbers from the folder.
"""

from __future__ import annotations

import logging
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..io.atomic import atomic_write_bytes
from .inputs import PageInputs
from .page import render_page
from .validate import page_bytes
from .._shared.lazy import lazy_exports

__all__ = ["IMAGE_CACHE_BYTES", "METRICS_ALL_UP_TO", "METRICS_MAX_PER_PAIR", "PageInputs", "cached_images",
           "metrics_sample", "html_report", "write_report"]

logger = logging.getLogger(__name__)

#: mappings scored per pair for the Table 2 of ``run`` beyond :data:`METRICS_ALL_UP_TO` (evenly spaced)
METRICS_MAX_PER_PAIR = 200
#: ``run`` scores every mapping (its Table 2 is then ``correct``'s, number for number) up to this many in all
METRICS_ALL_UP_TO = 100_000


#: bytes of images a report keeps while it is made (each photo read, and corrected, once while they fit):
#: at least this, up to :data:`IMAGE_CACHE_MAX_BYTES` when the photos and their corrections need more
IMAGE_CACHE_BYTES = 256 << 20
#: the most a report's image cache grows to (10 photos of 6 MP and their corrections: 360 MB)
IMAGE_CACHE_MAX_BYTES = 768 << 20
#: bytes of corrected images a run's report keeps while it is made (its photos are the run's cached ones)
CORRECTED_CACHE_BYTES = 64 << 20


def _bytes(images: Any) -> int:
    """Bytes of a sequence's images (views' sizes and header dtypes for a lazy one, 0 for None)."""
    from ..imaging.sequences import image_dtypes

    if images is None:
        return 0
    views = getattr(images, "views", None) or getattr(getattr(images, "originals", None), "views", None)
    if views is not None and len(views) == len(images):
        return sum(v.width * v.height * 3 * np.dtype(d).itemsize for v, d in zip(views, image_dtypes(images)))
    return sum(int(np.asarray(im).nbytes) for im in images) if isinstance(images, (list, tuple)) else 0


def cached_images(photos: Any, corrected: Any) -> tuple[Any, Any]:
    """``photos`` and ``corrected`` read through one shared cache; lazily corrected images from the cached photos.

    What :meth:`~o3d_seqcc.pipeline.RunResult.save` hands to Table 2, the seam steps and the page,
    so that together they read each photo once (``None`` stays ``None``). A run's photos keep their
    own cache, and its corrected images get one of :data:`CORRECTED_CACHE_BYTES`.
    """
    from ..correction.base import CorrectedImages
    from ..imaging.sequences import CachedImages, LRUCache

    if isinstance(photos, CachedImages):  # a run's photos (images.scene_photos), cached already
        if corrected is None or isinstance(corrected, CachedImages):
            return photos, corrected
        # the corrections (a lookup table applied to a cached photo: cheap) in a small cache of their own: the page
        # reads most views' twice at most, and keeping them all would add their size to the run's memory
        return photos, CachedImages(corrected, LRUCache(CORRECTED_CACHE_BYTES), "corrected")
    cache = LRUCache(max(IMAGE_CACHE_BYTES, min(IMAGE_CACHE_MAX_BYTES, _bytes(photos) + _bytes(corrected))))
    p = None if photos is None else CachedImages(photos, cache, "photos")
    if isinstance(corrected, CorrectedImages) and p is not None and corrected.originals is photos:
        corrected = CorrectedImages(p, corrected.transforms)  # the LUTs applied to the cached photos
    return p, None if corrected is None else CachedImages(corrected, cache, "corrected")


def metrics_sample(mappings) -> int | None:
    """``max_per_pair`` of ``run``'s Table 2: None (all) up to :data:`METRICS_ALL_UP_TO` mappings, else the cap."""
    return None if mappings.total <= METRICS_ALL_UP_TO else METRICS_MAX_PER_PAIR


def _page_inputs(source: Any, report: dict | None) -> PageInputs:
    """``source`` itself (a :class:`PageInputs`), or what a pipeline result says its page is drawn from
    (its ``page_inputs``: :meth:`~o3d_seqcc.pipeline.RunResult.page_inputs`,
    :meth:`~o3d_seqcc.pipeline.CorrectionRun.page_inputs`)."""
    if isinstance(source, PageInputs):
        return source if report is None else replace(source, rep=report)
    page_inputs = getattr(source, "page_inputs", None)
    if page_inputs is None:
        raise TypeError(f"a report is drawn from a PageInputs or a pipeline.RunResult / CorrectionRun, got "
                        f"{type(source).__name__}")
    return page_inputs(report=report)


def html_report(source: Any, *, report: dict | None = None, thumb_width: int = 160) -> str:
    """The HTML report of a result of :mod:`o3d_seqcc.pipeline`, as one self-contained page.

    Parameters
    ----------
    source : PageInputs, pipeline.RunResult or pipeline.CorrectionRun
        What the page is drawn from, or what :func:`~o3d_seqcc.pipeline.run`,
        :func:`~o3d_seqcc.pipeline.texture` or :func:`~o3d_seqcc.pipeline.correct_scene` returned
        (its ``page_inputs()``).
    report : dict, optional
        The ``report.json`` content to show (numbers, settings, timings, Table 2 under
        ``"metrics"``); default the result's own report (without Table 2 for ``run``: see
        :func:`o3d_seqcc.evaluation.table2.before_after`).
    thumb_width : int, default 160
        Width in pixels of the views' thumbnails (photos beside renders: twice that).

    Returns
    -------
    str
        The HTML document; images embedded as base64 PNG / JPEG, no external resource.

    Examples
    --------
    >>> import tempfile, o3d_seqcc as sc
    >>> room = sc.make_synthetic_scene(tempfile.mkdtemp() + '/room', n_views=3, width=96, height=72, seed=1,
    ...                                seen_only=True)
    >>> page = sc.html_report(sc.pipeline.texture(room.scene, atlas_size=512, seams=False))
    >>> page.startswith('<!DOCTYPE html>'), 'Per-face image selection' in page
    (True, True)
    """
    return render_page(_page_inputs(source, report), width=int(thumb_width))


def write_report(source: Any, path: str | os.PathLike, *, report: dict | None = None, thumb_width: int = 160) -> Path:
    """Write :func:`html_report` of ``source`` to ``path`` atomically; returns the path."""
    return atomic_write_bytes(Path(path), page_bytes(html_report(source, report=report, thumb_width=thumb_width)))

# the names the other stages use, imported from their modules on first use
__getattr__, __dir__ = lazy_exports(__name__, {
    # used by the other stages and the pipeline (tests/test_layout.py: nothing else is imported across)
    **dict.fromkeys(("BackgroundReport", "table2_metrics"), "background"),
    **dict.fromkeys(("build_page", "render_page"), "page"),
    "facts": "inputs",
    **dict.fromkeys(("correction_section", "document", "upgrade"), "schema"),
    **dict.fromkeys(("page_bytes", "validate_report"), "validate"),
})
