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

__all__ = ["FALLBACKS", "LEVELING_SMOOTHNESS", "MRF_SMOOTHNESS", "OVERFLOWS", "TextureSettings", "VisibilityLike"]

#: default Potts weight of the ``"mrf"`` selection
MRF_SMOOTHNESS = 4.0
#: default smoothness of the global seam leveling
LEVELING_SMOOTHNESS = 0.03
#: colours of faces seen by no view
FALLBACKS = ("smooth", "flat")
#: what to do when the charts do not fit the atlas
OVERFLOWS = ("grow", "scale", "error")


class VisibilityLike(Protocol):  # pragma: no cover - typing only
    """What the texturing stages read of a :class:`~o3d_seqcc.visibility.Visibility`."""

    usable: np.ndarray
    area: np.ndarray
    cos_angle: np.ndarray
    n_views: int
    n_faces: int

    def face_uv(self, selection: np.ndarray) -> np.ndarray: ...


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
        Side of the square atlas in texels.
    padding : int, default 4
        Gutter texels of real image content around every chart.
    texel_scale : float, default 1.0
        Atlas texels per source pixel.
    overflow : {"grow", "scale", "error"}, default "grow"
        When the charts do not fit: double the atlas side (up to ``max_atlas_size``), shrink
        ``texel_scale``, or raise.
    max_atlas_size : int, default 16384
        Largest atlas side ``"grow"`` may reach.
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
    padding: int = 4
    texel_scale: float = 1.0
    overflow: str = "grow"
    max_atlas_size: int = 16384
    fill_background: bool = True
    leveling: bool = True
    leveling_smoothness: float = LEVELING_SMOOTHNESS
    local_leveling: bool = True
    local_band: int = 8
    fallback: str = "smooth"

    def __post_init__(self) -> None:
        if self.fallback not in FALLBACKS:
            raise ValueError(f"unknown fallback {self.fallback!r}; valid: {', '.join(map(repr, FALLBACKS))}")
        if self.overflow not in OVERFLOWS:
            raise ValueError(f"unknown overflow {self.overflow!r}; valid: {', '.join(map(repr, OVERFLOWS))}")
        if isinstance(self.atlas_size, bool) or int(self.atlas_size) != self.atlas_size or int(self.atlas_size) < 8:
            raise InputError(f"atlas_size must be an integer >= 8, got {self.atlas_size}")
        if not self.padding >= 0 or not self.texel_scale > 0:
            raise InputError(f"padding must be >= 0 and texel_scale > 0, got {self.padding}, {self.texel_scale}")
        if self.local_leveling and (int(self.local_band) < 1 or int(self.local_band) != self.local_band):
            raise InputError(f"local_band must be an integer >= 1, got {self.local_band}")
        if not self.smoothness >= 0:
            raise InputError(f"smoothness (--smoothness) must be >= 0, got {self.smoothness}")
        if not self.leveling_smoothness >= 0:
            raise InputError(f"leveling_smoothness (--leveling-smoothness) must be >= 0, got {self.leveling_smoothness}")
        if int(self.atlas_size) > int(self.max_atlas_size):
            raise InputError(f"atlas_size (--atlas-size) must be at most max_atlas_size = {self.max_atlas_size}, "
                             f"got {self.atlas_size}")

    def updated(self, **changes: Any) -> "TextureSettings":
        """A copy with some fields changed; unknown names raise ``TypeError`` listing the valid ones."""
        bad = sorted(set(changes) - {f.name for f in fields(self)})
        if bad:
            raise TypeError(f"unknown texture setting(s) {bad}; valid: {sorted(f.name for f in fields(self))}")
        return replace(self, **changes)
