"""Camera-like photometric changes: the model of the synthetic scenes' and benchmarks' hidden truth.

``y = (1 - s) * x' + s * smoothstep(x')`` with ``x' = clip(x * gain * wb[c], 0, 1) ** gamma[c]`` and
``smoothstep(x) = x^2 (3 - 2x)``, channel by channel (:func:`apply_photometric`);
:func:`sample_photometric` draws camera-like parameters (most draws moderate),
:func:`sample_camera_change` draws them uniformly over whole ranges (:data:`HARD_CHANGE_RANGES`:
the synthetic ``photometric="camera-hard"`` mode; :data:`CAMERA_CHANGE_RANGES`: the semi-real
protocol's hidden change, :mod:`o3d_seqcc.evaluation.semireal`), :func:`identity_photometric` is the
identity.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import InputError
from ..imaging.arrays import img_as_float

__all__ = [
    "CAMERA_CHANGE_RANGES",
    "HARD_CHANGE_RANGES",
    "apply_photometric",
    "identity_photometric",
    "sample_camera_change",
    "sample_photometric",
]

#: Ranges of :func:`sample_camera_change` by default: the semi-real protocol's hidden change
#: (:mod:`o3d_seqcc.evaluation.semireal`): exposure factor, white balance +- share per channel, per-channel
#: gamma, S-curve strength.
CAMERA_CHANGE_RANGES: dict[str, Any] = {"exposure": (0.6, 1.6), "white_balance": 0.2, "gamma": (0.64, 1.51), "s_curve": (0.0, 0.6)}
#: Ranges of ``photometric="camera-hard"``: the hard room of issue 12 (S-curves up to 0.6,
#: exposure 0.65-1.42, per-channel gamma 0.67-1.43), every parameter drawn uniformly over them.
HARD_CHANGE_RANGES: dict[str, Any] = {"exposure": (0.65, 1.42), "white_balance": 0.2, "gamma": (0.67, 1.43), "s_curve": (0.0, 0.6)}


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


def sample_camera_change(
    rng: np.random.Generator,
    *,
    exposure: tuple[float, float] = CAMERA_CHANGE_RANGES["exposure"],
    white_balance: float = CAMERA_CHANGE_RANGES["white_balance"],
    gamma: tuple[float, float] = CAMERA_CHANGE_RANGES["gamma"],
    s_curve: tuple[float, float] = CAMERA_CHANGE_RANGES["s_curve"],
) -> dict[str, Any]:
    """Draw a camera-like change uniformly over its whole range (no preference for the identity).

    Harder than :func:`sample_photometric`: the exposure is log-uniform over ``exposure``, each
    channel's white-balance factor uniform in ``[1 - white_balance, 1 + white_balance]``, each
    channel's gamma independently log-uniform over ``gamma`` (so the colour cast changes with
    brightness) and the S-curve strength uniform over ``s_curve``.

    Parameters
    ----------
    rng : numpy.random.Generator
    exposure : (float, float), default (0.6, 1.6)
        Range of the exposure factor, ``0 < lo <= hi``.
    white_balance : float, default 0.2
        Largest relative change of a channel's white-balance factor, in [0, 1).
    gamma : (float, float), default (0.64, 1.51)
        Range of each channel's gamma, ``0 < lo <= hi``.
    s_curve : (float, float), default (0, 0.6)
        Range of the S-curve strength, ``0 <= lo <= hi <= 1``.

    Returns
    -------
    dict
        ``gain``, ``white_balance`` (3), ``gamma`` (3), ``s_curve``: parameters of
        :func:`apply_photometric`.

    Raises
    ------
    InputError
        A range out of bounds or reversed.
    """
    (e0, e1), (g0, g1), (s0, s1), wb = map(float, exposure), map(float, gamma), map(float, s_curve), float(white_balance)
    if not (0 < e0 <= e1 and 0 < g0 <= g1 and 0 <= s0 <= s1 <= 1 and 0 <= wb < 1):
        raise InputError(
            f"sample_camera_change: need 0 < exposure lo <= hi, 0 < gamma lo <= hi, 0 <= s_curve lo <= hi <= 1 and "
            f"0 <= white_balance < 1; got exposure={exposure}, gamma={gamma}, s_curve={s_curve}, white_balance={white_balance}"
        )
    gain = float(np.exp(rng.uniform(np.log(e0), np.log(e1))))
    wbf = rng.uniform(1.0 - wb, 1.0 + wb, size=3)
    gm = np.exp(rng.uniform(np.log(g0), np.log(g1), size=3))
    s = float(rng.uniform(s0, s1))
    return {"gain": gain, "white_balance": wbf.tolist(), "gamma": gm.tolist(), "s_curve": s}


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
