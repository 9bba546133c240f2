"""The options shared by several commands, under their former address (re-exported).

They live in the modules of the CLI's seams: :mod:`.scene_flags` (the scene, the loader's flags,
the outputs), :mod:`.correction_flags`, :mod:`.texture_flags` (texture, atlas, export, the settings
the flags make), :mod:`.console` (``--progress-lines``) and :mod:`.parser` (:func:`library_default`).
The commands import them from there; this module keeps ``o3d_seqcc.cli.common`` importable for
its callers (``meshlab_filters.filters`` reads :func:`library_default` here).
"""

from __future__ import annotations

from .console import add_progress_argument, progress_from_args
from .correction_flags import add_correction_arguments, add_split_argument, add_t_npm_argument, t_npm_value
from .parser import library_default
from .scene_flags import (
    add_scene_arguments,
    prepare_out_dir,
    print_report_path,
    print_run_summary,
    refuse_input_overwrite,
    scene_from_args,
    scene_options_from_args,
)
from .texture_flags import (
    add_atlas_arguments,
    add_export_arguments,
    add_texture_arguments,
    run_options_from_args,
    save_options_from_args,
    texture_job_from_args,
    texture_settings_from_args,
)

__all__ = [
    "add_atlas_arguments",
    "add_correction_arguments",
    "add_export_arguments",
    "add_progress_argument",
    "add_scene_arguments",
    "add_split_argument",
    "add_t_npm_argument",
    "add_texture_arguments",
    "library_default",
    "prepare_out_dir",
    "print_report_path",
    "print_run_summary",
    "progress_from_args",
    "refuse_input_overwrite",
    "run_options_from_args",
    "save_options_from_args",
    "scene_from_args",
    "scene_options_from_args",
    "t_npm_value",
    "texture_job_from_args",
    "texture_settings_from_args",
]
