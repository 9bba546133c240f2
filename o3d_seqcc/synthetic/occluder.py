"""A moving occluder: a person-sized box in a few photos of a synthetic room, absent from the mesh (issue 37).

:func:`add_occluder` takes a generated room (:func:`~o3d_seqcc.synthetic.make_synthetic_scene`)
and writes a copy of its photos in which a box (by default 0.5 x 0.5 x 1.8 m, saturated
magenta, far from every room colour: the room's albedo is at most 0.8 of full scale in each
channel) stands on the floor in front of two neighbouring cameras: someone walked through the
scene while those two photos were taken. The box is ray-cast with Open3D's ``RaycastingScene``
through every pixel centre (pixel centres at integer coordinates, the intrinsic's convention;
the ray of pixel (u, v) is ``K^-1 (u, v, 1)``) and drawn, flat, where it is nearer than the room
(the room's own ray-cast points, ``points/``). The same render gives the masks: ``masks/<view>.png``,
8-bit grey, 255 = keep, 0 = the box (every view has one; the photos without the box keep every
pixel). The scene holds no depth maps (photos only, as from photogrammetry), so that only the
masks or the outlier removal can keep the box out of the texture::

    out_dir/
      scene.json          the room's cameras and mesh, these photos, no depth
      images/vNN.png      the photos, the box drawn into two of them
      masks/vNN.png       the masks of that render
      occluder.json       the box (corners, colour), the views it is in and its pixels there

:func:`occluder_faces` counts the faces of a textured mesh whose texture shows the occluder.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..imaging.arrays import delta_e_2000
from ..io.images import read_image, write_image
from ..io.json_files import write_json
from ..io.load import load_scene, save_scene
from ..io.output import output_folder
from ..scene import Scene, View
from .generate import SyntheticScene
from .room import _FURNITURE, ROOM, _pixel_rays

__all__ = ["OCCLUDER_COLOUR", "OCCLUDER_SIZE", "OccluderScene", "add_occluder", "load_occluder", "occluder_faces"]

#: the box's colour (8-bit sRGB): saturated magenta
OCCLUDER_COLOUR = (255, 0, 255)
#: the box's size in metres (x, y, z): a person
OCCLUDER_SIZE = (0.5, 0.5, 1.8)
#: the box's distance from the two cameras' midpoint, tried in this order (metres)
_DISTANCES = (1.3, 1.1, 0.9)
#: clearance from walls and furniture (metres)
_CLEAR = 0.15


@dataclass(frozen=True, eq=False)
class OccluderScene:
    """What :func:`add_occluder` wrote.

    Attributes
    ----------
    scene : Scene
        ``root / "scene.json"``: the photos with the box, no masks (give ``masks=`` / ``--masks``).
    root, masks : pathlib.Path
        The folder and its ``masks/`` folder.
    views : tuple of str
        The views the box is in.
    box : (2, 3) float64
        Its lowest and highest corner (world coordinates).
    colour : tuple of int
    pixels : dict of str to int
        View -> pixels showing the box.
    """

    scene: Scene
    root: Path
    masks: Path
    views: tuple[str, ...]
    box: np.ndarray
    colour: tuple[int, int, int]
    pixels: dict


def _overlaps(lo: np.ndarray, hi: np.ndarray) -> bool:
    """The box [lo, hi] leaves less than :data:`_CLEAR` to a wall or touches a piece of furniture (with it)."""
    if (lo[:2] < _CLEAR).any() or (hi[:2] > np.array(ROOM[:2]) - _CLEAR).any():
        return True
    return any((lo[:2] < np.array(b[:2]) + _CLEAR).all() and (hi[:2] > np.array(a[:2]) - _CLEAR).all()
               for a, b in _FURNITURE.values())


def _box_render(view, lo: np.ndarray, hi: np.ndarray, room_points: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels whose centre ray meets the box before the room."""
    import open3d as o3d

    box = o3d.geometry.TriangleMesh.create_box(*(hi - lo)).translate(lo)
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.core.Tensor(np.asarray(box.vertices, np.float32)),
                     o3d.core.Tensor(np.asarray(box.triangles, np.uint32)))
    origin, dirs = _pixel_rays(view.intrinsic, view.extrinsic, view.width, view.height)
    rays = np.concatenate([np.broadcast_to(origin, dirs.shape), dirs], 1).astype(np.float32)
    t = rc.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(np.float64)  # camera z: the rays have z = 1
    E = np.asarray(view.extrinsic)
    p = np.asarray(room_points, np.float64).reshape(-1, 3)
    z = np.where(np.isfinite(p).all(axis=1), p @ E[2, :3] + E[2, 3], np.inf)
    return (np.isfinite(t) & (t < z)).reshape(view.height, view.width)


def _pairs(scene: Scene) -> list[tuple[int, int]]:
    """Neighbouring cameras (by the heading of their axes), in view order."""
    yaw = np.array([np.arctan2(v.axis[1], v.axis[0]) for v in scene.views])
    order = np.argsort(yaw, kind="stable")
    pairs = [tuple(sorted((int(order[k]), int(order[(k + 1) % len(order)])))) for k in range(len(order))]
    return sorted(set(pairs))


def add_occluder(room: SyntheticScene, out_dir: str | os.PathLike, *, views: tuple[int, int] | None = None,
                 size: tuple[float, float, float] = OCCLUDER_SIZE, colour: tuple[int, int, int] = OCCLUDER_COLOUR,
                 min_share: float = 0.03, overwrite: bool = False) -> OccluderScene:
    """Write ``room``'s photos with a box in two of them, and the masks of it (module docstring).

    Parameters
    ----------
    room : SyntheticScene
    out_dir : path-like
        Written as a whole (:func:`~o3d_seqcc.io.output.output_folder`); refused if it exists,
        unless ``overwrite`` (an earlier output of o3d_seqcc).
    views : (int, int), optional
        The two views the box is in (neighbours); default the first pair of neighbouring cameras
        where a box :data:`_DISTANCES` in front of them stands clear of the walls and furniture and
        covers at least ``min_share`` of each photo.
    size : (float, float, float), default :data:`OCCLUDER_SIZE`
    colour : (int, int, int), default :data:`OCCLUDER_COLOUR`

    Raises
    ------
    InputError
        No such place for the box.
    """
    scene, size = room.scene, np.asarray(size, dtype=np.float64)
    found = None
    for a, b in [tuple(views)] if views is not None else _pairs(scene):
        va, vb = scene.views[a], scene.views[b]
        ahead = va.axis[:2] + vb.axis[:2]
        ahead /= max(float(np.linalg.norm(ahead)), 1e-12)
        for d in _DISTANCES:
            foot = 0.5 * (va.center[:2] + vb.center[:2]) + d * ahead
            lo = np.array([*(foot - size[:2] / 2), 0.0])
            hi = lo + size
            if _overlaps(lo, hi):
                continue
            hits = [_box_render(scene.views[k], lo, hi, room.load_points(k)) for k in (a, b)]
            if min(h.mean() for h in hits) >= min_share:
                found = (a, b, lo, hi, hits)
                break
        if found:
            break
    if found is None:
        raise InputError(f"no place for a {size.tolist()} m box in front of two neighbouring cameras of {room.root}")
    a, b, lo, hi, hits = found
    drawn = {a: hits[0], b: hits[1]}
    with output_folder(out_dir, overwrite=overwrite, command="synthetic occluder") as stage:
        out = []
        for k, v in enumerate(scene.views):
            img_path, mask_path = stage / "images" / f"{v.name}.png", stage / "masks" / f"{v.name}.png"
            hit = drawn.get(k, np.zeros((v.height, v.width), dtype=bool))
            if k in drawn:
                img = np.array(read_image(v.image))
                img[hit] = np.asarray(colour, dtype=img.dtype)
                write_image(img_path, img)
            else:
                img_path.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(v.image, img_path)
            write_image(mask_path, np.repeat(np.where(hit, 0, 255).astype(np.uint8)[..., None], 3, axis=2))
            out.append(View(name=v.name, image=img_path, intrinsic=v.intrinsic, extrinsic=v.extrinsic, width=v.width,
                            height=v.height))
        save_scene(Scene(scene.mesh, tuple(out)), stage / "scene.json")
        names = (scene.views[a].name, scene.views[b].name)
        pixels = {scene.views[k].name: int(drawn[k].sum()) for k in (a, b)}
        write_json(stage / "occluder.json", {"box": [lo.tolist(), hi.tolist()], "colour": list(colour), "views": names,
                                             "pixels": pixels, "pixel_centres": "integer coordinates (K's)"})
    root = Path(out_dir)
    return OccluderScene(scene=load_scene(root / "scene.json"), root=root, masks=root / "masks", views=names,
                         box=np.stack([lo, hi]), colour=tuple(int(c) for c in colour), pixels=pixels)


def occluder_faces(textured, colour: tuple[int, int, int] = OCCLUDER_COLOUR, *, tol: float = 10.0) -> dict:
    """The faces of a textured mesh whose texture shows the occluder's colour.

    Every face's texels (those whose centre lies in its UV triangle; a face too small to hold one:
    the texel at its centroid) are compared with ``colour`` in CIEDE2000 (sRGB, D65).

    Parameters
    ----------
    textured : TexturedMesh
    colour : (int, int, int), default :data:`OCCLUDER_COLOUR`
    tol : float, default 10
        CIEDE2000 below which a colour is the occluder's.

    Returns
    -------
    dict
        ``mean_colour``: faces whose mean texel colour is within ``tol`` (the rule of issue 37);
        ``half_texels``: faces with at least half their texels within ``tol``; ``any_texel``: faces
        with a texel within ``tol``; ``faces``: the mesh's faces; ``area``: the share of the surface
        area of the ``mean_colour`` faces.
    """
    from ..texturing.bake import rasterize_faces
    from ..texturing.textured_mesh import sample_texture

    tm = textured
    if not tm.has_texture:
        raise InputError("occluder_faces needs a textured mesh (with an atlas)")
    H, W = tm.texture.shape[:2]
    faces = np.asarray(tm.faces)
    F = len(faces)
    scale = 65535.0 if tm.texture.dtype == np.uint16 else 255.0
    ref = np.asarray(colour, dtype=np.float64) / 255.0
    idx, face, _ = rasterize_faces(tm.texel_xy(), faces, H, W)
    rgb = tm.texture.reshape(-1, 3)[idx].astype(np.float64) / scale
    near = delta_e_2000(rgb, np.broadcast_to(ref, rgb.shape)) <= tol
    n = np.bincount(face, minlength=F)
    mean = np.stack([np.bincount(face, weights=rgb[:, c], minlength=F) for c in range(3)], axis=1)
    none = n == 0
    mean[~none] /= n[~none, None]
    if none.any():  # faces without a texel centre: their centroid's colour
        cen = tm.uv[faces[none]].mean(axis=1)
        mean[none] = sample_texture(tm.texture, cen)
    hit = delta_e_2000(mean, np.broadcast_to(ref, mean.shape)) <= tol
    share = np.bincount(face, weights=near, minlength=F) / np.maximum(n, 1)
    X = np.asarray(tm.vertices, dtype=np.float64)
    area = 0.5 * np.linalg.norm(np.cross(X[faces[:, 1]] - X[faces[:, 0]], X[faces[:, 2]] - X[faces[:, 0]]), axis=1)
    return {"mean_colour": int(hit.sum()), "half_texels": int(((share >= 0.5) & ~none).sum() + (hit & none).sum()),
            "any_texel": int((np.bincount(face, weights=near, minlength=F) > 0).sum() + (hit & none).sum()),
            "faces": int(F), "area": round(float(area[hit].sum() / max(area.sum(), 1e-300)), 6)}


def load_occluder(root: str | os.PathLike) -> dict:
    """``occluder.json`` of a folder :func:`add_occluder` wrote."""
    return json.loads((Path(root) / "occluder.json").read_text(encoding="utf-8"))
