"""Pairwise mappings (paper 3.1): the pixels of two photos that show the same surface point.

- :mod:`~o3d_seqcc.mappings.pairs`: :class:`PairMapping`, the lazy per-pair builder (:class:`LazyPairs` over a
  :class:`PairSource`), thinned reads of one pair or many (:func:`thinned`, :func:`thinned_many`);
- :mod:`~o3d_seqcc.mappings.counting`: the shared counts and areas of every pair of views;
- :mod:`~o3d_seqcc.mappings.compute`: :class:`Mappings` and :func:`compute_mappings`, the stage.
"""

from __future__ import annotations

from .._shared.lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {
    **dict.fromkeys(("DEFAULT_MODE", "MODES", "Mappings", "compute_mappings"), "compute"),
    **dict.fromkeys(("BATCH_PAIRS", "LazyPairs", "PairMapping", "PairSource", "thinned", "thinned_many"), "pairs"),
    **dict.fromkeys(("shared_counts", "shared_area"), "counting"),
})
