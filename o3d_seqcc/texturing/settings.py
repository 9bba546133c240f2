"""One settings struct for the texturing stages (mvs-texturing's ``tex::Settings``).

The defaults here are the defaults of every entry point: :func:`o3d_seqcc.texturing.select_views`,
:func:`o3d_seqcc.texturing.bake_texture`, :func:`o3d_seqcc.pipeline.run` (through
:class:`~o3d_seqcc.settings.RunSettings`), :func:`o3d_seqcc.texture_mesh`, the pymeshlab filters,
the MeshLab plugin and the ``texture`` / ``run`` / ``demo`` commands all read them from
:class:`TextureSettings`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._shared.options import SettingsBase, check_choice, check_types
from ..errors import InputError
from ..visibility.dense import VisibilityLike  # noqa: F401  (the stages' one visibility protocol, re-exported)

__all__ = ["DATA_TERMS", "FALLBACKS", "LEVELING_SMOOTHNESS", "MAX_ATLAS_SIZE", "MRF_SMOOTHNESS", "OUTLIER_REMOVALS",
           "OVERFLOWS", "UV_MODES", "TextureSettings", "VisibilityLike", "parse_atlas_size", "parse_texels_per_pixel"]

#: default Potts weight of the ``"mrf"`` selection
MRF_SMOOTHNESS = 4.0
#: default smoothness of the global seam leveling
LEVELING_SMOOTHNESS = 0.03
#: colours of faces seen by no view
FALLBACKS = ("smooth", "flat")
#: ``uv``: a new atlas of the charts, or the mesh's own texture coordinates
UV_MODES = ("atlas", "keep")
#: data terms of the "mrf" selection (:mod:`~o3d_seqcc.texturing.data_costs`)
DATA_TERMS = ("area", "area-cos", "gmi")
#: photometric outlier removal of the selection (texrecon's --outlier_removal)
OUTLIER_REMOVALS = ("none", "median", "gauss-clamping", "gauss-damping")
#: what to do when the charts do not fit the atlas at the asked density
OVERFLOWS = ("scale", "pages")


#: largest atlas side accepted (the texture size limit of current GPUs and engines)
MAX_ATLAS_SIZE = 16384

@dataclass(frozen=True)
class TextureSettings(SettingsBase):
    """Options of view selection, atlas baking and seam leveling.

    Attributes
    ----------
    selection : str, default "mrf"
        Per-face view selection method (:data:`o3d_seqcc.texturing.SELECTION_METHODS`).
    smoothness : float, default :data:`MRF_SMOOTHNESS` (4.0)
        ``"mrf"``: Potts weight per interior edge.
    seed : int, default 0
        Seed of ``"random"`` and of the ``"mrf"`` expansion order.
    data_term : {"gmi", "area", "area-cos"}, default "gmi"
        ``"mrf"``: what makes a photo good for a face: ``"gmi"``, the photo's gradient magnitude
        integrated over the face's projection (Waechter et al. 2014: large *and* sharp, so a
        blurred photo loses to a sharp one of the same size), on the corrected photos;
        ``"area"``, the projected area alone; ``"area-cos"``, area x cosine of the viewing angle.
    outlier_removal : {"median", "none", "gauss-clamping", "gauss-damping"}, default "median"
        Per face, drop the photos whose colour of it is far from the consensus of the others
        (on the corrected photos), so that a passer-by or a car the mesh does not hold is not
        textured in: ``"median"``, more than 20 CIE Lab units and 3 x the face's median distance
        from the per-channel median of its photos (faces seen by at least 3; robust to 2
        outliers in 5); texrecon's ``--outlier_removal`` ``"gauss-clamping"`` (drop) and
        ``"gauss-damping"`` (down-weight) test an iterated Gaussian of the colours (faces seen
        by at least 4; a minority of 2 in 5 is not found).
    atlas_size : int or "auto", default "auto"
        ``"auto"``: the atlas is sized to the charts at the photos' own resolution: one page cut
        to them (see ``power_of_two``), up to 8192 x 8192, and more square pages of 8192 x 8192
        beyond (:data:`~o3d_seqcc.texturing.packing.MAX_AUTO_ATLAS_SIZE`). An integer: the
        largest side of a page in texels, a budget (e.g. a game engine's), never exceeded: the
        page is the smallest that holds the charts within it (see ``texels_per_pixel`` and
        ``overflow``).
    texels_per_pixel : float or "auto", default "auto"
        Texel density, atlas texels per photo pixel. ``"auto"``: the photos' own resolution, 1
        (every texel a copy of a photo pixel; lowered only by an ``atlas_size`` budget with
        ``overflow="scale"``). Another density resamples the photos (Lanczos, clamped): 2 still
        renders the photo exactly from its own camera, a fraction blurs it.
    overflow : {"scale", "pages"}, default "scale"
        With an ``atlas_size`` budget, when the charts do not fit it at the asked density (1 for
        ``"auto"``): lower the density (a warning gives the factor), or write several atlas pages
        of ``atlas_size`` (one material each). ``atlas_size="auto"`` always adds pages.
    power_of_two : bool, default False
        Square pages whose side is a power of two (for engines that want one). ``False``: one
        page cut to the charts, its sides multiples of 4 (block compression's 4 x 4 blocks), and
        several square pages only when the charts need more than the largest page.
    shrink_to_fit : float, default 0.0
        With ``power_of_two``: the largest share (< 0.5) by which the texel density may drop to
        keep the charts on the power of two below the one they need (e.g. 0.05 when they overflow
        2048 by a few percent); a warning gives the factor and ``stats["density_scale"]`` records
        it. 0: the density is never lowered for this.
    padding : int, default 4
        Texels around every chart that hold its gutter (the photo's content around the chart),
        so that bilinear filtering and mip levels 1-2 do not bleed the next chart in; two
        charts are at least ``2 * padding`` texels apart.
    small_charts : int, default 16
        Charts of at most this many texels on their longer side are packed together in one block
        whose gutters are ``small_padding`` texels (the block itself keeps ``padding`` from the
        other charts): a chart of s texels is s / 2^L texels at mip level L, so a wide gutter buys
        a tiny chart little, and on fine meshes the tiny charts' gutters take most of the atlas
        (:mod:`~o3d_seqcc.texturing.blocks`). 0: every chart with ``padding``.
    small_padding : int, default 1
        The gutters between the charts of that block (< ``padding`` to have an effect).
    pack_effort : {"fast", "best"}, default "fast"
        xatlas's placement search, or every candidate position (``"best"``: xatlas's brute force;
        measured on Fountain 300k's charts: coverage 41.8 -> 46.2 %, the packing 1.5 -> 7.7 s).
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
    local_band : int, default 2
        Width in texels of the band changed by the local leveling. The colour differences it
        removes along a seam are mostly the photos' misregistered detail on real scans: a wider
        band spreads them over the texture's own detail (Fountain 300k, render sharpness over
        texrecon's, median of 8 views: band 8 0.94, 2 0.96, at the same seam metric).
    fallback : {"smooth", "flat"}, default "smooth"
        Colour of the faces seen by no view.
    uv : {"atlas", "keep"}, default "atlas"
        ``"atlas"``: a new atlas of the charts (each face's footprint in its photo, packed by
        xatlas). ``"keep"``: bake into the mesh's own texture coordinates (OBJ ``vt``, PLY
        ``s``/``t``, GLB ``TEXCOORD_0``; :func:`~o3d_seqcc.texturing.own_uv.bake_own_uv`): the
        output keeps the input's topology and UVs, one square page sized so that the median face
        gets ``texels_per_pixel``; zero-area, mirrored and overlapping UVs are reported. The
        atlas's packing options (``overflow``, ``shrink_to_fit``, ``merge_charts``) do not apply.
    """

    selection: str = "mrf"
    smoothness: float = MRF_SMOOTHNESS
    seed: int = 0
    data_term: str = "gmi"
    outlier_removal: str = "median"
    atlas_size: int | str = "auto"
    texels_per_pixel: float | str = "auto"
    overflow: str = "scale"
    power_of_two: bool = False
    shrink_to_fit: float = 0.0
    padding: int = 4
    small_charts: int = 16
    small_padding: int = 1
    pack_effort: str = "fast"
    merge_charts: int = 3
    fill_background: bool = True
    leveling: bool = True
    leveling_smoothness: float = LEVELING_SMOOTHNESS
    local_leveling: bool = True
    local_band: int = 2
    fallback: str = "smooth"
    uv: str = "atlas"

    _label = "texture setting"

    def __post_init__(self) -> None:
        check_types(self)
        check_choice("fallback", self.fallback, FALLBACKS, flag="--fallback")
        check_choice("data_term", self.data_term, DATA_TERMS, flag="--data-term")
        check_choice("outlier_removal", self.outlier_removal, OUTLIER_REMOVALS, flag="--outlier-removal")
        check_choice("overflow", self.overflow, OVERFLOWS, flag="--atlas-overflow")
        check_choice("uv", self.uv, UV_MODES, flag="--uv")
        check_choice("pack_effort", self.pack_effort, ("fast", "best"), flag="--pack-effort")
        object.__setattr__(self, "atlas_size", parse_atlas_size(self.atlas_size))
        object.__setattr__(self, "texels_per_pixel", parse_texels_per_pixel(self.texels_per_pixel))
        if not 0.0 <= float(self.shrink_to_fit) < 0.5:
            raise InputError(f"shrink_to_fit must be a share in [0, 0.5) (--shrink-to-fit), got {self.shrink_to_fit}")
        if isinstance(self.padding, bool) or int(self.padding) != self.padding or not 0 <= self.padding <= 64:
            raise InputError(f"padding must be an integer in 0..64, got {self.padding}")
        for name in ("small_charts", "small_padding"):
            v = getattr(self, name)
            if isinstance(v, bool) or int(v) != v or not 0 <= v <= 4096:
                raise InputError(f"{name} must be an integer in 0..4096 (--{name.replace('_', '-')}), got {v}")
        if isinstance(self.merge_charts, bool) or int(self.merge_charts) != self.merge_charts or self.merge_charts < 0:
            raise InputError(f"merge_charts must be an integer >= 0, got {self.merge_charts}")
        if self.local_leveling and (int(self.local_band) < 1 or int(self.local_band) != self.local_band):
            raise InputError(f"local_band must be an integer >= 1, got {self.local_band}")
        if not self.smoothness >= 0:
            raise InputError(f"smoothness (--smoothness) must be >= 0, got {self.smoothness}")
        if not self.leveling_smoothness >= 0:
            raise InputError(f"leveling_smoothness (--leveling-smoothness) must be >= 0, got {self.leveling_smoothness}")

    def updated(self, **changes: Any) -> "TextureSettings":
        """:meth:`replace` (its earlier name): a copy with some fields changed; unknown names raise
        :class:`~o3d_seqcc._shared.options.UnknownSettingError` (a ``TypeError``) listing the valid ones."""
        return self.replace(**changes)


def _auto_or_parsed(value: Any, parse: Any, message: str) -> Any:
    """A command-line style value: ``"auto"`` (any case, spaces around) kept as ``"auto"``, another string
    parsed with ``parse`` (``InputError(message)`` if it does not parse), anything else returned as given."""
    if not isinstance(value, str):
        return value
    v = value.strip().lower()
    if v == "auto":
        return "auto"
    try:
        return parse(v)
    except ValueError:
        raise InputError(message) from None


def parse_atlas_size(value: Any) -> int | str:
    """``"auto"`` or an integer side in 8..:data:`MAX_ATLAS_SIZE` (also given as a string, as on the command line).

    Raises
    ------
    InputError
        Anything else.
    """
    value = _auto_or_parsed(value, int, f"atlas_size (--atlas-size) must be 'auto' or an integer >= 8, got {value!r}")
    if isinstance(value, str):
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or not np.isfinite(value) \
            or int(value) != value or int(value) < 8:
        raise InputError(f"atlas_size (--atlas-size) must be 'auto' or an integer >= 8, got {value!r}")
    if int(value) > MAX_ATLAS_SIZE:
        raise InputError(f"atlas_size (--atlas-size) must be at most {MAX_ATLAS_SIZE} (the largest texture GPUs "
                         f"load), got {value}; use overflow='pages' (--atlas-overflow pages) for more")
    return int(value)


def parse_texels_per_pixel(value: Any) -> float | str:
    """``"auto"`` or a positive number (also given as a string, as on the command line).

    Raises
    ------
    InputError
        Anything else.
    """
    value = _auto_or_parsed(value, float, f"texels_per_pixel must be 'auto' or a number > 0, got {value!r}")
    if isinstance(value, str):
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) or not value > 0 \
            or not np.isfinite(value):
        raise InputError(f"texels_per_pixel must be 'auto' or a number > 0, got {value!r}")
    return float(value)
