"""MeshLab-facing layer of o3d_seqcc: MeshLab projects (.mlp) and peer texturing runs.

- :mod:`meshlab_filters.mlp`: write a :class:`~o3d_seqcc.scene.Scene` as a MeshLab project
  (mesh + registered rasters) and read one back.
- :mod:`meshlab_filters.peers`: the texturing peers used for comparison: MeshLab's
  ``compute_texcoord_parametrization_and_texture_from_registered_rasters`` through pymeshlab
  (in a headless subprocess under ``xvfb-run``) and Open3D's ``compute_uvatlas`` +
  ``project_images_to_albedo``.
"""

from __future__ import annotations

from .mlp import load_mlp, project_meshlab, save_mlp, vcg_camera_attributes, view_from_vcg_camera

__all__ = ["load_mlp", "project_meshlab", "save_mlp", "vcg_camera_attributes", "view_from_vcg_camera"]
