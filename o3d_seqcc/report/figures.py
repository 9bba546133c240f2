"""Figures of the HTML report (:mod:`o3d_seqcc.report`): the paper's Figures 4-8 for one run.

Plots are drawn with matplotlib's object API on an Agg canvas (no pyplot, no global state) and
returned as PNG bytes; photos as JPEG bytes; the joint-image-histogram thumbnails of every path
edge are drawn with numpy and OpenCV (about a millisecond each, so hundreds of edges stay
cheap). Nothing is written to disk, and the same input gives the same bytes.
"""

from __future__ import annotations

import io
import logging
from typing import Sequence

import cv2
import numpy as np

from ..imaging.arrays import img_as_uint8
from ..io.files import encode_image

__all__ = [
    "CHANNEL_RGB",
    "figure_png",
    "graph_figure",
    "jih_panel",
    "jih_thumbnail",
    "jpeg",
    "png",
    "thumbnail",
    "view_layout",
    "warm_up",
]

logger = logging.getLogger(__name__)

#: resolution of the report's plots (dots per inch)
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


def figure_png(fig) -> bytes:
    """PNG bytes of a matplotlib Figure (Agg canvas; no software-version metadata, so deterministic)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=fig.dpi, metadata={"Software": None})
    return buf.getvalue()


def warm_up() -> None:
    """Import matplotlib's Figure and Agg canvas now (about 0.3 s, mostly docstring processing).

    :meth:`o3d_seqcc.pipeline.RunResult.save` calls it in a thread while the mesh files are
    encoded and written, so the report does not wait for it.
    """
    import matplotlib.backends.backend_agg  # noqa: F401
    import matplotlib.figure  # noqa: F401


def _figure(width_in: float, height_in: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=DPI)
    FigureCanvasAgg(fig)
    return fig


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


def graph_figure(
    xy: np.ndarray,
    edges: Sequence[dict],
    paths: dict[int, list[int]],
    reference: int,
    *,
    title: str = "",
) -> bytes:
    """The colour-correction graph with its Dijkstra paths (paper Figures 4-5), PNG bytes.

    Parameters
    ----------
    xy : (V, 2) array
        Node positions (:func:`view_layout`).
    edges : list of dict
        ``{"a", "b", "n", "weight"}`` per graph edge (``CorrectionResult.graph_edges``).
    paths : dict[int, list[int]]
        ``view -> [view, ..., reference]``; views absent are unreachable (drawn grey).
    reference : int
    title : str

    Returns
    -------
    bytes
        Nodes numbered by view index, the reference in red; edges coloured by weight (colour
        bar), their width proportional to the number of mappings; path edges as black arrows
        from each view toward the reference.
    """
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.collections import LineCollection
    from matplotlib.colors import Normalize

    xy = np.asarray(xy, dtype=np.float64)
    n_views = len(xy)
    span = np.ptp(xy, axis=0) if n_views else np.ones(2)
    height = 6.3 * float(np.clip(span[1] / max(span[0], 1e-9), 0.4, 1.0)) + 0.6
    fig = _figure(7.6, height)
    ax = fig.add_axes((0.01, 0.01, 0.85, 1 - 0.4 / height))
    cax = fig.add_axes((0.89, 0.1, 0.022, 0.75))
    w = np.array([e["weight"] for e in edges], dtype=np.float64)
    cnt = np.array([e["n"] for e in edges], dtype=np.float64)
    lo, hi = (float(w.min()), float(w.max())) if len(w) else (0.0, 1.0)
    norm = Normalize(lo, hi if hi > lo else lo + 1e-9)
    cmap = colormaps["viridis"]
    if len(edges):
        segs = [[xy[e["a"]], xy[e["b"]]] for e in edges]
        ax.add_collection(LineCollection(segs, colors=cmap(norm(w)), linewidths=0.3 + 3.2 * cnt / cnt.max(),
                                         alpha=0.6, zorder=1))
    cb = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=cax)
    cb.set_label("edge weight w (lower = more mappings)", fontsize=7)
    cb.ax.tick_params(labelsize=6)
    nmax = cnt.max() if len(cnt) else 1.0
    by_pair = {(min(e["a"], e["b"]), max(e["a"], e["b"])): e["n"] for e in edges}
    arrows = list(dict.fromkeys((t, s) for v in sorted(paths) for t, s in zip(paths[v][:-1], paths[v][1:])))
    if arrows:
        # one quiver for all path edges, each shortened by a node radius at both ends (data units)
        ax_w, ax_h = 7.6 * 0.85, height - 0.4
        per_inch = 1.12 * max(span[0] / ax_w, span[1] / ax_h, 1e-9)
        r = 0.115 * per_inch
        t_idx, s_idx = np.array(arrows).T
        d = xy[s_idx] - xy[t_idx]
        length = np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        cut = np.minimum(r / length, 0.45)
        start, vec = xy[t_idx] + d * cut, d * (1 - 2 * cut)
        lw = np.array([0.8 + 1.6 * by_pair.get((min(t, s), max(t, s)), 0) / nmax for t, s in arrows])
        ax.quiver(start[:, 0], start[:, 1], vec[:, 0], vec[:, 1], angles="xy", scale_units="xy", scale=1.0,
                  width=0.0028, headwidth=4.5, headlength=5.5, headaxislength=5.0, color="black", zorder=3,
                  linewidths=lw * 0.3, edgecolors="black")
    face = ["#d62728" if v == reference else ("white" if v in paths else "#bbbbbb") for v in range(n_views)]
    ax.scatter(xy[:, 0], xy[:, 1], s=190, c=face, edgecolors="black", linewidths=0.8, zorder=4)
    for v in range(n_views):
        ax.text(xy[v, 0], xy[v, 1], str(v), ha="center", va="center", fontsize=6.5, zorder=5,
                color="white" if v == reference else "black", fontweight="bold" if v == reference else "normal")
    ax.set_title(title, fontsize=8.5)
    ax.set_aspect("equal")
    ax.margins(0.06)
    ax.autoscale_view()
    ax.axis("off")
    return figure_png(fig)


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
