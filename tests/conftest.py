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


# ---- the fast tier -------------------------------------------------------------------------------------------------
#: The heavy tests, marked ``slow`` here (``file::function``, every parametrization): ``-m "not slow"`` (the fast
#: tier, ``./dev.sh test -m "not slow"``) leaves them out; the full run (``./dev.sh test``, CI) runs them. Chosen
#: from ``pytest --durations=0`` of the full run: each takes about 4 s or more on this 2-core machine. A test module
#: may also mark itself (``pytestmark = pytest.mark.slow``); an entry naming no test of its file stops the run.
SLOW = """
""".split()
TESTS = Path(__file__).resolve().parent


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    slow, modules = set(SLOW), {}
    for item in items:
        rel = item.path.relative_to(TESTS).as_posix() if item.path.is_relative_to(TESTS) else str(item.path)
        modules.setdefault(rel, getattr(item, "module", None))
        if f"{rel}::{getattr(item, 'originalname', item.name)}" in slow:
            item.add_marker(pytest.mark.slow)
    stale = sorted(k for k in slow if k.split("::")[0] in modules
                   and not callable(getattr(modules[k.split("::")[0]], k.split("::")[1], None)))
    if stale:
        raise pytest.UsageError(f"tests/conftest.py SLOW names tests that do not exist: {stale}")
