"""Depth images for the depth-consistency filter (paper 3.2): rendered point clouds, discontinuities.

:func:`depth_from_point_cloud` renders a view's partial point cloud to a depth image (nearest
point per pixel) and fills its small holes with OpenCV's Navier-Stokes inpainting, as the paper
does; :func:`depth_edges` marks the pixels near depth discontinuities. :class:`DepthImage` holds a
view's depth image for the visibility's passes (a 16-bit map as its counts).
"""

from __future__ import annotations

import numpy as np

from ..geometry.camera import inside_image, pixel_index, project_points
from ..io.depth import depth_in_metres
from .settings import VisibilitySettings

__all__ = ["DepthImage", "depth_edges", "depth_from_point_cloud"]

class DepthImage:
    """A view's depth image in metres; a 16-bit depth map is held as its counts.

    :func:`~o3d_seqcc.io.depth.read_depth` gives ``counts / depth_scale`` in float64 (0 beyond
    :data:`~o3d_seqcc.io.mesh_files.MAX_COORDINATE`); holding the counts (2 bytes a pixel instead of 8)
    and converting at each look-up (:func:`~o3d_seqcc.io.depth.depth_in_metres`, the same function)
    gives the same values, bit for bit, without the float image.

    Parameters
    ----------
    depth : (H, W) float64, optional
        Metres, 0 = missing.
    counts : (H, W) uint16, optional
        Instead of ``depth``: a 16-bit map as stored, with its ``scale`` (units per metre).
    scale : float
    """

    def __init__(self, depth: np.ndarray | None = None, *, counts: np.ndarray | None = None,
                 scale: float = 1.0) -> None:
        if (depth is None) == (counts is None):
            raise ValueError("DepthImage takes depth or counts")
        self.depth = None if depth is None else np.asarray(depth)
        self.counts = None if counts is None else np.asarray(counts)
        self.scale = float(scale)
        self.shape = (self.depth if counts is None else self.counts).shape

    @property
    def nbytes(self) -> int:
        return int((self.depth if self.counts is None else self.counts).nbytes)

    def at(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(n,) float64 depths at the pixels ``(rows, cols)``."""
        if self.counts is None:
            return self.depth[rows, cols]
        return depth_in_metres(self.counts[rows, cols], self.scale)

    def image(self) -> np.ndarray:
        """(H, W) float64: the whole image."""
        return self.depth if self.counts is None else depth_in_metres(self.counts, self.scale)


def depth_from_point_cloud(
    points: np.ndarray,
    intrinsic: np.ndarray,
    extrinsic: np.ndarray,
    width: int,
    height: int,
    *,
    fill_radius: int = VisibilitySettings.fill_radius,
    inpaint_radius: float = 3.0,
) -> np.ndarray:
    """Render a depth image from a point cloud: nearest point per pixel, small holes inpainted.

    Parameters
    ----------
    points : (M, 3) float
        World points.
    intrinsic, extrinsic : arrays
        The view's camera.
    width, height : int
    fill_radius : int, default 6
        Empty pixels within this many pixels of a rendered one are filled with
        ``cv2.inpaint(..., cv2.INPAINT_NS)`` (Navier-Stokes, as in the paper); larger empty
        regions stay 0 (missing). 0 disables filling.
    inpaint_radius : float, default 3.0
        Neighbourhood radius passed to ``cv2.inpaint``.

    Returns
    -------
    (H, W) float64
        Camera z per pixel, 0 where missing.
    """
    import cv2

    uv, z = project_points(points, intrinsic, extrinsic)
    ok = inside_image(uv, z, width, height)
    r, c = pixel_index(uv[ok], width, height)
    pix = r * width + c
    zz = z[ok]
    D = np.zeros(height * width, dtype=np.float64)
    if len(pix):
        order = np.lexsort((zz, pix))
        ps, zs = pix[order], zz[order]
        first = np.ones(len(ps), dtype=bool)
        first[1:] = ps[1:] != ps[:-1]
        D[ps[first]] = zs[first]
    D = D.reshape(height, width)
    if fill_radius > 0 and (D > 0).any() and (D == 0).any():
        have = (D > 0).astype(np.uint8)
        k = 2 * int(fill_radius) + 1
        near = cv2.dilate(have, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
        mask = (near & (D == 0)).astype(np.uint8)
        if mask.any():
            filled = cv2.inpaint(D.astype(np.float32), mask, float(inpaint_radius), cv2.INPAINT_NS)
            D = np.where(mask > 0, np.maximum(filled.astype(np.float64), 0.0), D)
    return D


def depth_edges(D: np.ndarray, margin: int, atol: float, rtol: float) -> np.ndarray:
    """(H, W) bool: within ``margin`` px of a depth discontinuity.

    A discontinuity is a jump between 4-neighbouring pixels (both with depth) larger than
    ``max(atol, rtol * nearer depth)``; gradual changes (slanted surfaces) are not edges.
    """
    import cv2

    edge = np.zeros(D.shape, dtype=np.uint8)
    for a, b, sa, sb in (
        (D[:, :-1], D[:, 1:], (slice(None), slice(None, -1)), (slice(None), slice(1, None))),
        (D[:-1, :], D[1:, :], (slice(None, -1), slice(None)), (slice(1, None), slice(None))),
    ):
        near = np.minimum(a, b)
        jump = (a > 0) & (b > 0) & (np.abs(a - b) > np.maximum(atol, rtol * near))
        edge[sa] |= jump
        edge[sb] |= jump
    k = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * margin + 1, 2 * margin + 1))
    return cv2.dilate(edge, k) > 0
