"""Texture mapping (paper 3.8), one module per stage, as mvs-texturing's ``libs/tex``.

- :mod:`~o3d_seqcc.texturing.settings`: :class:`TextureSettings`, the one settings struct whose
  defaults every entry point uses;
- :mod:`~o3d_seqcc.texturing.selection`: per-face view selection (:func:`select_views`:
  ``"mrf"``, ``"largest-area"``, ``"random"``);
- :mod:`~o3d_seqcc.texturing.charts`: charts (image footprints of same-view regions, unseen
  faces welded in) and their UVs;
- :mod:`~o3d_seqcc.texturing.packing`: xatlas packing under an atlas-size budget;
- :mod:`~o3d_seqcc.texturing.packing_child`: that packing in child processes, beside the bake;
- :mod:`~o3d_seqcc.texturing.bake`: rasterisation, sampling, gutters, pull-push fill;
- :mod:`~o3d_seqcc.texturing.atlas`: the stages together (:func:`bake_texture`);
- :mod:`~o3d_seqcc.texturing.fallback`: colours of the faces seen by no view;
- :mod:`~o3d_seqcc.texturing.leveling`: global and local seam leveling;
- :mod:`~o3d_seqcc.texturing.textured_mesh`: :class:`TexturedMesh`, the one textured-mesh type
  (UVs with the origin bottom-left, as OBJ, trimesh and Open3D), with ``to_open3d`` /
  ``to_trimesh`` and :func:`load_textured_mesh`.
"""

from __future__ import annotations

from .._shared.lazy import lazy_exports

# names imported from their modules on first use: a child process that packs (packing_child) imports packing alone
__getattr__, __dir__ = lazy_exports(__name__, {
    # used by the other stages and the pipeline (tests/test_layout.py: nothing else is imported across)
    **dict.fromkeys(("gutter_texels", "rasterize_faces"), "bake"),
    **dict.fromkeys(("bake_own_uv", "check_corner_uv"), "own_uv"),
    **dict.fromkeys(("DATA_TERMS", "FALLBACKS", "OUTLIER_REMOVALS", "OVERFLOWS", "UV_MODES"), "settings"),
    "bake_texture": "atlas",
    "seam_leveling_offsets": "leveling",
    **dict.fromkeys(("SELECTION_METHODS", "count_transitions", "register_selection", "select_views",
                     "selection_stats"), "selection"),
    **dict.fromkeys(("LEVELING_SMOOTHNESS", "MRF_SMOOTHNESS", "TextureSettings"), "settings"),
    **dict.fromkeys(("TexturedMesh", "load_textured_mesh", "sample_texture"), "textured_mesh"),
})

__all__ = [
    "LEVELING_SMOOTHNESS",
    "MRF_SMOOTHNESS",
    "SELECTION_METHODS",
    "TextureSettings",
    "TexturedMesh",
    "bake_texture",
    "count_transitions",
    "load_textured_mesh",
    "register_selection",
    "sample_texture",
    "seam_leveling_offsets",
    "select_views",
    "selection_stats",
]
