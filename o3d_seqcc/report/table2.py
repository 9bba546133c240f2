"""The report's Table 2 section: the paper's image-based metrics before and after, and the ``o3d-seqcc correct``
command that gives the same table (its words derived from the run's settings and correct's defaults)."""

from __future__ import annotations

from pathlib import Path

from .html import esc as _esc, num as _num
from .inputs import PageInputs, facts

__all__ = ["correct_command", "table2_section"]


def correct_command(inp: PageInputs) -> str:
    """The ``o3d-seqcc correct`` command line that runs this report's correction (and scores every mapping)."""
    import shlex

    rep, c = inp.rep, inp.correction
    f = facts(rep)
    s = f["settings"]
    scene = rep.get("scene_path") or rep.get("scene") or "SCENE"
    words = ["o3d-seqcc", "correct", scene]
    if rep.get("mesh") and Path(scene).suffix.lower() not in (".json", ".mlp", ".sfm"):
        words += ["--mesh", rep["mesh"]]  # formats without a mesh of their own
    words += ["--reference", inp.scene.names[c.reference], "--method", c.method, "--t-npm", str(f["t_npm"]),
              "--mappings", str(f["mappings"] or "vertices")]
    if s.get("graph_weight", "paper") != "paper":
        words += ["--graph-weight", s["graph_weight"]]
    if int(s.get("seed", 0) or 0):
        words += ["--seed", str(s["seed"])]
    return " ".join(shlex.quote(str(w)) for w in words + ["--out", "OUT"])


def _correct_defaults(inp: PageInputs) -> str:
    """Why the command names this run's settings: correct's own defaults (from CorrectionSettings), and whether
    this run's mappings are them."""
    from ..correction.settings import CorrectionSettings

    d, mode = CorrectionSettings(), facts(inp.rep)["mappings"]
    same = "as this run's" if mode == d.mappings else f"this run used {_esc(mode)} mappings"
    return (f"correct's own defaults, reference {_esc(d.reference)} and {_esc(d.mappings)} mappings ({same}), may pick "
            "another reference and so correct and score differently")


def table2_section(inp: PageInputs, metrics: dict | None) -> str:
    if not metrics or "before" not in metrics:
        return "<p>No metrics in report.json (the command ran with --no-metrics).</p>"
    b, a = metrics["before"], metrics["after"]
    con = metrics.get("contrast", {})

    def cells(m: dict, key: str) -> str:
        return "".join(f'<td data-key="{key}.{metric}.{s}">{_num(m[metric][s])}</td>'
                       for metric in ("psnr", "ciede2000") for s in ("mean", "weighted_mean", "std"))

    def contrast(key: str) -> str:
        d = con.get(key) or {}
        return "".join(f'<td data-key="contrast.{key}.{s}">{_num(d.get(s), 3)}</td>' for s in ("mean", "min"))

    method = _esc(inp.correction.method) if inp.correction is not None else "corrected"
    scored = ""
    if inp.rep.get("command") == "run" and inp.correction is not None:
        cmd = f"<code>{_esc(correct_command(inp))}</code>"
        if b.get("max_per_pair"):
            scored = (f'<p class="callout">To get this table from <code>o3d-seqcc correct</code>, give it this run\'s '
                      f"settings: {cmd} ({_correct_defaults(inp)}). It scores all {b['n_mappings']} mappings; this table, written beside the "
                      f"run, a sample of at most {b['max_per_pair']} evenly spaced ones per pair ({b['n_scored']}; the "
                      f"weighted means still weight every pair by its full count), so its means differ from correct's "
                      f"by the sampling error.</p>")
        else:
            scored = (f'<p class="callout">{cmd} gives this very table: the same correction, scored on all '
                      f"{b['n_mappings']} mappings ({_correct_defaults(inp)}).</p>")
    return (f'{scored}<table class="t2"><tr><th></th><th colspan="3">PSNR dB (higher: more similar)</th>'
            f'<th colspan="3">CIEDE2000 (lower: more similar)</th><th colspan="2">contrast ratio (~1)</th></tr>'
            f"<tr><th></th>{'<th>mean</th><th>w. mean</th><th>std</th>' * 2}<th>mean</th><th>min</th></tr>"
            f"<tr><td>before (photos)</td>{cells(b, 'before')}{contrast('before')}</tr>"
            f"<tr><td>after ({method})</td>{cells(a, 'after')}{contrast('after')}</tr></table>"
            f"<p class=\"note\">Paper Table 2 over the {b['n_pairs']} view pairs with mappings ({b['n_mappings']} "
            f"mappings): mean, mean weighted by each pair's number of mappings, standard deviation over pairs. "
            f"Contrast ratio: std of the target view's colours over the source view's at the mappings of every pair at "
            f"different path depths, averaged over channels (below 1: the correction washes images out, which the "
            f"pairwise scores reward at misregistered mappings).</p>")
