"""What a report page is drawn from: :class:`PageInputs` (the report.json content and the run's data) and
:func:`facts` (the fields of a report.json the page reads, for any command and schema)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..scene import Scene

__all__ = ["PageInputs", "facts"]


@dataclass(frozen=True, eq=False)
class PageInputs:
    """What a report is drawn from: the report.json content and the run's data (None = absent)."""

    rep: dict
    scene: Scene
    photos: list | None  # the images before correction (or the images textured)
    corrected: list | None
    correction: Any = None  # CorrectionResult
    mappings: Any = None
    selection: np.ndarray | None = None
    mesh: tuple | None = None  # (vertices, faces) of the scene's mesh
    textured: Any = None  # TexturedMesh
    usable: np.ndarray | None = None  # (V,) faces usable per view
    selection_png: Any = None  # selection.png of the folder (rendered from the view report.json names), or a callable
    # returning it (the picture still being written beside the page)
    selection_seams: dict | None = None  # {"photos", "corrected"}: seams.SelectionSeams (computed when absent)
    casters: Any = None  # evaluation.render.Casters: the meshes' ray-casting scenes, each built once (made when absent)
    parts: Any = None  # parts.CorrectionParts: the JIHs and thumbnails computed before the page (computed when absent)


def facts(rep: dict) -> dict[str, Any]:
    """The fields the page needs, from a report.json of :mod:`o3d_seqcc.report.schema` (any command)."""
    c = rep.get("correction") or {}
    settings = c.get("settings") or {}
    command = rep.get("command", "run")
    return {"command": command, "method": c.get("method"), "t_npm": settings.get("t_npm", c.get("t_npm")),
            "t_npm_effective": c.get("t_npm"), "mappings": c.get("mappings"), "settings": settings,
            "timings": rep.get("timings_s") or {}, "correction_timings": c.get("timings_s") or {},
            "metrics": rep.get("metrics")}
