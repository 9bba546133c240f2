"""One settings struct for the texturing stages (mvs-texturing's ``tex::Settings``).

The defaults here are the defaults of every entry point: :func:`o3d_seqcc.texturing.select_views`,
:func:`o3d_seqcc.texturing.bake_texture`, :func:`o3d_seqcc.pipeline.run` and the ``texture`` /
``run`` commands all read them from :class:`TextureSettings`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, Protocol

import numpy as np

from ..errors import InputError

__all__ = ["FALLBACKS", "LEVELING_SMOOTHNESS", "MAX_ATLAS_SIZE", "MRF_SMOOTHNESS", "OVERFLOWS", "TextureSettings", "VisibilityLike",
           "parse_texels_per_pixel"]

#: default Potts weight of the ``"mrf"`` selection
MRF_SMOOTHNESS = 4.0
#: default smoothness of the global seam leveling
LEVELING_SMOOTHNESS = 0.03
#: colours of faces seen by no view
FALLBACKS = ("smooth", "flat")
#: what to do when the charts do not fit the atlas at the asked density
OVERFLOWS = ("scale", "pages")


class VisibilityLike(Protocol):  # pragma: no cover - typing only
    """What the texturing stages read of a :class:`~o3d_seqcc.visibility.Visibility`."""

    usable: np.ndarray
    area: np.ndarray
    cos_angle: np.ndarray
    n_views: int
    n_faces: int

    def face_uv(self, selection: np.ndarray) -> np.ndarray: ...


#: largest atlas side accepted (the texture size limit of current GPUs and engines)
MAX_ATLAS_SIZE = 16384

@dataclass(frozen=True)
class TextureSettings:
    """Options of view selection, atlas baking and seam leveling.

    Attributes
    ----------
    selection : str, default "mrf"
        Per-face view selection method (:data:`o3d_seqcc.texturing.SELECTION_METHODS`).
    smoothness : float, default :data:`MRF_SMOOTHNESS` (4.0)
        ``"mrf"``: Potts weight per interior edge.
    seed : int, default 0
        Seed of ``"random"`` and of the ``"mrf"`` expansion order.
    atlas_size : int, default 2048
        Largest side of the (square) atlas in texels: a budget, never exceeded. The atlas is
        the smallest power of two up to it that holds the charts (see ``texels_per_pixel``).
    texels_per_pixel : float or "auto", default "auto"
        Texel density, atlas texels per photo pixel. ``"auto"``: at least the photos' own
        resolution (1), raised to fill the chosen atlas (at most 2: charts are packed densely).
    overflow : {"scale", "pages"}, default "scale"
        When the charts do not fit ``atlas_size`` at the asked density (1 for ``"auto"``):
        lower the density (a warning gives the factor), or write several atlas pages of
        ``atlas_size`` (one material each).
    power_of_two : bool, default True
        Atlas sides are powers of two (``False``: multiples of 4, as small as the charts allow).
    padding : int, default 4
        Texels around every chart that hold its gutter (the photo's content around the chart),
        so that bilinear filtering and mip levels 1-2 do not bleed the next chart in; two
        charts are at least ``2 * padding`` texels apart.
    merge_charts : int, default 3
        Charts of at most this many faces join a neighbouring chart's parametrisation where
        that chart's view sees them (fewer charts, fewer seam vertices; each face still samples
        its own view); 0 keeps every chart.
    fill_background : bool, default True
        Pull-push fill of the texels outside every chart.
    leveling : bool, default True
        Global seam leveling (Waechter et al. 2014).
    leveling_smoothness : float, default :data:`LEVELING_SMOOTHNESS` (0.03)
        Smoothness of the global seam leveling's colour offsets inside the charts.
    local_leveling : bool, default True
        Local seam leveling in a band along chart borders.
    local_band : int, default 8
        Width in texels of the band changed by the local leveling.
    fallback : {"smooth", "flat"}, default "smooth"
        Colour of the faces seen by no view.
    """

    selection: str = "mrf"
    smoothness: float = MRF_SMOOTHNESS
    seed: int = 0
    atlas_size: int = 2048
    texels_per_pixel: float | str = "auto"
    overflow: str = "scale"
    power_of_two: bool = True
    padding: int = 4
    merge_charts: int = 3
    fill_background: bool = True
    leveling: bool = True
    leveling_smoothness: float = LEVELING_SMOOTHNESS
    local_leveling: bool = True
    local_band: int = 8
    fallback: str = "smooth"

    def __post_init__(self) -> None:
        _check_types(self)
        if self.fallback not in FALLBACKS:
            raise ValueError(f"unknown fallback {self.fallback!r}; valid: {', '.join(map(repr, FALLBACKS))}")
        if self.overflow not in OVERFLOWS:
            raise ValueError(f"unknown overflow {self.overflow!r}; valid: {', '.join(map(repr, OVERFLOWS))}")
        if isinstance(self.atlas_size, bool) or int(self.atlas_size) != self.atlas_size or int(self.atlas_size) < 8:
            raise InputError(f"atlas_size must be an integer >= 8, got {self.atlas_size}")
        object.__setattr__(self, "texels_per_pixel", parse_texels_per_pixel(self.texels_per_pixel))
        if isinstance(self.padding, bool) or int(self.padding) != self.padding or not 0 <= self.padding <= 64:
            raise InputError(f"padding must be an integer in 0..64, got {self.padding}")
        if isinstance(self.merge_charts, bool) or int(self.merge_charts) != self.merge_charts or self.merge_charts < 0:
            raise InputError(f"merge_charts must be an integer >= 0, got {self.merge_charts}")
        if self.local_leveling and (int(self.local_band) < 1 or int(self.local_band) != self.local_band):
            raise InputError(f"local_band must be an integer >= 1, got {self.local_band}")
        if not self.smoothness >= 0:
            raise InputError(f"smoothness (--smoothness) must be >= 0, got {self.smoothness}")
        if not self.leveling_smoothness >= 0:
            raise InputError(f"leveling_smoothness (--leveling-smoothness) must be >= 0, got {self.leveling_smoothness}")
        if int(self.atlas_size) > MAX_ATLAS_SIZE:
            raise InputError(f"atlas_size (--atlas-size) must be at most {MAX_ATLAS_SIZE} (the largest texture GPUs "
                             f"load), got {self.atlas_size}; use overflow='pages' (--atlas-overflow pages) for more")

    def updated(self, **changes: Any) -> "TextureSettings":
        """A copy with some fields changed; unknown names raise ``TypeError`` listing the valid ones."""
        bad = sorted(set(changes) - {f.name for f in fields(self)})
        if bad:
            raise TypeError(f"unknown texture setting(s) {bad}; valid: {sorted(f.name for f in fields(self))}")
        return replace(self, **changes)


def _is_int(v: Any) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


_TYPES = {"int": (_is_int, "an integer"),
          "float": (lambda v: _is_int(v) or isinstance(v, (float, np.floating)), "a number"),
          "bool": (lambda v: isinstance(v, (bool, np.bool_)) or _is_int(v) and v in (0, 1), "True or False"),
          "str": (lambda v: isinstance(v, str), "a string")}


def _check_types(settings: Any) -> None:
    """Every field of the type it is declared with (``atlas_size="big"`` names the field, not ``int()``)."""
    for f in fields(settings):
        kind = _TYPES.get(str(f.type))
        v = getattr(settings, f.name)
        if kind is not None and not kind[0](v):
            raise InputError(f"{f.name} must be {kind[1]}, got {v!r:.60} ({type(v).__name__})")


def parse_texels_per_pixel(value: Any) -> float | str:
    """``"auto"`` or a positive number (also given as a string, as on the command line).

    Raises
    ------
    InputError
        Anything else.
    """
    if isinstance(value, str):
        v = value.strip().lower()
        if v == "auto":
            return "auto"
        try:
            value = float(v)
        except ValueError:
            raise InputError(f"texels_per_pixel must be 'auto' or a number > 0, got {value!r}") from None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) or not value > 0 \
            or not np.isfinite(value):
        raise InputError(f"texels_per_pixel must be 'auto' or a number > 0, got {value!r}")
    return float(value)
