"""A run's output folder, both ways: what is written into it and what is read back from it.

- :mod:`~o3d_seqcc.run_folder.layout`: the name of every file the folder holds, defined once;
- :mod:`~o3d_seqcc.run_folder.write`: :func:`save_run` (``run`` / ``texture``) and
  :func:`save_correction` (``correct``): the folder staged and swapped in
  (:func:`o3d_seqcc.io.output.output_folder`), its parts written side by side, the report's page
  drawn from the result (:func:`run_page_inputs`, :func:`correction_page_inputs`);
- :mod:`~o3d_seqcc.run_folder.parts`: the photos, the MeshLab project, an in-memory mesh as a file;
- :mod:`~o3d_seqcc.run_folder.read`: ``report.json`` and ``selection.npy`` read back and checked,
  and :func:`regenerate_report` (``o3d-seqcc report RUN_DIR``).

No other module writes into a run's folder or spells its file names (``tests/test_layout.py``).
"""

from __future__ import annotations

from .._shared.lazy import lazy_exports

# names imported from their modules on first use: the layout's names cost nothing to import
__getattr__, __dir__ = lazy_exports(__name__, {
    **dict.fromkeys(("FolderPlan", "correction_page_inputs", "report_prelude", "run_page_inputs", "save_correction",
                     "save_rasters", "save_run", "write_run_folder"), "write"),
    **dict.fromkeys(("read_report_json", "read_selection", "regenerate_report"), "read"),
}, submodules=("layout",))

__all__ = ["FolderPlan", "correction_page_inputs", "layout", "read_report_json", "read_selection", "regenerate_report",
           "report_prelude", "run_page_inputs", "save_correction", "save_rasters", "save_run", "write_run_folder"]
