"""o3d_seqcc: sequential pairwise colour correction and texture mapping of 3D meshes.

Implements L. Dal'Col et al., "A Sequential Color Correction Approach for Texture Mapping of
3D Meshes", Sensors 2023, 23(2), 607, on top of Open3D, scikit-learn and networkx, and textures
the mesh sharply (one photo per face, texture atlas, OBJ/GLB export).

The pipeline, one package per stage, in order (this file's table below follows it)::

    scene = o3d_seqcc.load_scene("scene.json")                        # scene, io/
    vis = o3d_seqcc.compute_visibility(scene)                          # visibility/ (3.1-3.2)
    maps = o3d_seqcc.compute_mappings(scene, visibility=vis)           # mappings/ (3.1)
    res = o3d_seqcc.correct(scene, reference="auto", mappings=maps)    # correction/ (3.3-3.7)
    sel = o3d_seqcc.select_views(vis, method="mrf")                    # texturing/ (3.8)
    tm = o3d_seqcc.bake_texture(vis.mesh, res.images, vis, sel)
    ev = o3d_seqcc.evaluate(res.images, maps)                          # evaluation/ (4.2)
    o3d_seqcc.export_glb(tm, "mesh.glb")                               # io/

or the whole job with the command line's defaults (:class:`RunSettings` holds them all)::

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

from ._shared.lazy import lazy_exports
from .errors import InputError

__version__ = "0.1.0"

#: public name -> the module that defines it, stage by stage
_LAZY: dict[str, str] = {
    # the scene: the model and its loading (imported on first use too, so that the command line's own
    # handlers are in place before anything slow runs: Ctrl-C while `python -m o3d_seqcc` starts)
    **dict.fromkeys(("FORMAT", "PRIMESENSE_INTRINSIC", "Mesh", "Scene", "View", "load_mesh"), "scene"),
    **dict.fromkeys(("load_scene", "save_scene"), "io.load"),
    "Distortion": "geometry.distortion",
    **dict.fromkeys(("SyntheticScene", "make_synthetic_scene", "load_synthetic", "perturb_poses"), "synthetic"),
    # settings: every option's default, one object per stage and one for a run
    "RunSettings": "settings",
    "VisibilitySettings": "visibility.settings",
    "CorrectionSettings": "correction.settings",
    # 1. visibility (3.1-3.2): cameras checked first, then which faces each photo sees
    **dict.fromkeys(("check_cameras", "CameraReport"), "visibility.camera_checks"),
    **dict.fromkeys(("Visibility", "compute_visibility"), "visibility.compute"),
    "project_points": "geometry.camera",
    # 2. mappings (3.1)
    **dict.fromkeys(("Mappings", "PairMapping", "compute_mappings"), "mappings.compute"),
    **dict.fromkeys(("load_mappings", "save_mappings"), "io.mappings_npz"),
    "sample_colors": "imaging.arrays",
    # 3. correction (3.3-3.7): graph, JIH, CMF, the methods
    **dict.fromkeys(("build_graph", "correction_paths", "choose_reference"), "correction.graph"),
    "joint_histogram": "correction.jih",
    **dict.fromkeys(("fit_cmf", "CMF_METHODS"), "correction.cmf"),
    **dict.fromkeys(("correct", "DEFAULT_METHOD", "available_methods", "register_method", "METHODS",
                     "CorrectionContext", "CorrectionResult", "LutTransform", "FunctionTransform",
                     "IdentityTransform"), "correction"),
    # 4. texturing (3.8): selection, atlas, leveling
    "TextureSettings": "texturing.settings",
    **dict.fromkeys(("SELECTION_METHODS", "TexturedMesh", "load_textured_mesh", "select_views",
                     "bake_texture"), "texturing"),
    # 5. evaluation (4.2, Table 2), ground truth, seams, sharpness, renders
    **dict.fromkeys(("evaluate", "Evaluation"), "evaluation.metrics"),
    **dict.fromkeys(("evaluate_method", "MethodEvaluation"), "evaluation.fit"),
    **dict.fromkeys(("make_semireal", "evaluate_semireal"), "evaluation.semireal"),
    **dict.fromkeys(("SeamReport", "seam_metric"), "evaluation.seams"),
    **dict.fromkeys(("sharpness", "gradient_similarity"), "evaluation.sharpness"),
    **dict.fromkeys(("render_textured", "render_selection", "plot_pair"), "evaluation.render"),
    # export: OBJ / GLB / PLY
    **dict.fromkeys(("export_obj", "export_glb", "export_ply", "export_textured_mesh"), "io.export"),
    # the report
    "html_report": "report",
    "regenerate_report": "run_folder.read",
    # the whole job, its front doors
    "RunResult": "pipeline",
    **dict.fromkeys(("correct_images", "texture_mesh"), "open3d_api"),
    "run_demo": "demo",
}

#: packages and modules reachable as attributes (``o3d_seqcc.pipeline.run(...)``) without an explicit import
_SUBMODULES: dict[str, str] = {
    **{m: m for m in ("correction", "datasets", "demo", "evaluation", "geometry", "imaging", "io", "mappings",
                      "open3d_api", "pipeline", "report", "scene", "settings", "synthetic", "texturing", "visibility")},
    "parallel": "_shared.parallel",  # o3d_seqcc._shared.parallel.use(client): the executor of a block of calls
}

__all__ = ["InputError", "__version__", *_LAZY]

__getattr__, __dir__ = lazy_exports(__name__, _LAZY, submodules=_SUBMODULES)
