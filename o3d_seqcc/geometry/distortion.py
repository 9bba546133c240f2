"""Lens distortion, removed on the fly: a distorted photo read as the image of a pinhole camera.

A :class:`Distortion` holds a photo's own camera matrix (pixel centres at integers) and its
distortion coefficients in one of :data:`MODELS`:

- ``"opencv"``: OpenCV's ``(k1, k2, p1, p2[, k3[, k4, k5, k6]])`` on focal-normalised
  coordinates (COLMAP SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV; AliceVision radial1,
  radial3, brown);
- ``"fisheye"``: OpenCV's ``cv2.fisheye`` equidistant model ``(k1, k2, k3, k4)`` (COLMAP
  OPENCV_FISHEYE, SIMPLE_RADIAL_FISHEYE, RADIAL_FISHEYE; AliceVision fisheye4);
- ``"meshlab"``: MeshLab's ``LensDistortion`` ``(k0, k1)`` as vcglib's ``Camera::Project``
  applies it (its ``UndistortedToDistorted``, on the image-plane coordinates in millimetres,
  about the distortion centre MeshLab's project reader leaves at viewport pixel (0, 0); only
  ``k0`` is used, as in vcglib), so a raster projects where MeshLab projects it;
- ``"pixel-radial"``: ``(k1, k2, cx, cy, n)``, radial distortion in pixels about a centre of
  its own: the photo shows the pinhole pixel ``p = K (x, y, 1)`` at
  ``c + (p - c) (1 + k1 rho^2 + k2 rho^4)``, ``rho = |p - c| / n`` (MVE's
  ``image_undistort_k2k4``, when the principal point is not the distortion centre);
- ``"pixel-radial-inverse"``: ``(k1, cx, cy, n)``, the same defined the other way round: the
  photo's pixel ``d`` shows the pinhole pixel ``c + (d - c) (1 + k1 rho_d^2)``,
  ``rho_d = |d - c| / n`` (VisualSfM's model, MVE's ``image_undistort_vsfm``); inverted in
  closed form (the root continuous from the centre; none beyond the fold of a ``k1 < 0``);
- ``"metashape"``: Agisoft Metashape's frame camera ``(k1, k2, k3, k4, p1, p2, b1, b2)`` as its
  manual's "Camera models" appendix writes it, on focal-normalised ``(x, y)``: ``x' = x (1 + k1
  r^2 + k2 r^4 + k3 r^6 + k4 r^8) + p1 (r^2 + 2 x^2) + 2 p2 x y``, ``y' = y (...) + p2 (r^2 + 2
  y^2) + 2 p1 x y``, then ``u = cx + x' (f + b1) + y' b2``, ``v = cy + y' f`` (``f``, ``cx``,
  ``cy`` of the intrinsic); for the cameras OpenCV's model cannot express (``k4`` or ``b2``).

The scene's view gets the pinhole camera :meth:`Distortion.pinhole` (the photo's own matrix
when every pixel of the undistorted image then comes from inside the photo, else the same
matrix with the focal lengths raised just enough: the image keeps the photo's size and has no
empty border), and :meth:`Distortion.undistort` resamples each photo as it is read (the maps
of ``cv2.initUndistortRectifyMap`` / ``cv2.fisheye.initUndistortRectifyMap`` once per camera,
kept in a byte-bounded cache shared by the views of a camera; bilinear for photos, nearest
for depth maps).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError

__all__ = ["MAP_CACHE_BYTES", "MODELS", "Distortion"]

#: distortion models and the numbers of coefficients each takes
MODELS: dict[str, tuple[int, ...]] = {"opencv": (4, 5, 8), "fisheye": (4,), "meshlab": (2,), "pixel-radial": (5,),
                                      "pixel-radial-inverse": (4,), "metashape": (8,)}
#: models whose last three coefficients are the distortion centre and radius (cx, cy, n), not distortion terms
_PIXEL_RADIAL = {"pixel-radial": 2, "pixel-radial-inverse": 1}
#: byte budget of the undistortion maps kept (6 bytes per pixel and camera)
MAP_CACHE_BYTES = 256 * 2**20

_CACHE = None


def _cache():
    global _CACHE
    if _CACHE is None:
        from ..imaging.sequences import LRUCache

        _CACHE = LRUCache(MAP_CACHE_BYTES)
    return _CACHE


@dataclass(frozen=True, eq=False)
class Distortion:
    """A photo's lens distortion (see the module docstring).

    Parameters
    ----------
    model : {"opencv", "fisheye", "meshlab", "pixel-radial", "pixel-radial-inverse", "metashape"}
    coefficients : sequence of float
        4, 5 or 8 (opencv), 4 (fisheye), 2 (meshlab), 5 (pixel-radial), 4 (pixel-radial-inverse),
        8 (metashape).
    intrinsic : (3, 3) float
        The photo's own pinhole matrix (pixel centres at integers), before undistortion.
    meshlab : dict, optional
        ``"meshlab"`` only: MeshLab's ``PixelSizeMm``, ``CenterPx`` and ``ViewportPx`` as
        ``pixel_size_mm``, ``center_px``, ``viewport_px`` (2 numbers each) and
        ``distortion_center_px`` (default (0, 0), what MeshLab's project reader leaves).
    images, depth : bool, default True
        Whether the view's image / depth map are distorted (a view whose photo was replaced by
        an undistorted copy keeps ``images=False`` for its depth map).
    masks : bool, optional
        Whether the view's mask is distorted; default (None) as ``images`` (a mask is drawn on its
        photo; a photo replaced by an undistorted copy keeps ``masks=True`` for the mask of the
        original).
    """

    model: str
    coefficients: tuple[float, ...]
    intrinsic: np.ndarray
    meshlab: dict | None = field(default=None, repr=False)
    images: bool = True
    depth: bool = True
    masks: bool | None = None

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise InputError(f"unknown distortion model {self.model!r}; valid: {', '.join(MODELS)}")
        try:
            k = tuple(float(x) for x in self.coefficients)
        except (TypeError, ValueError):
            raise InputError(f"distortion coefficients must be numbers, got {self.coefficients!r:.80}") from None
        if len(k) not in MODELS[self.model] or not all(math.isfinite(x) for x in k):
            raise InputError(f"the {self.model} distortion model takes {' or '.join(map(str, MODELS[self.model]))} "
                             f"finite coefficients, got {list(k)}")
        if self.model in _PIXEL_RADIAL and not k[-1] > 0:
            raise InputError(f"the {self.model} distortion's radius n (its last coefficient) must be > 0, got {k[-1]}")
        object.__setattr__(self, "coefficients", k)
        K = np.array(self.intrinsic, dtype=np.float64)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise InputError(f"the distorted camera's intrinsic must be a finite (3, 3) pinhole matrix, got "
                             f"{np.asarray(self.intrinsic).tolist()!r:.120}")
        K.setflags(write=False)
        object.__setattr__(self, "intrinsic", K)
        if self.model == "meshlab":
            m = dict(self.meshlab or {})
            try:
                m = {k: [float(x) for x in m[k]] if k in m else [0.0, 0.0]
                     for k in ("pixel_size_mm", "center_px", "viewport_px", "distortion_center_px")}
                if not all(len(v) == 2 and all(map(math.isfinite, v)) for v in m.values()) or \
                        min(m["pixel_size_mm"] + m["viewport_px"]) <= 0:
                    raise ValueError
            except (TypeError, ValueError):
                raise InputError("a meshlab distortion needs pixel_size_mm, center_px and viewport_px (2 finite "
                                 "numbers each, sizes > 0) and optionally distortion_center_px") from None
            object.__setattr__(self, "meshlab", m)

    @property
    def is_zero(self) -> bool:
        """All distortion coefficients are zero (a pinhole camera)."""
        return not any(self.coefficients[:_PIXEL_RADIAL.get(self.model)])

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Distortion):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]

    def to_dict(self) -> dict:
        """JSON form (``scene.json``'s ``distortion``); :meth:`from_dict` reads it back exactly."""
        d = {"model": self.model, "coefficients": list(self.coefficients), "intrinsic": self.intrinsic.tolist()}
        if self.meshlab is not None:
            d["meshlab"] = self.meshlab
        if not self.images:
            d["images"] = False
        if not self.depth:
            d["depth"] = False
        if self.masks is not None:
            d["masks"] = bool(self.masks)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "Distortion":
        if not isinstance(d, dict) or not {"model", "coefficients", "intrinsic"} <= set(d):
            raise InputError("a distortion is an object with 'model', 'coefficients' and 'intrinsic'")
        unknown = set(d) - {"model", "coefficients", "intrinsic", "meshlab", "images", "depth", "masks"}
        if unknown:
            raise InputError(f"distortion has unknown keys {sorted(map(str, unknown))}")
        return cls(model=d["model"], coefficients=d["coefficients"], intrinsic=d["intrinsic"],
                   meshlab=d.get("meshlab"), images=bool(d.get("images", True)), depth=bool(d.get("depth", True)),
                   masks=None if d.get("masks") is None else bool(d["masks"]))

    # ---------------------------------------------------------------------------------- the model

    def distort(self, xy: np.ndarray) -> np.ndarray:
        """Photo pixel coordinates of undistorted, focal-normalised camera coordinates.

        Parameters
        ----------
        xy : (n, 2) float
            ``(X / Z, Y / Z)`` in OpenCV camera axes.

        Returns
        -------
        (n, 2) float64
            Where the photo shows those directions (pixel centres at integers).
        """
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        K = self.intrinsic
        if self.model == "meshlab":
            return self._meshlab_distort(xy)
        if self.model in _PIXEL_RADIAL:
            return self._pixel_radial_distort(xy)
        if self.model == "metashape":
            return _metashape_distort(xy, self.coefficients, K)
        import cv2

        pts = np.concatenate([xy, np.ones((len(xy), 1))], axis=1).reshape(-1, 1, 3)
        zero = np.zeros(3)
        if self.model == "fisheye":
            out, _ = cv2.fisheye.projectPoints(pts, zero, zero, K, np.array(self.coefficients))
        else:
            out, _ = cv2.projectPoints(pts, zero, zero, K, np.array(self.coefficients))
        return out.reshape(-1, 2)

    def _meshlab_distort(self, xy: np.ndarray) -> np.ndarray:
        """vcglib ``Camera::Project``: image-plane mm, its ``UndistortedToDistorted`` (literally), back to pixels.

        Our pixel (x, y) is MeshLab's viewport point (x + 0.5, H - y - 0.5) (y up); the image
        plane point is (viewport - CenterPx) * PixelSizeMm, so relative to the principal point
        ``u = ((x - cx) px, -(y - cy) py)``.
        """
        K = self.intrinsic
        m = self.meshlab
        pix = np.asarray(m["pixel_size_mm"])
        x_px = K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2]
        y_px = K[1, 1] * xy[:, 1] + K[1, 2]
        u = np.stack([(x_px - K[0, 2]) * pix[0], -(y_px - K[1, 2]) * pix[1]], axis=1)
        k0 = self.coefficients[0]
        d = u if k0 == 0 else _vcg_undistorted_to_distorted(u, self._meshlab_dc(), k0)
        return np.stack([d[:, 0] / pix[0] + K[0, 2], K[1, 2] - d[:, 1] / pix[1]], axis=1)

    def _meshlab_dc(self) -> np.ndarray:
        """vcglib's ``ViewportPxTo_neg1_1(DistorCenterPx)``: ``2 (DistorCenterPx - CenterPx) / ViewportPx``."""
        m = self.meshlab
        return 2.0 * (np.asarray(m["distortion_center_px"]) - np.asarray(m["center_px"])) / np.asarray(m["viewport_px"])

    def _pixel_radial_distort(self, xy: np.ndarray) -> np.ndarray:
        """``"pixel-radial"`` / ``"pixel-radial-inverse"``: the pinhole pixel moved radially about ``(cx, cy)``."""
        K, k = self.intrinsic, self.coefficients
        c, n = np.array(k[-3:-1]), k[-1]
        p = np.stack([K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2], K[1, 1] * xy[:, 1] + K[1, 2]], axis=1)
        q = p - c
        rho2 = np.einsum("ij,ij->i", q, q) / (n * n)
        if self.model == "pixel-radial":
            scale = 1.0 + rho2 * (k[0] + k[1] * rho2)
        else:
            scale = _inverse_radial_scale(np.sqrt(rho2), k[0])
        return c + q * scale[:, None]

    def pinhole(self, width: int, height: int) -> np.ndarray:
        """(3, 3) matrix of the undistorted image (``width`` x ``height``): every pixel inside the photo.

        The photo's own matrix when all of the undistorted image's border maps inside the
        photo; else its focal lengths scaled up (principal point kept) by the smallest factor,
        found by bisection to 1e-4, for which it does.
        """
        key = ("pinhole", self._key(), int(width), int(height))
        hit = _cache().get(key)
        if hit is not None:
            return hit[0].copy()
        W, H = int(width), int(height)
        n = max(W, H) // 2 + 2
        xs, ys = np.linspace(-0.5, W - 0.5, n), np.linspace(-0.5, H - 0.5, n)
        border = np.concatenate([np.stack([xs, np.full(n, -0.5)], 1), np.stack([xs, np.full(n, H - 0.5)], 1),
                                 np.stack([np.full(n, -0.5), ys], 1), np.stack([np.full(n, W - 0.5), ys], 1)])
        K0 = self.intrinsic

        def fits(s: float) -> bool:
            K = K0.copy()
            K[0, 0] *= s
            K[0, 1] *= s
            K[1, 1] *= s
            y = (border[:, 1] - K[1, 2]) / K[1, 1]
            x = (border[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
            d = self.distort(np.stack([x, y], 1))
            return bool(np.all(np.isfinite(d)) and np.all((d[:, 0] >= -0.5) & (d[:, 0] <= W - 0.5)
                                                          & (d[:, 1] >= -0.5) & (d[:, 1] <= H - 0.5)))

        s = 1.0
        if not fits(1.0):
            lo, hi = 1.0, 2.0
            while not fits(hi):
                lo, hi = hi, hi * 2
                if hi > 64:
                    raise InputError(f"the {self.model} distortion {list(self.coefficients)} maps no pinhole image "
                                     f"of {W}x{H} inside the photo; check the coefficients")
            while hi - lo > 1e-4:
                mid = 0.5 * (lo + hi)
                lo, hi = (lo, mid) if fits(mid) else (mid, hi)
            s = hi
        K = K0.copy()
        K[0, 0] *= s
        K[0, 1] *= s
        K[1, 1] *= s
        _cache()[key] = (K,)
        return K.copy()

    def _key(self) -> tuple:
        m = tuple(sorted((k, tuple(v)) for k, v in (self.meshlab or {}).items()))
        return (self.model, self.coefficients, tuple(self.intrinsic.ravel()), m)

    def maps(self, width: int, height: int, pinhole: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``cv2.remap`` maps (fixed point, CV_16SC2 + CV_16UC1) from the photo to the pinhole image; cached."""
        import cv2

        W, H = int(width), int(height)
        P = np.asarray(pinhole, dtype=np.float64)
        key = ("maps", self._key(), W, H, tuple(P.ravel()))

        def make():
            if self.model == "opencv":
                return cv2.initUndistortRectifyMap(self.intrinsic, np.array(self.coefficients), None, P, (W, H),
                                                   cv2.CV_16SC2)
            if self.model == "fisheye":
                return cv2.fisheye.initUndistortRectifyMap(self.intrinsic, np.array(self.coefficients), np.eye(3), P,
                                                           (W, H), cv2.CV_16SC2)
            u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
            y = (v.ravel() - P[1, 2]) / P[1, 1]
            x = (u.ravel() - P[0, 2] - P[0, 1] * y) / P[0, 0]
            d = self.distort(np.stack([x, y], 1)).astype(np.float32)
            return cv2.convertMaps(d[:, 0].reshape(H, W), d[:, 1].reshape(H, W), cv2.CV_16SC2)

        return _cache().get(key, make)

    def undistort(self, image: np.ndarray, pinhole: np.ndarray, *, nearest: bool = False) -> np.ndarray:
        """The photo (or depth map) as the pinhole camera ``pinhole`` sees it: same size and dtype.

        Parameters
        ----------
        image : (H, W) or (H, W, C) array
        pinhole : (3, 3) float
            :meth:`pinhole` of this size.
        nearest : bool, default False
            Nearest-neighbour (depth maps: no depth mixed across edges) instead of bilinear.
        """
        import cv2

        img = np.asarray(image)
        H, W = img.shape[:2]
        m1, m2 = self.maps(W, H, pinhole)
        src = img if img.dtype in (np.uint8, np.uint16, np.float32) else img.astype(np.float64)
        out = cv2.remap(np.ascontiguousarray(src), m1, m2, cv2.INTER_NEAREST if nearest else cv2.INTER_CUBIC,
                        borderMode=cv2.BORDER_REPLICATE)
        return out.astype(img.dtype, copy=False)


def _vcg_undistorted_to_distorted(u: np.ndarray, dc: np.ndarray, k0: float) -> np.ndarray:
    """vcglib ``Camera<S>::UndistortedToDistorted`` (vcg/math/camera.ipp), vectorised, as it is written."""
    rel = u - dc
    Ru = np.hypot(rel[:, 0], rel[:, 1])
    c = 1.0 / k0
    dd = -c * Ru
    Q = c / 3.0
    R = -dd / 2.0
    D = Q ** 3 + np.sqrt(np.abs(R))
    Rd = np.empty_like(Ru)
    one = D >= 0
    with np.errstate(invalid="ignore"):
        Dp = np.sqrt(np.where(one, D, 0.0))
        Rr = R[one]
        S = np.power(Rr + Dp[one], 1.0 / 3.0)  # C's pow: NaN for a negative base
        T = np.where(Rr >= Dp[one], np.power(np.maximum(Rr - Dp[one], 0.0), 1.0 / 3.0),
                     -np.power(np.abs(np.trunc(Rr - Dp[one])), 1.0 / 3.0))
        r1 = S + T
        r1 = np.where(r1 < 0, math.sqrt(-1.0 / (3.0 * k0)) if k0 < 0 else np.nan, r1)
        Rd[one] = r1
        Dn = np.sqrt(-D[~one])
        S3 = np.power(np.hypot(R[~one], Dn), 1.0 / 3.0)
        T3 = np.arctan2(Dn, R[~one]) / 3.0
        Rd[~one] = -S3 * np.cos(T3) + math.sqrt(3.0) * S3 * np.sin(T3)
    lam = np.where(Ru > 0, Rd / np.where(Ru > 0, Ru, 1.0), 1.0)
    out = u * lam[:, None]
    same = Ru == 0
    out[same] = u[same]
    return out


def _inverse_radial_scale(rho_u: np.ndarray, k: float) -> np.ndarray:
    """``rho_d / rho_u`` for the root ``rho_d`` of ``rho_d (1 + k rho_d^2) = rho_u`` continuous from 0.

    Closed form, stable for small ``k``: ``rho_d = 2 sinh(asinh(b) / 3) / sqrt(3k)`` with
    ``b = 1.5 rho_u sqrt(3k)`` for ``k > 0`` (the one real root), ``2 sin(asin(a) / 3) /
    sqrt(-3k)`` with ``a = 1.5 rho_u sqrt(-3k)`` for ``k < 0`` (the smallest positive root; NaN
    for ``a > 1``, beyond the fold, where no direction is seen).
    """
    rho_u = np.asarray(rho_u, dtype=np.float64)
    if k == 0:
        return np.ones_like(rho_u)
    s = math.sqrt(3.0 * abs(k))
    with np.errstate(invalid="ignore"):
        rho_d = (2.0 / s) * (np.sinh(np.arcsinh(1.5 * rho_u * s) / 3.0) if k > 0
                             else np.sin(np.arcsin(1.5 * rho_u * s) / 3.0))
    return np.where(rho_u > 0, rho_d / np.where(rho_u > 0, rho_u, 1.0), 1.0)


def _metashape_distort(xy: np.ndarray, k: tuple[float, ...], K: np.ndarray) -> np.ndarray:
    """Photo pixels of undistorted focal-normalised points under Metashape's frame camera model."""
    k1, k2, k3, k4, p1, p2, b1, b2 = k
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)))
    xd = x * radial + p1 * (r2 + 2.0 * x * x) + 2.0 * p2 * x * y
    yd = y * radial + p2 * (r2 + 2.0 * y * y) + 2.0 * p1 * x * y
    return np.stack([K[0, 2] + xd * (K[0, 0] + b1) + yd * (K[0, 1] + b2), K[1, 2] + yd * K[1, 1]], axis=1)
