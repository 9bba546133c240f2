"""MeshLab-facing layer of o3d_seqcc: our jobs as filters in pymeshlab's calling style, MeshLab projects.

- :func:`apply` (``apply(ms, "seqcc_color_correct_rasters", reference="auto")``),
  :func:`print_filter_parameter_list`, :func:`filter_list`: the filters of :mod:`.filters`, run on a
  ``pymeshlab.MeshSet`` that holds a project (:mod:`.meshset` explains how);
- :func:`screenshot_meshlab`, :class:`MeshLabSession`: the MeshLab application opening a project
  under a virtual display, driven with xdotool (:mod:`.app`);
- :mod:`.native`: the filters of the native MeshLab plugin (``meshlab_filters/plugin/``, C++, GPL-3),
  generated from the library, and :func:`~.native.filter_script` (``.mlx`` files that run them);
- the ``.mlp`` reader and writer are a scene format of the package (:mod:`o3d_seqcc.io.meshlab`):
  ``o3d_seqcc.load_scene("project.mlp")`` and every command accept a MeshLab project, and the
  ``--out`` of ``run`` / ``texture`` / ``correct`` holds a ``project.mlp``.
"""

from __future__ import annotations

from o3d_seqcc.io.meshlab import load_mlp, project_meshlab, save_mlp, vcg_camera_attributes, view_from_vcg_camera

from .app import MeshLabSession, MeshLabShot, missing_tools, save_screenshot, screenshot_meshlab, write_view_state
from .filters import apply, filter_list, filter_parameter_text, get_filter, print_filter_parameter_list

__all__ = [
    "MeshLabSession",
    "MeshLabShot",
    "apply",
    "filter_list",
    "filter_parameter_text",
    "get_filter",
    "load_mlp",
    "missing_tools",
    "print_filter_parameter_list",
    "project_meshlab",
    "save_mlp",
    "save_screenshot",
    "screenshot_meshlab",
    "vcg_camera_attributes",
    "view_from_vcg_camera",
    "write_view_state",
]
