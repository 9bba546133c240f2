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
#: The heavy tests, marked ``slow`` here (``file`` for a whole module, ``file::function`` for every parametrization): ``-m "not slow"`` (the fast
#: tier, ``./dev.sh test -m "not slow"``) leaves them out; the full run (``./dev.sh test``, CI) runs them. Chosen
#: from ``pytest --durations=0`` of the full run: each takes about 4 s or more on this 2-core machine. A test module
#: may also mark itself (``pytestmark = pytest.mark.slow``); an entry naming no test of its file stops the run.
SLOW = """
cli/test_cli_correct.py::test_correct_writes_images_scene_report_and_chains
cli/test_cli_evaluate.py::test_correct_chains_into_evaluate
cli/test_cli_evaluate.py::test_evaluate_prints_and_writes_json
cli/test_cli_messages.py::test_quiet_prints_nothing_on_success
cli/test_cli_texture.py::test_run_corrects_and_textures
cli/test_cli_texture.py::test_texture_engine_options
cli/test_cli_texture.py::test_texture_with_images_folder
cli/test_cli_texture.py::test_texture_writes_outputs_and_refuses_existing_folder
cli/test_progress.py::test_cli_shows_bars_on_a_terminal_and_not_in_a_pipe
geometry/test_distortion.py::test_distorted_scene_textured_like_the_undistorted_one
hostile/test_hostile.py::test_cli_terminated_exit_code_and_cleanup
hostile/test_hostile.py::test_a_signal_inside_the_saves_thread_start_leaves_no_staging_folder
io/test_fuzz_loaders.py
io/test_reliability.py::test_a_warning_is_printed_once
io/test_reliability.py::test_failure_after_loading_leaves_nothing_and_rerun_works
io/test_reliability.py::test_killed_run_leaves_previous_output_intact
io/test_reliability.py::test_overwrite_replaces_the_whole_previous_output
io/test_reliability.py::test_symlinked_out_is_followed_and_images_symlink_not_written_through
meshlab/test_meshlab_native.py::test_progress_lines_of_the_command_line
report/test_report.py::test_the_report_is_one_self_contained_file
report/test_report.py::test_the_report_renders_in_headless_chromium
test_open3d_api.py::test_texture_mesh_is_an_open3d_textured_mesh
texturing/test_atlas.py::test_fountain_mip_bleed_level2_and_coverage
integration/test_cli_demo.py
integration/test_dask.py
integration/test_examples.py
integration/test_lean.py
integration/test_pipeline.py
integration/test_readme.py
meshlab/test_meshlab_app.py
meshlab/test_meshlab_plugin.py
meshlab/test_meshlab_pymeshlab.py
report/test_report_viewer.py
report/test_viewer_bundle.py
mappings/test_mappings.py::test_fountain_counts_and_depth_agreement
test_open3d_api.py::test_fountain_through_open3d_readers_equals_the_command_line
test_scene.py::test_fountain_mesh_projects_onto_depth_map
texturing/test_atlas.py::test_fountain_glb_opens_right_way_up
texturing/test_texturing.py::test_fountain_selection_and_bake
visibility/test_camera_checks.py::test_fountain_passes
""".split()
TESTS = Path(__file__).resolve().parent


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    slow, modules = set(SLOW), {}
    for item in items:
        rel = item.path.relative_to(TESTS).as_posix() if item.path.is_relative_to(TESTS) else str(item.path)
        modules.setdefault(rel, getattr(item, "module", None))
        if rel in slow or f"{rel}::{getattr(item, 'originalname', item.name)}" in slow:
            item.add_marker(pytest.mark.slow)
    stale = sorted(k for k in slow if not (TESTS / k.split("::")[0]).is_file() or (
        "::" in k and k.split("::")[0] in modules and not callable(getattr(modules[k.split("::")[0]], k.split("::")[1], None))))
    if stale:
        raise pytest.UsageError(f"tests/conftest.py SLOW names tests that do not exist: {stale}")
