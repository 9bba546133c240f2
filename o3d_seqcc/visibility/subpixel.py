"""Sub-pixel meshes (issue 36): faces smaller than a pixel in every photo, counted and warned about once.

A mesh finer than its photos (a finely subdivided room, a 2M-face scan with 160 x 120 photos) gains nothing
from its faces: no photo holds their detail, the texture gets no more of it, and every stage still pays per face.
:func:`subpixel_faces` measures the share of the faces some photo sees whose largest projection over the photos
is below one square pixel; :func:`warn_subpixel` warns once when it is most of them, with the share and what to
do (decimate to a suggested face count, or use larger photos).
"""

from __future__ import annotations

import logging
from typing import Sequence

import numpy as np

from ..errors import warn

__all__ = ["SUBPIXEL_AREA", "SUBPIXEL_SHARE", "subpixel_faces", "warn_subpixel"]

logger = logging.getLogger(__name__)

#: a face is sub-pixel when its largest projection over the photos is below this (px^2)
SUBPIXEL_AREA = 1.0
#: the warning: when more than this share of the seen faces is sub-pixel
SUBPIXEL_SHARE = 0.5
#: the decimation suggested: a face count giving the median seen face this largest projection (px^2)
SUGGESTED_AREA = 4.0
#: below this suggested face count the mesh is a few pixels in the photos, and no decimation is suggested
MIN_SUGGESTED_FACES = 100


def subpixel_faces(records: Sequence, n_faces: int) -> dict:
    """The faces' largest projected area over the views, summarised.

    Parameters
    ----------
    records : sequence of ViewRecord
        ``faces`` (k,) ids and ``area`` (k,) px^2 of the faces valid in each view.
    n_faces : int

    Returns
    -------
    dict
        ``seen_faces`` (valid in some view), ``share`` (of them below :data:`SUBPIXEL_AREA`), ``median_px2`` (the
        median seen face's largest area) and ``suggested_faces`` (a face count whose median face would cover
        :data:`SUGGESTED_AREA`, assuming the area divides evenly).
    """
    largest = np.zeros(int(n_faces), dtype=np.float32)
    for r in records:  # one vectorised step per view
        f = np.asarray(r.faces, dtype=np.int64)
        if len(f):
            largest[f] = np.maximum(largest[f], np.asarray(r.area, dtype=np.float32))
    seen = largest > 0
    n = int(seen.sum())
    if not n:
        return {"seen_faces": 0, "share": 0.0, "median_px2": 0.0, "suggested_faces": 0}
    med = float(np.median(largest[seen]))
    logger.debug("sub-pixel faces: %d of %d seen faces below %g px^2 in every photo", int((largest[seen] < SUBPIXEL_AREA).sum()),
                 n, SUBPIXEL_AREA)
    return {"seen_faces": n, "share": float(np.mean(largest[seen] < SUBPIXEL_AREA)), "median_px2": med,
            "suggested_faces": int(max(1, round(n * med / SUGGESTED_AREA)))}


def warn_subpixel(summary: dict, where: str = "") -> bool:
    """Warn (once per call) when most seen faces are sub-pixel (:func:`subpixel_faces`); whether it warned."""
    if summary["seen_faces"] == 0 or summary["share"] <= SUBPIXEL_SHARE:
        return False
    msg = (f"{100 * summary['share']:.0f}% of the {summary['seen_faces']} faces the photos see{where} are smaller than "
           f"a pixel in every photo (the median face covers {summary['median_px2']:.2g} px^2 at most): the photos "
           "cannot give them detail, and every stage pays per face; ")
    if summary["suggested_faces"] < MIN_SUGGESTED_FACES:  # no mesh is worth decimating to a handful of faces
        msg += ("the whole mesh is only a few pixels in the photos: check that they show it (cameras, units), or use "
                "photos taken closer")
    else:
        msg += (f"decimate the mesh to about {summary['suggested_faces']} faces (Open3D: simplify_quadric_decimation; "
                "MeshLab: Filters > Remeshing > Quadric Edge Collapse Decimation) or use larger photos")
    warn(msg)
    return True
