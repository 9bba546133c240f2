"""Pairwise mappings (paper 3.1): the pixels of two photos that show the same surface point.

- :mod:`~o3d_seqcc.mappings.pairs`: :class:`PairMapping`, the lazy per-pair builder, shared counts and areas;
- :mod:`~o3d_seqcc.mappings.compute`: :class:`Mappings` and :func:`compute_mappings`, the stage.
"""

from __future__ import annotations

from .._shared.lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {
    **dict.fromkeys(("DEFAULT_MODE", "MODES", "Mappings", "compute_mappings"), "compute"),
    **dict.fromkeys(("PairMapping", "shared_counts", "shared_area"), "pairs"),
})
