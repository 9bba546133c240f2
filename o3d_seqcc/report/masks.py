"""The report's masks section: the share of every photo's pixels its mask leaves out, and what that removed.

Read from ``report.json``'s ``visibility_stats.per_view`` (``masked_share``: the masked pixels
over the photo's pixels; ``masked``: the face-view incidences the mask filter removed,
:mod:`o3d_seqcc.visibility.masks`), so ``o3d-seqcc report RUN_DIR`` draws it from the folder.
"""

from __future__ import annotations

from .html import esc, num

__all__ = ["masks_rows", "masks_section"]


def masks_rows(rep: dict) -> list[dict]:
    """The per-view visibility entries of a report.json that have a mask (empty without masks)."""
    per_view = (rep.get("visibility_stats") or {}).get("per_view") or []
    return [e for e in per_view if isinstance(e, dict) and e.get("masked_share") is not None]


def masks_section(rep: dict) -> str:
    """The section's body: one row per photo with a mask (its masked area, faces masked, faces usable)."""
    rows = masks_rows(rep)
    body = "".join(
        f"<tr><th>{esc(e.get('name', '?'))}</th><td>{num(100.0 * float(e['masked_share']), 1)} %</td>"
        f"<td>{num(e.get('masked'))}</td><td>{num(e.get('usable'))}</td></tr>" for e in rows)
    every = sum(1 for e in rows if float(e["masked_share"]) >= 1.0)
    note = (f" {every} photo{'s' if every != 1 else ''} masked entirely: {'they contribute' if every != 1 else 'it contributes'}"
            " nothing." if every else "")
    return ('<table class="kv"><tr><th>photo</th><th>masked area</th><th>faces masked</th><th>faces usable</th></tr>'
            f"{body}</table><p class=\"note\">The share of each photo's pixels its mask leaves out, and the faces it "
            "then shows only through masked pixels (within 4 px of one: not used from that photo, for the colour "
            f"correction, the view selection or the texture).{note}</p>")
