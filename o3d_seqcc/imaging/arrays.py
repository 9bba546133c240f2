"""Image helpers every stage shares: dtype conversion, sub-pixel sampling, CIE Lab and CIEDE2000.

One conversion helper per direction, used everywhere (as scikit-image's ``img_as_float``):

- :func:`img_as_float`: uint8 (/255), uint16 (/65535) or float -> float64 in [0, 1];
- :func:`img_as_dtype`: float in [0, 1] -> uint8 / uint16 (rounded, clipped) or a float dtype;
- :func:`img_as_uint8`: any supported image -> uint8 (16-bit rounded to the nearest level).

Sampling follows the package's pixel convention (x right, y down, pixel centres at integers):
:func:`sample_bilinear` (clamped to the border, any shape of query points) and
:func:`sample_colors` (the (n, 2) ``uv`` form with a choice of interpolation).

Colour differences come from one library, scikit-image: :func:`rgb_to_lab` (sRGB with its
transfer function -> XYZ -> CIE Lab, D65, 2 degree observer), :func:`ciede2000` and
:func:`delta_e_2000` (sRGB in, CIEDE2000 out).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = [
    "ciede2000",
    "delta_e_2000",
    "dtype_scale",
    "img_as_dtype",
    "img_as_float",
    "img_as_uint8",
    "linear_to_srgb",
    "rgb_to_lab",
    "sample_bilinear",
    "sample_colors",
    "srgb_to_linear",
]

INTERPOLATIONS = ("bilinear", "nearest")


def dtype_scale(dtype: np.dtype | type) -> float:
    """The value that maps ``dtype`` to 1.0: 255 for uint8, 65535 for uint16, 1 for floats.

    Raises
    ------
    InputError
        Any other dtype (the message names the supported ones).
    """
    dtype = np.dtype(dtype)
    if dtype == np.uint8:
        return 255.0
    if dtype == np.uint16:
        return 65535.0
    if np.issubdtype(dtype, np.floating):
        return 1.0
    raise InputError(f"images must be uint8, uint16 or float in [0, 1]; got dtype {dtype}")


def img_as_float(image: np.ndarray) -> np.ndarray:
    """Any supported image as float64 in [0, 1] (a new array; the input is not modified).

    Parameters
    ----------
    image : (..., C) uint8, uint16 or float array
        uint8 is divided by 255, uint16 by 65535; floats are taken as [0, 1] (NaN -> 0, clipped).

    Returns
    -------
    numpy.ndarray
        float64, same shape.
    """
    image = np.asarray(image)
    scale = dtype_scale(image.dtype)
    if scale == 1.0:
        return np.clip(np.nan_to_num(image.astype(np.float64), nan=0.0), 0.0, 1.0)
    return image.astype(np.float64) / scale


def img_as_dtype(image: np.ndarray, dtype: np.dtype | type) -> np.ndarray:
    """Float values in [0, 1] as ``dtype``: uint8 / uint16 rounded and clipped, floats clipped.

    Parameters
    ----------
    image : array_like of float
        Values in [0, 1] (NaN -> 0, out-of-range values clipped).
    dtype : numpy dtype
        uint8, uint16 or a float dtype.

    Returns
    -------
    numpy.ndarray
        Same shape, ``dtype``.
    """
    dtype = np.dtype(dtype)
    scale = dtype_scale(dtype)
    x = np.clip(np.nan_to_num(np.asarray(image, dtype=np.float64), nan=0.0), 0.0, 1.0)
    if scale == 1.0:
        return x.astype(dtype)
    return np.rint(x * scale).astype(dtype)


def img_as_uint8(image: np.ndarray, *, where: str = "image") -> np.ndarray:
    """An (H, W, 3) RGB image as uint8 (returned as is when it already is uint8).

    16-bit levels are rounded to the nearest 8-bit level (``(x + 128) // 257``), floats in
    [0, 1] to ``rint(255 x)``.

    Raises
    ------
    InputError
        Not (H, W, 3), or an unsupported dtype; the message starts with ``where``.
    """
    a = np.asarray(image)
    if a.ndim != 3 or a.shape[2] != 3:
        raise InputError(f"{where}: expected an (H, W, 3) RGB image, got shape {a.shape}")
    if a.dtype == np.uint8:
        return a
    if a.dtype == np.uint16:
        return ((a.astype(np.uint32) + 128) // 257).astype(np.uint8)
    if np.issubdtype(a.dtype, np.floating):
        return img_as_dtype(a, np.uint8)
    raise InputError(f"{where}: unsupported image dtype {a.dtype} (use uint8, uint16 or float in [0, 1])")


def sample_bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear lookup at pixel coordinates, clamped to the border.

    Parameters
    ----------
    image : (H, W, C) or (H, W) array
        Any real dtype.
    x, y : (...) float arrays of the same shape
        Column and row coordinates (pixel centres at integers). Points outside
        ``[0, W-1] x [0, H-1]`` take the border values.

    Returns
    -------
    numpy.ndarray
        (..., C) float64 (or (...) for a 2-D image), in the image's own units (0-255 for
        uint8; divide by :func:`dtype_scale` for [0, 1]).
    """
    img = np.asarray(image)
    if img.ndim not in (2, 3):
        raise ValueError(f"image must be (H, W) or (H, W, C), got shape {img.shape}")
    h, w = img.shape[:2]
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, w - 1.0)
    y = np.clip(np.asarray(y, dtype=np.float64), 0.0, h - 1.0)
    x0 = np.floor(x).astype(np.intp)
    y0 = np.floor(y).astype(np.intp)
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    fx = x - x0
    fy = y - y0
    if img.ndim == 3:
        fx = fx[..., None]
        fy = fy[..., None]
    if img.flags.c_contiguous:  # the four neighbours gathered from the flat image (np.take: several times faster)
        flat = img.reshape((h * w,) + img.shape[2:])
        shape = x0.shape + img.shape[2:]
        r0, r1 = y0 * w, y1 * w

        def at(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
            return np.take(flat, (rows + cols).reshape(-1), axis=0).reshape(shape)
    else:
        r0, r1 = y0, y1

        def at(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
            return img[rows, cols]

    # the neighbours' values as float64 (exact) in the products: value * (1 - fx) + value * fx, per row then column
    gx = 1.0 - fx
    top = np.multiply(at(r0, x0), gx, dtype=np.float64) + np.multiply(at(r0, x1), fx, dtype=np.float64)
    bot = np.multiply(at(r1, x0), gx, dtype=np.float64) + np.multiply(at(r1, x1), fx, dtype=np.float64)
    return top * (1.0 - fy) + bot * fy


def sample_colors(image: np.ndarray, uv: np.ndarray, *, interpolation: str = "bilinear") -> np.ndarray:
    """Sample an image at sub-pixel positions.

    Parameters
    ----------
    image : (H, W, C) or (H, W) array
        uint8, uint16 or float image (C is usually 3).
    uv : (n, 2) array
        Pixel coordinates, x right, y down, pixel centres at integers. Positions outside
        ``[0, W-1] x [0, H-1]`` (e.g. in the outer half pixel) are clamped to the border.
    interpolation : {"bilinear", "nearest"}, default "bilinear"
        Bilinear interpolation of the four surrounding pixel centres (:func:`sample_bilinear`),
        or the pixel whose area contains the point (``floor(x + 0.5)``).

    Returns
    -------
    (n, C) float64 (or (n,) for a 2-D image)
        Colours in the image's own units (0-255 for uint8, 0-65535 for uint16).

    Raises
    ------
    ValueError
        Unknown interpolation, malformed or non-finite ``uv``.
    """
    img = np.asarray(image)
    if img.ndim not in (2, 3):
        raise ValueError(f"image must be (H, W) or (H, W, C), got shape {img.shape}")
    uv = np.asarray(uv, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv must have shape (n, 2), got {uv.shape}")
    if not np.all(np.isfinite(uv)):
        raise ValueError("uv contains NaN/inf")
    if interpolation == "bilinear":
        return sample_bilinear(img, uv[:, 0], uv[:, 1])
    if interpolation != "nearest":
        raise ValueError(f"unknown interpolation {interpolation!r}; valid: {', '.join(map(repr, INTERPOLATIONS))}")
    h, w = img.shape[:2]
    xi = np.minimum(np.floor(np.clip(uv[:, 0], 0.0, w - 1.0) + 0.5).astype(np.intp), w - 1)
    yi = np.minimum(np.floor(np.clip(uv[:, 1], 0.0, h - 1.0) + 0.5).astype(np.intp), h - 1)
    return img[yi, xi].astype(np.float64)


def srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear light (IEC 61966-2-1), float64, clipped to [0, 1] first."""
    c = np.clip(np.asarray(values, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(values: np.ndarray) -> np.ndarray:
    """Linear light >= 0 -> sRGB-encoded values (inverse of :func:`srgb_to_linear` on [0, 1]), float64;
    negatives clipped to 0, values above 1 continued along the same curve (a curve's extrapolation)."""
    c = np.maximum(np.asarray(values, dtype=np.float64), 0.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1.0 / 2.4) - 0.055)


def rgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """sRGB in [0, 1] (gamma-encoded) to CIE Lab (D65, 2 degree observer), scikit-image.

    Parameters
    ----------
    rgb : (..., 3) float array
        Non-linear sRGB values in [0, 1] (clipped to it).

    Returns
    -------
    numpy.ndarray
        (..., 3) float64 Lab, L in [0, 100].
    """
    from skimage.color import rgb2lab

    rgb = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0)
    if rgb.shape[-1] != 3:
        raise ValueError(f"rgb_to_lab expects (..., 3) colours, got shape {rgb.shape}")
    if rgb.size == 0:
        return np.zeros(rgb.shape)
    return np.asarray(rgb2lab(rgb, illuminant="D65", observer="2", channel_axis=-1), dtype=np.float64)


def ciede2000(lab1: np.ndarray, lab2: np.ndarray) -> np.ndarray:
    """CIEDE2000 colour difference (kL = kC = kH = 1) between CIE Lab colours, scikit-image.

    Parameters
    ----------
    lab1, lab2 : (..., 3) float arrays
        CIE Lab values (L in [0, 100]).

    Returns
    -------
    numpy.ndarray
        (...) float64 Delta E 2000 (Sharma, Wu and Dalal 2005).
    """
    from skimage.color import deltaE_ciede2000

    a = np.asarray(lab1, dtype=np.float64)
    b = np.asarray(lab2, dtype=np.float64)
    if a.size == 0:
        return np.zeros(np.broadcast_shapes(a.shape, b.shape)[:-1])
    return np.asarray(deltaE_ciede2000(a, b, channel_axis=-1), dtype=np.float64)


def delta_e_2000(rgb_a: np.ndarray, rgb_b: np.ndarray) -> np.ndarray:
    """CIEDE2000 between sRGB colours in [0, 1] ((..., 3) each), via CIE Lab D65.

    Returns
    -------
    numpy.ndarray
        (...) float64.
    """
    return ciede2000(rgb_to_lab(rgb_a), rgb_to_lab(rgb_b))
