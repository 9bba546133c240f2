"""The parts of a run's page that need only the correction and the photos: computable before the page.

The joint image histograms of every path edge (paper Figures 6-7) with their thumbnails, and
every view's thumbnail before and after the correction (Figure 10), depend on the correction
alone: :func:`o3d_seqcc.pipeline.run` computes them (:func:`correction_parts`) on a background
thread while it textures, beside Table 2, so that saving the run does not wait for them; the
page (:func:`o3d_seqcc.report.page.render_page`) computes what it is not given, with the same
functions, so the page is the same either way.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..evaluation.metrics import thin_indices
from ..imaging.arrays import dtype_scale, sample_colors
from ..mappings.pairs import thinned
from .figures import jih_thumbnail, png, thumbnail

__all__ = ["JIH_BITS", "JIH_MAX_MAPPINGS", "THUMB_WIDTH", "CorrectionParts", "correction_parts", "edge_jihs",
           "jih_thumbnails", "path_edges", "thinned_pair", "view_thumbnails"]

#: bit depth of the JIH drawn (2**bits bins per axis)
JIH_BITS = 7
#: mappings per edge drawn in a JIH (evenly spaced)
JIH_MAX_MAPPINGS = 2000
#: width in pixels of the views' thumbnails (the page's default)
THUMB_WIDTH = 160


@dataclass(frozen=True, eq=False)
class CorrectionParts:
    """What :func:`correction_parts` computes for a page.

    Attributes
    ----------
    jihs : dict
        Path edge (t, s) -> (inlier JIH (3, B, B) uint16 counts, outlier JIH or None) (:func:`edge_jihs`).
    jih_thumbs : dict
        Path edge -> PNG bytes of its thumbnail (:func:`jih_thumbnails`).
    thumbs : (list, list or None)
        The views' thumbnails (uint8, ``width`` wide): the photos, the corrected images.
    width : int
        The thumbnails' width.
    """

    jihs: dict
    jih_thumbs: dict
    thumbs: tuple
    width: int


def path_edges(paths: dict) -> list[tuple[int, int]]:
    """The (target, source) edges of the correction's paths, each once, in the order of the views' paths."""
    return list(dict.fromkeys((t, s) for v in sorted(paths) for t, s in zip(paths[v][:-1], paths[v][1:])))


def _outlier_k(c) -> float | None:
    """The outlier threshold the correction's fit used (seqcc's ``outlier_k``), None for methods without one."""
    from ..correction import METHODS

    p = inspect.signature(METHODS[c.method]).parameters.get("outlier_k") if c.method in METHODS else None
    return None if p is None else c.settings.get("options", {}).get("outlier_k", p.default)


def thinned_pair(mappings, t: int, s: int, k: int):
    """``mappings.pair(t, s)`` at :func:`~o3d_seqcc.evaluation.metrics.thin_indices` ``(n, k)`` of its mappings:
    only those built (:func:`~o3d_seqcc.mappings.pairs.thinned`: the same values as the whole pair, thinned)."""
    lo, hi = (t, s) if t < s else (s, t)
    if (lo, hi) not in mappings.pairs:
        return mappings.pair(t, s)  # no mappings: the empty pair
    _, pm = thinned(mappings.pairs, (lo, hi), lambda n: thin_indices(n, k))
    return pm if t < s else pm.swapped()


def edge_jihs(photos, correction, mappings, edges: list[tuple[int, int]]) -> dict:
    """(t, s) -> (inlier JIH, outlier JIH or None), from the photos' colours at the pair's mappings.

    At most :data:`JIH_MAX_MAPPINGS` mappings per edge, :data:`JIH_BITS` bits per axis; the
    outliers are the ones the correction's fit discards (its ``outlier_k``), when it has one.
    """
    from ..correction.jih import joint_histogram
    from ..correction.methods.seqcc import colour_inliers, quantile_luts

    k = _outlier_k(correction)
    out = {}
    for t, s in edges:
        pm = thinned_pair(mappings, t, s, JIH_MAX_MAPPINGS)
        ct = sample_colors(photos[t], pm.uv_a) / dtype_scale(photos[t].dtype)
        cs = sample_colors(photos[s], pm.uv_b) / dtype_scale(photos[s].dtype)
        if k is not None and len(ct):
            lut = correction.edge_luts.get((t, s))
            keep = colour_inliers(ct, cs, quantile_luts(ct, cs, n_out=256 if lut is None else lut.shape[1]), k=float(k))
            out[(t, s)] = (_counts(joint_histogram(ct[keep], cs[keep], bits=JIH_BITS)),
                           _counts(joint_histogram(ct[~keep], cs[~keep], bits=JIH_BITS)))
        else:
            out[(t, s)] = (_counts(joint_histogram(ct, cs, bits=JIH_BITS)), None)
    return out


def _counts(jih: np.ndarray) -> np.ndarray:
    """The histogram's counts (at most :data:`JIH_MAX_MAPPINGS`) as uint16: the same values, a quarter of the bytes
    (a run keeps every path edge's from its correction to its save)."""
    return jih.astype(np.uint16) if jih.max(initial=0) <= np.iinfo(np.uint16).max else jih


def jih_thumbnails(jihs: dict, edge_luts: dict) -> dict:
    """Edge -> PNG bytes of its three JIHs overlaid with its CMF (:func:`~o3d_seqcc.report.figures.jih_thumbnail`)."""
    return {e: png(jih_thumbnail(jihs[e][0], edge_luts.get(e), jihs[e][1])) for e in jihs}


def view_thumbnails(photos, corrected, width: int = THUMB_WIDTH) -> tuple[list, list | None]:
    """Every view's thumbnail ``width`` pixels wide (uint8): of the photos, and of the corrected images (or None)."""
    return tuple(None if ims is None else [thumbnail(im, width) for im in ims] for ims in (photos, corrected))


def correction_parts(photos: Any, corrected: Any, correction: Any, mappings: Any, *,
                     width: int = THUMB_WIDTH) -> CorrectionParts:
    """The JIHs of the correction's path edges, their thumbnails and the views' thumbnails (one pass per image set).

    Parameters
    ----------
    photos, corrected : sequences of (H, W, 3) images
        The photos as taken and corrected (one per view).
    correction : CorrectionResult
        With its paths and per-edge lookup tables.
    mappings : Mappings
    width : int, default :data:`THUMB_WIDTH`
    """
    jihs = edge_jihs(photos, correction, mappings, path_edges(correction.paths)) if correction.paths else {}
    return CorrectionParts(jihs=jihs, jih_thumbs=jih_thumbnails(jihs, correction.edge_luts),
                           thumbs=view_thumbnails(photos, corrected, width), width=int(width))
