"""What the correction bought, where a person sees it: one close-up of the textured model three ways.

The same close-up (a photo's camera zoomed onto the part of the model where the selection
changes photo most visibly) is rendered by ray casting

- as the run wrote it (the atlas, after seam leveling),
- with every face showing its selected photo as corrected, and
- with every face showing its selected photo as taken (no correction),

the last two before any atlas or seam leveling, so that they differ only by the correction; and
the selection seams (edges where the texturing photo changes) are drawn on the close-up in the
colour of the step they show in the photos, uncorrected and corrected
(:func:`o3d_seqcc.evaluation.seams.selection_seams`). The seam metric of the finished texture hardly
changes with the correction (seam leveling hides the steps either way); these steps, and the
colours on either side of them, are what it changes.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..evaluation.render import Casters, RayHits, raycast, render_textured, resized_view
from ..scene import View
from ..evaluation.seams import SelectionSeams, photo_colors

__all__ = ["CLOSEUP_WIDTH", "SEAM_SCALE_MAX", "closeup_renders", "closeup_view", "correction_section", "seam_colors",
           "seam_scale_css"]

#: width in pixels of the close-up renders
CLOSEUP_WIDTH = 320
#: CIEDE2000 at the top of the seam colour scale (larger steps take its last colour)
SEAM_SCALE_MAX = 20.0
#: colour scale of seam steps: (CIEDE2000, RGB) stops, linear between them (light and clear to dark red)
_SCALE = ((0.0, (255, 255, 178)), (2.0, (254, 217, 118)), (5.0, (254, 178, 76)), (8.0, (253, 141, 60)),
          (12.0, (240, 59, 32)), (20.0, (150, 0, 38)))


def seam_colors(delta_e: np.ndarray) -> np.ndarray:
    """(n, 3) uint8: the seam colour scale at each CIEDE2000 value (clipped to 0..:data:`SEAM_SCALE_MAX`)."""
    x = np.clip(np.asarray(delta_e, dtype=np.float64), 0.0, SEAM_SCALE_MAX)
    keys = np.array([k for k, _ in _SCALE])
    rgb = np.array([c for _, c in _SCALE], dtype=np.float64)
    return np.stack([np.rint(np.interp(x, keys, rgb[:, c])) for c in range(3)], axis=-1).astype(np.uint8)


def seam_scale_css() -> str:
    """A CSS ``linear-gradient`` of the seam colour scale, left 0, right :data:`SEAM_SCALE_MAX`."""
    stops = ", ".join(f"rgb{c} {100 * k / SEAM_SCALE_MAX:.0f}%" for k, c in _SCALE)
    return f"linear-gradient(to right, {stops})"


def closeup_view(view: View, mesh: tuple, seams: SelectionSeams | None, *, zoom: float = 2.5,
                 width: int = CLOSEUP_WIDTH, casters: Casters | None = None) -> View:
    """The camera of ``view`` zoomed ``zoom`` times onto the window where the visible seams step most.

    Seam midpoints are projected into the view (those hidden behind the mesh left out, by a
    small ray cast) and weighted by their step; the window of 1 / ``zoom`` of the image with the
    largest sum is the close-up (the image centre when no seam is visible). ``casters``: the
    meshes' ray-casting scenes, shared with the report's other renders.
    """
    w_win, h_win = view.width / zoom, view.height / zoom
    cx, cy = (view.width - 1) / 2.0, (view.height - 1) / 2.0
    if seams is not None and len(seams.delta_e):
        small = resized_view(view, min(view.width, 96))
        mid = seams.segments.mean(axis=1)
        R, t = small.rotation, small.translation
        cam = mid @ R.T + t
        z = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = small.intrinsic[0, 0] * cam[:, 0] / z + small.intrinsic[0, 2]
            v = small.intrinsic[1, 1] * cam[:, 1] / z + small.intrinsic[1, 2]
        inside = (z > 0) & (u >= -0.5) & (u < small.width - 0.5) & (v >= -0.5) & (v < small.height - 0.5)
        if inside.any():
            hits = raycast(mesh, small, caster=None if casters is None else casters.get(mesh))
            k = np.flatnonzero(inside)
            r = np.clip(np.floor(v[k] + 0.5).astype(int), 0, small.height - 1)
            c = np.clip(np.floor(u[k] + 0.5).astype(int), 0, small.width - 1)
            seen = z[k] <= hits.depth[r, c] * 1.02 + 1e-9
            if seen.any():
                grid = np.zeros((small.height, small.width))
                np.add.at(grid, (r[seen], c[seen]), seams.delta_e[k[seen]] + 1e-3)
                sx = small.width / view.width
                kw, kh = max(1, int(round(w_win * sx))), max(1, int(round(h_win * sx)))
                box = cv2.boxFilter(grid, -1, (kw, kh), normalize=False, borderType=cv2.BORDER_CONSTANT)
                by, bx = np.unravel_index(int(np.argmax(box)), box.shape)
                cx, cy = (bx + 0.5) / sx - 0.5, (by + 0.5) / sx - 0.5
    cx = float(np.clip(cx, w_win / 2 - 0.5, view.width - w_win / 2 - 0.5))
    cy = float(np.clip(cy, h_win / 2 - 0.5, view.height - h_win / 2 - 0.5))
    left, top = cx - w_win / 2, cy - h_win / 2  # window edges, pixel centres at integers
    width = int(width)
    height = max(1, int(round(width * h_win / w_win)))
    s = width / w_win
    K = np.array(view.intrinsic, dtype=np.float64)
    K[0, :2] *= s
    K[1, 1] *= s
    K[0, 2] = s * (view.intrinsic[0, 2] - left) - 0.5
    K[1, 2] = s * (view.intrinsic[1, 2] - top) - 0.5
    # a camera only: in-memory pixels or depth of the original size do not belong to it (never read)
    return replace(view, intrinsic=K, width=width, height=height, image=view.image or Path(f"{view.name}.png"),
                   pixels=None, depth_map=None, points=None)


def _photo_renders(tm: Any, hits: RayHits, views, base: np.ndarray, *image_sets) -> list[np.ndarray]:
    """``base`` with every pixel of a face seen by a view replaced by that view's colour there, per image set."""
    m = hits.mask
    fid = hits.face_ids[m]
    fv = np.asarray(tm.face_view)[fid]
    seen = fv >= 0
    pts = np.einsum("nk,nkd->nd", hits.bary[m][seen], np.asarray(tm.vertices)[np.asarray(tm.faces)[fid[seen]]])
    cols = photo_colors(views, pts, fv[seen], *image_sets)
    rows, cc = np.nonzero(m)
    out = []
    for col in cols if len(image_sets) > 1 else [cols]:
        img = base.copy()
        img[rows[seen], cc[seen]] = np.clip(np.rint(col * 255), 0, 255).astype(np.uint8)
        out.append(img)
    return out


def _seam_overlay(render: np.ndarray, hits: RayHits, view: View, seams: SelectionSeams, delta_e: np.ndarray,
                  *, thickness: int = 2) -> np.ndarray:
    """The render in light grey with the visible seams drawn in the colour of their step."""
    grey = cv2.cvtColor(render, cv2.COLOR_RGB2GRAY).astype(np.float64)
    base = np.where(hits.mask[..., None], (150 + 0.35 * grey)[..., None], 255.0)
    out = np.ascontiguousarray(np.repeat(np.clip(base, 0, 255).astype(np.uint8), 3, axis=2))
    if len(delta_e) == 0:
        return out
    R, t, K = view.rotation, view.translation, view.intrinsic
    cam = seams.segments.reshape(-1, 3) @ R.T + t
    z = cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.stack([K[0, 0] * cam[:, 0] / z + K[0, 1] * cam[:, 1] / z + K[0, 2],
                       K[1, 1] * cam[:, 1] / z + K[1, 2]], axis=1).reshape(-1, 2, 2)
    zz = z.reshape(-1, 2)
    mid = uv.mean(axis=1)
    ok = (zz > 0).all(axis=1) & np.isfinite(mid).all(axis=1)
    ok &= (mid[:, 0] >= -0.5) & (mid[:, 0] < view.width - 0.5) & (mid[:, 1] >= -0.5) & (mid[:, 1] < view.height - 0.5)
    k = np.flatnonzero(ok)
    r = np.clip(np.floor(mid[k, 1] + 0.5).astype(int), 0, view.height - 1)
    c = np.clip(np.floor(mid[k, 0] + 0.5).astype(int), 0, view.width - 1)
    k = k[zz[k].mean(axis=1) <= hits.depth[r, c] * 1.02 + 1e-9]  # not behind the surface the pixel shows
    colors = seam_colors(delta_e[k])
    for i in np.argsort(delta_e[k], kind="stable"):  # the largest steps on top (one line per visible seam edge)
        p, q = np.rint(uv[k[i]]).astype(int)
        cv2.line(out, (int(p[0]), int(p[1])), (int(q[0]), int(q[1])), tuple(int(x) for x in colors[i]), thickness,
                 cv2.LINE_AA)
    return out


def closeup_renders(tm: Any, view: View, views, photos, corrected, seams_photos: SelectionSeams,
                    seams_corrected: SelectionSeams, *, casters: Casters | None = None) -> dict[str, np.ndarray]:
    """The close-up from ``view`` four ways, (H, W, 3) uint8 each.

    ``result`` (the textured mesh as written), ``corrected`` / ``photos`` (each face its
    selected photo, corrected / as taken, no atlas, no leveling), ``seams_photos`` /
    ``seams_corrected`` (the visible selection seams in the colour of their step, on a grey
    render).
    """
    hits = raycast(tm, view, caster=None if casters is None else casters.get(tm))
    result = render_textured(tm, view, hits=hits)
    c, p = _photo_renders(tm, hits, views, result, corrected, photos)
    out = {"result": result, "corrected": c, "photos": p}
    out["seams_photos"] = _seam_overlay(result, hits, view, seams_photos, seams_photos.delta_e)
    out["seams_corrected"] = _seam_overlay(result, hits, view, seams_corrected, seams_corrected.delta_e)
    return out


def correction_section(tm: Any, view: View, views, photos, corrected, mesh: tuple,
                       seams_photos: SelectionSeams, seams_corrected: SelectionSeams, method: str, *,
                       casters: Casters | None = None) -> str:
    """The report's section "What the correction changes": the close-ups and the seam steps, as HTML."""
    from .figures import jpeg
    from .html import esc, img, num

    cv = closeup_view(view, mesh, seams_photos, casters=casters)
    shots = closeup_renders(tm, cv, views, photos, corrected, seams_photos, seams_corrected, casters=casters)
    a, b = seams_photos.summary(), seams_corrected.summary()
    cells = [("result", "the result: corrected, atlas, seams levelled"),
             ("corrected", f"each face its photo corrected ({esc(method)}), no leveling"),
             ("photos", "each face its photo as taken, no leveling"),
             ("seams_photos", f"seam steps, photos as taken: mean {num(a['mean'])}"),
             ("seams_corrected", f"seam steps, corrected: mean {num(b['mean'])}")]
    figs = "".join(f'<figure>{img(jpeg(shots[k], quality=90), "image/jpeg", k)}<figcaption>{t}</figcaption></figure>'
                   for k, t in cells)
    scale = (f'<div class="scale"><div><span class="bar" style="background:{seam_scale_css()}"></span>'
             f'<div class="ticks"><span>0</span><span>5</span><span>10</span><span>15</span>'
             f'<span>≥ {SEAM_SCALE_MAX:.0f}</span></div></div><span>seam colours: the CIEDE2000 step across each '
             f"edge where the selection changes photo, in the photos as taken and corrected</span></div>")
    rows = "".join(f"<tr><th>{t}</th><td>{num(a[k], d)}</td><td>{num(b[k], d)}</td></tr>" for k, t, d in (
        ("mean", "mean", 2), ("median", "median", 2), ("p90", "90th percentile", 2),
        ("frac_above_5", "share above 5 (clearly visible)", 3)))
    table = (f'<table class="kv"><tr><th>{a["n_edges"]} seam edges</th><th>photos as taken</th><th>corrected</th>'
             f"</tr>{rows}</table>")
    return (f'<figure data-fig="correction" class="closeup"><div class="row">{figs}</div>{scale}<figcaption>The same '
            f"close-up of the textured model (the camera of {esc(view.name)}"
            f", zoomed onto its most visible seams), rendered three ways: as written, and with every face showing its "
            f"selected photo directly (no atlas, no seam leveling), corrected and as taken; below, the edges where the "
            f"selection changes photo, coloured by the CIEDE2000 step the two photos show there. Seam leveling hides "
            f"these steps in the finished texture either way (see the seam metric); the correction removes them "
            f"before it, so the colours on both sides agree instead of being blended.</figcaption></figure>{table}")
