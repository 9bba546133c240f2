"""Camera-like photometric changes: the model of the synthetic scenes' and benchmarks' hidden truth.

``y = (1 - s) * x' + s * smoothstep(x')`` with ``x' = clip(x * gain * wb[c], 0, 1) ** gamma[c]`` and
``smoothstep(x) = x^2 (3 - 2x)``, channel by channel (:func:`apply_photometric`);
:func:`sample_photometric` draws camera-like parameters, :func:`identity_photometric` is the
identity.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .imageops import img_as_float

__all__ = ["apply_photometric", "identity_photometric", "sample_photometric"]


def identity_photometric() -> dict[str, Any]:
    """Parameters of the identity photometric change (what view 0 gets)."""
    return {"gain": 1.0, "white_balance": [1.0, 1.0, 1.0], "gamma": [1.0, 1.0, 1.0], "s_curve": 0.0}


def sample_photometric(rng: np.random.Generator) -> dict[str, Any]:
    """Draw random camera-like photometric parameters.

    Every parameter spans the documented range, but like a camera's auto exposure and tone
    curve most draws are moderate: log exposure and the view's log tone-curve gamma, and the white-balance factors, are drawn
    from triangular distributions peaking at 1 (the identity) over the full range; the channels'
    gammas are that gamma times a small per-channel factor (log-normal, sigma 0.06, clipped to
    the range), so the colour cast comes mostly from the white balance, as in a camera.

    Parameters
    ----------
    rng : numpy.random.Generator

    Returns
    -------
    dict
        ``gain`` exposure factor in [0.6, 1.6]; ``white_balance`` three per-channel factors in
        [0.8, 1.2] (triangular, peak 1); ``gamma`` three per-channel exponents in [0.65, 1.5];
        ``s_curve`` strength in [0, 0.5] (uniform).
    """
    gain = float(np.exp(rng.triangular(np.log(0.6), 0.0, np.log(1.6))))
    wb = rng.triangular(0.8, 1.0, 1.2, size=3)
    g0 = np.exp(rng.triangular(np.log(0.65), 0.0, np.log(1.5)))
    gamma = np.clip(g0 * np.exp(rng.normal(0.0, 0.06, size=3)), 0.65, 1.5)
    s = float(rng.uniform(0.0, 0.5))
    return {"gain": gain, "white_balance": wb.tolist(), "gamma": gamma.tolist(), "s_curve": s}


def apply_photometric(image: np.ndarray, params: dict[str, Any]) -> np.ndarray:
    """Apply a photometric change (the camera model of the synthetic scenes).

    ``y = (1 - s) * x' + s * smoothstep(x')`` with ``x' = clip(x * gain * wb[c], 0, 1) ** gamma[c]``
    and ``smoothstep(x) = x^2 (3 - 2x)``, channel by channel.

    Parameters
    ----------
    image : (..., 3) array
        uint8 (0-255), uint16 (0-65535) or float in [0, 1], RGB.
    params : dict
        ``gain`` (float), ``white_balance`` (3 floats), ``gamma`` (3 floats), ``s_curve`` (float),
        as from :func:`sample_photometric`.

    Returns
    -------
    numpy.ndarray
        (..., 3) float64 in [0, 1] (not quantised; the generator stores
        ``round(255 * y)`` as uint8).
    """
    x = img_as_float(image)
    if x.shape[-1] != 3:
        raise ValueError(f"apply_photometric expects (..., 3) RGB, got shape {x.shape}")
    gain = float(params["gain"])
    wb = np.asarray(params["white_balance"], dtype=np.float64)
    gamma = np.asarray(params["gamma"], dtype=np.float64)
    s = float(params["s_curve"])
    y = np.clip(x * (gain * wb), 0.0, 1.0) ** gamma
    return np.clip((1.0 - s) * y + s * (y * y * (3.0 - 2.0 * y)), 0.0, 1.0)
