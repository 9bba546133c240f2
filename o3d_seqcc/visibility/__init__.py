"""Visibility (paper 3.1-3.2): which faces each photo sees, whole and unoccluded.

- :mod:`~o3d_seqcc.visibility.camera_checks`: the cameras against the mesh before any work
  (:func:`check_cameras` -> :class:`CameraReport` or an ``InputError`` naming the fix);
- :mod:`~o3d_seqcc.visibility.depthmaps`: depth images from point clouds (Navier-Stokes inpainting), depth edges;
- :mod:`~o3d_seqcc.visibility.occlusion`: the z-buffer test of one view (Open3D ``RaycastingScene``);
- :mod:`~o3d_seqcc.visibility.per_view`: one view's task (frustum, projection, the filters) -> ``ViewRecord``;
- :mod:`~o3d_seqcc.visibility.refine`: faces no photo holds whole, split into parts;
- :mod:`~o3d_seqcc.visibility.stray`: far-away components no photo sees, dropped;
- :mod:`~o3d_seqcc.visibility.settings`: :class:`VisibilitySettings`, the options of the stage and their defaults;
- :mod:`~o3d_seqcc.visibility.compute`: :class:`Visibility` (one sparse record per view) and
  :func:`compute_visibility`, the stage.
"""

from __future__ import annotations

from .._shared.lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {
    # used by the other stages and the pipeline (tests/test_layout.py: nothing else is imported across)
    **dict.fromkeys(("FLIP", "MIN_AREA_SEEN"), "camera_checks"),
    **dict.fromkeys(("DenseVisibility", "VisibilityLike"), "dense"),
    "coverage": "refine",
    **dict.fromkeys(("Visibility", "compute_visibility", "UsableFaces"), "compute"),
    **dict.fromkeys(("VisibilitySettings", "FILTERS", "OBLIQUE_REFERENCES"), "settings"),
    **dict.fromkeys(("ViewRecord", "view_record"), "per_view"),
    **dict.fromkeys(("check_cameras", "CameraReport"), "camera_checks"),
    "depth_from_point_cloud": "depthmaps",
})
