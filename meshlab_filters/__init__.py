"""MeshLab-facing layer of o3d_seqcc: MeshLab projects (.mlp) in the calling style of pymeshlab.

The ``.mlp`` reader and writer are a scene format of the package (:mod:`o3d_seqcc.io.meshlab`);
``o3d_seqcc.load_scene("project.mlp")`` and every command accept a MeshLab project.
"""

from __future__ import annotations

from o3d_seqcc.io.meshlab import load_mlp, project_meshlab, save_mlp, vcg_camera_attributes, view_from_vcg_camera

__all__ = ["load_mlp", "project_meshlab", "save_mlp", "vcg_camera_attributes", "view_from_vcg_camera"]
