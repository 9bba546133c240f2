"""The one textured-mesh type of the package (trimesh's ``TextureVisuals`` idea).

UV convention (the OBJ / trimesh / Open3D one): ``uv`` in [0, 1], origin at the **bottom-left**
corner of the texture, u to the right, v up. The centre of texel (column X, row Y, row 0 at the
top of the image) of a W x H texture is at ``((X + 0.5) / W, 1 - (Y + 0.5) / H)``;
:meth:`TexturedMesh.texel_xy` converts back to texel coordinates. glTF puts the origin at the
top-left: :mod:`o3d_seqcc.io.export` writes ``(u, 1 - v)`` there.

A :class:`TexturedMesh` holds either a texture atlas with per-vertex UVs (vertices duplicated
along UV seams), or per-vertex colours. An atlas of several pages is held as one image
with the pages stacked vertically (``pages`` > 1; UVs refer to that image, so every reader of
``texture`` and ``uv`` works unchanged); :meth:`TexturedMesh.page_textures` and
:meth:`TexturedMesh.page_uv` give the pages and the page-local UVs the exporters write. It converts to Open3D (:meth:`TexturedMesh.to_open3d`,
an ``o3d.t.geometry.TriangleMesh`` with the albedo in its material) and trimesh
(:meth:`TexturedMesh.to_trimesh`), and :func:`load_textured_mesh` reads any textured OBJ / GLB /
PLY (ours or another tool's) with trimesh.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..imaging.arrays import dtype_scale, sample_bilinear
from ..geometry.meshops import float32_offset

__all__ = ["TexturedMesh", "load_textured_mesh", "sample_texture"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class TexturedMesh:
    """A triangle mesh with a texture atlas (or per-vertex colours).

    Attributes
    ----------
    vertices : (M, 3) float64
        World coordinates; duplicated along UV seams.
    faces : (F, 3) int64
        Indices into ``vertices``.
    uv : (M, 2) float64 or None
        Texture coordinates in [0, 1], origin bottom-left, v up (see the module docstring).
    texture : (H, W, 3) uint8 / uint16 or None
        RGB texture atlas, row 0 at the top.
    normals : (M, 3) float64 or None
        Unit vertex normals.
    vertex_colors : (M, 3) float64 in [0, 1] or None
        Per-vertex colours (meshes without a texture).
    face_view : (F,) int64 or None
        View that textures each face, -1 = fallback colour (seen by no view).
    vertex_index : (M,) int64 or None
        Index of each vertex in the input mesh.
    face_chart : (F,) int64 or None
        Chart of each face (the faces of a chart share one parametrisation).
    pages : int
        Atlas pages stacked vertically in ``texture`` (each ``texture.shape[1]`` square).
    stats : dict
        Baking statistics (:func:`~o3d_seqcc.texturing.bake_texture`).
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None = None
    texture: np.ndarray | None = None
    normals: np.ndarray | None = None
    vertex_colors: np.ndarray | None = None
    face_view: np.ndarray | None = None
    vertex_index: np.ndarray | None = None
    face_chart: np.ndarray | None = None
    pages: int = 1
    stats: dict = field(default_factory=dict)

    @property
    def has_texture(self) -> bool:
        return self.uv is not None and self.texture is not None

    @property
    def atlas_size(self) -> int:
        """The larger side of a page in texels (what an ``atlas_size`` budget bounds)."""
        return max(self.page_shape)

    @property
    def page_shape(self) -> tuple[int, int]:
        """``(height, width)`` of every page in texels (pages are stacked vertically in ``texture``)."""
        if self.texture is None:
            raise InputError("this mesh has no texture")
        return int(self.texture.shape[0]) // max(int(self.pages), 1), int(self.texture.shape[1])

    def page_textures(self) -> list[np.ndarray]:
        """The atlas pages, each (H, W, 3) (views into ``texture``; :attr:`page_shape`)."""
        if self.texture is None:
            raise InputError("this mesh has no texture")
        h = self.texture.shape[0] // max(int(self.pages), 1)
        return [self.texture[p * h:(p + 1) * h] for p in range(max(int(self.pages), 1))]

    def face_page(self) -> np.ndarray:
        """(F,) int64: the page of every face (0 for a single page)."""
        if self.pages <= 1 or not self.has_texture:
            return np.zeros(len(self.faces), dtype=np.int64)
        y = (1.0 - self.uv[self.faces].mean(axis=1)[:, 1]) * self.pages
        return np.clip(np.floor(y).astype(np.int64), 0, self.pages - 1)

    def page_uv(self) -> np.ndarray:
        """(M, 2) float64: UVs in each vertex's own page (OBJ convention); equal to ``uv`` for one page.

        A vertex belongs to the page of its faces (a chart never spans pages).
        """
        if self.pages <= 1:
            return np.asarray(self.uv, dtype=np.float64)
        vp = np.zeros(len(self.uv), dtype=np.int64)
        vp[self.faces.reshape(-1)] = np.repeat(self.face_page(), 3)
        v = 1.0 - ((1.0 - self.uv[:, 1]) * self.pages - vp)
        return np.stack([self.uv[:, 0], v], axis=1)

    def texel_xy(self) -> np.ndarray:
        """(M, 2) float64 texel coordinates of the UVs: x right, y down, texel centres at integers."""
        if not self.has_texture:
            raise InputError("this mesh has no texture coordinates")
        h, w = self.texture.shape[:2]
        return np.stack([self.uv[:, 0] * w - 0.5, (1.0 - self.uv[:, 1]) * h - 0.5], axis=1)

    def to_open3d(self):
        """This mesh as ``open3d.t.geometry.TriangleMesh``.

        Vertex positions and normals, ``triangle.indices``, ``triangle.texture_uvs`` (F, 3, 2)
        float32 in the OBJ convention Open3D uses, and the texture as the ``albedo`` map of a
        ``defaultLit`` material, so ``o3d.visualization.draw`` shows it textured and
        ``o3d.t.io.write_triangle_mesh`` writes it. A vertex-coloured mesh gets ``vertex.colors``.
        Positions are float64 where float32 would not hold them (far from the origin,
        :func:`~o3d_seqcc.geometry.meshops.float32_offset`).
        """
        import open3d as o3d

        m = o3d.t.geometry.TriangleMesh()
        far = float32_offset(self.vertices).any()
        m.vertex.positions = o3d.core.Tensor(np.asarray(self.vertices, dtype=np.float64 if far else np.float32))
        m.triangle.indices = o3d.core.Tensor(np.asarray(self.faces, dtype=np.int32))
        if self.normals is not None:
            m.vertex.normals = o3d.core.Tensor(np.asarray(self.normals, dtype=np.float32))
        if self.has_texture:
            m.triangle.texture_uvs = o3d.core.Tensor(np.asarray(self.uv[self.faces], dtype=np.float32))
            m.material.set_default_properties()
            m.material.material_name = "defaultLit"
            m.material.texture_maps["albedo"] = o3d.t.geometry.Image(o3d.core.Tensor(np.ascontiguousarray(self.texture)))
        elif self.vertex_colors is not None:
            m.vertex.colors = o3d.core.Tensor(np.asarray(self.vertex_colors, dtype=np.float32))
        return m

    def to_trimesh(self):
        """This mesh as ``trimesh.Trimesh`` (``TextureVisuals`` with a PIL image, or vertex colours)."""
        import trimesh
        from PIL import Image

        visual = None
        if self.has_texture:
            tex = self.texture if self.texture.dtype == np.uint8 else (self.texture >> 8).astype(np.uint8)
            visual = trimesh.visual.TextureVisuals(uv=np.asarray(self.uv), image=Image.fromarray(tex))
        elif self.vertex_colors is not None:
            rgb = np.clip(np.rint(np.asarray(self.vertex_colors) * 255), 0, 255).astype(np.uint8)
            visual = trimesh.visual.ColorVisuals(vertex_colors=rgb)
        return trimesh.Trimesh(vertices=np.asarray(self.vertices), faces=np.asarray(self.faces),
                               vertex_normals=self.normals, visual=visual, process=False)


def sample_texture(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup of texture colours at UV coordinates (clamped to the texture's edge).

    Parameters
    ----------
    texture : (H, W, 3) uint8 / uint16 / float array
    uv : (n, 2) float array
        OBJ convention (origin bottom-left, v up); see the module docstring.

    Returns
    -------
    (n, 3) float64
        Colours in [0, 1].
    """
    texture = np.asarray(texture)
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    h, w = texture.shape[:2]
    return sample_bilinear(texture, uv[:, 0] * w - 0.5, (1.0 - uv[:, 1]) * h - 0.5) / dtype_scale(texture.dtype)


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


def _stack_materials(geoms: list, where: str) -> TexturedMesh:
    """One TexturedMesh from several textured meshes (one per material): their images stacked, exactly.

    trimesh's own merge (``Scene.to_mesh``) packs the images with UVs scaled by
    ``(size - 1) / atlas``, which moves lookups by up to a texel across each image (and shrinks
    images when the packed atlas would exceed 8192²). Here the images are stacked vertically
    at full size, left-aligned (width = the widest), and each UV is mapped to the same texel
    position in the stack: ``x = u w_g`` and ``y = y0_g + (1 - v) h_g`` in texel-edge units,
    no resampling. Equal square images (our own pages) give ``pages`` = their number.
    """
    texs = [_image_to_rgb_array(getattr(g.visual.material, "baseColorTexture", None)
                                or g.visual.material.image, where) for g in geoms]
    if len({t.dtype for t in texs}) > 1:
        texs = [t.astype(np.uint16) * 257 if t.dtype == np.uint8 else t for t in texs]
    width = max(t.shape[1] for t in texs)
    heights = np.array([t.shape[0] for t in texs])
    y0 = np.concatenate([[0], np.cumsum(heights)[:-1]])
    total = int(heights.sum())
    stack = np.zeros((total, width, 3), dtype=texs[0].dtype)
    verts, faces, uvs, base = [], [], [], 0
    for g, t, y in zip(geoms, texs, y0):
        h, w = t.shape[:2]
        stack[y:y + h, :w] = t
        uv = np.asarray(g.visual.uv, dtype=np.float64)
        uvs.append(np.stack([uv[:, 0] * w / width, 1.0 - (y + (1.0 - uv[:, 1]) * h) / total], axis=1))
        verts.append(np.asarray(g.vertices, dtype=np.float64))
        faces.append(np.asarray(g.faces, dtype=np.int64) + base)
        base += len(g.vertices)
    square = all(t.shape[:2] == (width, width) for t in texs)
    return TexturedMesh(vertices=np.concatenate(verts), faces=np.concatenate(faces), uv=np.concatenate(uvs),
                        texture=stack, pages=len(texs) if square else 1)


def _textured_parts(scene: Any) -> list | None:
    """The scene's meshes (transforms applied) when there are several and every one has a texture and UVs."""
    import trimesh

    geoms = [g for g in scene.dump() if isinstance(g, trimesh.Trimesh) and len(g.faces)]
    if len(geoms) < 2:
        return None
    for g in geoms:
        vis, mat = g.visual, getattr(g.visual, "material", None)
        img = None if mat is None else (getattr(mat, "baseColorTexture", None) or getattr(mat, "image", None))
        if getattr(vis, "kind", None) != "texture" or vis.uv is None or len(vis.uv) != len(g.vertices) or img is None:
            return None
    return geoms


def load_textured_mesh(mesh_or_path: Any) -> TexturedMesh:
    """Read a textured (or vertex-coloured) mesh with trimesh.

    Parameters
    ----------
    mesh_or_path : path-like, trimesh.Trimesh, trimesh.Scene or TexturedMesh
        OBJ (+MTL+image), GLB/glTF, PLY, ... A scene is merged into one mesh. Several textured
        parts (an OBJ with several materials, as texrecon writes, or a GLB with one primitive
        per page, as ours) keep their images texel for texel, stacked vertically (see
        ``pages``).

    Returns
    -------
    TexturedMesh

    Raises
    ------
    InputError
        Missing or unreadable file, no faces, neither a texture (with UVs) nor vertex colours.
    """
    if isinstance(mesh_or_path, TexturedMesh):
        return mesh_or_path
    import trimesh

    if isinstance(mesh_or_path, (str, os.PathLike)):
        p = Path(mesh_or_path)
        if not p.is_file():
            raise InputError(f"mesh not found: {p}")
        where = str(p)
        try:
            mesh = trimesh.load_scene(str(p), process=False)  # what trimesh.load(force="mesh") merges
        except Exception as e:  # trimesh raises many types on malformed files
            raise InputError(f"cannot read mesh {p}: {e}") from None
    else:
        mesh, where = mesh_or_path, type(mesh_or_path).__name__
    if isinstance(mesh, trimesh.Scene):
        parts = _textured_parts(mesh)
        if parts is not None:
            return _stack_materials(parts, where)
        try:
            mesh = mesh.to_mesh() if hasattr(mesh, "to_mesh") else mesh.dump(concatenate=True)
        except Exception as e:  # an empty scene, or geometry trimesh cannot merge
            raise InputError(f"{where}: no triangles found ({e}); give a triangle mesh with faces") from None
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
                logger.warning("%s: baseColorFactor %s ignored", where, list(factor))
        else:
            uv = None
    if tex is None and getattr(visual, "kind", None) == "vertex":
        colors = np.asarray(visual.vertex_colors)
        if len(colors) == len(v):
            vc = colors[:, :3].astype(np.float64) / 255.0
    if tex is None and vc is None:
        raise InputError(
            f"{where}: the mesh has neither a texture with UV coordinates nor vertex colours; "
            "give a textured OBJ/GLB (or a PLY with vertex colours)"
        )
    return TexturedMesh(vertices=v, faces=f, uv=uv, texture=tex, vertex_colors=vc)
