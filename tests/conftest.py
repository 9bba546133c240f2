"""Shared fixtures: paths to ../shared (real data) and small scene builders."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

# headless: never try to open a window
os.environ.setdefault("MPLBACKEND", "Agg")

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
FOUNTAIN = SHARED / "datasets" / "fountain_small"


@pytest.fixture(scope="session")
def fountain_root() -> Path:
    """The fountain_small dataset folder (skips when ../shared is absent)."""
    if not (FOUNTAIN / "scene" / "key.log").is_file():
        pytest.skip(f"real data not found at {FOUNTAIN} (../shared is absent)")
    return FOUNTAIN


@pytest.fixture(scope="session")
def fountain_scene(fountain_root):
    """Fountain with the decimated 16k-face mesh."""
    from o3d_seqcc.datasets import fountain

    return fountain(fountain_root, mesh="scene/mesh_decimated_uv_blender.ply")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)
