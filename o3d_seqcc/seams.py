"""Seam metric of a textured mesh: colour jumps across the edges between faces.

None of the paper's tools measures texture seams, so this module does (issue 5). For every
*interior* edge of a mesh (an edge shared by exactly two faces once vertices are merged by
position, so that an edge between two UV charts counts as interior), both adjacent faces are
sampled just inside the edge -- a fixed distance in texture space, half a texel by default --
each in its **own** texture coordinates, and the colours are compared with CIEDE2000 (sRGB ->
CIE Lab, D65). Edges inside a chart (same texture coordinates on both sides) are continuous by
construction and count 0, so the metric measures seams, not the photo's own texture gradient
(which would reward blurred textures). A seam between two charts textured from differently
exposed photos gives the colour difference of the photos. See :func:`seam_metric`.

Works on any textured OBJ / GLB (ours or another tool's) read by trimesh, and on meshes with
per-vertex colours (colours interpolated at the sample points).
"""

from __future__ import annotations

import logging
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError

__all__ = ["SeamReport", "ColoredMesh", "TexturedMesh", "bilinear", "delta_e_2000", "delta_e_2000_lab", "load_textured_mesh",
           "sample_texture", "seam_metric", "srgb_to_lab"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class SeamReport:
    """Summary of the seam metric.

    Attributes
    ----------
    n_edges : int
        Number of interior edges measured (edges shared by exactly two faces).
    mean : float
        Mean over edges of the per-edge CIEDE2000 (each edge averaged over its samples).
    median : float
        Median per-edge CIEDE2000.
    p99 : float
        99th percentile of the per-edge CIEDE2000.
    frac_above_5 : float
        Fraction of edges whose CIEDE2000 exceeds 5 (a clearly visible seam), in [0, 1].
    n_boundary_edges : int
        Edges with one adjacent face (not measured).
    n_nonmanifold_edges : int
        Edges with more than two adjacent faces (not measured).
    n_seam_edges : int
        Interior edges on a UV seam (different texture coordinates on the two sides); the
        others are inside a chart and count as 0.
    seam_mean : float
        Mean CIEDE2000 over the UV-seam edges only (0 when there is none).
    offset : float
        The sampling distance from the edge, in texels.
    per_edge : (n_edges,) float64 array or None
        Per-edge CIEDE2000 when requested (``keep_per_edge=True``).
    edges : (n_edges, 2) int64 array or None
        The merged-vertex ids of each measured edge (with ``keep_per_edge=True``).
    is_seam : (n_edges,) bool array or None
        Which measured edges are UV seams (with ``keep_per_edge=True``).
    """

    n_edges: int
    mean: float
    median: float
    p99: float
    frac_above_5: float
    n_boundary_edges: int = 0
    n_nonmanifold_edges: int = 0
    n_seam_edges: int = 0
    seam_mean: float = 0.0
    offset: float = 0.5
    per_edge: np.ndarray | None = field(default=None, repr=False)
    edges: np.ndarray | None = field(default=None, repr=False)
    is_seam: np.ndarray | None = field(default=None, repr=False)

    def to_dict(self) -> dict[str, Any]:
        """The scalar fields as a JSON-friendly dict (no per-edge arrays)."""
        d = asdict(self)
        d.pop("per_edge")
        d.pop("edges")
        d.pop("is_seam")
        return d


@dataclass(frozen=True, eq=False)
class ColoredMesh:
    """A triangle mesh with per-corner texture coordinates and one texture image.

    Attributes
    ----------
    vertices : (N, 3) float64
    faces : (F, 3) int64
    uv : (N, 2) float64 or None
        Texture coordinates per vertex, OBJ convention (origin bottom-left, v up), in [0, 1].
    texture : (H, W, 3) uint8 / uint16 or None
        RGB texture image.
    vertex_colors : (N, 3) float64 in [0, 1] or None
        Per-vertex colours (used when there is no texture).
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None = None
    texture: np.ndarray | None = None
    vertex_colors: np.ndarray | None = None

    @property
    def has_texture(self) -> bool:
        return self.uv is not None and self.texture is not None


#: Former name of :class:`ColoredMesh`, kept for callers (``o3d_seqcc.cli.texture``).
TexturedMesh = ColoredMesh


def _image_to_rgb_array(img: Any, where: str) -> np.ndarray:
    arr = np.asarray(img.convert("RGB") if hasattr(img, "convert") else img)
    if arr.ndim == 2:
        arr = np.repeat(arr[..., None], 3, axis=2)
    if arr.ndim != 3 or arr.shape[2] < 3:
        raise InputError(f"{where}: texture image has shape {arr.shape}; expected an RGB image")
    arr = arr[..., :3]
    if arr.dtype not in (np.uint8, np.uint16):
        raise InputError(f"{where}: texture dtype {arr.dtype} unsupported (expected 8- or 16-bit)")
    return np.ascontiguousarray(arr)


def load_textured_mesh(mesh_or_path: Any) -> ColoredMesh:
    """Read a textured (or vertex-coloured) mesh with trimesh.

    Parameters
    ----------
    mesh_or_path : path-like, trimesh.Trimesh, trimesh.Scene or ColoredMesh
        OBJ (+MTL+image), GLB/glTF, PLY, ... A scene is merged into one mesh
        (``force="mesh"``).

    Returns
    -------
    ColoredMesh

    Raises
    ------
    InputError
        Missing file, no faces, neither a texture (with UVs) nor vertex colours.
    """
    if isinstance(mesh_or_path, ColoredMesh):
        return mesh_or_path
    import trimesh

    if isinstance(mesh_or_path, (str, os.PathLike)):
        p = Path(mesh_or_path)
        if not p.is_file():
            raise InputError(f"mesh not found: {p}")
        where = str(p)
        try:
            mesh = trimesh.load(str(p), force="mesh", process=False)
        except Exception as e:  # trimesh raises many types on malformed files
            raise InputError(f"cannot read mesh {p}: {e}") from None
    else:
        mesh, where = mesh_or_path, type(mesh_or_path).__name__
        if isinstance(mesh, trimesh.Scene):
            mesh = mesh.to_mesh() if hasattr(mesh, "to_mesh") else mesh.dump(concatenate=True)
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError(f"{where}: no triangles found; give a triangle mesh with faces")
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    visual = mesh.visual
    uv = tex = vc = None
    if getattr(visual, "kind", None) == "texture" and getattr(visual, "uv", None) is not None:
        uv = np.asarray(visual.uv, dtype=np.float64)
        mat = visual.material
        img = getattr(mat, "baseColorTexture", None)
        if img is None:
            img = getattr(mat, "image", None)
        if img is not None and len(uv) == len(v):
            tex = _image_to_rgb_array(img, where)
            factor = getattr(mat, "baseColorFactor", None)
            if factor is not None and not np.allclose(np.asarray(factor)[:3], 255 if np.max(factor) > 1 else 1):
                logger.warning("%s: baseColorFactor %s ignored by the seam metric", where, list(factor))
        else:
            uv = None
    if tex is None:
        try:
            colors = np.asarray(visual.vertex_colors) if getattr(visual, "kind", None) == "vertex" else None
        except Exception:
            colors = None
        if colors is not None and len(colors) == len(v):
            vc = colors[:, :3].astype(np.float64) / 255.0
    if tex is None and vc is None:
        raise InputError(
            f"{where}: the mesh has neither a texture with UV coordinates nor vertex colours; "
            "the seam metric needs a textured OBJ/GLB (or a PLY with vertex colours)"
        )
    return ColoredMesh(vertices=v, faces=f, uv=uv, texture=tex, vertex_colors=vc)


def sample_texture(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup of texture colours at UV coordinates.

    Parameters
    ----------
    texture : (H, W, 3) uint8 / uint16 / float array
        RGB texture.
    uv : (n, 2) float array
        OBJ / trimesh convention: u right, v up, (0, 0) the bottom-left corner of the image,
        texel centres at ((i + 0.5) / W, 1 - (j + 0.5) / H). Outside [0, 1] clamps to the edge.

    Returns
    -------
    (n, 3) float64
        Colours in [0, 1] (integer textures are divided by their maximum value).
    """
    texture = np.asarray(texture)
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    h, w = texture.shape[:2]
    x = uv[:, 0] * w - 0.5
    y = (1.0 - uv[:, 1]) * h - 0.5
    return bilinear(texture, x, y)


def bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear lookup at pixel coordinates (pixel centres at integers), clamped to the border.

    Parameters
    ----------
    image : (H, W, C) uint8 / uint16 / float array
    x, y : (...) float arrays
        Column and row coordinates.

    Returns
    -------
    (..., C) float64
        Values in [0, 1] for integer images (divided by 255 / 65535), as-is for float images.
    """
    image = np.asarray(image)
    scale = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(image.dtype, 1.0)
    h, w = image.shape[:2]
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, w - 1.0)
    y = np.clip(np.asarray(y, dtype=np.float64), 0.0, h - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), max(w - 2, 0))
    y0 = np.minimum(np.floor(y).astype(np.int64), max(h - 2, 0))
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None]
    img = image if image.ndim == 3 else image[..., None]
    out = (
        img[y0, x0] * ((1 - fx) * (1 - fy))
        + img[y0, x1] * (fx * (1 - fy))
        + img[y1, x0] * ((1 - fx) * fy)
        + img[y1, x1] * (fx * fy)
    )
    return out / scale


# sRGB linear RGB -> XYZ (the standard's rounded matrix, as colour-science), and the D65 white (CIE 1931 2 deg, xy 0.3127, 0.3290)
_SRGB_TO_XYZ = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])  # IEC 61966-2-1
_D65_XYZ = np.array([0.3127 / 0.3290, 1.0, (1.0 - 0.3127 - 0.3290) / 0.3290])


def srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """CIE Lab (D65) of sRGB colours in [0, 1] ((..., 3), clipped), numpy only.

    Same conversion as colour-science's ``XYZ_to_Lab(sRGB_to_XYZ(rgb))`` (to ~1e-6).
    """
    c = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0)
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    xyz = lin @ _SRGB_TO_XYZ.T / _D65_XYZ
    eps, kappa = 216.0 / 24389.0, 24389.0 / 27.0
    f = np.where(xyz > eps, np.cbrt(xyz), (kappa * xyz + 16.0) / 116.0)
    return np.stack([116.0 * f[..., 1] - 16.0, 500.0 * (f[..., 0] - f[..., 1]), 200.0 * (f[..., 1] - f[..., 2])], axis=-1)


def delta_e_2000_lab(lab_a: np.ndarray, lab_b: np.ndarray) -> np.ndarray:
    """CIEDE2000 (kL = kC = kH = 1) between CIE Lab colours ((..., 3) each), vectorised numpy
    (Sharma, Wu and Dalal 2005), equal to colour-science's ``delta_E(method="CIE 2000")``."""
    L1, a1, b1 = np.moveaxis(np.asarray(lab_a, dtype=np.float64), -1, 0)
    L2, a2, b2 = np.moveaxis(np.asarray(lab_b, dtype=np.float64), -1, 0)
    C1, C2 = np.hypot(a1, b1), np.hypot(a2, b2)
    Cm7 = ((C1 + C2) / 2.0) ** 7
    G = 0.5 * (1.0 - np.sqrt(Cm7 / (Cm7 + 25.0**7)))
    a1p, a2p = (1.0 + G) * a1, (1.0 + G) * a2
    C1p, C2p = np.hypot(a1p, b1), np.hypot(a2p, b2)
    h1p = np.degrees(np.arctan2(b1, a1p)) % 360.0
    h2p = np.degrees(np.arctan2(b2, a2p)) % 360.0
    h1p = np.where((b1 == 0) & (a1p == 0), 0.0, h1p)
    h2p = np.where((b2 == 0) & (a2p == 0), 0.0, h2p)
    dLp = L2 - L1
    dCp = C2p - C1p
    dh = h2p - h1p
    dh = np.where(dh > 180.0, dh - 360.0, np.where(dh < -180.0, dh + 360.0, dh))
    zero = (C1p * C2p) == 0
    dh = np.where(zero, 0.0, dh)
    dHp = 2.0 * np.sqrt(C1p * C2p) * np.sin(np.radians(dh) / 2.0)
    Lpm = (L1 + L2) / 2.0
    Cpm = (C1p + C2p) / 2.0
    hs = h1p + h2p
    hpm = np.where(np.abs(h1p - h2p) <= 180.0, hs / 2.0, np.where(hs < 360.0, (hs + 360.0) / 2.0, (hs - 360.0) / 2.0))
    hpm = np.where(zero, hs, hpm)
    T = (1.0 - 0.17 * np.cos(np.radians(hpm - 30.0)) + 0.24 * np.cos(np.radians(2.0 * hpm))
         + 0.32 * np.cos(np.radians(3.0 * hpm + 6.0)) - 0.20 * np.cos(np.radians(4.0 * hpm - 63.0)))
    dtheta = 30.0 * np.exp(-(((hpm - 275.0) / 25.0) ** 2))
    Cpm7 = Cpm**7
    Rc = 2.0 * np.sqrt(Cpm7 / (Cpm7 + 25.0**7))
    Sl = 1.0 + 0.015 * (Lpm - 50.0) ** 2 / np.sqrt(20.0 + (Lpm - 50.0) ** 2)
    Sc = 1.0 + 0.045 * Cpm
    Sh = 1.0 + 0.015 * Cpm * T
    Rt = -np.sin(np.radians(2.0 * dtheta)) * Rc
    return np.sqrt((dLp / Sl) ** 2 + (dCp / Sc) ** 2 + (dHp / Sh) ** 2 + Rt * (dCp / Sc) * (dHp / Sh))


def delta_e_2000(rgb_a: np.ndarray, rgb_b: np.ndarray) -> np.ndarray:
    """CIEDE2000 between sRGB colours in [0, 1] ((..., 3) each), via CIE Lab D65.

    Pure numpy (:func:`srgb_to_lab`, :func:`delta_e_2000_lab`), numerically the same as
    colour-science's ``delta_E(XYZ_to_Lab(sRGB_to_XYZ(.)), ..., method="CIE 2000")`` without
    its import cost (~0.4 s).
    """
    return delta_e_2000_lab(srgb_to_lab(rgb_a), srgb_to_lab(rgb_b))


def _merge_positions(vertices: np.ndarray, tol: float) -> np.ndarray:
    """Id per vertex such that vertices within ``tol`` (on a grid) share an id."""
    q = np.round(vertices / tol).astype(np.int64)
    _, inv = np.unique(q, axis=0, return_inverse=True)
    return inv.reshape(-1)


def _interior_edges(faces_merged: np.ndarray):
    """Face-edge incidences of edges shared by exactly two faces.

    Returns (face_a, corner_a0, corner_a1, face_b, corner_b0, corner_b1, edges, n_boundary,
    n_nonmanifold) where corner_x0 is the local corner (0..2) of face x at the edge's smaller
    merged vertex id and corner_x1 at the larger one.
    """
    F = len(faces_merged)
    c0 = np.tile(np.arange(3), F)
    c1 = (c0 + 1) % 3
    fid = np.repeat(np.arange(F), 3)
    a = faces_merged[fid, c0]
    b = faces_merged[fid, c1]
    ok = a != b  # degenerate (collapsed) edges are not edges
    fid, c0, c1, a, b = fid[ok], c0[ok], c1[ok], a[ok], b[ok]
    swap = a > b
    lo, hi = np.where(swap, b, a), np.where(swap, a, b)
    clo, chi = np.where(swap, c1, c0), np.where(swap, c0, c1)
    key = lo.astype(np.int64) * (int(faces_merged.max()) + 1) + hi
    order = np.argsort(key, kind="stable")
    key_s = key[order]
    uniq, start, counts = np.unique(key_s, return_index=True, return_counts=True)
    two = counts == 2
    i0 = order[start[two]]
    i1 = order[start[two] + 1]
    # two incidences from the same face (degenerate/duplicate) are not a shared edge
    good = fid[i0] != fid[i1]
    i0, i1 = i0[good], i1[good]
    edges = np.stack([lo[i0], hi[i0]], axis=1)
    return (fid[i0], clo[i0], chi[i0], fid[i1], clo[i1], chi[i1], edges, int(np.sum(counts == 1)), int(np.sum(counts > 2)))


def _face_samples(
    uvpts: np.ndarray, corners: np.ndarray, corner_lo: np.ndarray, corner_hi: np.ndarray, t: np.ndarray,
    offset: float, max_weight: float = 1.0 / 3.0,
) -> np.ndarray:
    """Barycentric weights (E, S, 3) of points along an edge, moved ``offset`` units inward.

    ``uvpts`` are the per-vertex coordinates in which distances are measured (texture
    coordinates in texels). A point at parameter ``t`` on the edge (A at the ``corner_lo``
    corner, B at ``corner_hi``) is moved along the inward normal of the edge, in the face's own
    coordinates, by ``offset`` (capped at ``max_weight`` times the face's altitude over the edge
    so that the point stays well inside thin faces): the weight of the opposite corner is
    ``min(offset / altitude, max_weight)`` and the point is P(t) + w (O - F), F the foot of the
    altitude from the opposite corner O.
    """
    E, S = len(corner_lo), len(t)
    opposite = 3 - corner_lo - corner_hi
    rows = np.arange(E)
    A = uvpts[corners[rows, corner_lo]]
    B = uvpts[corners[rows, corner_hi]]
    O = uvpts[corners[rows, opposite]]
    ab = B - A
    L2 = np.einsum("ij,ij->i", ab, ab)
    ao = O - A
    t_o = np.divide(np.einsum("ij,ij->i", ao, ab), L2, out=np.full(E, 0.5), where=L2 > 0)
    cross = np.abs(ab[:, 0] * ao[:, 1] - ab[:, 1] * ao[:, 0]) if uvpts.shape[1] == 2 else np.linalg.norm(np.cross(ab, ao), axis=1)
    L = np.sqrt(L2)
    alt = np.divide(cross, L, out=np.zeros(E), where=L > 0)
    wo = np.where(alt > 0, np.minimum(np.divide(offset, alt, out=np.full(E, np.inf), where=alt > 0), max_weight), 0.0)
    w_lo = (1.0 - t)[None, :] - (wo * (1.0 - t_o))[:, None]
    w_hi = t[None, :] - (wo * t_o)[:, None]
    w_o = np.broadcast_to(wo[:, None], (E, S))
    w = np.stack([w_lo, w_hi, w_o], axis=-1)
    # very obtuse faces: keep the point inside the face
    w = np.clip(w, 0.0, None)
    w /= w.sum(axis=-1, keepdims=True)
    out = np.zeros((E, S, 3))
    r, c = rows[:, None], np.arange(S)[None, :]
    out[r, c, corner_lo[:, None]] = w[..., 0]
    out[r, c, corner_hi[:, None]] = w[..., 1]
    out[r, c, opposite[:, None]] = w[..., 2]
    return out


def _colors_at(tm: ColoredMesh, faces: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Colours (E*S, 3) in [0, 1] at barycentric points (E, S, 3) of faces (E,)."""
    corners = tm.faces[faces]  # (E, 3)
    if tm.has_texture:
        uv = np.einsum("esk,ekd->esd", bary, tm.uv[corners]).reshape(-1, 2)
        return sample_texture(tm.texture, uv)
    return np.einsum("esk,ekd->esd", bary, tm.vertex_colors[corners]).reshape(-1, 3)


def _is_continuous(tm: ColoredMesh, fa, ca0, ca1, fb, cb0, cb1, tol: float) -> np.ndarray:
    """(E,) bool: both faces carry the same texture coordinates (or vertex colours) at both ends."""
    if tm.has_texture:
        h, w = tm.texture.shape[:2]
        attr = tm.uv * np.array([w, h], dtype=np.float64)  # texels
    else:
        attr = tm.vertex_colors * 255.0
    fa_c, fb_c = tm.faces[fa], tm.faces[fb]
    r = np.arange(len(fa))
    d0 = np.abs(attr[fa_c[r, ca0]] - attr[fb_c[r, cb0]]).max(axis=1)
    d1 = np.abs(attr[fa_c[r, ca1]] - attr[fb_c[r, cb1]]).max(axis=1)
    return (d0 <= tol) & (d1 <= tol)


def seam_metric(
    mesh_or_path: Any,
    *,
    offset: float = 0.5,
    samples_per_edge: int = 4,
    merge_tol: float | None = None,
    continuity_tol: float = 0.01,
    keep_per_edge: bool = False,
) -> SeamReport:
    """Seam metric: CIEDE2000 across every interior edge of a textured mesh.

    Definition (tool-agnostic: it only reads positions, texture coordinates and the texture
    image, so it applies to any textured OBJ/GLB). For each edge shared by exactly two faces
    (after merging vertices by position):

    - if both faces carry the **same texture coordinates** at both ends of the edge (within
      ``continuity_tol`` texels), the texture is continuous across it by construction (an edge
      inside a chart): a renderer shows no seam there, and its value is 0 -- the limit of the
      sampling below as the offset goes to 0, where both sides read the same texel;
    - otherwise (a UV seam: the faces lie in different charts, possibly from different images)
      take ``samples_per_edge`` points evenly spaced along the edge (``t = (k + 0.5) / S``),
      move each ``offset`` **texels** inward, perpendicular to the edge in each face's **own**
      texture coordinates (capped at a third of the face's altitude in texels, so thin faces are
      not crossed), look both textures up there (bilinear) and average the CIEDE2000 of the
      pairs (sRGB -> CIE Lab D65).

    "Just inside" is thus a fixed distance in texture space: at half a texel, the bilinear
    lookup reads texels whose centres lie at most half a texel outside the face, so a chart's
    gutter hardly leaks in, and the photo's own gradient across the seam contributes over one
    texel at most. Meshes with per-vertex colours are sampled on the edge itself (an edge
    whose two faces share the colours at both ends scores 0).

    Parameters
    ----------
    mesh_or_path : path-like, trimesh.Trimesh or ColoredMesh
        A textured OBJ/GLB (or a mesh with vertex colours).
    offset : float, default 0.5
        Distance of the samples from the edge, in texels of the texture image (> 0).
    samples_per_edge : int, default 4
        Points per edge (>= 1).
    merge_tol : float, optional
        Vertices closer than this (grid rounding) are the same position. Default: 1e-6 x the
        bounding-box diagonal.
    continuity_tol : float, default 0.01
        Texture coordinates closer than this (in texels; 0-255 units for vertex colours) are
        the same: the edge is inside a chart.
    keep_per_edge : bool, default False
        Keep the per-edge values (``per_edge``, ``edges``, ``is_seam``) in the report.

    Returns
    -------
    SeamReport
        ``mean``, ``median``, ``p99``, ``frac_above_5`` over all interior edges (edges inside a
        chart count as 0); ``n_seam_edges`` and ``seam_mean`` over the UV-seam edges alone.

    Raises
    ------
    InputError
        No texture / vertex colours, a non-positive offset, or no interior edge (e.g. a
        triangle soup whose vertices do not coincide).
    """
    if not float(offset) > 0.0:
        raise InputError(f"offset must be > 0 (texels inward from the edge), got {offset}")
    samples_per_edge = int(samples_per_edge)
    if samples_per_edge < 1:
        raise InputError(f"samples_per_edge must be >= 1, got {samples_per_edge}")
    tm = load_textured_mesh(mesh_or_path)
    diag = float(np.linalg.norm(np.ptp(tm.vertices, axis=0)))
    tol = float(merge_tol) if merge_tol is not None else max(diag * 1e-6, 1e-12)
    merged = _merge_positions(tm.vertices, tol)
    fm = merged[tm.faces]
    fa, ca0, ca1, fb, cb0, cb1, edges, n_bnd, n_nm = _interior_edges(fm)
    if len(fa) == 0:
        raise InputError(
            "the mesh has no interior edge (no edge shared by two faces after merging vertices within "
            f"{tol:g}); is it a triangle soup? pass a larger merge_tol"
        )
    seam = ~_is_continuous(tm, fa, ca0, ca1, fb, cb0, cb1, float(continuity_tol))
    de = np.zeros(len(fa))
    if seam.any():
        t = (np.arange(samples_per_edge) + 0.5) / samples_per_edge
        if tm.has_texture:
            h, w = tm.texture.shape[:2]
            pts, off = tm.uv * np.array([w, h], dtype=np.float64), float(offset)
        else:
            pts, off = tm.vertices, 0.0
        s_ = np.flatnonzero(seam)
        col_a = _colors_at(tm, fa[s_], _face_samples(pts, tm.faces[fa[s_]], ca0[s_], ca1[s_], t, off))
        col_b = _colors_at(tm, fb[s_], _face_samples(pts, tm.faces[fb[s_]], cb0[s_], cb1[s_], t, off))
        de[s_] = delta_e_2000(col_a, col_b).reshape(len(s_), samples_per_edge).mean(axis=1)
    n_seam = int(seam.sum())
    logger.info("seam metric: %d interior edges (%d on UV seams), %d boundary, %d non-manifold",
                len(de), n_seam, n_bnd, n_nm)
    return SeamReport(
        n_edges=int(len(de)),
        mean=float(de.mean()),
        median=float(np.median(de)),
        p99=float(np.percentile(de, 99)),
        frac_above_5=float(np.mean(de > 5.0)),
        n_boundary_edges=n_bnd,
        n_nonmanifold_edges=n_nm,
        n_seam_edges=n_seam,
        seam_mean=float(de[seam].mean()) if n_seam else 0.0,
        offset=float(offset),
        per_edge=de if keep_per_edge else None,
        edges=edges if keep_per_edge else None,
        is_seam=seam if keep_per_edge else None,
    )
