"""The report page: one section per figure of the paper, assembled into one self-contained HTML string.

:class:`~o3d_seqcc.report.inputs.PageInputs` is what a page is drawn from (the ``report.json`` content and the run's data,
in memory or recomputed); :func:`render_page` draws it. Figures come from
:mod:`o3d_seqcc.report.figures`; images are embedded as base64 data URIs, the graph as inline SVG.
"""

from __future__ import annotations

import logging
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..imaging.arrays import img_as_uint8
from .._shared.parallel import carried
from ..evaluation.render import Casters, render_selection, render_textured, resized_view, selection_palette
from ..evaluation.seams import selection_seams_of
from .comparison import correction_section
from .figures import graph_svg, jih_panel, jpeg, png, thumbnail, view_layout
from .parts import JIH_BITS, JIH_MAX_MAPPINGS, edge_jihs, jih_thumbnails, path_edges, view_thumbnails
from .html import esc, img, num
from .style import CSS as _CSS
from .inputs import PageInputs, facts
from .masks import masks_rows, masks_section
from .table2 import table2_section
from .viewer import model_section

__all__ = ["JIH_BITS", "JIH_MAX_MAPPINGS", "MAX_DETAIL_EDGES", "SELECTION_WIDTH", "Page", "build_page",
           "render_page"]

logger = logging.getLogger(__name__)

#: width in pixels of the selection picture drawn when the folder holds no selection.png of the same view (reused as is)
SELECTION_WIDTH = 640
#: rows (edges) of the detailed JIH / CMF figure (about 0.1 s each; a longer path shows its first and last edges)
MAX_DETAIL_EDGES = 3


_esc, _img, _num = esc, img, num


def _selection_seams(inp: PageInputs) -> dict:
    """The colour steps at the selection seams, in the photos and in the corrected images (given or computed)."""
    if inp.selection_seams is not None:
        return inp.selection_seams
    v, f = inp.mesh
    return selection_seams_of(v, f, inp.selection, inp.scene.views, {"photos": inp.photos, "corrected": inp.corrected})


def _name(inp: PageInputs, v: int) -> str:
    return f"#{v} {inp.scene.names[v]}"


def t_npm_text(f: dict) -> str:
    """The graph threshold one way everywhere (HTML): the setting, and the count it means in this run's mappings."""
    name = "t<sub>npm</sub>"
    setting, eff, mode = f.get("t_npm"), f.get("t_npm_effective"), f.get("mappings") or ""
    unit = "px of shared surface" if mode == "surface" else "mappings"
    if eff is None or str(eff) == str(setting):
        return f"{name} = {_esc(setting)} {unit}"
    if mode in ("surface", "vertices"):  # only "auto" differs from its count
        how = "1 % of a photo" if mode == "surface" else "the paper's"
        return f"{name} = {_esc(setting)} ({how}) = {_esc(eff)} {unit}"
    return (f"{name} = {_esc(setting)} (the setting, in vertex mappings) = {_esc(eff)} {_esc(mode)} "
            f"mappings (the threshold this run's counts were held to)")


# -------------------------------------------------------------------------------- graph (Fig 4-5)
def _graph_section(inp: PageInputs, f: dict) -> str:
    c = inp.correction
    ref, names = c.reference, inp.scene.names
    xy = view_layout(np.array([v.center for v in inp.scene.views]))
    n_paths = sum(1 for v in c.paths if v != ref)
    title = f"reference: {names[ref]} (#{ref}); {len(c.graph_edges)} edges, {n_paths} paths"
    fig = graph_svg(xy, c.graph_edges, c.paths, ref, title=title)
    weight = c.settings.get("graph_weight", "paper")
    total = inp.mappings.total if inp.mappings is not None else None
    formula = "w = 1 − n / N" if weight == "paper" else "w = log(N / n)"
    unit = "px of shared surface" if getattr(inp.mappings, "mode", None) == "surface" else "mappings"
    n_txt = f", N = {total} {unit} over all pairs" if total is not None else ""
    unreach = ", ".join(_esc(_name(inp, v)) for v in c.unreachable) or "none"
    cap = (f"Colour-correction graph (paper Figures 4-5). One node per view, numbered by index and placed by its "
           f"camera position (seen from above: the two main axes of the camera centres); the reference "
           f"<b>{_esc(names[ref])}</b> (#{ref}) in red. An edge joins two views sharing at least "
           f"{t_npm_text({**f, 't_npm_effective': c.t_npm})}: its width grows with that count n, its colour is its "
           f"weight {formula}{n_txt}. Black arrows: the Dijkstra path of every view toward the reference. "
           f"Unreachable views (grey): {unreach}.")
    by_pair = {(e["a"], e["b"]): e for e in c.graph_edges}
    rows = "".join(
        f"<tr><td>{_esc(_name(inp, t))}</td><td>{_esc(_name(inp, s))}</td>"
        f"<td>{by_pair[(min(t, s), max(t, s))]['n']}</td><td>{by_pair[(min(t, s), max(t, s))]['weight']:.6f}</td></tr>"
        for t, s in path_edges(c.paths))
    table = (f"<details><summary>{len(path_edges(c.paths))} path edges (target → source)</summary><table>"
             f"<tr><th>target</th><th>source</th><th>mappings n</th><th>weight w</th></tr>{rows}</table></details>")
    return (f'<figure data-fig="4-5">{fig}<figcaption>{cap}'
            f"</figcaption></figure>{table}{_residuals_table(inp)}")


def _residuals_table(inp: PageInputs) -> str:
    """Every graph edge's residual before and after the correction, worst after first, and the photos the
    correction could not bring in line (what ``correction.edge_residuals`` / ``out_of_line`` hold)."""
    from ..correction.base import OUT_OF_LINE_LEVELS, OUT_OF_LINE_RATIO

    c = inp.correction
    if not c.edge_residuals:
        return (f"<p>Method {_esc(c.method)} measures no per-edge residuals (seqcc-global does: how far each pair's "
                f"two photos are apart before and after the correction).</p>")
    items = sorted(c.edge_residuals.items(), key=lambda kv: -kv[1][1])
    rows = "".join(f"<tr class=\"residual\"><td>{_esc(_name(inp, a))}</td><td>{_esc(_name(inp, b))}</td><td>{r0:.2f}</td>"
                   f"<td>{r1:.2f}</td></tr>" for (a, b), (r0, r1) in items)
    bad = c.out_of_line()
    worse = sum(1 for _, (r0, r1) in items if r1 > r0)
    rule = (f"their edges still more than {OUT_OF_LINE_LEVELS:g} levels and more than {OUT_OF_LINE_RATIO:g} times the "
            f"median photo's apart on average")
    verdict = (f"Photos the correction could not bring in line ({rule}): "
               f"<b>{', '.join(_esc(_name(inp, v)) for v in bad)}</b>." if bad else
               f"Every photo was brought in line (none with {rule} after the correction).")
    return (f'<p data-residuals="{len(items)}">{verdict} {worse} of {len(items)} edges are further apart after the '
            f"correction than before.</p><details><summary>{len(items)} graph edges: residual before → after "
            f"(root-mean-square difference of the pair's matched quantiles over its shared surface, in 8-bit levels; "
            f"worst after first)</summary><table><tr><th>view a</th><th>view b</th><th>before</th><th>after</th></tr>"
            f"{rows}</table></details>")


# --------------------------------------------------------------------------- JIH / CMF (Fig 6-7)
def _jih_section(inp: PageInputs, path: list[int] | None, jihs: dict, thumbs: dict) -> str:
    c = inp.correction
    luts = c.edge_luts
    detail = ""
    if path:
        edges = list(zip(path[:-1], path[1:]))
        shown = edges if len(edges) <= MAX_DETAIL_EDGES else edges[:MAX_DETAIL_EDGES - 1] + edges[-1:]
        def panel(t: int, s: int, ch: int) -> bytes:
            inl, out = jihs[(t, s)]
            lut = luts.get((t, s))
            return png(jih_panel(inl[ch], ch, None if lut is None else lut[ch], None if out is None else out[ch]))

        cells = "".join(f'<figure>{_img(panel(t, s, ch), "image/png", f"JIH {t} {s} {ch}")}<figcaption>'
                        f"{'RGB'[ch]}: x #{t}, y #{s}</figcaption></figure>"
                        for t, s in shown for ch in range(3))
        which = "edge by edge" if len(shown) == len(edges) else f"{len(shown)} of its {len(edges)} edges (all below)"
        detail = (f'<figure data-fig="6-7"><div class="grid panels">{cells}</div>'
                  f"<figcaption>The path of {_esc(_name(inp, path[0]))} toward the reference, {which} (rows) and "
                  f"channel by channel (columns): the joint image histogram of the colours at the pair's mappings "
                  f"(x: the target view's value, y: the source view's, 0 to 1; darker = more mappings, log scale; grey: "
                  f"mappings the outlier pass discarded) and the fitted colour mapping function (curve; dotted: identity)."
                  f"</figcaption></figure>")
    cells = "".join(
        f'<figure class="thumb">{_img(thumbs[e], "image/png", f"JIH {e[0]} to {e[1]}")}'
        f"<figcaption>#{e[0]} → #{e[1]}</figcaption></figure>" for e in jihs)
    what = "with its R, G, B CMF curves" if luts else f"(method {_esc(c.method)} fits no per-edge CMF)"
    return (detail + f'<figure data-fig="6-7-grid"><div class="grid jih">{cells}</div><figcaption>Every path edge '
            f"(target → source): the three channels' JIHs overlaid in their colours, {what}.</figcaption></figure>")


# ------------------------------------------------------------------------------ steps (Figure 8)
def _steps_section(inp: PageInputs, path: list[int], thumbs: dict, width: int) -> str:
    from ..correction import LutTransform
    from ..correction.luts import compose_luts

    v, luts, ref = path[0], inp.correction.edge_luts, inp.correction.reference
    top = [f'<figure class="{"ref" if u == ref else ""}">'
           f'{_img(jpeg(thumbnail(inp.photos[u], width)), "image/jpeg", f"view {u}")}'
           f"<figcaption>{_esc(_name(inp, u))}{' (reference)' if u == ref else ' (source)' if u == v else ''}"
           f"</figcaption></figure>" for u in path]
    edges = list(zip(path[:-1], path[1:]))
    bottom = ['<div class="blank"></div>']
    if all(e in luts for e in edges):
        src = img_as_uint8(inp.photos[v])
        n_out = luts[edges[0]].shape[1]
        for k in range(1, len(edges) + 1):
            lut = np.stack([compose_luts([luts[e][c] for e in edges[:k]], n_out=n_out) for c in range(3)])
            img = LutTransform(lut).apply_levels(src)
            t, s = edges[k - 1]
            bottom.append(f'<figure>{_img(jpeg(thumbnail(img, width)), "image/jpeg", f"step {k}")}'
                          f'{_img(thumbs[(t, s)], "image/png", f"CMF {t} to {s}", "cmf")}'
                          f"<figcaption>step {k}: CMF #{t} → #{s}</figcaption></figure>")
        final = inp.correction.transforms[v]
        if isinstance(final, LutTransform) and final.lut.shape == lut.shape and np.allclose(final.lut, lut, atol=1e-9):
            note = ("Second row: the source view after each step (the CMFs composed along the path so far), under the "
                    "view whose colours that step reaches; the last one is its corrected image. The small plot is the "
                    "step's JIH and CMF.")
        else:  # a method that refines the sequential estimate (seqcc-global): its result in one more column
            top.append('<div class="blank"></div>')
            bottom.append(f'<figure>{_img(jpeg(thumbnail(inp.corrected[v], width)), "image/jpeg", "corrected")}'
                          f"<figcaption>after the joint refinement</figcaption></figure>")
            note = ("Second row: the source view after each step of the sequential estimate (the edges' curves composed "
                    "along the path so far), under the view whose colours that step reaches; the small plot is the "
                    f"step's JIH and curve. Last column: its corrected image, after {_esc(inp.correction.method)} "
                    "refined every view's curves jointly over all graph edges from that estimate.")
    else:
        bottom += ['<div class="blank"></div>'] * (len(edges) - 1)
        bottom.append(f'<figure>{_img(jpeg(thumbnail(inp.corrected[v], width)), "image/jpeg", "corrected")}'
                      f"<figcaption>corrected</figcaption></figure>")
        note = f"Method {_esc(inp.correction.method)} keeps no per-edge CMF: second row, the corrected image only."
    cols = f'style="grid-template-columns:repeat({len(top)},minmax(0,{width}px))"'
    return (f'<figure data-fig="8"><div class="grid steps" {cols}>{"".join(top + bottom)}</div><figcaption>'
            f"Sequential pairwise colour correction (paper Figure 8) of {_esc(_name(inp, v))}, "
            f"{len(edges)} step(s) to the reference: first row, the images of its path. {note}</figcaption></figure>")


# ---------------------------------------------------------------------------- before / after (Fig 10)
def _grid_section(inp: PageInputs, small: list, small_after: list | None) -> str:
    c = inp.correction
    cells = []
    for v in range(len(inp.scene.views)):
        ref = c is not None and v == c.reference
        lost = c is not None and v in c.unreachable
        badge = (' <span class="badge">reference</span>' if ref else
                 ' <span class="badge grey">no path</span>' if lost else "")
        imgs = _img(small[v], "image/jpeg", f"view {v} before")
        if small_after is not None:
            imgs += _img(small_after[v], "image/jpeg", f"view {v} after")
        cells.append(f'<figure class="{"ref" if ref else ""}">{imgs}<figcaption>{_esc(_name(inp, v))}{badge}'
                     f"</figcaption></figure>")
    cap = ("All views (paper Figure 10): the photo above, the corrected image below it; the reference is outlined "
           "in red; views without a path to it stay unchanged." if small_after is not None
           else "All views, as textured (no colour correction in this command).")
    return f'<figure data-fig="10"><div class="grid views">{"".join(cells)}</div><figcaption>{cap}</figcaption></figure>'


# -------------------------------------------------------------------- selection and renders (9, 12-13)
def _render_views(inp: PageInputs) -> tuple[int, int]:
    """The view seeing the most faces (or the one selection.png used), and a second one far from it."""
    names = inp.scene.names
    pv = (inp.rep.get("selection") or {}).get("picture_view")
    usable = inp.usable if inp.usable is not None else np.ones(len(names))
    a = names.index(pv) if pv in names else int(np.argmax(usable))
    centers = np.array([v.center for v in inp.scene.views])
    ok = [v for v in range(len(names)) if v != a and usable[v] >= 0.5 * usable.max()]
    b = max(ok, key=lambda v: (float(np.linalg.norm(centers[v] - centers[a])), -v)) if ok else a
    return a, b


def _selection_section(inp: PageInputs, view: int) -> str:
    n = len(inp.scene.views)
    same = (inp.rep.get("selection") or {}).get("picture_view") == inp.scene.names[view]
    given = inp.selection_png() if callable(inp.selection_png) else inp.selection_png
    if given is not None and same:
        picture = _img(given, "image/png", "selection")  # the folder's selection.png: the same picture
    else:
        cam = inp.scene.views[view]
        img = render_selection(inp.mesh, inp.selection, resized_view(cam, SELECTION_WIDTH), n_views=n,
                               caster=inp.casters.get(inp.mesh))
        picture = _img(jpeg(img, quality=90), "image/jpeg", "selection")
    pal = selection_palette(n)
    counts = np.bincount(inp.selection[inp.selection >= 0], minlength=n)
    items = [f'<li><span class="sw" style="background:rgb({pal[v][0]},{pal[v][1]},{pal[v][2]})"></span>'
             f"{_esc(_name(inp, v))}: {counts[v]} faces</li>" for v in np.argsort(-counts, kind="stable") if counts[v]]
    unseen = int((inp.selection < 0).sum())
    items.append(f'<li><span class="sw" style="background:rgb(40,40,40)"></span>seen by no view: {unseen} faces</li>')
    return (f'<figure data-fig="9" class="side">{picture}'
            f'<ul class="legend">{"".join(items)}</ul><figcaption>Per-face image selection (paper Figure 9) seen from '
            f"{_esc(_name(inp, view))}: every face in the colour of the view it is textured from (legend: views by "
            f"number of faces).</figcaption></figure>")


def _renders_section(inp: PageInputs, views: tuple[int, int], width: int) -> str:
    rows = []
    for v in dict.fromkeys(views):
        view = inp.scene.views[v]
        render = render_textured(inp.textured, resized_view(view, min(view.width, width)),
                                 caster=inp.casters.get(inp.textured))
        cells = [("photo", inp.photos[v])]
        if inp.corrected is not None:
            cells.append(("corrected photo", inp.corrected[v]))
        cells.append(("textured mesh, rendered from this camera", render))
        rows.append('<div class="row">' + "".join(
            f'<figure>{_img(jpeg(thumbnail(im, width)), "image/jpeg", f"{what} {v}")}<figcaption>{_esc(_name(inp, v))}: '
            f"{what}</figcaption></figure>" for what, im in cells) + "</div>")
    return (f'<figure data-fig="12-13">{"".join(rows)}<figcaption>The textured mesh rendered by ray casting from two '
            f"cameras (paper Figures 12-13; no lighting, white where the mesh is absent) beside the photos: texture "
            f"seams and colour steps show as edges the photo does not have.</figcaption></figure>")


# ------------------------------------------------------------------------------------- tables
def _flat(d: Any, prefix: str = "") -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    if isinstance(d, dict):
        for k, v in d.items():
            out += _flat(v, f"{prefix}{k}." if not isinstance(v, dict) or v else prefix + str(k))
        return out
    if isinstance(d, list) and (len(d) > 8 or any(isinstance(x, (dict, list)) for x in d)):
        return out
    return [(prefix.rstrip("."), ", ".join(map(str, d)) if isinstance(d, list) else d)]


def _value(v: Any) -> str:
    return _esc(f"{v:.6g}") if isinstance(v, float) else _esc(v)


def _kv_tables(d: dict) -> str:
    """One key / value table per top-level group (nested keys flattened), side by side."""
    loose = {k: v for k, v in d.items() if not isinstance(v, dict)}
    groups = ([("", loose)] if loose else []) + [(k, v) for k, v in d.items() if isinstance(v, dict) and v]
    out = []
    for name, g in groups:
        rows = "".join(f"<tr><th>{_esc(k)}</th><td>{_value(v)}</td></tr>" for k, v in _flat(g))
        head = f'<tr><th colspan="2" class="group">{_esc(name)}</th></tr>' if name else ""
        out.append(f'<table class="kv">{head}{rows}</table>')
    return f'<div class="tables">{"".join(out)}</div>'


def _seams_section(rep: dict, steps: dict | None = None) -> str:
    keys = ("mean", "median", "p99", "frac_above_5", "seam_mean", "n_edges", "n_seam_edges")
    cols = [("textured mesh", rep.get("seams"))]
    if rep.get("seams_original_images"):
        cols.append(("same texturing, uncorrected photos", rep["seams_original_images"]))
    cols = [(n, s) for n, s in cols if s]
    if not cols:
        return "<p>No seam metric (the command ran with --no-seams).</p>"
    head = "".join(f"<th>{_esc(n)}</th>" for n, _ in cols)
    rows = "".join(f"<tr><th>{k}</th>" + "".join(f"<td>{_num(s.get(k), 3)}</td>" for _, s in cols) + "</tr>"
                   for k in keys)
    note = ""
    if steps is not None:
        a, b = (steps[k].summary() for k in ("photos", "corrected"))
        note = (f" Before any atlas and leveling, the {a['n_edges']} edges where the selection changes photo show a "
                f"mean step of {_num(a['mean'])} in the photos as taken and {_num(b['mean'])} in the corrected ones "
                f"(share above 5: {_num(a['frac_above_5'], 3)} → {_num(b['frac_above_5'], 3)}; see What the "
                f"correction changes): the seam leveling removes what is left.")
    return (f'<table class="kv"><tr><th></th>{head}</tr>{rows}</table><p class="note">CIEDE2000 across every interior '
            f"mesh edge between the two faces' texture colours (mean, median, 99th percentile, share above 5; "
            f"seam_mean: over the edges where the texture changes chart).{note}</p>")


def _settings(inp: PageInputs, f: dict) -> dict:
    rep = inp.rep
    where = rep.get("scene") or rep.get("scene_path") or "(a scene in memory)"
    s: dict[str, Any] = {"command": f["command"], "scene": where, "mesh": rep.get("mesh") or "(in memory)",
                         "views": len(inp.scene.views)}
    if (rep.get("scene_options") or {}).get("skipped_images"):  # --skip-missing-images: the photos left out
        s["skipped_images"] = rep["scene_options"]["skipped_images"]
    if f["method"]:
        s["correction"] = {"method": f["method"], "reference": rep["correction"].get("reference"),
                           "t_npm": f["t_npm"], "t_npm_effective": f["t_npm_effective"], "mappings": f["mappings"],
                           **{k: v for k, v in f["settings"].items() if k != "t_npm"}}
    for key in ("texture_settings", "selection", "atlas"):
        if rep.get(key):
            s[key] = {k: v for k, v in rep[key].items() if k not in ("faces_per_view", "leveling", "local_leveling")}
    vis = rep.get("visibility_stats")
    if vis:
        keys = ("valid", "occluded", "depth_inconsistent", "oblique", "masked", "usable")
        s["visibility"] = {k: vis[k] for k in keys if k in vis}
        if "views_without_depth" in vis:  # a filter turned off is named here, not only in a warning
            off = vis["views_without_depth"]
            s["visibility"]["depth_consistency"] = (
                "on for every photo" if not off else
                f"off for {len(off)} of {vis.get('n_views', len(inp.scene.views))} photos (no depth map or point "
                f"cloud): {', '.join(off)}")
    return s


# ------------------------------------------------------------------------------------- page


def _sections(inp: PageInputs, f: dict, width: int, pool) -> list[tuple[str, str, str]]:
    """(id, title, body) of every section the data allow; each timed at DEBUG.

    What the correction did first (Figure 10, Table 2), then how (Figures 4-8), then the texturing
    (Figures 9, 12-13, seams), then timings and settings. The sections are built side by side on
    ``pool``'s threads (numpy, OpenCV and Open3D release the GIL) and joined in this order; only
    this thread waits for a result another part needs.
    """
    c = inp.correction
    out: list = []

    def add(sid: str, title: str, build, *args, **kw) -> None:
        out.append((sid, title, pool.submit(carried(build, f"report section {sid}"), *args, **kw)))

    textured = inp.textured is not None and inp.selection is not None and inp.mesh is not None
    if textured:
        a, b = _render_views(inp)
        add("model", "The textured model", model_section, inp.textured, inp.scene.views[a], inp.scene, inp.photos,
            inp.corrected, method=None if c is None else c.method)
        if c is not None and inp.corrected is not None:
            seams = _selection_seams(inp)
            add("correction", "What the correction changes", correction_section, inp.textured, inp.scene.views[a],
                inp.scene.views, inp.photos, inp.corrected, inp.mesh, seams["photos"], seams["corrected"], c.method,
                casters=inp.casters)
    given = inp.parts if inp.parts is not None and inp.parts.width == width and inp.photos is not None else None
    before, after = given.thumbs if given is not None else pool.submit(
        carried(view_thumbnails, "report thumbnails"), inp.photos, inp.corrected if inp.photos is not None else None,
        width).result() if inp.photos is not None else (None, None)
    if before is not None:
        add("views", "Before / after, all views (Figure 10)" if after else "Views", _grid_section, inp,
            [jpeg(im, quality=80) for im in before], None if after is None else [jpeg(im, quality=80) for im in after])
    if masks_rows(inp.rep):
        add("masks", "Masks: the masked area per photo", masks_section, inp.rep)
    if c is not None:
        add("table2", "Image-based metrics (Table 2)", table2_section, inp, f["metrics"])
    if c is not None and after is not None:
        change = [float(np.abs(x.astype(np.int16) - y).mean()) for x, y in zip(before, after)]
        cands = [v for v, p in sorted(c.paths.items()) if len(p) > 1]
        hops = max((len(c.paths[v]) for v in cands), default=0)
        # Figure 8's path: a longest one, the view its correction changed most
        longest = [v for v in cands if len(c.paths[v]) == hops]
        path = c.paths[max(longest, key=lambda v: (change[v], -v))] if longest else None
        add("graph", "Colour-correction graph and paths (Figures 4-5)", _graph_section, inp, f)
        if inp.mappings is not None and c.paths:
            edges = path_edges(c.paths)
            if inp.parts is not None:
                jihs, thumbs = inp.parts.jihs, inp.parts.jih_thumbs
            else:
                jihs = pool.submit(carried(edge_jihs, "report JIH"), inp.photos, c, inp.mappings, edges).result()
                thumbs = jih_thumbnails(jihs, c.edge_luts)
            add("jih", "Joint image histograms and colour mapping functions (Figures 6-7)", _jih_section, inp, path,
                jihs, thumbs)
            if path:
                add("steps", "Sequential pairwise correction of one path (Figure 8)", _steps_section, inp, path,
                    thumbs, 3 * width // 2)
    if textured:
        add("selection", "Per-face image selection (Figure 9)", _selection_section, inp, a)
        add("renders", "Textured mesh and photos (Figures 12-13)", _renders_section, inp, (a, b), 2 * width)
        add("seams", "Seam metric", _seams_section, inp.rep, inp.selection_seams)
    out.append(("timings", "Timings (s)", None))  # drawn by Page.html, from the report it is given
    out.append(("settings", "Settings", _kv_tables(_settings(inp, f))))
    return [(sid, title, body if body is None or isinstance(body, str) else body.result()) for sid, title, body in out]


def timings_block(rep: dict) -> str:
    """The timings section's body from a report.json dict, between ``<!-- timings -->`` markers (the one part of
    a page that differs between two identical runs; the run's writer fills it in last)."""
    f = facts(rep)
    timings = {"stages": f["timings"], **({"correction": f["correction_timings"]} if f["correction_timings"] else {})}
    return f"<!-- timings -->{_kv_tables(timings)}<!-- /timings -->"


def _cards(inp: PageInputs, f: dict) -> list[tuple[str, str]]:
    c, m = inp.correction, f["metrics"] or {}
    cards = []
    if m.get("before"):
        cards.append(("CIEDE2000 over pairs, before → after",
                      f"{_num(m['before']['ciede2000']['mean'])} → {_num(m['after']['ciede2000']['mean'])}"))
        cards.append(("PSNR dB, before → after",
                      f"{_num(m['before']['psnr']['mean'])} → {_num(m['after']['psnr']['mean'])}"))
        if ((m.get("contrast") or {}).get("after") or {}).get("mean") is not None:
            cards.append(("contrast ratio after", _num(m["contrast"]["after"]["mean"], 3)))
    if c is not None:
        cards.append(("reference", _name(inp, c.reference)))
        cards.append(("views without a path", str(len(c.unreachable))))
    if inp.selection_seams is not None:
        a, b = (inp.selection_seams[k].summary()["mean"] for k in ("photos", "corrected"))
        cards.append(("colour step at the seams in the photos, uncorrected → corrected", f"{_num(a)} → {_num(b)}"))
    if inp.rep.get("seams"):
        cards.append(("seam CIEDE2000 of the texture (after leveling), mean", _num(inp.rep["seams"]["mean"], 3)))
    a = inp.rep.get("atlas") or {}
    if a.get("atlas_size"):
        pages = int(a.get("pages", 1))
        w, h = a.get("page_width") or a["atlas_size"], a.get("page_height") or a["atlas_size"]
        cards.append(("texture atlas" + (f", {pages} pages" if pages > 1 else ""), f"{w} × {h}"))
        mem = a.get("texture_memory")
        if mem:
            cards.append(("GPU texture memory (RGBA8, mipmaps)", f"{mem['gpu_bytes'] / 2**20:.1f} MiB"))
            if len(mem["pages"]) > 1:
                for i, pg in enumerate(mem["pages"]):
                    cards.append((f"atlas page {i + 1}", f"{pg['width']} × {pg['height']}, {100 * pg['coverage']:.0f} % "
                                  f"covered, {pg['gpu_bytes'] / 2**20:.1f} MiB"))
        if a.get("texels_per_pixel") is not None:
            cards.append(("atlas texels per photo pixel", _num(a["texels_per_pixel"])))
        if a.get("coverage") is not None:
            cards.append(("atlas covered by triangles", f"{100 * a['coverage']:.0f} %"))
    return cards


@dataclass(frozen=True)
class Page:
    """A report page with its sections drawn; :meth:`html` writes it with the timings of the report it is given.

    The timings are the one part a run knows last (its export's and its report's seconds): the run's
    writer draws the page while the files are written (:func:`build_page`) and writes it once they are.
    """

    command: str
    sub: str
    cards: str
    sections: tuple  # (id, title, body); the timings section's body is None

    def html(self, rep: dict) -> str:
        """The page as one HTML document, the timings section drawn from ``rep`` (report.json's content)."""
        from .. import __version__

        sections = [(sid, t, timings_block(rep) if sid == "timings" else b) for sid, t, b in self.sections]
        nav = "".join(f'<a href="#{sid}">{_esc(t.split(" (")[0])}</a>' for sid, t, _ in sections)
        body = "".join(f'<section id="{sid}"><h2>{_esc(t)}</h2>{b}</section>' for sid, t, b in sections)
        return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><meta name="viewport" '
                f'content="width=device-width,initial-scale=1"><title>o3d-seqcc report: {_esc(self.command)}</title>'
                f"<style>{_CSS}</style></head><body><main><h1>o3d-seqcc report: {_esc(self.command)}</h1>"
                f'<p class="sub">{self.sub}</p><div class="cards">{self.cards}</div><nav>{nav}</nav>{body}'
                f'<p class="note">Figures and table numbered as in L. Dal\'Col et al., "A Sequential Color Correction '
                f'Approach for Texture Mapping of 3D Meshes", Sensors 2023, 23(2), 607. Written by o3d_seqcc '
                f"{_esc(__version__)}.</p></main></body></html>\n")


def build_page(inp: PageInputs, *, width: int = 160) -> Page:
    """The report page of ``inp`` (sections only for the data present), thumbnails ``width`` pixels wide."""
    from . import cached_images

    f = facts(inp.rep)
    photos, corrected = cached_images(inp.photos, inp.corrected)  # each photo read once (unless given cached)
    inp = replace(inp, photos=photos, corrected=corrected, casters=inp.casters or Casters())
    if inp.textured is not None and inp.selection is not None and inp.mesh is not None and inp.correction is not None \
            and inp.corrected is not None and inp.selection_seams is None:
        inp = replace(inp, selection_seams=_selection_seams(inp))  # the cards and two sections show them
    pool = ThreadPoolExecutor(max_workers=2, thread_name_prefix="o3d_seqcc-report")
    try:
        sections = _sections(inp, f, width, pool)
    finally:  # an error: the sections not started are dropped, the running ones finish
        pool.shutdown(wait=True, cancel_futures=True)
    c = inp.correction
    faces = "" if inp.selection is None else f", {len(inp.selection)} faces"
    where = inp.rep.get("scene") or inp.rep.get("scene_path") or "a scene in memory"
    sub = (f"{_esc(f['command'])} of {_esc(where)}: {len(inp.scene.views)} views{faces}"
           + (f", method {_esc(c.method)}" if c is not None else ""))
    cards = "".join(f'<div class="card"><span>{_esc(k)}</span><b>{_esc(v)}</b></div>' for k, v in _cards(inp, f))
    return Page(command=f["command"], sub=sub, cards=cards, sections=tuple(sections))


def render_page(inp: PageInputs, *, width: int = 160) -> str:
    """The report page of ``inp`` as one HTML document (:func:`build_page`, with ``inp.rep``'s timings)."""
    return build_page(inp, width=width).html(inp.rep)
