"""Image arrays and image sequences, used by every stage.

- :mod:`~o3d_seqcc.imaging.arrays`: operations on one image array: the one dtype conversion
  (``img_as_float`` / ``img_as_dtype`` / ``img_as_uint8``), bilinear sampling, the sRGB transfer
  functions, CIE Lab and CIEDE2000;
- :mod:`~o3d_seqcc.imaging.sequences`: lazy sequences of a scene's photos (read on access, LRU caches).
"""

from __future__ import annotations

from .._shared.lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {
    # used by the other stages and the pipeline (tests/test_layout.py: nothing else is imported across)
    **dict.fromkeys(("INTERPOLATIONS", "dtype_scale", "rgb_to_lab", "sample_bilinear"), "arrays"),
    **dict.fromkeys(("CachedImages", "default_cache_bytes", "image_dtypes"), "sequences"),
    **dict.fromkeys(("img_as_float", "img_as_dtype", "img_as_uint8", "sample_colors", "ciede2000", "delta_e_2000"), "arrays"),
    **dict.fromkeys(("srgb_to_linear", "linear_to_srgb"), "arrays"),
    **dict.fromkeys(("SceneImages", "FloatImages", "ImageSequence", "LRUCache", "scene_photos"), "sequences"),
})
