"""Evaluation (paper 4.2, Table 2) and ground truth: scores of a correction and of a texture.

- :mod:`~o3d_seqcc.evaluation.metrics`: PSNR / CIEDE2000 over the mappings (:func:`evaluate`);
- :mod:`~o3d_seqcc.evaluation.table2`: the paper's Table 2 of a correction, before and after (:func:`before_after`);
- :mod:`~o3d_seqcc.evaluation.fit`: fit a method and score it, in-sample and held out (:func:`evaluate_method`);
- :mod:`~o3d_seqcc.evaluation.photometric`: camera-like photometric changes (the synthetic and semi-real truth);
- :mod:`~o3d_seqcc.evaluation.semireal`: semi-real ground truth on real photos (:func:`make_semireal`,
  :func:`evaluate_semireal`);
- :mod:`~o3d_seqcc.evaluation.seams`: the seam metric, the mip-bleed metric, the selection seams;
- :mod:`~o3d_seqcc.evaluation.sharpness`: sharpness (Laplacian variance), gradient similarity;
- :mod:`~o3d_seqcc.evaluation.render`: ray-cast renders of a textured mesh, selection pictures, mapping plots.
"""

from __future__ import annotations

from .._shared.lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {
    # used by the other stages and the pipeline (tests/test_layout.py: nothing else is imported across)
    **dict.fromkeys(("image_delta_e", "thin_indices"), "metrics"),
    **dict.fromkeys(("CAMERA_CHANGE_RANGES", "HARD_CHANGE_RANGES", "apply_photometric", "identity_photometric",
                     "sample_camera_change", "sample_photometric"), "photometric"),
    **dict.fromkeys(("Casters", "RayHits", "picture_view", "raycast", "resized_view", "selection_palette",
                     "write_selection_picture"), "render"),
    **dict.fromkeys(("SelectionSeams", "photo_colors", "selection_seams_of"), "seams"),
    **dict.fromkeys(("Evaluation", "evaluate", "psnr"), "metrics"),
    "before_after": "table2",
    **dict.fromkeys(("MethodEvaluation", "evaluate_method", "evaluate_scene"), "fit"),
    **dict.fromkeys(("make_semireal", "evaluate_semireal"), "semireal"),
    **dict.fromkeys(("SeamReport", "seam_metric", "selection_seams"), "seams"),
    **dict.fromkeys(("sharpness", "gradient_similarity"), "sharpness"),
    **dict.fromkeys(("render_textured", "render_selection", "plot_pair"), "render"),
})
