"""Colours of the faces seen by no view (their texels still need colours).

``"smooth"`` (default): per-vertex colours interpolated over the face (Gouraud), a vertex taking
the mean colour of the seen faces around it (their selected images at its projection, plus the
seam-leveling offsets), propagated along mesh edges to vertices with no seen face around them,
grey (128, 128, 128) where nothing reaches. ``"flat"``: one colour per face, the mean of its seen
neighbours (propagated face to face). The bake (:mod:`~o3d_seqcc.texturing.atlas`) paints the
faces' texels with these corner colours, interpolated barycentrically.
"""

from __future__ import annotations

import numpy as np

from .settings import TextureSettings

__all__ = ["FALLBACK_GREY", "fallback_corner_colors"]

#: grey used for faces that no view sees and that touch no seen face (RGB, 0-255)
FALLBACK_GREY = (128, 128, 128)


def _propagate(values: np.ndarray, known: np.ndarray, pairs: np.ndarray, *, iters: int) -> np.ndarray:
    """Fill unknown rows of ``values`` (n, 3) with the mean of their known neighbours, front by front.

    ``pairs`` (E, 2): undirected neighbour pairs. Rows that no front reaches after ``iters``
    steps get :data:`FALLBACK_GREY`. Returns a new array.

    Each step computes the rows next to the last front only (the unknown rows with a known
    neighbour are exactly the last front's unknown neighbours), from the rows of the adjacency
    they need: every row is averaged once, so the whole fill costs one pass over the edges, not
    one per step (a sub-pixel mesh's large unseen regions took 256 passes: 14.9 s of a 2.2M-face
    bake). The sums run over the same entries in the same order as a whole-matrix product:
    the same numbers.
    """
    import scipy.sparse as sp

    n = len(values)
    col = np.array(values, dtype=np.float64)
    have = np.asarray(known, dtype=np.float64)
    if len(pairs) and not have.all():
        adj = sp.coo_matrix((np.ones(2 * len(pairs)), (np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]])),
                            shape=(n, n)).tocsr()
        masked = col * have[:, None]  # the known rows' values, 0 elsewhere
        front = np.flatnonzero(have > 0)
        for _ in range(int(iters)):
            cand = np.unique(adj[front].indices)
            cand = cand[have[cand] == 0]
            if not len(cand):
                break
            sub = adj[cand]
            ssum = sub @ masked
            cnt = sub @ have
            col[cand] = ssum / cnt[:, None]
            have[cand] = 1.0
            masked[cand] = col[cand]
            front = cand
    col[have == 0] = FALLBACK_GREY
    return col


def fallback_corner_colors(
    corner_col: np.ndarray, wf: np.ndarray, labels: np.ndarray, adjacency: np.ndarray, *,
    fallback: str = TextureSettings.fallback, iters: int = 256,
) -> np.ndarray:
    """Colours of the corners of the faces seen by no view.

    Parameters
    ----------
    corner_col : (F, 3, 3) float
        Colour (0-255 units) of every corner of every seen face: its view at the corner's
        projection, plus the seam-leveling offset; rows of unseen faces are ignored.
    wf : (F, 3) int
        Welded vertex id of every face corner (:func:`o3d_seqcc.geometry.meshops.weld_vertices`).
    labels : (F,) int
        View of every face, -1 = unseen.
    adjacency : (E, 2) int
        Faces sharing an edge (``"flat"``).
    fallback : {"smooth", "flat"}
    iters : int
        Propagation steps (mesh edges) away from the seen faces.

    Returns
    -------
    (F, 3, 3) float64
        Corner colours in 0-255 (those of the seen faces are the input's, clipped).
    """
    seen = labels >= 0
    out = np.clip(np.nan_to_num(np.asarray(corner_col, dtype=np.float64)), 0.0, 255.0)
    if seen.all():
        return out
    if fallback == "flat":
        col = np.where(seen[:, None], out.mean(axis=1), 0.0)
        col = _propagate(col, seen, adjacency, iters=iters)
        out[~seen] = np.clip(col[~seen], 0.0, 255.0)[:, None, :]
        return out
    wf = np.asarray(wf, dtype=np.int64)
    n_w = int(wf.max()) + 1 if wf.size else 0
    w_ids = wf[seen].reshape(-1)
    cnt = np.bincount(w_ids, minlength=n_w).astype(np.float64)
    c3 = out[seen].reshape(-1, 3)
    col = np.stack([np.bincount(w_ids, weights=c3[:, c], minlength=n_w) for c in range(3)], axis=1)
    known = cnt > 0
    col[known] /= cnt[known, None]
    e = wf[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    col = _propagate(col, known, e[e[:, 0] != e[:, 1]], iters=iters)
    out[~seen] = np.clip(col[wf[~seen]], 0.0, 255.0)
    return out
