"""Measurements of ``benchmarks/peers.py``: one tool's textured output against the photos.

Every tool's output file is read by the same loader (``o3d_seqcc.texturing.load_textured_mesh``:
texrecon's multi-material OBJ keeps its pages texel for texel) and measured the same way:

- renders from the photos' cameras (``o3d_seqcc.evaluation.render.render_textured``, 3 x 3 rays per pixel,
  box-filtered), on one **common mask** per view: the pixels where the scene's mesh and every
  tool's mesh are hit (so a tool with holes is not scored on the others' pixels, nor they on its
  background), eroded by 2 pixels;
- ``sharpness``: variance of the Laplacian of the render over the photo's
  (``o3d_seqcc.evaluation.render.sharpness``; 1 = as sharp; it rewards any high frequency, doubled edges
  included);
- ``gsim``: gradient similarity with the photo (``o3d_seqcc.evaluation.render.gradient_similarity``: per
  24-px tile, ``2 <g, h> / (|g|^2 + |h|^2)`` of the render's and the photo's gradient fields at
  the best shift within 3 px, weighted by the photo's gradient energy; 1 = the photo's gradients
  in place; the scan's misregistration within 3 px is forgiven, blur, faint blends, doubled edges,
  edges misplaced by more and noise are not);
- seams: ``o3d_seqcc.evaluation.seams.seam_metric`` mean and share of edges > 5 (CIEDE2000);
- holes: input faces missing from the output and the share of the input's surface area the
  output lacks (texrecon deletes the faces no photo sees; MeshLab and Open3D drop
  non-manifold faces);
- texels: the atlas images' texels (every page, from the MTL's ``map_Kd`` files) and texels per
  photo pixel: per rendered pixel of the measured views, the square root of its face's area in
  texels over its area in that photo's pixels, median over the pixels.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from o3d_seqcc.evaluation.render import gradient_similarity, raycast, render_textured, sharpness
from o3d_seqcc.evaluation.seams import seam_metric
from o3d_seqcc.texturing import TexturedMesh, load_textured_mesh


def load_output(mesh_path: Path, rotation=None) -> TexturedMesh:
    """A tool's output in the scene's frame (ours is exported Y-up: ``p_file = R p_scene``, undone)."""
    tm = load_textured_mesh(mesh_path)
    if rotation is None or np.allclose(rotation, np.eye(3)):
        return tm
    R = np.asarray(rotation, dtype=np.float64)
    return replace(tm, vertices=tm.vertices @ R, normals=None if tm.normals is None else tm.normals @ R)


def _areas(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    p = v[f]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def atlas_texels(mesh_path: Path) -> dict:
    """Texels of the texture images an OBJ's MTL names (every page), or of a GLB's images."""
    from PIL import Image

    mesh_path = Path(mesh_path)
    sizes = []
    if mesh_path.suffix.lower() == ".obj":
        mtls = re.findall(r"^mtllib\s+(.+?)\s*$", mesh_path.read_text(errors="replace"), flags=re.M)
        for m in mtls:
            for name in re.findall(r"^\s*map_Kd\s+(.+?)\s*$", (mesh_path.parent / m).read_text(errors="replace"), flags=re.M):
                with Image.open(mesh_path.parent / name) as im:
                    sizes.append(im.size)
    else:
        tm = load_textured_mesh(mesh_path)
        sizes = [(p.shape[1], p.shape[0]) for p in tm.page_textures()]
    return {"pages": len(sizes), "page_sizes": [f"{w}x{h}" for w, h in sizes],
            "texels": int(sum(w * h for w, h in sizes))}


def holes(tm: TexturedMesh, mesh_in) -> dict:
    """Faces of the input missing from the output, and the input's surface area the output lacks."""
    a_in = float(_areas(mesh_in.vertices, mesh_in.faces).sum())
    a_out = float(_areas(tm.vertices, tm.faces).sum())
    return {"faces_in": int(len(mesh_in.faces)), "faces_out": int(len(tm.faces)),
            "faces_missing": int(max(len(mesh_in.faces) - len(tm.faces), 0)),
            "area_missing": max(0.0, 1.0 - a_out / a_in)}


def texels_per_pixel(tm: TexturedMesh, view, hits) -> np.ndarray:
    """Per pixel hit in ``view``: sqrt(face area in texels / face area in the photo's pixels)."""
    from o3d_seqcc.geometry.camera import project_points

    txy = tm.texel_xy()[tm.faces]
    at = 0.5 * np.abs((txy[:, 1, 0] - txy[:, 0, 0]) * (txy[:, 2, 1] - txy[:, 0, 1])
                      - (txy[:, 2, 0] - txy[:, 0, 0]) * (txy[:, 1, 1] - txy[:, 0, 1]))
    fid = hits.face_ids[hits.mask]
    uniq, inv = np.unique(fid, return_inverse=True)
    uv, _ = project_points(tm.vertices[tm.faces[uniq]].reshape(-1, 3), view.intrinsic, view.extrinsic)
    p = uv.reshape(-1, 3, 2)
    ap = 0.5 * np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    ok = ap > 1e-6
    r = np.full(len(uniq), np.nan)
    r[ok] = np.sqrt(at[uniq][ok] / ap[ok])
    return r[inv]


def measure_tool(tm: TexturedMesh, mesh_in, views, hits: dict, masks: dict, photos: dict, renders: dict) -> dict:
    """The figures of one tool's output (see the module docstring); ``masks`` are the common masks per view."""
    rep = seam_metric(tm)
    out = {"seam_mean": rep.mean, "seam_gt5": rep.frac_above_5, "seam_edges": rep.n_edges, **holes(tm, mesh_in)}
    tpp = []
    out["sharpness"], out["gsim"] = {}, {}
    for k, view in views.items():
        m, ph, img = masks[k], photos[k], renders[k]
        out["sharpness"][k] = sharpness(img, m) / sharpness(ph, m)
        out["gsim"][k] = gradient_similarity(img, ph, m)
        h = hits[k]
        sel = m[h.mask]
        tpp.append(texels_per_pixel(tm, view, h)[sel])
    t = np.concatenate(tpp)
    out["texels_per_pixel"] = float(np.nanmedian(t)) if np.isfinite(t).any() else float("nan")
    return out


def render_views(tm: TexturedMesh, views: dict, supersample: int) -> tuple[dict, dict]:
    """Renders (supersampled) and 1-ray-per-pixel hits of every view."""
    renders, hits = {}, {}
    for k, view in views.items():
        hits[k] = raycast(tm, view)
        renders[k] = render_textured(tm, view, supersample=supersample)
    return renders, hits


def artefact_window(render: np.ndarray, photo: np.ndarray, mask: np.ndarray, size: tuple[int, int],
                    candidates: int = 12) -> tuple[int, int]:
    """Top-left corner of a ``size`` (w, h) window showing a render's artefacts, if it has any.

    Where a render is "sharper than the photo" the extra high frequency is either detail from a
    sharper photo or an artefact (doubled edges at a misregistered seam, aliasing). Of the
    ``candidates`` non-overlapping windows (on the common mask) where the render's Laplacian
    energy most exceeds the photo's, this returns the one least like the photo
    (:func:`o3d_seqcc.evaluation.render.gradient_similarity` of the window): the place to crop to show it.
    """
    import cv2

    def lap2(img):
        g = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY).astype(np.float64) / 255.0
        return cv2.Laplacian(g, cv2.CV_64F, ksize=1) ** 2

    w, h = size
    m = cv2.erode(mask.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(np.float64)
    excess = (lap2(render) - lap2(photo)) * m
    box = cv2.boxFilter(excess, -1, (w, h), normalize=False, anchor=(0, 0), borderType=cv2.BORDER_CONSTANT)
    cover = cv2.boxFilter(m, -1, (w, h), normalize=False, anchor=(0, 0), borderType=cv2.BORDER_CONSTANT)
    H, W = mask.shape
    box[cover < 0.99 * w * h] = -np.inf  # windows on the mesh (every tool covers them)
    box[H - h + 1:, :] = -np.inf
    box[:, W - w + 1:] = -np.inf
    picks = []
    for _ in range(int(candidates)):  # greedy: the best window, then none overlapping it
        y, x = np.unravel_index(int(np.argmax(box)), box.shape)
        if not np.isfinite(box[y, x]):
            break
        picks.append((int(x), int(y)))
        box[max(0, y - h + 1):y + h, max(0, x - w + 1):x + w] = -np.inf
    if not picks:
        return 0, 0

    def sim(x, y):
        sl = (slice(y, y + h), slice(x, x + w))
        try:
            return gradient_similarity(render[sl], photo[sl], mask[sl])
        except Exception:  # a window without gradients in the photo: nothing to show
            return np.inf

    return min(picks, key=lambda p: sim(*p))


def label(img: np.ndarray, text: str, scale: float = 0.5) -> np.ndarray:
    import cv2

    out = np.ascontiguousarray(img.copy())
    (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    cv2.rectangle(out, (0, 0), (min(out.shape[1], tw + 8), th + 8), (0, 0, 0), -1)
    cv2.putText(out, text, (4, th + 3), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def crop_tile(img: np.ndarray, x: int, y: int, w: int, h: int, zoom: int) -> np.ndarray:
    import cv2

    c = img[y:y + h, x:x + w]
    return cv2.resize(c, None, fx=zoom, fy=zoom, interpolation=cv2.INTER_NEAREST)
