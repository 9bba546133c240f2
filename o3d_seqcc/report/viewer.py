"""The report's 3D viewer: the textured model, inline, in a WebGL viewer that works offline.

The model is embedded as a GLB (:func:`o3d_seqcc.io.export.glb_bytes`: unlit, Y-up, the atlas
reduced to :data:`VIEWER_TEXTURE_SIZE` texels and JPEG-encoded) in base64, beside two more
textures of the same UV layout, made here by looking every texel up in the photo that
textures its face (:func:`viewer_textures`): the corrected photos and the photos as taken, both
before seam leveling, so that switching between them shows exactly what the correction does
to the texture. The per-face selection travels as one uint16 per face and is drawn in the
report's palette. The viewer itself is three.js with its GLTFLoader and OrbitControls,
bundled by esbuild into ``viewer.min.js`` (package data; ``viewer/build.sh`` in the
repository rebuilds it from ``viewer/package-lock.json``) and inlined into the page.

The atlas as written (every page, at full resolution up to :data:`VIEWER_FULL_SIZE` texels on
the stacked image's longest side) travels as one more mode, "full resolution", that the viewer
decodes only when it is chosen: the page opens as fast as before and still shows the sharpness of
the result on demand. A loading notice covers the canvas until the model is drawn (and while a
texture decodes), so a page captured before that shows what it waits for, not an empty box.

Models of more than :data:`VIEWER_MAX_FACES` faces are not embedded (the page would weigh tens
of megabytes); the section then says so and names the files to open instead.
"""

from __future__ import annotations

import base64
import functools
import json
from dataclasses import replace
from importlib import resources
from typing import Any

import cv2
import numpy as np

from ..io.export import glb_bytes
from ..imaging.arrays import img_as_uint8
from ..evaluation.render import selection_palette
from ..scene import View
from ..evaluation.seams import photo_colors
from .figures import jpeg

__all__ = ["VIEWER_FULL_SIZE", "VIEWER_MAX_FACES", "VIEWER_TEXTURE_SIZE", "model_section", "viewer_bundle", "viewer_html", "viewer_model",
           "viewer_textures"]

#: faces of the largest model the report embeds (about 4 MB of GLB per 100k faces)
VIEWER_MAX_FACES = 200_000
#: longest side in texels of the viewer's textures (the atlas is reduced to it)
VIEWER_TEXTURE_SIZE = 1024
#: longest side of the full-resolution mode's texture (the stacked pages; WebGL 2 implementations hold 8192 at least
#: in practice, SwiftShader included): the atlas as written up to it, reduced beyond
VIEWER_FULL_SIZE = 8192
#: colour of faces seen by no view in the selection colours (as in Figure 9)
UNSEEN_RGB = (40, 40, 40)


@functools.lru_cache(maxsize=1)
def viewer_bundle() -> str:
    """The minified viewer (three.js, GLTFLoader, OrbitControls and ours): package data ``viewer.min.js``."""
    return resources.files(__package__).joinpath("viewer.min.js").read_text(encoding="utf-8")


def viewer_model(tm: Any, *, size: int = VIEWER_TEXTURE_SIZE) -> Any:
    """``tm`` with its atlas (pages stacked, as held) reduced to at most ``size`` texels on its longest side.

    One page (the stacked image is the texture; the UVs already address it), so the GLB holds
    one primitive whose faces are ``tm``'s, in order.
    """
    tex = img_as_uint8(np.asarray(tm.texture), where="texture")
    h, w = tex.shape[:2]
    s = min(1.0, size / max(h, w))
    if s < 1.0:
        tex = cv2.resize(tex, (max(1, int(round(w * s))), max(1, int(round(h * s)))), interpolation=cv2.INTER_AREA)
    return replace(tm, texture=np.ascontiguousarray(tex), pages=1)


def viewer_textures(small: Any, views, image_sets: dict[str, Any]) -> dict[str, np.ndarray]:
    """Textures of ``small``'s UV layout looked up in the photos: every texel in its face's own view.

    Parameters
    ----------
    small : TexturedMesh
        The viewer's model (:func:`viewer_model`), with ``face_view``.
    views : sequence of View
    image_sets : dict
        Name -> one image per view (e.g. ``{"corrected": ..., "photos": ...}``).

    Returns
    -------
    dict
        Name -> (h, w, 3) uint8: ``small.texture`` where a texel lies in a face some view sees
        replaced by that view's colour at the texel's surface point (no seam leveling); gutters
        and faces seen by no view keep the atlas's texels.
    """
    from ..texturing.bake import rasterize_faces

    tex = np.asarray(small.texture)
    h, w = tex.shape[:2]
    faces = np.asarray(small.faces)
    idx, face, bary = rasterize_faces(small.texel_xy(), faces, h, w)
    fv = np.asarray(small.face_view)[face]
    keep = fv >= 0
    idx, face, bary, fv = idx[keep], face[keep], bary[keep].astype(np.float64), fv[keep]
    pts = np.einsum("nk,nkd->nd", bary, np.asarray(small.vertices)[faces[face]])
    names = list(image_sets)
    cols = photo_colors(views, pts, fv, *(image_sets[k] for k in names)) if names else []
    out = {}
    for name, col in zip(names, cols if len(names) > 1 else [cols]):
        img = tex.reshape(-1, 3).copy()
        img[idx] = np.clip(np.rint(col * 255), 0, 255).astype(np.uint8)
        out[name] = img.reshape(h, w, 3)
    return out


def _camera(view: View, R: np.ndarray, vertices: np.ndarray) -> dict[str, Any]:
    """The viewer's first camera: ``view``'s position and direction in the Y-up frame, aimed at the model."""
    c = R @ view.center
    d = R @ (view.rotation.T @ np.array([0.0, 0.0, 1.0]))
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    centre = (lo + hi) / 2
    diag = float(np.linalg.norm(hi - lo)) or 1.0
    depth = float(np.dot(centre - c, d))
    depth = depth if depth > 0.05 * diag else 0.5 * diag
    fov = float(np.degrees(2 * np.arctan(view.height / 2 / view.intrinsic[1, 1])))
    far = float(np.linalg.norm(c - centre)) + 2 * diag
    return {"position": c.tolist(), "target": (c + depth * d).tolist(), "fov": round(fov, 3),
            "near": round(far / 5000, 6), "far": round(far, 6)}


def viewer_html(small: Any, view: View, rotation: np.ndarray, n_views: int, modes: list[tuple[str, str, Any]],
                *, note: str = "") -> str:
    """The viewer's HTML: the canvas, the mode buttons, the data and the bundle (one offline block).

    Parameters
    ----------
    small : TexturedMesh
        The model to embed (:func:`viewer_model`), in the scene's frame.
    view : View
        The first camera.
    rotation : (3, 3) float
        The scene's frame to the viewer's Y-up frame (:func:`o3d_seqcc.geometry.orientation.up_axis_transform`).
    n_views : int
        Palette size of the selection colours.
    modes : list of (key, label, texture) or (key, label, texture, lazy)
        The texture modes, first the default; ``texture`` None for the GLB's own (the result);
        ``lazy``: decoded when the mode is first chosen.
    note : str
        HTML shown under the buttons.
    """
    R = np.asarray(rotation, dtype=np.float64)
    glb = glb_bytes(small, unlit=True, texture_format="jpg", quality=85, transform=R)
    fv = np.asarray(small.face_view) if small.face_view is not None else np.full(len(small.faces), -1)
    sel = np.where(fv >= 0, fv + 1, 0).astype("<u2")
    palette = [list(UNSEEN_RGB)] + selection_palette(n_views).astype(int).tolist()
    data = {
        "glb": base64.b64encode(glb).decode("ascii"),
        "modes": [{"key": m[0], "label": m[1], "lazy": bool(m[3]) if len(m) > 3 else False,
                   "texture": None if m[2] is None else
                   "data:image/jpeg;base64," + base64.b64encode(jpeg(m[2], quality=85)).decode("ascii")}
                  for m in modes],
        "selection": base64.b64encode(sel.tobytes()).decode("ascii"),
        "palette": palette,
        "camera": _camera(view, R, np.asarray(small.vertices) @ R.T),
    }
    buttons = "".join(
        f'<label><input type="radio" name="o3d-mode" value="{k}"{" checked" if i == 0 else ""}> {label}</label>'
        for i, (k, label, *_) in enumerate(modes + [("selection", "selection colours (Figure 9)", None)]))
    payload = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    return (f'<div id="o3d-viewer" class="viewer" data-state="loading"><canvas></canvas>'
            f'<div class="viewer-loading" role="status">Loading the 3D model…</div>'
            f'<div class="viewer-modes">{buttons}</div><p class="viewer-note note">{note}</p></div>'
            f'<script type="application/json" id="o3d-viewer-data">{payload}</script>'
            f"<script>{viewer_bundle()}</script>")


def model_section(tm: Any, view: View, scene, photos, corrected, *, method: str | None = None,
                  max_faces: int = VIEWER_MAX_FACES) -> str:
    """The report's section "The textured model": the viewer, or why the model is not embedded.

    ``corrected`` None (the ``texture`` command): the modes are the result and the photos
    before seam leveling; otherwise the result, the corrected photos and the photos as taken.
    """
    from ..errors import InputError
    from ..geometry.orientation import up_axis_transform
    from .html import esc

    n = len(tm.faces)
    if n > max_faces:
        return (f'<p class="callout">The textured model has {n} faces, more than this page embeds ({max_faces}, to '
                f"keep it a few megabytes): open <code>mesh.glb</code> of this folder in any glTF viewer, or "
                f"<code>project.mlp</code> in MeshLab. The renders below show it.</p>")
    try:
        rotation, _ = up_axis_transform(scene, "y")
    except InputError:
        rotation = np.eye(3)
    small = viewer_model(tm)
    have_views = small.face_view is not None and len(small.face_view) == n and photos is not None
    sets = {} if not have_views else ({"photos": photos} if corrected is None else
                                      {"corrected": corrected, "photos": photos})
    tex = viewer_textures(small, scene.views, sets) if sets else {}
    if corrected is None:
        modes = [("result", "the result (seams levelled)", None)]
        if "photos" in tex:
            modes.append(("photos", "photos, before seam leveling", tex["photos"]))
    else:
        modes = [("result", "the result (corrected, seams levelled)", None)]
        if tex:
            modes += [("corrected", f"corrected photos ({esc(method or '')}), before seam leveling", tex["corrected"]),
                      ("photos", "photos as taken (no correction), before seam leveling", tex["photos"])]
    h, w = small.texture.shape[:2]
    full = viewer_model(tm, size=VIEWER_FULL_SIZE).texture
    fh, fw = full.shape[:2]
    th, tw = np.asarray(tm.texture).shape[:2]
    if (fh, fw) != (h, w):
        what = "as written" if (fh, fw) == (th, tw) else f"reduced from {tw}×{th}"
        modes.insert(1, ("full", f"full resolution ({fw}×{fh} texels, {what})", full, True))
    note = (f"Drag to orbit, wheel or pinch to zoom, right-drag to pan. The model's {n} faces as written, with its "
            f"texture reduced to {w}×{h} texels"
            + (f" (<i>full resolution</i> shows the atlas at {fw}×{fh}, decoded when chosen)" if (fh, fw) != (h, w)
               else "") +
            "; the other textures are the same layout filled from each face's "
            "photo directly, so switching between them shows what "
            + ("the seam leveling changes (this command corrects no colours). " if corrected is None else
               "the correction (and the seam leveling) changes. ") +
            f"The first view is the camera of {esc(view.name)}.")
    return viewer_html(small, view, rotation, len(scene.views), modes, note=note)
