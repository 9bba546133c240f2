"""Figures of the HTML report (:mod:`o3d_seqcc.report`): the paper's Figures 4-8 for one run.

No plotting library: the colour-correction graph is written directly as SVG text (the page
draws it), the joint image histograms and their curves are drawn with numpy and OpenCV (about a
millisecond each, so hundreds of edges stay cheap) and returned as PNG bytes, photos as JPEG
bytes. Nothing is written to disk, and the same input gives the same bytes.
"""

from __future__ import annotations

import logging
from typing import Sequence

import cv2
import numpy as np

from ..imaging.arrays import img_as_uint8
from ..io.images import encode_image

__all__ = [
    "CHANNEL_RGB",
    "GRAPH_WIDTH",
    "graph_svg",
    "jih_panel",
    "jih_thumbnail",
    "jpeg",
    "nice_ticks",
    "png",
    "thumbnail",
    "view_layout",
    "viridis",
]

logger = logging.getLogger(__name__)

#: pixels per inch of the report's figures (font sizes and margins in points are converted with it)
DPI = 90
#: display colour of each channel's JIH and CMF (R, G, B), 0..255
CHANNEL_RGB = ((200, 30, 30), (30, 150, 40), (35, 70, 210))


def png(image: np.ndarray) -> bytes:
    """PNG bytes of an (H, W, 3) image (any dtype :func:`~o3d_seqcc.imaging.arrays.img_as_uint8` takes)."""
    return encode_image(img_as_uint8(image), ".png")


def jpeg(image: np.ndarray, *, quality: int = 85) -> bytes:
    """JPEG bytes of an (H, W, 3) image (8-bit)."""
    return encode_image(img_as_uint8(image), ".jpg", quality=quality)


def thumbnail(image: np.ndarray, width: int) -> np.ndarray:
    """(h, width, 3) uint8: the image shrunk by area averaging to ``width`` pixels (never enlarged)."""
    img = img_as_uint8(image)
    h, w = img.shape[:2]
    if w <= width:
        return img
    height = max(1, int(round(h * width / w)))
    return cv2.resize(img, (int(width), height), interpolation=cv2.INTER_AREA)


def view_layout(centers: np.ndarray) -> np.ndarray:
    """(V, 2) positions of the views for the graph: camera centres seen along their least spread axis.

    The centres are projected on their two main axes (a top view for cameras walking around an
    object at about one height) and scaled to [-1, 1]; when they are (nearly) on a line or a
    point, the views are put on a circle in the order of the main axis instead.
    """
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    n = len(c)
    c = c - c.mean(axis=0) if n else c
    s = np.linalg.svd(c, compute_uv=False) if n >= 2 else np.zeros(2)
    if n < 3 or s[1] < 0.05 * max(s[0], 1e-12):
        order = np.argsort(c[:, np.argmax(c.std(axis=0))] if n else [], kind="stable")
        ang = np.empty(n)
        ang[order] = 2 * np.pi * np.arange(n) / max(n, 1)
        return np.stack([np.cos(ang), np.sin(ang)], axis=1)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    xy = c @ vt[:2].T
    return xy / np.abs(xy).max()


#: viridis (matplotlib's 256 colours) at every 16th entry and the last, linear between them: the edges' colour scale
_VIRIDIS = np.array([[int(h[i:i + 2], 16) for i in (0, 2, 4)] for h in (
    "440154", "48186a", "472d7b", "424086", "3b528b", "33638d", "2c728e", "26828e", "21918c", "1fa088", "28ae80",
    "3fbc73", "5ec962", "84d44b", "addc30", "d8e219", "fde725")], dtype=np.float64)
#: the graph's size in pixels: width, node radius (CSS pixels)
GRAPH_WIDTH, NODE_RADIUS = 684, 8.6


def viridis(x: np.ndarray) -> np.ndarray:
    """(n, 3) uint8 colours of the viridis scale at ``x`` in [0, 1] (clipped)."""
    x = np.clip(np.asarray(x, dtype=np.float64).reshape(-1), 0.0, 1.0)
    keys = np.linspace(0.0, 1.0, len(_VIRIDIS))
    return np.stack([np.rint(np.interp(x, keys, _VIRIDIS[:, c])) for c in range(3)], axis=1).astype(np.uint8)


def nice_ticks(lo: float, hi: float, n: int = 6) -> tuple[np.ndarray, int]:
    """About ``n`` round values (steps of 1, 2, 2.5 or 5 times a power of ten) in [lo, hi], and the decimals they need."""
    if not hi > lo:
        return np.array([lo]), max(0, 6 - int(np.floor(np.log10(abs(lo) or 1.0))))
    raw = (hi - lo) / n
    mag = 10.0 ** np.floor(np.log10(raw))
    mult = next(m for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * mag >= raw * (1 - 1e-9))
    step = mult * mag
    ticks = np.arange(np.ceil(lo / step - 1e-9), np.floor(hi / step + 1e-9) + 1) * step
    return ticks, max(0, int(-np.floor(np.log10(step) + 1e-9)) + (1 if mult == 2.5 else 0))


def _rgb(c: np.ndarray) -> str:
    return "#%02x%02x%02x" % tuple(int(v) for v in c)


def graph_svg(
    xy: np.ndarray,
    edges: Sequence[dict],
    paths: dict[int, list[int]],
    reference: int,
    *,
    title: str = "",
) -> str:
    """The colour-correction graph with its Dijkstra paths (paper Figures 4-5), an inline SVG element.

    Written directly as SVG text (no plotting library: the page draws it; nothing to encode),
    :data:`GRAPH_WIDTH` pixels wide and as high as the layout needs; the same input gives the
    same text.

    Parameters
    ----------
    xy : (V, 2) array
        Node positions (:func:`view_layout`), x to the right, y up.
    edges : list of dict
        ``{"a", "b", "n", "weight"}`` per graph edge (``CorrectionResult.graph_edges``).
    paths : dict[int, list[int]]
        ``view -> [view, ..., reference]``; views absent are unreachable (drawn grey).
    reference : int
    title : str
        Plain text (escaped here).

    Returns
    -------
    str
        ``<svg>...</svg>``: nodes numbered by view index, the reference in red; edges coloured by
        weight (viridis, with its colour bar), their width proportional to the number of
        mappings; path edges as black arrows from each view toward the reference.
    """
    from .html import esc

    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    n_views = len(xy)
    span = np.ptp(xy, axis=0) if n_views else np.ones(2)
    W = GRAPH_WIDTH
    H = int(round(DPI * (6.3 * float(np.clip(span[1] / max(span[0], 1e-9), 0.4, 1.0)) + 0.6)))
    ax_x, ax_w, ax_top = 0.01 * W, 0.85 * W, 0.4 * DPI  # the plot's box: 0.4 in for the title above it
    ax_h = H - 0.01 * H - ax_top
    mid = (xy.min(axis=0) + xy.max(axis=0)) / 2 if n_views else np.zeros(2)
    k = min(ax_w / (max(span[0], 1e-9) * 1.12), ax_h / (max(span[1], 1e-9) * 1.12))  # equal aspect, 6 % margins
    px = np.stack([ax_x + ax_w / 2 + k * (xy[:, 0] - mid[0]), ax_top + ax_h / 2 - k * (xy[:, 1] - mid[1])], axis=1)
    w = np.array([e["weight"] for e in edges], dtype=np.float64)
    cnt = np.array([e["n"] for e in edges], dtype=np.float64)
    lo, hi = (float(w.min()), float(w.max())) if len(w) else (0.0, 1.0)
    out = [f'<svg class="graph" viewBox="0 0 {W} {H}" width="{W}" height="{H}" '
           f'role="img" aria-label="colour-correction graph" font-size="8" text-anchor="middle">'
           f'<text x="{ax_x + ax_w / 2:.1f}" y="{0.25 * DPI:.1f}" font-size="10.6">{esc(title)}</text>']
    if len(edges):
        col = viridis((w - lo) / (hi - lo) if hi > lo else np.zeros(len(w)))
        width = 1.25 * (0.3 + 3.2 * cnt / cnt.max())
        ab = np.array([(e["a"], e["b"]) for e in edges], dtype=np.int64)
        out.append('<g stroke-opacity="0.6" stroke-linecap="round">' + "".join(
            f'<line x1="{p[0]:.1f}" y1="{p[1]:.1f}" x2="{q[0]:.1f}" y2="{q[1]:.1f}" stroke="{_rgb(c)}" '
            f'stroke-width="{s:.2f}"/>' for p, q, c, s in zip(px[ab[:, 0]], px[ab[:, 1]], col, width)) + "</g>")
    nmax = cnt.max() if len(cnt) else 1.0
    by_pair = {(min(e["a"], e["b"]), max(e["a"], e["b"])): e["n"] for e in edges}
    arrows = list(dict.fromkeys((t, s) for v in sorted(paths) for t, s in zip(paths[v][:-1], paths[v][1:])))
    if arrows:  # each from the rim of its view's node to the rim of the next one's
        t_idx, s_idx = np.array(arrows).T
        d = px[s_idx] - px[t_idx]
        length = np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        cut = np.minimum((NODE_RADIUS + 1.0) / length, 0.45)
        start, tip = px[t_idx] + d * cut, px[s_idx] - d * cut
        u = d / length
        head = np.minimum(8.0, 0.6 * np.linalg.norm(tip - start, axis=1))[:, None]  # arrowheads as triangles
        base = tip - u * head
        side = np.stack([-u[:, 1], u[:, 0]], axis=1) * head * 0.45
        lw = np.array([1.0 + 1.2 * by_pair.get((min(t, s), max(t, s)), 0) / nmax for t, s in arrows])
        out.append('<g class="arrows" stroke="#000">' + "".join(
            f'<line x1="{p[0]:.1f}" y1="{p[1]:.1f}" x2="{q[0]:.1f}" y2="{q[1]:.1f}" stroke-width="{s:.2f}"/>'
            for p, q, s in zip(start, base, lw)) + "</g><g>" + "".join(
            f'<path d="M{t[0]:.1f},{t[1]:.1f}L{a[0]:.1f},{a[1]:.1f}L{b[0]:.1f},{b[1]:.1f}z"/>'
            for t, a, b in zip(tip, base + side, base - side)) + "</g>")
    fill = ["#d62728" if v == reference else ("#fff" if v in paths else "#bbb") for v in range(n_views)]
    out.append('<g stroke="#000">' + "".join(f'<circle cx="{p[0]:.1f}" cy="{p[1]:.1f}" r="{NODE_RADIUS}" fill="{f}"/>'
                                             for p, f in zip(px, fill)) + "</g>")
    bold = ' fill="#fff" font-weight="bold"'
    out.append("<g>" + "".join(f'<text x="{p[0]:.1f}" y="{p[1] + 2.8:.1f}"{bold if v == reference else ""}>{v}</text>'
                               for v, p in enumerate(px)) + "</g>")
    # the colour bar of the weights, its ticks and label on the right
    bx, bw, b_top, b_bot = 0.89 * W, 0.022 * W, 0.15 * H, 0.9 * H
    n_band = 64  # the scale as bands (no gradient: the page refers to nothing, not even a fragment)
    band = (b_bot - b_top) / n_band
    out.append('<g shape-rendering="crispEdges">' + "".join(
        f'<rect x="{bx:.1f}" y="{b_bot - (i + 1) * band:.2f}" width="{bw:.1f}" height="{band + 0.3:.2f}" '
        f'fill="{_rgb(c)}"/>' for i, c in enumerate(viridis((np.arange(n_band) + 0.5) / n_band))) + "</g>"
               f'<rect x="{bx:.1f}" y="{b_top:.1f}" width="{bw:.1f}" height="{b_bot - b_top:.1f}" fill="none" '
               f'stroke="#000" stroke-width="0.8"/>')
    ticks, dec = nice_ticks(lo, hi, 8) if len(w) else (np.array([]), 0)
    for t in ticks:
        y = b_bot - (t - lo) / (hi - lo) * (b_bot - b_top) if hi > lo else (b_top + b_bot) / 2
        out.append(f'<line x1="{bx + bw:.1f}" y1="{y:.1f}" x2="{bx + bw + 3:.1f}" y2="{y:.1f}" stroke="#000" '
                   f'stroke-width="0.8"/><text x="{bx + bw + 5:.1f}" y="{y + 2.5:.1f}" font-size="7.5" '
                   f'text-anchor="start">{t:.{dec}f}</text>')
    lx, ly = bx + bw + 46, (b_top + b_bot) / 2
    out.append(f'<text transform="translate({lx:.1f},{ly:.1f}) rotate(-90)" font-size="8.75">edge weight w '
               f"(lower = more mappings)</text></svg>")
    return "".join(out)


def jih_panel(jih: np.ndarray, channel: int, lut: np.ndarray | None = None, outliers: np.ndarray | None = None,
              *, size: int = 200) -> np.ndarray:
    """One channel's joint image histogram with its fitted CMF, framed with ticks: (size + 22, size + 22, 3) uint8.

    Paper Figures 6-7, drawn with numpy and OpenCV (a few milliseconds; matplotlib took 0.1 s a
    panel). Target value to the right, source value up, both 0..1 (ticks at 0, 0.5, 1); cells
    shaded from white to the channel's colour by ``0.3 + 0.7 log(1 + n) / log(1 + max)`` (a
    single mapping shows); mappings the fit discarded light grey; the CMF curve dark; the
    identity dotted.

    Parameters
    ----------
    jih : (B, B) counts
        ``jih[x, y]``: x the target value bin, y the source value bin.
    channel : int
        0, 1, 2 for R, G, B (the colour).
    lut : (L,) float, optional
        The CMF as a lookup table over L evenly spaced inputs in [0, 1].
    outliers : (B, B) counts, optional
    """
    j = np.asarray(jih, dtype=np.float64)
    top = max(float(j.max()), 1.0)
    level = np.where(j > 0, 0.3 + 0.7 * np.log1p(j) / np.log1p(top), 0.0).T[::-1]  # rows: source value, top = 1
    col = np.array(CHANNEL_RGB[channel], dtype=np.float64) / 255.0
    img = 1.0 - level[..., None] * (1.0 - col)
    if outliers is not None:
        o = (np.asarray(outliers) > 0).T[::-1] & (level == 0)
        img[o] = 0.82
    cell = cv2.resize(img_as_uint8(np.clip(img, 0, 1)), (size, size), interpolation=cv2.INTER_NEAREST)
    m = 18  # left / bottom margin for the tick labels, 4 px on the other sides
    out = np.full((size + m + 4, size + m + 4, 3), 255, dtype=np.uint8)
    out[4:4 + size, m:m + size] = cell
    diag = np.arange(0, size, 5)
    out[4 + size - 1 - diag, m + diag] = 140
    if lut is not None:
        lut = np.asarray(lut, dtype=np.float64)
        x = m + np.linspace(0, size - 1, lut.shape[0])
        pts = np.stack([x, 4 + (1.0 - np.clip(lut, 0, 1)) * (size - 1)], axis=1)
        dark = tuple(int(v * 0.6) for v in CHANNEL_RGB[channel])
        cv2.polylines(out, [np.rint(pts * 4).astype(np.int32)], False, dark, 2, cv2.LINE_AA, shift=2)
    cv2.rectangle(out, (m - 1, 3), (m + size, 4 + size), (120, 120, 120), 1)
    font, grey = cv2.FONT_HERSHEY_SIMPLEX, (70, 70, 70)
    for k, t in enumerate(("0", ".5", "1")):
        p = int(round(k * (size - 1) / 2))
        out[4 + size: 4 + size + 3, m + p] = 120
        out[4 + size - 1 - p, m - 3:m] = 120
        cv2.putText(out, t, (m + p - 4 * len(t), size + m + 2), font, 0.33, grey, 1, cv2.LINE_AA)
        cv2.putText(out, t, (max(0, m - 4 - 7 * len(t)), 4 + size - 1 - p + 4), font, 0.33, grey, 1, cv2.LINE_AA)
    return out


def jih_thumbnail(jih: np.ndarray, lut: np.ndarray | None = None, outliers: np.ndarray | None = None,
                  *, size: int = 128) -> np.ndarray:
    """One edge's three JIHs overlaid in their channel colours, with the CMF curves: (size, size, 3) uint8.

    Target value to the right, source value up (as :func:`jih_panel`); mappings the fit
    discarded darken the cells grey; the dotted diagonal is the identity.
    """
    jih = np.asarray(jih, dtype=np.float64)
    img = np.ones(jih.shape[1:] + (3,), dtype=np.float64)
    for c in range(3):
        top = jih[c].max()
        if top <= 0:
            continue
        a = np.where(jih[c] > 0, 0.2 + 0.8 * np.log1p(jih[c]) / np.log1p(top), 0.0).T[::-1]
        col = np.array(CHANNEL_RGB[c]) / 255.0
        img *= 1.0 - 0.85 * a[..., None] * (1.0 - col)
    if outliers is not None:
        o = (np.asarray(outliers).sum(axis=0) > 0).T[::-1]
        img[o] *= 0.7
    out = cv2.resize(img_as_uint8(np.clip(img, 0, 1)), (size, size), interpolation=cv2.INTER_NEAREST)
    diag = np.stack([np.arange(0, size, 4), size - 1 - np.arange(0, size, 4)], axis=1)
    out[diag[:, 1], diag[:, 0]] = 150
    if lut is not None:
        lut = np.asarray(lut, dtype=np.float64)
        x = np.linspace(0, size - 1, lut.shape[1])
        for c in range(3):
            pts = np.stack([x, (1.0 - np.clip(lut[c], 0, 1)) * (size - 1)], axis=1)
            dark = tuple(int(v * 0.75) for v in CHANNEL_RGB[c])
            cv2.polylines(out, [np.rint(pts).astype(np.int32)], False, dark, 1, cv2.LINE_AA)
    out[[0, -1], :] = 160
    out[:, [0, -1]] = 160
    return out
