"""Numbers read from input files: finite and normal, checked where they are read.

A camera file can hold anything a text editor or a broken exporter writes: ``nan``, ``inf``, ``1e999``
(inf once parsed) or a denormal such as ``1e-320``, which parses, passes ``> 0`` and then overflows
whatever divides by it (a ``depth_scale`` of 1e-320 made every depth inf, with a numpy warning as the
only sign). Every reader parses its numbers with :func:`parse_number`, and every camera and scale
passes :func:`check_numbers` when a :class:`~o3d_seqcc.scene.View` is made, so what is wrong is an
:class:`~o3d_seqcc.errors.InputError` naming the file, the line or field, and the value.
"""

from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["TINY", "check_numbers", "is_finite_normal", "parse_number"]

#: the smallest positive normal float64 (2.2e-308): nonzero numbers below it in magnitude are denormal
TINY = sys.float_info.min


def is_finite_normal(x: float) -> bool:
    """Whether ``x`` is finite and either 0 or at least :data:`TINY` in magnitude."""
    return math.isfinite(x) and not 0 < abs(x) < TINY


def parse_number(token: str, what: str, *, fix: str = "write the file again") -> float:
    """``token`` as a float that is finite and not denormal.

    Parameters
    ----------
    token : str
        The text read from the file.
    what : str
        Where it was read, for the message: the file, the line or element and the field
        (``"bundle.out: line 3: camera 0: f"``).
    fix : str, optional
        What the user should do, ending the message.

    Raises
    ------
    InputError
        ``token`` is not a number, or is NaN, infinite or denormal.
    """
    try:
        x = float(token)
    except (TypeError, ValueError):
        raise InputError(f"{what}: {str(token)[:40]!r} is not a number; {fix}") from None
    if not is_finite_normal(x):
        raise InputError(f"{what}: {str(token)[:40]!r} is not a finite normal number (NaN, inf, or below {TINY:.3g} in "
                         f"magnitude); {fix}")
    return x


def check_numbers(values: Any, what: str, *, fix: str = "give finite numbers") -> np.ndarray:
    """``values`` as a float64 array whose entries are all finite and none denormal.

    Parameters
    ----------
    values : array-like of float
    what : str
        The field (and where it came from) for the message.
    fix : str, optional

    Returns
    -------
    ndarray of float64
        ``values`` (a copy when converted).

    Raises
    ------
    InputError
        An entry is NaN, infinite or denormal (the first such entry is named).
    """
    a = np.asarray(values, dtype=np.float64)
    bad = ~np.isfinite(a) | ((a != 0) & (np.abs(a) < TINY))
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        at = f" at {list(idx)}" if a.ndim else ""
        raise InputError(f"{what}: {float(a[idx])!r}{at} is not a finite normal number (NaN, inf, or below {TINY:.3g} in "
                         f"magnitude); {fix}")
    return a
