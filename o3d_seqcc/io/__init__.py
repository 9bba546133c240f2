"""Readers and writers, one module per format; :mod:`o3d_seqcc.io.load` dispatches on a table.

Scene formats (a mesh + registered views): ``scene_json`` (the native ``scene.json``),
``meshlab`` (MeshLab ``.mlp`` projects), ``rgbd_folder`` (Open3D RGB-D folders), ``colmap``
(COLMAP text and binary models), ``meshroom`` (Meshroom / AliceVision ``cameras.sfm``).
:func:`o3d_seqcc.io.load.load_scene` detects the format and calls its loader
(:data:`o3d_seqcc.io.load.SCENE_FORMATS`). Below them, the file layer that all of them use, one
module an idea: :mod:`~o3d_seqcc.io.regular_files` (opening input files), :mod:`~o3d_seqcc.io.atomic`
(every write atomic), :mod:`~o3d_seqcc.io.raster_checks` (the pixel budget, complete files),
:mod:`~o3d_seqcc.io.images` (photos), :mod:`~o3d_seqcc.io.depth` (depth maps), :mod:`~o3d_seqcc.io.json_files`,
:mod:`~o3d_seqcc.io.paths` (paths named by scene files), :mod:`~o3d_seqcc.io.mesh_files` (meshes and
point clouds), :mod:`~o3d_seqcc.io.headers` (what a file's first bytes promise).

Every image, depth map, mesh and point cloud is read through that layer, with the same steps for
every file, before any decoder sees it:

1. **regular files only** (:func:`~o3d_seqcc.io.regular_files.open_regular`): a FIFO, a device, a socket or a
   folder is an error naming it, found without blocking (opened non-blocking and checked with ``fstat``: a
   named pipe never hangs a run);
2. **any path bytes**: files are read through their descriptor (OpenCV decodes from memory, ``cv2.imdecode``;
   Open3D gets an ASCII alias of the open file), so a folder name that is not UTF-8 works as in the shell;
3. **budgets from the header, before decoding**: images and depth maps have at most
   :data:`~o3d_seqcc.io.raster_checks.MAX_IMAGE_PIXELS` pixels (``--max-image-pixels``); a PLY / OFF / STL
   header may not declare more elements than its file can hold (:mod:`o3d_seqcc.io.headers`);
4. **complete files**: a JPEG's main image must end with its end-of-image marker after its first
   scan (an EXIF thumbnail's marker does not count), a PNG's chunks must reach IEND;
5. **sane values**: mesh vertices finite and within :data:`~o3d_seqcc.io.mesh_files.MAX_COORDINATE`;
   point-cloud points that are not are dropped with a warning; depth that is not finite is "missing".

This package's ``__init__`` imports none of its modules (the names below load lazily), so the scene
model can use the file layer without an import loop.
"""

from .._shared.lazy import lazy_exports

# the names the other stages use, imported from their modules on first use
__getattr__, __dir__ = lazy_exports(__name__, {
    # used by the other stages and the pipeline (tests/test_layout.py: nothing else is imported across)
    **dict.fromkeys(("atomic_path", "atomic_write_bytes"), "atomic"),
    **dict.fromkeys(("check_depth_file", "depth_in_metres", "read_depth", "read_stored_depth"), "depth"),
    **dict.fromkeys(("DEFAULT_FORMATS", "EXPORT_UP_AXES", "FILE_SUFFIXES", "FORMATS", "TEXTURE_FORMATS",
                     "check_export_options", "export_meshlab_ply", "export_textured_mesh", "float32_offset",
                     "glb_bytes", "parse_formats", "texture_file_names"), "export"),
    **dict.fromkeys(("encode_image", "image_dtype", "read_image", "read_view_images", "write_image"), "images"),
    **dict.fromkeys(("read_json", "write_json"), "json_files"),
    **dict.fromkeys(("AXES", "EXTRINSIC_CONVENTIONS", "as_scene", "camera_fixes", "detect_format", "load_scene",
                     "save_scene"), "load"),
    "save_mappings": "mappings_npz",
    **dict.fromkeys(("check_mask_file", "mask_array", "mask_distorted", "view_mask"), "masks"),
    **dict.fromkeys(("read_corner_uv", "read_mesh", "read_point_cloud"), "mesh_files"),
    **dict.fromkeys(("MeshLayer", "save_mlp"), "meshlab"),
    **dict.fromkeys(("MissingImage", "check_photo", "missing_images", "near_miss"), "missing"),
    **dict.fromkeys(("add_output_file", "check_output", "check_output_file", "output_file", "output_folder",
                     "write_output_file", "write_output_json"), "output"),
    **dict.fromkeys(("MAX_IMAGE_PIXELS", "set_max_image_pixels"), "raster_checks"),
    "open_regular": "regular_files",
    "SCENE_JSON": "scene_json",
})
