"""The parts of :func:`o3d_seqcc.pipeline.run`'s report that need no atlas, on a background thread while it textures.

:class:`BackgroundReport` starts Table 2 and the page's correction figures right after the correction, and the
selection seams' colour steps right after the selection; :meth:`o3d_seqcc.pipeline.RunResult.save` takes them
from it instead of computing them again.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Any, Sequence

import numpy as np

from .._shared.parallel import carried
from ..correction import CorrectionResult
from ..evaluation.table2 import before_after
from ..evaluation.seams import selection_seams_of
from ..mappings.compute import Mappings
from . import metrics_sample
from .parts import correction_parts

__all__ = ["BackgroundReport", "table2_metrics"]


def table2_metrics(images: tuple, maps: Mappings, paths: dict) -> dict:
    """Table 2 of a run's report (:func:`~o3d_seqcc.evaluation.table2.before_after`) on ``(photos, corrected)``."""
    photos, corrected = images
    return before_after(photos, corrected, maps, paths, max_per_pair=metrics_sample(maps))


class BackgroundReport:
    """The parts of :func:`run`'s report that need no atlas, computed on one background thread while it textures.

    Table 2 and the page's correction figures (the path edges' joint histograms, the views'
    thumbnails: :func:`~o3d_seqcc.report.parts.correction_parts`) depend on the correction
    alone, the selection seams' colour steps also on the selection; the selection and the bake
    leave a core idle much of the time. Started right after the correction (the seams right
    after the selection), they are ready when :meth:`RunResult.save` writes the report instead
    of being computed there. The same functions on the same inputs: the same numbers and
    pictures as computing them in ``save``.
    """

    def __init__(self, originals: Any, res: CorrectionResult, maps: Mappings) -> None:
        self._key = (originals, res, maps)
        # the photos through the run's cache, the corrections applied on access: caching them here, next to the
        # texturing's arrays, would raise the run's peak memory (save() caches them for the page, as before)
        self._images = (originals, res.images)
        self._carried = carried
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="o3d_seqcc-report")
        self._table2 = self._pool.submit(carried(table2_metrics, "background: table 2"), self._images, maps, res.paths)
        self._parts = self._pool.submit(carried(correction_parts, "background: report figures"), originals,
                                        res.images, res, maps)
        self._seams: tuple | None = None

    def selected(self, mesh: Any, selection: np.ndarray, views: Sequence) -> None:
        """The selection is known: measure its seams' steps next, then let the thread end."""
        photos, corrected = self._images
        self._seams = (selection, self._pool.submit(
            self._carried(selection_seams_of, "background: selection seams"), mesh.vertices, mesh.faces, selection,
            views, {"photos": photos, "corrected": corrected}))
        self.close(cancel=False)

    def close(self, *, cancel: bool = True) -> None:
        """No more work (``cancel``: drop what has not started, e.g. after an error); the thread ends after its task
        (the interpreter's exit waits for it: no native code cut off)."""
        self._pool.shutdown(wait=False, cancel_futures=cancel)

    def matches(self, result: Any) -> bool:
        """Whether ``result`` holds the correction this was started for (not another one put in by ``replace``)."""
        originals, res, maps = self._key
        return result.originals is originals and result.correction is res and result.mappings is maps

    def result(self) -> dict:
        """Table 2."""
        return self._table2.result()

    def parts(self) -> Any:
        """The page's correction figures (:class:`~o3d_seqcc.report.parts.CorrectionParts`)."""
        return self._parts.result()

    def seams(self, selection: np.ndarray) -> dict | None:
        """The selection seams' steps (photos, corrected), when measured for this ``selection``."""
        if self._seams is None or self._seams[0] is not selection:
            return None
        return self._seams[1].result()
