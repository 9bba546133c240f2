"""Pictures: ray-cast renders from a scene view, selection colouring, sharpness, gradient similarity, mapping plots.

Paper Figures 2-3 (pairwise mappings, :func:`plot_pair`), 9 (per-face image selection coloured
by image) and 12-13 (textured mesh from chosen viewpoints). Rendering is plain ray casting with Open3D's ``RaycastingScene``: the
first hit of each pixel's ray gives a face and barycentric coordinates, from which the face's
texture coordinates are interpolated and the texture looked up bilinearly. No lighting, no
mip-mapping: a render from a view's own camera is directly comparable with that view's photo.
"""

from __future__ import annotations

import functools
import io
import logging
import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_write_bytes
from ..io.images import write_image
from ..geometry.meshops import local_origin
from ..scene import View
from .sharpness import gradient_similarity, sharpness  # noqa: F401 - public here too
from ..texturing.textured_mesh import load_textured_mesh, sample_texture

__all__ = [
    "Casters",
    "RayCaster",
    "RayHits",
    "gradient_similarity",
    "picture_view",
    "plot_pair",
    "raycast",
    "render_selection",
    "render_textured",
    "resized_view",
    "selection_palette",
    "sharpness",
    "supersampled_view",
    "write_selection_picture",
]

logger = logging.getLogger(__name__)

_INVALID = np.iinfo(np.uint32).max


@dataclass(frozen=True, eq=False)
class RayHits:
    """First hits of a view's pixel rays.

    Attributes
    ----------
    face_ids : (H, W) int64
        Face hit by each pixel's ray, -1 for background.
    bary : (H, W, 3) float64
        Barycentric weights of the hit point w.r.t. the face's three corners (0 for background).
    depth : (H, W) float64
        Camera z of the hit point (metres), ``inf`` for background.
    cos_angle : (H, W) float64
        Cosine between the face normal and the direction to the camera (negative = back face).
    """

    face_ids: np.ndarray
    bary: np.ndarray
    depth: np.ndarray
    cos_angle: np.ndarray

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool: pixels that see the mesh."""
        return self.face_ids >= 0


def _arrays(mesh: Any) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(mesh, tuple) and len(mesh) == 2:
        v, f = mesh
    elif hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        v, f = mesh.vertices, mesh.faces
    else:
        tm = load_textured_mesh(mesh)
        v, f = tm.vertices, tm.faces
    v = np.asarray(v, dtype=np.float64)
    f = np.asarray(f, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise InputError(f"mesh must have (N, 3) vertices and (F, 3) faces, got {v.shape} and {f.shape}")
    return v, f


#: rays cast per chunk by :func:`raycast` (about 150 bytes each while a chunk is in flight)
RAY_CHUNK = 1 << 17


class RayCaster:
    """One mesh's ray-casting scene (Open3D ``RaycastingScene``), built once and cast from any number of views.

    Building the scene (its bounding volume hierarchy) costs about as much as casting a photo's
    rays (0.13 CPU s for 300k faces): a report casts five times on two meshes. The scene is
    committed here, so :meth:`cast` may run on several threads at once. ``mesh``: anything
    :func:`raycast` takes.
    """

    def __init__(self, mesh: Any) -> None:
        import open3d as o3d

        v, f = _arrays(mesh)
        self.origin = local_origin(v)  # ray casting is float32: in a local frame, so far-away scenes stay precise
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(
            o3d.core.Tensor(np.ascontiguousarray(v - self.origin, dtype=np.float32)),
            o3d.core.Tensor(np.ascontiguousarray(f, dtype=np.uint32)),
        )
        probe = np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 1.0]], dtype=np.float32)
        self.scene.cast_rays(o3d.core.Tensor(probe))  # builds the hierarchy now, on this thread

    def rows(self, view: View, *, bary: bool = True, depth: bool = True) -> Iterator[tuple[int, int, dict]]:
        """``(r0, r1, hits)`` for rows r0..r1 of ``view``'s pixels, :data:`RAY_CHUNK` rays at a time.

        ``hits`` holds ``face_ids`` (-1: background) and ``cos_angle``, and ``bary`` / ``depth``
        when asked for: the arrays of :class:`RayHits` for those rows (the same per-pixel
        arithmetic whatever the chunk).
        """
        import open3d as o3d

        K, R, C = view.intrinsic, view.rotation, view.center
        H, W = int(view.height), int(view.width)
        kinv = np.linalg.inv(K).T
        step = max(1, RAY_CHUNK // max(W, 1))
        for r0 in range(0, H, step):
            r1 = min(H, r0 + step)
            xs, ys = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(r0, r1, dtype=np.float64))
            pix = np.stack([xs, ys, np.ones_like(xs)], axis=-1)  # pixel centres at integers
            d_cam = pix @ kinv  # z = 1: t_hit is the camera depth
            d_world = d_cam @ R  # R^T d for each pixel
            rays = np.concatenate([np.broadcast_to(C - self.origin, d_world.shape), d_world], axis=-1).astype(np.float32)
            ans = self.scene.cast_rays(o3d.core.Tensor(rays))
            prim = ans["primitive_ids"].numpy().astype(np.int64)
            hit = prim != _INVALID
            out = {"face_ids": np.where(hit, prim, -1)}
            if bary:
                uvs = ans["primitive_uvs"].numpy().astype(np.float64)
                b = np.empty(uvs.shape[:-1] + (3,))
                b[..., 0], b[..., 1:] = 1.0 - uvs[..., 0] - uvs[..., 1], uvs
                b[~hit] = 0.0
                out["bary"] = b
            if depth:
                d = ans["t_hit"].numpy().astype(np.float64)
                d[~hit] = np.inf
                out["depth"] = d
            normals = ans["primitive_normals"].numpy().astype(np.float64)
            dn = d_world / np.linalg.norm(d_world, axis=-1, keepdims=True)
            c = -np.sum(normals * dn, axis=-1)
            c[~hit] = 0.0
            out["cos_angle"] = c
            yield r0, r1, out

    def cast(self, view: View) -> RayHits:
        """:func:`raycast` of this mesh from ``view``."""
        H, W = int(view.height), int(view.width)
        face_ids, depth, cos = np.empty((H, W), np.int64), np.empty((H, W)), np.empty((H, W))
        bary = np.empty((H, W, 3))
        for r0, r1, h in self.rows(view):
            face_ids[r0:r1], bary[r0:r1], depth[r0:r1], cos[r0:r1] = h["face_ids"], h["bary"], h["depth"], h["cos_angle"]
        return RayHits(face_ids=face_ids, bary=bary, depth=depth, cos_angle=cos)


class Casters:
    """The :class:`RayCaster` of each mesh, built once when first asked for (from any thread), for one job.

    A mesh is a ``(vertices, faces)`` pair (keyed by the two arrays) or an object with
    ``vertices`` and ``faces`` (keyed by itself); the objects are held while the cache lives, so
    a key is never another mesh's.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._items: dict[tuple, tuple[Any, threading.Lock, list]] = {}

    def get(self, mesh: Any) -> RayCaster:
        """``mesh``'s caster (built here on first use; another thread asking meanwhile waits for it)."""
        key = tuple(id(a) for a in mesh) if isinstance(mesh, tuple) else (id(mesh),)
        with self._lock:
            _, lock, box = self._items.setdefault(key, (mesh, threading.Lock(), []))
        with lock:
            if not box:
                box.append(RayCaster(mesh))
            return box[0]


def raycast(mesh: Any, view: View, *, caster: RayCaster | None = None) -> RayHits:
    """Cast one ray through every pixel centre of ``view`` and record the first hit.

    Parameters
    ----------
    mesh : Mesh, TexturedMesh, trimesh.Trimesh, (vertices, faces) or path
        Anything with ``vertices`` (N, 3) and ``faces`` (F, 3).
    view : View
        Camera (intrinsic, world-to-camera extrinsic in OpenCV axes, width x height).
    caster : RayCaster, optional
        ``mesh``'s scene built before (:class:`RayCaster`), reused instead of building it again.

    Returns
    -------
    RayHits
    """
    return (caster if caster is not None else RayCaster(mesh)).cast(view)


def _background(background: Sequence[int]) -> np.ndarray:
    bg = np.asarray(background, dtype=np.float64).reshape(-1)
    if bg.shape != (3,) or np.any(bg < 0) or np.any(bg > 255):
        raise InputError(f"background must be an RGB triple in 0..255, got {background!r}")
    return bg


def render_textured(
    mesh: Any,
    view: View,
    *,
    background: Sequence[int] = (255, 255, 255),
    cull_backfaces: bool = False,
    supersample: int = 1,
    hits: RayHits | None = None,
    caster: RayCaster | None = None,
) -> np.ndarray:
    """Render a textured mesh from a view's camera by ray casting and bilinear texture lookup.

    Bilinear lookup without mip-mapping aliases where the texture is minified (texels smaller
    than pixels); ``supersample`` > 1 renders s x s rays per pixel and averages them (box
    filter), which is what a viewer with mip-mapping / multisampling shows.

    Parameters
    ----------
    mesh : path-like, trimesh.Trimesh or TexturedMesh
        Textured OBJ / GLB (or a mesh with vertex colours).
    view : View
        Camera to render from (its own width x height).
    background : RGB triple, default white
        Colour of pixels that see no face.
    cull_backfaces : bool, default False
        Paint pixels whose first hit is a back face (normal away from the camera) as background
        (paper section 3.8 hides faces facing away in a closed room).
    supersample : int, default 1
        Rays per pixel along each axis (s x s rays, averaged).
    hits : RayHits, optional
        Reuse a previous :func:`raycast` of the same mesh and of ``supersampled_view(view, s)``.
    caster : RayCaster, optional
        The mesh's ray-casting scene, built before (when ``hits`` is not given).

    Returns
    -------
    (H, W, 3) uint8
    """
    tm = load_textured_mesh(mesh)
    bg = _background(background)
    s = int(supersample)
    if s < 1:
        raise InputError(f"supersample must be a positive integer, got {supersample!r}")
    rview = supersampled_view(view, s)
    if hits is None:
        hits = raycast(tm, rview, caster=caster)
    elif hits.face_ids.shape != (rview.height, rview.width):
        raise InputError(f"hits are {hits.face_ids.shape[::-1]} but the render needs {rview.width}x{rview.height}")
    mask = hits.mask & ((hits.cos_angle > 0) if cull_backfaces else True)
    out = np.empty((rview.height, rview.width, 3), dtype=np.float64)
    out[:] = bg / 255.0
    fid = hits.face_ids[mask]
    w = hits.bary[mask]
    corners = tm.faces[fid]
    if tm.has_texture:
        uv = np.einsum("nk,nkd->nd", w, tm.uv[corners])
        out[mask] = sample_texture(tm.texture, uv)
    else:
        out[mask] = np.einsum("nk,nkd->nd", w, tm.vertex_colors[corners])
    if s > 1:
        out = out.reshape(view.height, s, view.width, s, 3).mean(axis=(1, 3))
    return np.clip(np.rint(out * 255.0), 0, 255).astype(np.uint8)


def resized_view(view: View, width: int, height: int | None = None) -> View:
    """The camera of ``view`` with another image size (same field of view, pixel centres at integers).

    With ``sx = width / view.width`` (and ``sy`` likewise; ``height`` defaults to the same
    aspect), pixel ``i`` of the new image is centred on ``(i + 0.5) / sx - 0.5`` of the original,
    so ``fx' = sx fx`` and ``cx' = sx (cx + 0.5) - 0.5``. Used to render smaller than the photo
    (a report's figures) or larger (:func:`supersampled_view`).
    """
    from dataclasses import replace

    width = int(width)
    height = int(round(view.height * width / view.width)) if height is None else int(height)
    if width < 1 or height < 1:
        raise InputError(f"resized_view: size must be positive, got {width}x{height}")
    if (width, height) == (view.width, view.height):
        return view
    sx, sy = width / view.width, height / view.height
    K = np.array(view.intrinsic)
    K[0, :] *= sx
    K[1, :] *= sy
    K[0, 2] = sx * (view.intrinsic[0, 2] + 0.5) - 0.5
    K[1, 2] = sy * (view.intrinsic[1, 2] + 0.5) - 0.5
    K[2] = [0.0, 0.0, 1.0]
    # a camera only: in-memory pixels or depth of the original size do not belong to it (never read)
    return replace(view, intrinsic=K, width=width, height=height, image=view.image or Path(f"{view.name}.png"),
                   pixels=None, depth_map=None, points=None)


def supersampled_view(view: View, s: int) -> View:
    """The camera of ``view`` with s x s pixels per pixel (same field of view, pixel centres at integers).

    Sub-pixel ``i`` of the new image is centred on ``(i + 0.5) / s - 0.5`` of the original, so
    ``fx' = s fx`` and ``cx' = s (cx + 0.5) - 0.5``; averaging s x s blocks gives back the
    original pixel grid (:func:`resized_view`).
    """
    s = int(s)
    return resized_view(view, view.width * s, view.height * s)


#: distinct colours of the selection palette (more views repeat them)
_PALETTE_MAX = 64
#: colours the selection palette keeps clear of: the background, unseen faces (dark grey) and greys
_PALETTE_AVOID = ((255, 255, 255), (40, 40, 40))
#: ``_distinct_palette(64)``, written out: each palette of n colours is its first n (the greedy choice does not
#: depend on n), and computing it takes 0.2 CPU s (``tests/evaluation/test_render.py`` checks the two agree)
_PALETTE = np.array([
    [225, 0, 255], [255, 45, 0], [60, 150, 0], [0, 135, 225], [225, 165, 0], [0, 195, 195], [165, 15, 75], [120, 90, 0],
    [0, 45, 210], [225, 150, 165], [180, 240, 0], [0, 90, 60], [180, 165, 255], [135, 45, 0], [60, 240, 165],
    [120, 105, 165], [255, 165, 120], [255, 0, 135], [165, 165, 105], [135, 210, 255], [0, 135, 150], [150, 0, 150],
    [195, 105, 0], [75, 150, 120], [255, 135, 240], [0, 90, 135], [195, 90, 90], [90, 105, 45], [195, 225, 165],
    [240, 210, 150], [165, 90, 135], [90, 105, 255], [0, 210, 30], [90, 60, 105], [225, 210, 0], [180, 135, 180],
    [255, 195, 240], [15, 165, 210], [150, 135, 0], [135, 45, 255], [255, 120, 105], [195, 0, 30], [0, 120, 45],
    [135, 180, 0], [120, 165, 255], [120, 195, 165], [195, 150, 105], [255, 135, 0], [150, 90, 60], [0, 180, 105],
    [120, 240, 225], [165, 120, 225], [195, 120, 90], [210, 0, 165], [15, 120, 105], [75, 75, 150], [120, 135, 195],
    [135, 45, 45], [120, 135, 75], [195, 60, 0], [0, 225, 255], [240, 75, 195], [75, 75, 0], [255, 90, 120]],
    dtype=np.uint8)


@functools.lru_cache(maxsize=16)
def _distinct_palette(n: int) -> np.ndarray:
    """n colours, each the sRGB grid colour farthest (CIEDE2000) from the background, grey and those chosen before."""
    from ..imaging.arrays import ciede2000, rgb_to_lab

    g = np.linspace(0.0, 1.0, 18)
    rgb = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    lab = rgb_to_lab(rgb)
    # coloured (greys read as shading), neither too dark nor too light (the shading darkens by up to 45 %)
    ok = (lab[:, 0] > 30) & (lab[:, 0] < 88) & (np.hypot(lab[:, 1], lab[:, 2]) > 30)
    rgb, lab = rgb[ok], lab[ok]
    avoid = rgb_to_lab(np.array(_PALETTE_AVOID, dtype=np.float64) / 255.0)
    dist = ciede2000(lab[:, None], avoid[None]).min(axis=1)
    out = np.empty(n, dtype=np.int64)
    for k in range(n):  # O(n x grid) CIEDE2000 evaluations, once per n (cached)
        out[k] = int(np.argmax(dist))
        dist = np.minimum(dist, ciede2000(lab, lab[out[k]][None]))
    return np.clip(np.rint(rgb[out] * 255), 0, 255).astype(np.uint8)


def selection_palette(n: int, *, cmap: str | None = None) -> np.ndarray:
    """(n, 3) uint8 colours, one per image index, as distinct from each other as possible.

    By default a greedy farthest-point choice (CIEDE2000) among coloured sRGB values that stay
    clear of white (the background), of the dark grey of unseen faces and of greys (which read
    as shading): every colour is the one farthest from all before it, so the smallest
    difference between two of them is about 30 for 8 colours, 22 for 16 and 16 for 33; beyond
    64 the colours repeat. With ``cmap``, a matplotlib colormap's
    colours instead (listed maps are cycled, darker on the second cycle).
    """
    n = max(int(n), 0)
    if cmap is None:  # beyond 64 views no palette keeps them apart: the 64 colours repeat
        return np.resize(_PALETTE[:min(n, _PALETTE_MAX)], (n, 3))
    import matplotlib

    cm = matplotlib.colormaps[cmap]
    k = getattr(cm, "N", 20)
    idx = np.arange(n)
    if k <= 32:  # listed (qualitative) map: cycle its entries, alternate darker on the 2nd cycle
        rgb = np.asarray(cm(idx % k))[:, :3] * np.where((idx // k) % 2 == 1, 0.6, 1.0)[:, None]
    else:
        rgb = np.asarray(cm((idx + 0.5) / max(n, 1)))[:, :3]
    return np.clip(np.rint(rgb * 255), 0, 255).astype(np.uint8)


def render_selection(
    mesh: Any,
    faces_view: np.ndarray,
    view: View,
    *,
    n_views: int | None = None,
    background: Sequence[int] = (255, 255, 255),
    unseen_color: Sequence[int] = (40, 40, 40),
    shade: bool = True,
    cmap: str | None = None,
    hits: RayHits | None = None,
    caster: RayCaster | None = None,
) -> np.ndarray:
    """Render the per-face image selection, each face coloured by its selected image (Fig. 9a/d).

    Parameters
    ----------
    mesh : Mesh, TexturedMesh, trimesh.Trimesh, (vertices, faces) or path
    faces_view : (F,) int array
        Selected view index per face, -1 for faces seen by no view.
    view : View
        Camera to render from.
    n_views : int, optional
        Number of images (palette size); default ``faces_view.max() + 1``.
    background, unseen_color : RGB triples
        Colours of empty pixels and of faces with no selected image.
    shade : bool, default True
        Darken faces by the angle to the camera (0.55 + 0.45 |cos|) so geometry stays readable.
    cmap : str, optional
        Matplotlib colormap; default :func:`selection_palette`'s distinct colours.
    hits : RayHits, optional
        Reuse a previous :func:`raycast`.
    caster : RayCaster, optional
        ``mesh``'s ray-casting scene, built before; without ``hits`` the picture is cast and
        coloured :data:`RAY_CHUNK` rays at a time (the whole view's hits are never held).

    Returns
    -------
    (H, W, 3) uint8
    """
    v, f = _arrays(mesh)
    sel = np.asarray(faces_view).reshape(-1)
    if len(sel) != len(f):
        raise InputError(f"faces_view has {len(sel)} entries but the mesh has {len(f)} faces")
    bg = _background(background)
    n = int(n_views) if n_views is not None else int(max(sel.max(initial=-1) + 1, 1))
    pal = np.vstack([selection_palette(n, cmap=cmap).astype(np.float64), _background(unseen_color)])
    out = np.empty((view.height, view.width, 3), dtype=np.uint8)
    if hits is not None:
        _colour_rows(out, hits.face_ids, hits.cos_angle, sel, pal, n, bg, shade)
        return out
    for r0, r1, h in (caster if caster is not None else RayCaster((v, f))).rows(view, bary=False, depth=False):
        _colour_rows(out[r0:r1], h["face_ids"], h["cos_angle"], sel, pal, n, bg, shade)
    return out


def _colour_rows(out: np.ndarray, face_ids: np.ndarray, cos_angle: np.ndarray, sel: np.ndarray, pal: np.ndarray,
                 n: int, bg: np.ndarray, shade: bool) -> None:
    """``out`` (rows, W, 3) uint8: each hit pixel its face's view colour (shaded), the others ``bg`` (rounded and
    clipped per pixel: the background's value once, the hits' from their colours)."""
    m = face_ids >= 0
    out[~m] = np.clip(np.rint(bg), 0, 255).astype(np.uint8)
    s = sel[face_ids[m]]
    col = pal[np.where((s >= 0) & (s < n), s, n)]
    if shade:
        col = col * (0.55 + 0.45 * np.abs(cos_angle[m]))[:, None]
    out[m] = np.clip(np.rint(col), 0, 255).astype(np.uint8)


def _stage_pairs(mappings, a: int, b: int) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(title, uv_a, uv_b) of the vertex mappings of a pair after each filter stage (Figure 3)."""
    vis = mappings.visibility
    titles = {
        "valid": "no filter",
        "+occlusion": "+ z-buffering",
        "+depth": "+ depth consistency",
        "+oblique": "+ camera viewpoint (final)",
    }
    out = []
    faces = vis.mesh.faces
    for key, m in vis.stage_masks().items():
        k = np.flatnonzero(m[a] & m[b])
        tri = faces[k]
        out.append((titles[key], vis.vertex_uv(a, tri.reshape(-1)), vis.vertex_uv(b, tri.reshape(-1))))
    return out


def _position_colors(uv: np.ndarray, width: int, height: int) -> np.ndarray:
    """(n, 3) RGB in [0, 1]: hue from x, value from y (saturated, visible on photos)."""
    from matplotlib.colors import hsv_to_rgb

    h = np.clip(uv[:, 0] / max(width - 1, 1), 0, 1) * 0.85
    v = 1.0 - 0.45 * np.clip(uv[:, 1] / max(height - 1, 1), 0, 1)
    return hsv_to_rgb(np.stack([h, np.ones_like(h), v], axis=1))


def plot_pair(
    scene,
    mappings,
    a: int | str,
    b: int | str,
    path: str | os.PathLike,
    *,
    stages: bool = True,
    max_points: int = 20000,
    marker_size: float | None = None,
    image_alpha: float = 0.5,
    seed: int = 0,
    images: tuple[np.ndarray, np.ndarray] | None = None,
) -> Path:
    """Figure of a pair's mappings like the paper's Figures 2-3, written atomically as PNG.

    Both images side by side with the mappings drawn as points; corresponding points have the
    same colour (a 2-D colour map of the position in view ``a``: the hue changes from left to
    right, the brightness from top to bottom). With ``stages`` and a visibility attached, four rows show the vertex mappings with
    no filter, + z-buffering, + depth consistency and + camera viewpoint (Figure 3 a-h);
    otherwise one row shows the mappings themselves.

    Parameters
    ----------
    scene : Scene
    mappings : Mappings
    a, b : int or str
        View indices or names.
    path : path-like
        Output PNG.
    stages : bool, default True
    max_points : int, default 20000
        Random subset drawn per row (seeded) when a row has more mappings.
    marker_size : float, optional
        Marker area in points^2; default ``4 * max(1, 640 / width)`` (bigger for small images).
    image_alpha : float, default 0.5
        Opacity of the photos (dimmed so that the points stand out).
    seed : int, default 0
    images : pair of arrays, optional
        Images to draw instead of the views' files (e.g. corrected images).

    Returns
    -------
    pathlib.Path
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ia, ib = scene.index(a), scene.index(b)
    if ia == ib:
        raise ValueError("plot_pair needs two different views")
    va, vb = scene.views[ia], scene.views[ib]
    if images is None:
        images = (va.load_image(), vb.load_image())
    imgs = []
    for im in images:
        im = np.asarray(im)
        if im.dtype == np.uint16:
            im = (im / 65535.0).astype(np.float32)
        elif im.dtype != np.uint8:
            im = np.clip(im, 0, 1)
        imgs.append(im)
    if stages and mappings.visibility is not None:
        rows = _stage_pairs(mappings, ia, ib) if ia < ib else [
            (t, ub, ua) for t, ua, ub in _stage_pairs(mappings, ib, ia)
        ]
    else:
        pm = mappings.pair(ia, ib)
        rows = [(f"{mappings.mode} mappings", pm.uv_a, pm.uv_b)]
    rng = np.random.default_rng(seed)
    if marker_size is None:
        marker_size = 4.0 * max(1.0, 640.0 / max(va.width, vb.width))
    aspect = max(va.height / va.width, vb.height / vb.width)
    fig = Figure(figsize=(12, 12 * aspect * len(rows) / 2 + 0.6 * len(rows)), dpi=100)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(rows), 2, squeeze=False)
    for r, (title, ua, ub) in enumerate(rows):
        n = len(ua)
        sel = rng.choice(n, max_points, replace=False) if n > max_points else np.arange(n)
        col = _position_colors(ua[sel], va.width, va.height)
        for c, (ax, img, uv, view) in enumerate(zip(axes[r], imgs, (ua, ub), (va, vb))):
            ax.imshow(img, interpolation="nearest", alpha=image_alpha)
            ax.scatter(uv[sel, 0], uv[sel, 1], s=marker_size, c=col, marker=".", linewidths=0)
            ax.set_xlim(-0.5, view.width - 0.5)
            ax.set_ylim(view.height - 0.5, -0.5)
            ax.set_xticks([])
            ax.set_yticks([])
            letter = "abcdefghijklmnop"[2 * r + c]
            ax.set_title(f"({letter}) {view.name}: {title}, {n} mappings", fontsize=9)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return atomic_write_bytes(path, buf.getvalue())


def write_selection_picture(scene, visibility, labels: np.ndarray, path, view: str | int | None = None, *,
                            caster: RayCaster | None = None) -> tuple[Path, str]:
    """Render the per-face selection coloured by image (paper Figure 9a) from one view to a PNG.

    Parameters
    ----------
    scene : Scene
    visibility : Visibility
    labels : (F,) int
        View per face (-1 = unseen).
    path : path-like
        Output PNG (written atomically).
    view : str or int, optional
        View name or index; default the view in which the most faces are usable.
    caster : RayCaster, optional
        ``visibility.mesh``'s ray-casting scene, built before.

    Returns
    -------
    (pathlib.Path, str)
        The path and the view's name.
    """
    k = picture_view(scene, visibility, view)
    img = render_selection(visibility.mesh, labels, scene.views[k], n_views=len(scene.views), caster=caster)
    write_image(path, img)
    return Path(path), scene.names[k]


def picture_view(scene, visibility, view: str | int | None = None) -> int:
    """The view :func:`write_selection_picture` renders from: ``view``, or the one in which the most faces are usable."""
    return int(np.argmax(visibility.usable_counts())) if view is None else scene.index(view)
