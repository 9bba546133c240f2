"""Synthetic scenes with ground truth: a textured room (:mod:`.room`) rendered with known
camera-like photometric changes (:mod:`o3d_seqcc.evaluation.photometric`) by :mod:`.generate`."""

from __future__ import annotations

from ..evaluation.photometric import (
    CAMERA_CHANGE_RANGES,
    HARD_CHANGE_RANGES,
    apply_photometric,
    identity_photometric,
    sample_camera_change,
    sample_photometric,
)
from .generate import PHOTOMETRIC_MODES, SYNTHETIC_FORMAT, SyntheticScene, load_synthetic, make_synthetic_scene, perturb_poses
from .room import ALBEDO_RANGE, DEFAULT_CELL_SIZE, ring_slots
from .._shared.lazy import lazy_exports

__all__ = [
    "ALBEDO_RANGE",
    "CAMERA_CHANGE_RANGES",
    "DEFAULT_CELL_SIZE",
    "HARD_CHANGE_RANGES",
    "PHOTOMETRIC_MODES",
    "SYNTHETIC_FORMAT",
    "SyntheticScene",
    "apply_photometric",
    "identity_photometric",
    "load_synthetic",
    "make_synthetic_scene",
    "perturb_poses",
    "ring_slots",
    "sample_camera_change",
    "sample_photometric",
]

# the names the other stages use, imported from their modules on first use
__getattr__, __dir__ = lazy_exports(__name__, {
    # used by the other stages and the pipeline (tests/test_layout.py: nothing else is imported across)
    "LAYOUTS": "room",
})
