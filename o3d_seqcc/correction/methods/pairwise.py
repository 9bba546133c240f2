"""Per-edge colour transfer baselines of the paper's Table 1 (#1-#4), applied along the graph's paths.

``"none"`` (#1)
    Identity.
``"reinhard"`` (#2, Reinhard et al. 2001)
    l-alpha-beta mean / standard deviation transfer, statistics of the colours at each pair's
    mappings, applied step by step along the path.
``"root-polynomial"`` (#3, Finlayson et al. 2015)
    Degree-2 root-polynomial regression: features ``r, g, b, sqrt(rg), sqrt(gb), sqrt(rb)`` ->
    3x6 matrix by least squares on the pair's colours, applied step by step along the path.
``"vandermonde"`` (#4, De Marchi)
    Per-channel cubic polynomial CMF by Vandermonde least squares, composed as lookup tables.
"""

from __future__ import annotations

import numpy as np

from ..cmf import fit_cmf
from ..base import CorrectionContext, IdentityTransform, lut_per_path, sequential

__all__ = ["lab_reinhard_to_rgb", "rgb_to_lab_reinhard", "root_polynomial_features"]


def _method_none(ctx: CorrectionContext) -> list:
    return [IdentityTransform() for _ in ctx.images]



def _method_vandermonde(ctx: CorrectionContext, *, degree: int = 3) -> list:
    """Per-channel polynomial CMF (Vandermonde least squares, De Marchi), composed along paths."""

    def edge_lut(t: int, s: int) -> np.ndarray:
        ct, cs = ctx.colors(t, s)
        return np.stack(
            [
                fit_cmf(
                    ct[:, c], cs[:, c], method="polynomial", degree=degree, guard=False, pairing="joint", n_out=ctx.lut_size
                )
                for c in range(3)
            ]
        )

    return lut_per_path(ctx, edge_lut)


# Reinhard et al. 2001 l-alpha-beta
_RGB2LMS = np.array([[0.3811, 0.5783, 0.0402], [0.1967, 0.7244, 0.0782], [0.0241, 0.1288, 0.8444]])
_LMS2RGB = np.linalg.inv(_RGB2LMS)
_LMS2LAB = np.diag([1 / np.sqrt(3), 1 / np.sqrt(6), 1 / np.sqrt(2)]) @ np.array([[1, 1, 1], [1, 1, -2], [1, -1, 0]])
_LAB2LMS = np.linalg.inv(_LMS2LAB)
_LOG_EPS = 1.0 / 510.0  # half an 8-bit level: keeps log10 finite on black pixels


def rgb_to_lab_reinhard(rgb: np.ndarray) -> np.ndarray:
    """(n, 3) RGB in [0, 1] -> (n, 3) Reinhard l-alpha-beta (log10 LMS, decorrelated)."""
    lms = np.maximum(np.asarray(rgb, dtype=np.float64) @ _RGB2LMS.T, _LOG_EPS)
    return np.log10(lms) @ _LMS2LAB.T


def lab_reinhard_to_rgb(lab: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rgb_to_lab_reinhard` (not clipped)."""
    return (10.0 ** (np.asarray(lab, dtype=np.float64) @ _LAB2LMS.T)) @ _LMS2RGB.T


def _method_reinhard(ctx: CorrectionContext) -> list:
    """Reinhard et al. (2001) mean/std transfer in l-alpha-beta, per path edge, sequentially."""

    def make_step(t: int, s: int):
        ct, cs = ctx.colors(t, s)
        lt, ls = rgb_to_lab_reinhard(ct), rgb_to_lab_reinhard(cs)
        mt, ms = lt.mean(0), ls.mean(0)
        st, ss = lt.std(0), ls.std(0)
        ratio = np.where(st > 1e-6, ss / np.where(st > 1e-6, st, 1.0), 1.0)

        def step(x: np.ndarray) -> np.ndarray:
            return lab_reinhard_to_rgb((rgb_to_lab_reinhard(x) - mt) * ratio + ms)

        return step

    return sequential(ctx, make_step)


def root_polynomial_features(rgb: np.ndarray) -> np.ndarray:
    """(n, 3) RGB in [0, 1] -> (n, 6) degree-2 root-polynomial terms r, g, b, sqrt(rg), sqrt(gb), sqrt(rb)."""
    rgb = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, None)
    r, g, b = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    return np.stack([r, g, b, np.sqrt(r * g), np.sqrt(g * b), np.sqrt(r * b)], axis=1)


def _method_root_polynomial(ctx: CorrectionContext) -> list:
    """Finlayson et al. (2015) degree-2 root-polynomial regression per path edge, sequentially."""

    def make_step(t: int, s: int):
        ct, cs = ctx.colors(t, s)
        M, *_ = np.linalg.lstsq(root_polynomial_features(ct), cs, rcond=None)  # (6, 3)

        def step(x: np.ndarray) -> np.ndarray:
            return root_polynomial_features(x) @ M

        return step

    return sequential(ctx, make_step)
