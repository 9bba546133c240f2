"""One ``report.json`` schema for every command (``run``, ``texture``, ``correct``, the MeshLab filters).

Every report holds the same top-level keys (:data:`KEYS`, in that order; ``null`` where the
command has no such part: ``texture`` corrects nothing, ``correct`` textures nothing):

- ``schema`` (:data:`SCHEMA`), ``command``, ``scene`` (as given), ``scene_path`` / ``mesh``
  (absolute, null for a scene in memory), ``scene_options`` (how it was loaded), ``images``
  (``"scene"``, ``"corrected"`` or ``"given"``), ``views`` (names, in order);
- ``correction`` (:func:`correction_section`): method, reference (name and index), ``t_npm``
  (the threshold used, in the mappings' units), ``mappings`` (mode), ``settings`` (``t_npm`` as
  asked, seed, interpolation, graph weight, the method's options), ``unreachable``, ``paths``,
  ``graph_edges`` and their count, the correction's own ``timings_s``; ``correct`` adds the
  per-view ``lookup_tables``;
- ``metrics`` (Table 2), ``texture_settings``, ``selection``, ``atlas``, ``export``,
  ``seams``, ``seams_original_images``, ``selection_seams``, ``visibility_stats``, ``files``
  (kind -> path written);
- ``timings_s``: seconds per stage (one name for every command).

Reports written before this schema (no ``schema`` key: ``correct`` wrote its correction at the
top level and its seconds as ``timings``) are read through :func:`upgrade`, so older folders
still regenerate (``o3d-seqcc report RUN_DIR``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["KEYS", "SCHEMA", "correction_section", "document", "upgrade"]

#: the ``schema`` of every report.json written now
SCHEMA = "o3d_seqcc.report/2"
#: the top-level keys of every report.json, in order
KEYS = ("schema", "command", "scene", "scene_path", "mesh", "scene_options", "images", "views", "correction", "metrics",
        "texture_settings", "selection", "atlas", "export", "seams", "seams_original_images", "selection_seams",
        "visibility_stats", "files", "timings_s")


def _seconds(timings: dict) -> dict[str, float]:
    return {k: round(float(v), 4) for k, v in timings.items()}


def document(command: str, **parts: Any) -> dict[str, Any]:
    """A report.json document: every key of :data:`KEYS` in order (None where ``parts`` has none).

    Raises
    ------
    KeyError
        A part that is not a key of the schema (a programming error, not the user's).
    """
    unknown = sorted(set(parts) - set(KEYS))
    if unknown:
        raise KeyError(f"not keys of {SCHEMA}: {unknown}")
    rep: dict[str, Any] = {k: parts.get(k) for k in KEYS}
    rep["schema"], rep["command"] = SCHEMA, command
    rep["files"] = dict(parts.get("files") or {})
    rep["timings_s"] = _seconds(parts.get("timings_s") or {})
    rep["scene_options"] = dict(parts.get("scene_options") or {})
    return rep


def correction_section(res: Any, names: list[str], mappings_mode: str | None, *, lookup_tables: bool = False) -> dict:
    """The ``correction`` part of a report from a :class:`~o3d_seqcc.correction.CorrectionResult`."""
    out = {
        "method": res.method,
        "reference": names[res.reference],
        "reference_index": int(res.reference),
        "t_npm": res.t_npm,
        "mappings": mappings_mode,
        "settings": res.settings,
        "unreachable": [names[i] for i in res.unreachable],
        "paths": {names[k]: [names[i] for i in p] for k, p in sorted(res.paths.items())},
        "n_graph_edges": len(res.graph_edges),
        "graph_edges": [{**e, "a_name": names[e["a"]], "b_name": names[e["b"]]} for e in res.graph_edges],
        "timings_s": _seconds(res.timings),
    }
    residuals = res.edge_residuals
    if residuals:
        out["edge_residuals"] = [{"a": int(a), "b": int(b), "a_name": names[a], "b_name": names[b], "before": float(r0),
                                  "after": float(r1)} for (a, b), (r0, r1) in sorted(residuals.items())]
        out["out_of_line"] = [names[v] for v in res.out_of_line()]
    if lookup_tables:
        from ..correction.base import IdentityTransform, LutTransform

        if any(isinstance(tr, LutTransform) for tr in res.transforms):
            luts = {names[v]: (np.round(tr.lut, 6).tolist() if isinstance(tr, LutTransform) else "identity")
                    for v, tr in enumerate(res.transforms) if isinstance(tr, (LutTransform, IdentityTransform))}
            out["lookup_tables"] = {"note": "per view: 3 rows (R, G, B) of L values in [0, 1] over L evenly spaced "
                                    "inputs in [0, 1], or 'identity' (reference, unreachable views)", "tables": luts}
    return out


_OLD_CORRECT = ("seed", "method", "reference", "reference_index", "t_npm", "t_npm_effective", "mappings", "graph_edges",
                "paths", "unreachable", "lookup_tables", "graph_weight", "timings")


def upgrade(rep: Any) -> Any:
    """A report.json of an older o3d_seqcc in this schema (the same document when it already is; anything not
    an object is returned as it is, for the validator to refuse)."""
    if not isinstance(rep, dict) or rep.get("schema") == SCHEMA:
        return rep
    rep = dict(rep)
    if rep.get("command") == "correct" or ("correction" not in rep and "method" in rep):
        old = {k: rep.pop(k) for k in _OLD_CORRECT if k in rep}
        if old.get("method") is not None:
            settings = {"t_npm": old.get("t_npm", "auto"), "seed": old.get("seed", 0)}
            if "graph_weight" in old:
                settings["graph_weight"] = old["graph_weight"]
            edges = old.get("graph_edges")
            rep["correction"] = {
                "method": old["method"], "reference": old.get("reference"), "reference_index": old.get("reference_index"),
                "t_npm": old.get("t_npm_effective", old.get("t_npm")), "mappings": old.get("mappings"),
                "settings": settings, "unreachable": old.get("unreachable", []), "paths": old.get("paths", {}),
                **({"n_graph_edges": len(edges), "graph_edges": edges} if isinstance(edges, list) else {}),
                **({"lookup_tables": old["lookup_tables"]} if "lookup_tables" in old else {}),
            }
        rep["timings_s"] = old.get("timings", rep.get("timings_s", {}))
    known = {k: v for k, v in rep.items() if k in KEYS and k not in ("schema", "command")}
    extra = {k: v for k, v in rep.items() if k not in KEYS}
    doc = {**document(str(rep.get("command", "run")), **{k: v for k, v in known.items()
                                                         if k not in ("timings_s", "files", "scene_options")}),
           **extra}
    for k in ("timings_s", "files", "scene_options"):  # as written (the validator checks their types)
        if k in rep:
            doc[k] = rep[k]
    doc["schema"] = rep.get("schema", "o3d_seqcc.report/1")
    return doc
