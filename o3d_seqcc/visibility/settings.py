"""The options of :func:`~o3d_seqcc.visibility.compute_visibility`, where their defaults live.

:func:`~o3d_seqcc.visibility.compute_visibility`, :func:`~o3d_seqcc.mappings.compute_mappings`,
:func:`o3d_seqcc.pipeline.run` / ``texture`` / ``correct_scene`` (through
:class:`~o3d_seqcc.settings.RunSettings`) and the ``mappings`` command's filter options all read
them from :class:`VisibilitySettings`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .._shared.options import SettingsBase, check_choice, check_types
from ..errors import InputError

__all__ = ["FILTERS", "OBLIQUE_REFERENCES", "VisibilitySettings"]

#: names of the filters of :func:`~o3d_seqcc.visibility.compute_visibility`
FILTERS = ("occlusion", "depth", "oblique")
#: viewing directions of the oblique filter
OBLIQUE_REFERENCES = ("ray", "axis")

#: the fields the per-view visibility tasks read (:attr:`~o3d_seqcc.visibility.Visibility.options`)
_FILTER_FIELDS = ("occlusion_tol", "occlusion_atol", "occlusion_spacing", "occlusion_max_level", "depth_tol",
                  "depth_atol", "max_depth_disagreement", "fill_radius", "depth_edge_margin", "max_angle",
                  "oblique_reference", "two_sided", "filters")


@dataclass(frozen=True)
class VisibilitySettings(SettingsBase):
    """Options of the projection, the three visibility filters and the face split (paper 3.1-3.2).

    Attributes
    ----------
    occlusion_tol : float in [0, 1), default 0.01
        Relative z-buffer tolerance: a test point at distance ``d`` is hidden when the mesh is hit
        closer than ``d * (1 - occlusion_tol) - occlusion_atol``.
    occlusion_atol : float >= 0, default 1e-3
        Absolute z-buffer tolerance in scene units (1 mm for metric scenes).
    occlusion_spacing : float >= 0, default 4.0
        Spacing in px of the interior test points of faces larger than ``2 * spacing**2`` px^2;
        0 tests vertices only.
    occlusion_max_level : int >= 1, default 64
        Cap on the interior grid level (at most ~2000 test points per face and view).
    depth_tol : float >= 0, default 0.03
        Relative depth-consistency threshold (3 % of the mesh depth) ...
    depth_atol : float >= 0, default 0.05
        ... with this absolute floor in scene units (5 cm): inconsistent when
        ``|z_mesh - z_image| > max(depth_atol, depth_tol * z_mesh)``. The defaults absorb the
        few-cm noise of consumer depth sensors and TSDF meshes; a 30 cm disagreement is caught
        up to 10 m.
    max_depth_disagreement : float >= 0, default 0.5
        Warn when more than this fraction of the vertices of a view's valid, unoccluded faces
        disagree with its depth data (depth map or point cloud not registered to the mesh?).
    fill_radius : int >= 0, default 6
        Hole filling of depth images rendered from point clouds, see
        :func:`~o3d_seqcc.visibility.depth_from_point_cloud`. Depth maps are used as they are
        (0 = no evidence).
    depth_edge_margin : int >= 0, default 0
        Also mark as depth-inconsistent the faces with a vertex within this many pixels of a
        depth discontinuity (a jump beyond the depth tolerance in the depth image). Guards
        against colour/depth misregistration (fountain: 2-17 px) sampling the wrong side of an
        occluding contour; 0 (the paper) disables it.
    max_angle : float in (0, 180], default 75.0
        Oblique threshold in degrees between the face normal and the viewing direction.
    oblique_reference : {"ray", "axis"}, default "ray"
        Viewing direction: from the face centroid to the camera centre, or the camera's focal
        axis (the paper). "ray" is the default because at the image border the focal axis
        underestimates the true viewing angle by up to the half field of view.
    two_sided : bool, default False
        Treat faces as two-sided (no back-face removal; angles use ``|cos|``). For meshes with
        unreliable orientation.
    filters : tuple of {"occlusion", "depth", "oblique"}, default all of :data:`FILTERS`
        Filters to apply; disabled filters give all-False masks.
    split_faces : bool, default True
        Split the faces that no view can use whole but some view sees in part (clipped by the
        image border, partly hidden, larger than any photo, or whose texture would slide inside
        them) until their parts are usable (:mod:`o3d_seqcc.visibility.refine`: conforming
        longest-edge bisection); the visibility's ``mesh`` is then the refined mesh and
        ``parent_faces`` maps its faces to the input's. False keeps the input's faces.
    split_min_px : float > 0, default 4.0
        ... down to parts whose longest edge is this many pixels in the views seeing them.
    split_max_distortion : float > 0, default 0.5
        Also split faces whose texture would slide by more than this many pixels inside them
        (their corners' projections interpolated linearly vs the photo's perspective:
        :func:`o3d_seqcc.visibility.refine.distortion`; large faces seen in depth); ``inf``
        turns it off.
    split_max_rounds : int >= 0, default 8
        ... in at most this many rounds (each divides a split face's area by about 4).
    """

    _label = "visibility setting"

    occlusion_tol: float = 0.01
    occlusion_atol: float = 1e-3
    occlusion_spacing: float = 4.0
    occlusion_max_level: int = 64
    depth_tol: float = 0.03
    depth_atol: float = 0.05
    max_depth_disagreement: float = 0.5
    fill_radius: int = 6
    depth_edge_margin: int = 0
    max_angle: float = 75.0
    oblique_reference: str = "ray"
    two_sided: bool = False
    filters: tuple = FILTERS
    split_faces: bool = True
    split_min_px: float = 4.0
    split_max_distortion: float = 0.5
    split_max_rounds: int = 8

    def __post_init__(self) -> None:
        if isinstance(self.filters, str) or not hasattr(self.filters, "__iter__"):
            raise InputError(f"filters must be a tuple of filter names among {', '.join(map(repr, FILTERS))}, got "
                             f"{self.filters!r:.60}")
        filters = tuple(self.filters)
        unknown = sorted(set(filters) - set(FILTERS))
        if unknown:
            raise InputError(f"unknown filter(s) {unknown}; valid: {', '.join(FILTERS)}")
        object.__setattr__(self, "filters", filters)
        check_choice("oblique_reference", self.oblique_reference, OBLIQUE_REFERENCES)
        check_types(self)
        if not 0.0 < float(self.max_angle) <= 180.0:
            raise InputError(f"max_angle (--max-angle) must be in (0, 180] degrees, got {self.max_angle}")
        if not (0 <= self.occlusion_tol < 1 and self.occlusion_atol >= 0):
            raise InputError(f"occlusion_tol (--occlusion-tol) must be in [0, 1) and occlusion_atol >= 0, "
                             f"got {self.occlusion_tol}, {self.occlusion_atol}")
        if not (self.depth_tol >= 0 and self.depth_atol >= 0):
            raise InputError(f"depth_tol (--depth-tol) and depth_atol (--depth-atol) must be >= 0, got "
                             f"{self.depth_tol}, {self.depth_atol}")
        for name in ("occlusion_spacing", "fill_radius", "depth_edge_margin", "split_max_rounds"):
            if not getattr(self, name) >= 0:
                raise InputError(f"{name} must be >= 0, got {getattr(self, name)}")
        if not self.occlusion_max_level >= 1:
            raise InputError(f"occlusion_max_level must be >= 1, got {self.occlusion_max_level}")
        if not self.max_depth_disagreement >= 0:
            raise InputError(f"max_depth_disagreement must be a fraction >= 0, got {self.max_depth_disagreement}")
        if not (self.split_min_px > 0 and self.split_max_distortion > 0):
            raise InputError(f"split_min_px and split_max_distortion must be > 0, got {self.split_min_px}, "
                             f"{self.split_max_distortion}")

    def filter_options(self) -> dict[str, Any]:
        """The options the per-view filter tasks read, as :attr:`Visibility.options` records them."""
        casts = {"occlusion_max_level": int, "fill_radius": int, "depth_edge_margin": int, "two_sided": bool,
                 "oblique_reference": str, "filters": tuple}
        return {k: casts.get(k, float)(getattr(self, k)) for k in _FILTER_FIELDS}
