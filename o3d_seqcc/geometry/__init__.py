"""Geometry shared by the stages: pinhole projection, lens distortion, mesh topology and normals,
conforming face splits, the scene's up direction.

- :mod:`~o3d_seqcc.geometry.camera`: pinhole projection;
- :mod:`~o3d_seqcc.geometry.distortion`: :class:`Distortion` (OpenCV, fisheye, MeshLab's lens models);
- :mod:`~o3d_seqcc.geometry.meshops`: vertex welding, edge topology, face adjacency, normals, local frames;
- :mod:`~o3d_seqcc.geometry.meshsplit`: conforming longest-edge bisection (no T-junctions) and its reverse;
- :mod:`~o3d_seqcc.geometry.orientation`: the up direction from the cameras, the Y-up / Z-up rotation.
"""

from __future__ import annotations

from .._shared.lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {
    # used by the other stages and the pipeline (tests/test_layout.py: nothing else is imported across)
    **dict.fromkeys(("inside_image", "pixel_index", "project_columns"), "camera"),
    **dict.fromkeys(("bounds", "corner_mean", "face_normals", "float32_offset", "local_origin",
                     "oriented_face_normals", "row_norms", "vertex_normals"), "meshops"),
    "UP_AXES": "orientation",
    "project_points": "camera",
    "Distortion": "distortion",
    **dict.fromkeys(("face_adjacency", "edge_topology", "weld_vertices"), "meshops"),
    **dict.fromkeys(("bisect", "coarsen"), "meshsplit"),
    **dict.fromkeys(("estimate_up", "up_axis_transform"), "orientation"),
})
