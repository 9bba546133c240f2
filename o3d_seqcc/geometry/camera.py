"""Pinhole projection in the package's conventions (OpenCV axes, pixel centres at integers).

``u = fx * X / Z + skew * Y / Z + cx``, ``v = fy * Y / Z + cy`` with ``(X, Y, Z) = R x + t`` the
camera-frame coordinates of a world point (``extrinsic = [R | t]``, world-to-camera); pixel
``(i, j)`` covers ``[i - 0.5, i + 0.5) x [j - 0.5, j + 0.5)``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["inside_image", "pixel_index", "project_columns", "project_points"]


def project_points(
    points: np.ndarray, intrinsic: np.ndarray, extrinsic: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole projection of world points.

    Parameters
    ----------
    points : (n, 3) float
        World coordinates.
    intrinsic : (3, 3) float
    extrinsic : (4, 4) float
        World-to-camera, OpenCV axes.

    Returns
    -------
    uv : (n, 2) float64
        Pixel coordinates (pixel centres at integers); NaN where ``z <= 0``.
    z : (n,) float64
        Camera-frame depth.

    Examples
    --------
    >>> import numpy as np, o3d_seqcc as sc
    >>> K = np.array([[100.0, 0, 50], [0, 100, 40], [0, 0, 1]])
    >>> uv, depth = sc.project_points(np.array([[0.0, 0, 2], [0.2, -0.1, 2]]), K, np.eye(4))
    >>> uv.tolist(), depth.tolist()
    ([[50.0, 40.0], [60.0, 35.0]], [2.0, 2.0])
    """
    X = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    u, v, z = project_columns(np.ascontiguousarray(X.T), np.asarray(intrinsic, np.float64), np.asarray(extrinsic, np.float64))
    uv = np.stack([u, v], axis=1)
    return uv, z


def inside_image(uv: np.ndarray, z: np.ndarray, width: int, height: int) -> np.ndarray:
    """(...,) bool: in front of the camera and inside ``[-0.5, W-0.5) x [-0.5, H-0.5)``."""
    u, v = uv[..., 0], uv[..., 1]
    with np.errstate(invalid="ignore"):
        return (z > 0) & (u >= -0.5) & (u < width - 0.5) & (v >= -0.5) & (v < height - 0.5)


def pixel_index(uv: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Nearest pixel (row, col) of in-image coordinates (pixel i covers [i-0.5, i+0.5))."""
    c = np.clip(np.floor(uv[:, 0] + 0.5), 0, width - 1).astype(np.intp)
    r = np.clip(np.floor(uv[:, 1] + 0.5), 0, height - 1).astype(np.intp)
    return r, c


def project_columns(XT: np.ndarray, K: np.ndarray, E: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Projection of column-major points ``XT`` (3, N): ``u, v, z`` each (N,), NaN u, v where ``z <= 0``."""
    R, t = E[:3, :3], E[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = R[0, 0] * XT[0] + R[0, 1] * XT[1] + R[0, 2] * XT[2] + t[0]
        y = R[1, 0] * XT[0] + R[1, 1] * XT[1] + R[1, 2] * XT[2] + t[1]
        z = R[2, 0] * XT[0] + R[2, 1] * XT[1] + R[2, 2] * XT[2] + t[2]
        inv = np.where(z > 0, 1.0 / z, np.nan)
        x *= inv
        y *= inv
        u = K[0, 0] * x + K[0, 1] * y + K[0, 2]
        v = K[1, 1] * y + K[1, 2]
    return u, v, z
