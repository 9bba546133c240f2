"""Readers and writers, one module per format; :mod:`o3d_seqcc.io.load` dispatches on a table.

Scene formats (a mesh + registered views): ``scene_json`` (the native ``scene.json``),
``meshlab`` (MeshLab ``.mlp`` projects), ``rgbd_folder`` (Open3D RGB-D folders), ``colmap``
(COLMAP text and binary models), ``meshroom`` (Meshroom / AliceVision ``cameras.sfm``).
:func:`o3d_seqcc.io.load.load_scene` detects the format and calls its loader
(:data:`o3d_seqcc.io.load.SCENE_FORMATS`); :mod:`o3d_seqcc.io.files` holds the file primitives
(images, depth maps, JSON; every write atomic) that all of them use.

This package's ``__init__`` imports nothing, so the scene model can use
:mod:`o3d_seqcc.io.files` without an import loop.
"""
