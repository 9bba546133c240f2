"""o3d_seqcc: sequential pairwise colour correction and texture mapping of 3D meshes.

Implements L. Dal'Col et al., "A Sequential Color Correction Approach for Texture Mapping of
3D Meshes", Sensors 2023, 23(2), 607, on top of Open3D, scikit-learn and networkx, and textures
the mesh sharply (one photo per face, texture atlas, OBJ/GLB export).

The pipeline, one module per stage::

    scene = o3d_seqcc.load_scene("scene.json")                        # scene
    vis = o3d_seqcc.compute_visibility(scene)                          # visibility (3.1-3.2)
    maps = o3d_seqcc.compute_mappings(scene, visibility=vis)           # mappings (3.1)
    res = o3d_seqcc.correct(scene, reference="auto", mappings=maps)    # graph, jih, cmf, correction (3.3-3.7)
    ev = o3d_seqcc.evaluate(res.images, maps)                          # metrics (4.2)
    sel = o3d_seqcc.select_views(vis, method="mrf")                    # texturing (3.8)

or the whole job with the command line's defaults::

    res = o3d_seqcc.pipeline.run("scene.json")                         # correct + texture
    res.save("out/")                                                   # what `o3d-seqcc run` writes

Every option's default is written once, in a settings object (:class:`VisibilitySettings`,
:class:`CorrectionSettings`, :class:`TextureSettings`, and :class:`RunSettings` holding them)::

    s = o3d_seqcc.RunSettings.from_options(method="seqcc", max_angle=60)
    res = o3d_seqcc.pipeline.run("scene.json", settings=s)             # = run(..., method="seqcc", max_angle=60)

Heavy dependencies are imported on first use of a name (PEP 562), so ``import o3d_seqcc`` is
cheap.
"""

from __future__ import annotations

import importlib
from typing import Any

from .errors import InputError

__version__ = "0.1.0"

# public name -> module that defines it
_LAZY: dict[str, str] = {
    # the scene model and its loading (numpy, OpenCV): imported on first use too, so that the command line's
    # own handlers are in place before anything slow runs (Ctrl-C while `python -m o3d_seqcc` starts)
    **dict.fromkeys(("FORMAT", "PRIMESENSE_INTRINSIC", "Mesh", "Scene", "View", "load_mesh"), "scene"),
    **dict.fromkeys(("load_scene", "save_scene"), "io.load"),
    # synthetic test / demo scenes
    "SyntheticScene": "synthetic",
    "make_synthetic_scene": "synthetic",
    "load_synthetic": "synthetic",
    "perturb_poses": "synthetic",
    # camera sanity, lens distortion
    "check_cameras": "visibility.camera_checks",
    "CameraReport": "visibility.camera_checks",
    "Distortion": "geometry.distortion",
    # settings: every option's default, one object per stage and one for a run
    "RunSettings": "settings",
    "VisibilitySettings": "visibility.settings",
    "CorrectionSettings": "correction.settings",
    # visibility and mappings (paper 3.1-3.2)
    "Visibility": "visibility.compute",
    "compute_visibility": "visibility.compute",
    "project_points": "geometry.camera",
    "Mappings": "mappings.compute",
    "PairMapping": "mappings.compute",
    "compute_mappings": "mappings.compute",
    "load_mappings": "io.mappings_npz",
    "save_mappings": "io.mappings_npz",
    "sample_colors": "imaging.arrays",
    # graph, JIH, CMF, correction (3.3-3.7)
    "build_graph": "correction.graph",
    "correction_paths": "correction.graph",
    "choose_reference": "correction.graph",
    "joint_histogram": "correction.jih",
    "fit_cmf": "correction.cmf",
    "CMF_METHODS": "correction.cmf",
    "correct": "correction",
    "DEFAULT_METHOD": "correction",
    "available_methods": "correction",
    "register_method": "correction",
    "METHODS": "correction",
    "CorrectionContext": "correction",
    "CorrectionResult": "correction",
    "LutTransform": "correction",
    "FunctionTransform": "correction",
    "IdentityTransform": "correction",
    # evaluation (4.2) and semi-real ground truth
    "evaluate": "evaluation.metrics",
    "Evaluation": "evaluation.metrics",
    "evaluate_method": "evaluation.fit",
    "MethodEvaluation": "evaluation.fit",
    "make_semireal": "evaluation.semireal",
    "evaluate_semireal": "evaluation.semireal",
    # texturing, export, seams, renders (3.8)
    "SELECTION_METHODS": "texturing",
    "TextureSettings": "texturing.settings",
    "TexturedMesh": "texturing",
    "load_textured_mesh": "texturing",
    "select_views": "texturing",
    "bake_texture": "texturing",
    "export_obj": "io.export",
    "export_glb": "io.export",
    "export_ply": "io.export",
    "export_textured_mesh": "io.export",
    "SeamReport": "evaluation.seams",
    "seam_metric": "evaluation.seams",
    "render_textured": "evaluation.render",
    "render_selection": "evaluation.render",
    "sharpness": "evaluation.sharpness",
    "gradient_similarity": "evaluation.sharpness",
    "plot_pair": "evaluation.render",
    # Open3D front door
    "correct_images": "open3d_api",
    "texture_mesh": "open3d_api",
    # the whole job
    "RunResult": "pipeline",
    "run_demo": "demo",
    "html_report": "report",
    "regenerate_report": "report",
}

#: submodules reachable as attributes (``o3d_seqcc.pipeline.run(...)``) without an explicit import
_SUBMODULES = frozenset({
    "correction", "datasets", "demo", "evaluation", "geometry", "imaging", "io", "mappings", "open3d_api",
    "pipeline", "report", "scene", "settings", "synthetic", "texturing", "visibility",
})

__all__ = [
    "InputError",
    "__version__",
    *_LAZY,
]


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        value = importlib.import_module(f".{name}", __name__)
        globals()[name] = value
        return value
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'o3d_seqcc' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__) | _SUBMODULES)
