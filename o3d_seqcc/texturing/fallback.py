"""Colours of the faces seen by no view (they still need texels in the atlas).

``"smooth"`` (default): per-vertex colours interpolated over the face (Gouraud), a vertex taking
the mean colour of the seen faces around it (their selected images at its projection, plus the
seam-leveling offsets), propagated along mesh edges to vertices with no seen face around them,
grey (128, 128, 128) where nothing reaches; each face gets a small block of texels holding the
affine colour ramp (exact under bilinear filtering). ``"flat"``: one colour per face, the mean
of its seen neighbours (faces of the same colour share a block).
"""

from __future__ import annotations

import numpy as np

from ..imageops import sample_bilinear
from ..meshops import weld_vertices

__all__ = ["FALLBACK_GREY", "fallback_blocks"]

#: grey used for faces that no view sees and that touch no seen face (RGB, 0-255)
FALLBACK_GREY = (128, 128, 128)


def _propagate(values: np.ndarray, known: np.ndarray, pairs: np.ndarray, *, iters: int) -> np.ndarray:
    """Fill unknown rows of ``values`` (n, 3) with the mean of their known neighbours, front by front.

    ``pairs`` (E, 2): undirected neighbour pairs. Rows that no front reaches after ``iters``
    steps get :data:`FALLBACK_GREY`. Returns a new array.
    """
    import scipy.sparse as sp

    n = len(values)
    col = np.array(values, dtype=np.float64)
    have = np.asarray(known, dtype=np.float64)
    if len(pairs) and not have.all():
        adj = sp.coo_matrix((np.ones(2 * len(pairs)), (np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]])),
                            shape=(n, n)).tocsr()
        for _ in range(int(iters)):
            ssum = adj @ (col * have[:, None])
            cnt = adj @ have
            upd = (have == 0) & (cnt > 0)
            if not upd.any():
                break
            col[upd] = ssum[upd] / cnt[upd, None]
            have[upd] = 1.0
    col[have == 0] = FALLBACK_GREY
    return col


def _face_colors(
    images: list[np.ndarray], fuv: np.ndarray, faces: np.ndarray, labels: np.ndarray, adjacency: np.ndarray, *,
    offsets: np.ndarray | None = None, iters: int = 64,
) -> np.ndarray:
    """(F, 3) colours (0-255): the selected image at the centroid projection for seen faces (plus
    ``offsets`` (F, 3) when given), the mean of the neighbours for unseen ones."""
    col = np.zeros((len(faces), 3))
    known = labels >= 0
    for v in np.unique(labels[known]):
        sel = np.flatnonzero(labels == v)
        c = fuv[sel].mean(axis=1)
        img = images[v]
        xi = np.clip(np.rint(c[:, 0]).astype(np.int64), 0, img.shape[1] - 1)
        yi = np.clip(np.rint(c[:, 1]).astype(np.int64), 0, img.shape[0] - 1)
        col[sel] = img[yi, xi]
    if offsets is not None:
        col[known] = np.clip(col[known] + offsets[known], 0.0, 255.0)
    return _propagate(col, known, adjacency, iters=iters)


def _corner_colors(
    images: list[np.ndarray], fuv: np.ndarray, verts: np.ndarray, faces: np.ndarray, labels: np.ndarray, *,
    corner_offsets: np.ndarray | None = None, iters: int = 256,
) -> np.ndarray:
    """(F, 3, 3) colour of every face corner (0-255): per welded vertex, the mean of the seen
    faces' corners at it (selected image at its projection, plus ``corner_offsets``), propagated
    along mesh edges to vertices with no seen face around them."""
    wv = weld_vertices(verts)
    n_w = int(wv.max()) + 1 if len(wv) else 0
    seen = np.flatnonzero(labels >= 0)
    col_c = np.zeros((len(seen), 3, 3))
    for v in np.unique(labels[seen]):
        sel = labels[seen] == v
        p = fuv[seen[sel]]  # (n, 3, 2)
        col_c[sel] = sample_bilinear(images[v], p[..., 0], p[..., 1])
    if corner_offsets is not None:
        col_c += corner_offsets[seen]
    w_ids = wv[faces[seen]].reshape(-1)
    cnt = np.bincount(w_ids, minlength=n_w).astype(np.float64)
    col = np.stack([np.bincount(w_ids, weights=col_c.reshape(-1, 3)[:, c], minlength=n_w) for c in range(3)], axis=1)
    known = cnt > 0
    col[known] /= cnt[known, None]
    e = wv[faces][:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    col = _propagate(col, known, e[e[:, 0] != e[:, 1]], iters=iters)
    return np.clip(col[wv[faces]], 0.0, 255.0)


def fallback_blocks(
    images: list[np.ndarray], fuv: np.ndarray, verts: np.ndarray, faces: np.ndarray, labels: np.ndarray,
    adjacency: np.ndarray, *, fallback: str, pad: int, corner_offsets: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Texel blocks of the faces seen by no view.

    Parameters
    ----------
    images : list of (H, W, 3) uint8
    fuv : (F, 3, 2) float
        Projection of every face's corners in its selected view (NaN for unseen faces).
    verts : (N, 3) float, faces : (F, 3) int, labels : (F,) int (-1 = unseen)
    adjacency : (E, 2) int
        Face pairs sharing an edge.
    fallback : {"smooth", "flat"}
    pad : int
        Texels around the colour ramp of a block.
    corner_offsets : (F, 3, 3) float or None
        Seam-leveling offsets of the seen faces' corners.

    Returns
    -------
    blocks : (n_blocks, blk, blk, 3) uint8
    block_of_face : (F,) int64
        Block of every unseen face, -1 for seen faces.
    corner_xy : (3, 2) float64
        The texel of each face corner inside its block.
    """
    unseen = np.flatnonzero(labels < 0)
    block_of_face = np.full(len(faces), -1, dtype=np.int64)
    if fallback == "flat":
        blk = 2 * pad + 1
        corner_xy = np.full((3, 2), float(pad))
        if len(unseen) == 0:
            return np.zeros((0, blk, blk, 3), np.uint8), block_of_face, corner_xy
        cols = _face_colors(images, fuv, faces, labels, adjacency,
                            offsets=None if corner_offsets is None else corner_offsets.mean(axis=1))
        c8 = np.clip(np.rint(cols[unseen]), 0, 255).astype(np.uint8)
        rgb, inv = np.unique(c8, axis=0, return_inverse=True)
        block_of_face[unseen] = inv.reshape(-1)
        return np.broadcast_to(rgb[:, None, None, :], (len(rgb), blk, blk, 3)).copy(), block_of_face, corner_xy
    legs = 8  # corners at (pad, pad), (pad + 8, pad), (pad, pad + 8): a gentle ramp per texel
    blk = legs + 2 * pad + 1
    corner_xy = np.array([[pad, pad], [pad + legs, pad], [pad, pad + legs]], dtype=np.float64)
    if len(unseen) == 0:
        return np.zeros((0, blk, blk, 3), np.uint8), block_of_face, corner_xy
    cc = _corner_colors(images, fuv, verts, faces, labels, corner_offsets=corner_offsets)[unseen]
    t = (np.arange(blk, dtype=np.float64) - pad) / legs
    tx, ty = t[None, :, None], t[:, None, None]  # block[y, x] = c0 + (c1 - c0) x + (c2 - c0) y
    c0, c1, c2 = (cc[:, k][:, None, None, :] for k in range(3))
    blocks = c0 + (c1 - c0) * tx[None] + (c2 - c0) * ty[None]
    block_of_face[unseen] = np.arange(len(unseen))
    return np.clip(np.rint(blocks), 0, 255).astype(np.uint8), block_of_face, corner_xy
