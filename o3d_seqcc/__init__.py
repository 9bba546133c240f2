"""o3d_seqcc: sequential pairwise colour correction and texture mapping of 3D meshes.

Implements Dal'Col et al., "A Sequential Color Correction Approach for Texture Mapping of 3D
Meshes", Sensors 2023, 23(2), 607, on top of Open3D, scikit-learn and networkx.
"""

from __future__ import annotations

from .errors import InputError
from .scene import FORMAT, PRIMESENSE_INTRINSIC, Mesh, Scene, View, load_mesh, load_scene, save_scene

__version__ = "0.1.0"

__all__ = [
    "FORMAT",
    "PRIMESENSE_INTRINSIC",
    "InputError",
    "Mesh",
    "Scene",
    "View",
    "__version__",
    "load_mesh",
    "load_scene",
    "save_scene",
]
