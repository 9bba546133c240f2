"""Per-photo masks in the visibility: a face a photo shows through masked pixels is not usable in it.

A view with a mask (:meth:`~o3d_seqcc.scene.View.load_mask`: False = masked out) gets the filter
bit :data:`~o3d_seqcc.visibility.per_view.MASKED` on every valid face whose projection comes
within :data:`MASK_MARGIN` pixels of a masked pixel: the face's projected bounding box, grown by
the margin, holds a masked pixel (a pixel is in the box when its square, centre +- 0.5, meets
it), counted in O(1) per face from a summed-area table of the mask. The test is conservative
(a box holds its triangle) and exact for the box; the margin covers what the later stages read
around a point of a face: bilinear taps (1 px) in the mappings and the data costs' gradients,
OpenCV's Lanczos-4 taps (up to 4 px) in the bake. So no pixel a masked face would read is
masked, and every later stage (mappings, view selection, outliers, charts, bake) reads the
usable faces only: masked pixels count nowhere. Faces no photo can then use whole are split by
:mod:`~o3d_seqcc.visibility.refine` as those partly hidden are (its probes skip masked pixels),
so the parts clear of the mask are textured.

Masks are read one view at a time (a view's task), held packed (one bit a pixel) while a job's
passes need them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MASK_MARGIN", "MaskImage", "mask_image", "masked_faces", "masked_points"]

#: pixels around a face's projection that must be unmasked for the face to be usable (OpenCV's INTER_LANCZOS4 reads
#: up to 4 pixels from the point it samples; bilinear taps and Sobel gradients 1)
MASK_MARGIN = 4.0


@dataclass(frozen=True, eq=False)
class MaskImage:
    """A view's mask, held packed.

    Attributes
    ----------
    bits : (ceil(H * W / 8),) uint8
        ``numpy.packbits`` of the (H, W) masked-out pixels, row-major.
    height, width : int
    masked_pixels : int
        Pixels masked out.
    """

    bits: np.ndarray
    height: int
    width: int
    masked_pixels: int

    @property
    def share(self) -> float:
        """The share of the photo's pixels masked out, in [0, 1]."""
        return self.masked_pixels / max(self.height * self.width, 1)

    @property
    def nbytes(self) -> int:
        return int(self.bits.nbytes)

    def masked(self) -> np.ndarray:
        """(H, W) bool: the pixels masked out."""
        n = self.height * self.width
        return np.unpackbits(self.bits, count=n).reshape(self.height, self.width).view(bool)

    def table(self) -> np.ndarray:
        """(H + 1, W + 1) summed-area table of the masked pixels (a leading row and column of zeros; OpenCV's
        ``integral``, int32, float64 past 2**31 pixels: 6 ms at 6 MP)."""
        import cv2

        small = self.height * self.width < 2**31
        return cv2.integral(self.masked().view(np.uint8), sdepth=cv2.CV_32S if small else cv2.CV_64F)


def mask_image(view) -> MaskImage | None:
    """A view's mask as a :class:`MaskImage` (read once, undistorted with its photo), or None without one."""
    keep = view.load_mask()
    if keep is None:
        return None
    masked = ~np.asarray(keep, dtype=bool)
    return MaskImage(bits=np.packbits(masked, axis=None), height=int(masked.shape[0]), width=int(masked.shape[1]),
                     masked_pixels=int(np.count_nonzero(masked)))


def masked_faces(mask: MaskImage, u: np.ndarray, v: np.ndarray, i0: np.ndarray, i1: np.ndarray, i2: np.ndarray, *,
                 margin: float = MASK_MARGIN) -> np.ndarray:
    """(k,) bool: the faces (corners ``i0, i1, i2`` into the vertex projections ``u, v``) whose projected bounding box,
    grown by ``margin`` pixels, meets a masked pixel (module docstring)."""
    k = len(i0)
    if not mask.masked_pixels or not k:
        return np.zeros(k, dtype=bool)
    if mask.masked_pixels == mask.height * mask.width:
        return np.ones(k, dtype=bool)
    W, H = mask.width, mask.height

    def span(a: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
        lo = np.minimum(np.minimum(a[i0], a[i1]), a[i2]) - margin
        hi = np.maximum(np.maximum(a[i0], a[i1]), a[i2]) + margin
        first = np.clip(np.floor(lo + 0.5), 0, n - 1).astype(np.intp)  # the pixel whose square holds lo
        last = np.clip(np.floor(hi + 0.5), 0, n - 1).astype(np.intp)
        return first, last + 1

    c0, c1 = span(u, W)
    r0, r1 = span(v, H)
    S = mask.table()
    return (S[r1, c1] - S[r0, c1] - S[r1, c0] + S[r0, c0]) > 0


def masked_points(mask: MaskImage | None, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n,) bool: the points (pixel coordinates, centres at integers) that fall on a masked pixel (nearest; points
    outside the image take the nearest border pixel)."""
    if mask is None or not mask.masked_pixels or not len(u):
        return np.zeros(len(u), dtype=bool)
    c = np.clip(np.floor(np.asarray(u) + 0.5), 0, mask.width - 1).astype(np.intp)
    r = np.clip(np.floor(np.asarray(v) + 0.5), 0, mask.height - 1).astype(np.intp)
    idx = r * mask.width + c
    return (mask.bits[idx >> 3] >> (7 - (idx & 7)).astype(np.uint8) & 1).astype(bool)
