"""``o3d-seqcc texture SCENE --out OUT``: per-face view selection, texture atlas, OBJ/GLB export.

Writes ``OUT/mesh.glb`` and/or ``OUT/mesh.obj`` (+ ``mesh.mtl``, ``mesh.png``), optionally
``OUT/mesh_colors.ply``, ``OUT/selection.npy`` ((F,) int64 view per face, -1 = unseen),
``OUT/selection.png`` (the selection coloured by image from one view, paper Figure 9a) and
``OUT/report.json`` (selection statistics: image transitions, unseen faces; atlas statistics;
seam metric; timings). Global seam leveling (:func:`o3d_seqcc.texturing.bake_texture`,
``leveling=True``) is on unless ``--no-leveling``, local seam leveling (``local_leveling=True``) unless
``--no-local-leveling``. ``OUT`` must not exist unless ``--overwrite``
is given.
"""

from __future__ import annotations

import argparse
import io
import logging
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .._io import atomic_write_bytes, read_image, write_json
from ..errors import InputError
from ..texturing import LEVELING_SMOOTHNESS, MRF_SMOOTHNESS
from .info import add_scene_arguments, load_scene_from_args

logger = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff")


def prepare_out_dir(out: str | Path, overwrite: bool) -> Path:
    """Create ``out``; refuse (InputError) when it exists and ``overwrite`` is False."""
    out = Path(out)
    if out.exists():
        if not overwrite:
            raise InputError(f"output folder {out} exists; choose another --out or pass --overwrite")
        if not out.is_dir():
            raise InputError(f"--out {out} exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    return out


def load_images_dir(scene, folder: str | Path) -> list[np.ndarray]:
    """Images named after the views (``<name>.png``/``.jpg``/...) from ``folder``."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"--images {folder} is not a folder")
    out = []
    for v in scene.views:
        cands = [folder / f"{v.name}{s}" for s in IMAGE_SUFFIXES] + [folder / v.image.name]
        p = next((c for c in cands if c.is_file()), None)
        if p is None:
            raise InputError(f"--images {folder}: no image for view {v.name!r} (expected {v.name}.png or {v.image.name})")
        img = read_image(p)
        if img.shape[:2] != (v.height, v.width):
            raise InputError(f"{p} is {img.shape[1]}x{img.shape[0]} but view {v.name!r} is {v.width}x{v.height}")
        out.append(img)
    return out


def parse_formats(text: str) -> list[str]:
    """``"glb,obj"`` -> ``["glb", "obj"]``; unknown names raise InputError listing the valid ones."""
    from ..export import FORMATS

    formats = list(dict.fromkeys(f.strip().lower() for f in text.split(",") if f.strip()))
    bad = [f for f in formats if f not in FORMATS]
    if bad or not formats:
        raise InputError(f"--format: unknown format(s) {bad or text!r}; valid: {', '.join(FORMATS)}")
    return formats


def add_texture_arguments(p: argparse.ArgumentParser, *, with_images: bool = True) -> None:
    """Options shared by ``texture`` and ``run``."""
    from ..texturing import SELECTION_METHODS

    p.add_argument("--out", required=True, help="output folder (refused if it exists, unless --overwrite)")
    p.add_argument("--selection", default="mrf", choices=sorted(SELECTION_METHODS),
                   help="per-face image selection: mrf (default: largest areas with few image transitions), "
                   "largest-area or random (the paper's two)")
    p.add_argument("--atlas-size", type=int, default=2048, help="texture atlas side in texels (default 2048)")
    p.add_argument("--texel-scale", type=float, default=1.0, help="atlas texels per image pixel (default 1)")
    p.add_argument("--padding", type=int, default=4, help="gutter texels around every chart (default 4)")
    p.add_argument("--overflow", choices=("grow", "scale", "error"), default="grow",
                   help="when the charts do not fit the atlas: grow it (default), shrink the texels, or fail")
    p.add_argument("--smoothness", type=float, default=MRF_SMOOTHNESS,
                   help=f"mrf: Potts weight per interior edge (default {MRF_SMOOTHNESS:g})")
    p.add_argument("--format", default="glb,obj", help="comma-separated export formats among glb, obj, ply (default glb,obj)")
    p.add_argument("--seed", type=int, default=0, help="seed of random selection / mrf order (default 0)")
    p.add_argument("--unlit", action="store_true", help="GLB material with KHR_materials_unlit")
    p.add_argument("--no-leveling", action="store_true",
                   help="skip global seam leveling (per-chart low-frequency colour offsets that cancel the colour "
                   "steps at chart seams; on by default)")
    p.add_argument("--leveling-smoothness", type=float, default=LEVELING_SMOOTHNESS,
                   help=f"seam leveling: weight of the smoothness of the offsets inside charts (default {LEVELING_SMOOTHNESS})")
    p.add_argument("--no-local-leveling", action="store_true",
                   help="skip local seam leveling (after the global one: the colour steps left along chart borders "
                   "are blended away in a thin strip of --local-band texels; on by default)")
    p.add_argument("--local-band", type=int, default=8,
                   help="local seam leveling: width of the blended strip along chart borders, in texels (default 8)")
    p.add_argument("--fallback", choices=("smooth", "flat"), default="smooth",
                   help="colour of faces seen by no view: smooth (default: vertex colours of the seen faces around, "
                   "interpolated) or flat (one colour per face)")
    p.add_argument("--selection-view", default=None,
                   help="view (name or index) from which OUT/selection.png is rendered (default: the view that sees "
                   "the most faces); 'none' to skip the picture")
    p.add_argument("--no-seams", action="store_true", help="skip the seam metric in report.json")
    p.add_argument("--overwrite", action="store_true", help="write into an existing output folder")
    if with_images:
        p.add_argument("--images", help="folder of (corrected) images named after the views, used instead of the scene's")


def to_seam_mesh(tm) -> Any:
    """A :class:`o3d_seqcc.seams.ColoredMesh` (OBJ UV convention, v up) view of a baked mesh."""
    from .. import seams

    SeamMesh = getattr(seams, "ColoredMesh", None) or getattr(seams, "TexturedMesh")

    uv = np.stack([tm.uv[:, 0], 1.0 - tm.uv[:, 1]], axis=1)
    return SeamMesh(vertices=tm.vertices, faces=tm.faces, uv=uv, texture=tm.texture)


def seam_summary(tm) -> dict[str, Any] | None:
    """Seam metric of a baked mesh as a dict, or None when ``o3d_seqcc.seams`` is unavailable."""
    try:
        from ..seams import seam_metric
    except ImportError:  # pragma: no cover - seams module missing
        logger.warning("o3d_seqcc.seams not available: no seam metric")
        return None
    return seam_metric(to_seam_mesh(tm)).to_dict()


def write_selection_picture(scene, visibility, labels: np.ndarray, path: Path, view: str | int | None = None) -> tuple[Path, str]:
    """Render the per-face selection coloured by image (paper Figure 9a) from one view to ``path``.

    ``view``: a view name or index; default the view in which the most faces are usable.
    Returns the path and the view's name.
    """
    from .._io import write_image
    from ..render import render_selection

    if view is None:
        k = int(np.argmax(np.asarray(visibility.usable).sum(axis=1)))
    else:
        k = scene.index(int(view) if isinstance(view, str) and view.isdigit() and view not in scene.names else view)
    img = render_selection(visibility.mesh, labels, scene.views[k], n_views=len(scene.views))
    write_image(path, img)
    return path, scene.names[k]


def texture_and_export(
    scene,
    images: Sequence[np.ndarray],
    visibility,
    out: Path,
    args: argparse.Namespace,
    timings: dict[str, float],
) -> tuple[Any, dict[str, Any]]:
    """Select views, bake, export into ``out``; returns the TexturedMesh and a report dict."""
    from ..export import export_textured_mesh
    from ..texturing import bake_texture, face_adjacency, select_views, selection_stats

    mesh = visibility.mesh
    t = time.perf_counter()
    adjacency = face_adjacency(mesh.faces, mesh.vertices)
    opts: dict[str, Any] = {}
    if args.selection == "mrf":
        opts = {"adjacency": adjacency, "smoothness": args.smoothness}
    labels = select_views(visibility, method=args.selection, seed=args.seed, **opts)
    timings["selection"] = time.perf_counter() - t
    sel = selection_stats(labels, adjacency, len(scene.views))
    t = time.perf_counter()
    tm = bake_texture(
        mesh, images, visibility, labels, atlas_size=args.atlas_size, padding=args.padding,
        texel_scale=args.texel_scale, overflow=args.overflow, adjacency=adjacency,
        leveling=not getattr(args, "no_leveling", False),
        leveling_smoothness=getattr(args, "leveling_smoothness", LEVELING_SMOOTHNESS),
        local_leveling=not getattr(args, "no_local_leveling", False),
        local_band=getattr(args, "local_band", 8),
        fallback=getattr(args, "fallback", "smooth"),
    )
    timings["bake"] = time.perf_counter() - t
    sel_png = None
    sv = getattr(args, "selection_view", None)
    if sv is None or str(sv).lower() != "none":
        t = time.perf_counter()
        sel_png = write_selection_picture(scene, visibility, labels, out / "selection.png", sv)
        timings["selection_picture"] = time.perf_counter() - t
    t = time.perf_counter()
    written = export_textured_mesh(tm, out, formats=parse_formats(args.format), unlit=args.unlit)
    files = {k: str(v) for k, v in written.items()}
    buf = io.BytesIO()
    np.save(buf, labels)
    atomic_write_bytes(out / "selection.npy", buf.getvalue())
    timings["export"] = time.perf_counter() - t
    seams = None
    if not args.no_seams:
        t = time.perf_counter()
        seams = seam_summary(tm)
        timings["seams"] = time.perf_counter() - t
    if sel_png is not None:
        files["selection_png"] = str(sel_png[0])
    report = {
        "selection": {"method": args.selection, "seed": args.seed, **sel,
                      **({"picture_view": sel_png[1]} if sel_png is not None else {})},
        "atlas": {k: v for k, v in tm.stats.items() if not k.startswith("time_")},
        "seams": seams,
        "files": files,
    }
    return tm, report


def run(args: argparse.Namespace) -> int:
    from ..visibility import compute_visibility

    t_all = time.perf_counter()
    timings: dict[str, float] = {}
    parse_formats(args.format)
    scene = load_scene_from_args(args)
    out = prepare_out_dir(args.out, args.overwrite)
    t = time.perf_counter()
    images = load_images_dir(scene, args.images) if args.images else [v.load_image() for v in scene.views]
    timings["load_images"] = time.perf_counter() - t
    t = time.perf_counter()
    vis = compute_visibility(scene)
    timings["visibility"] = time.perf_counter() - t
    tm, report = texture_and_export(scene, images, vis, out, args, timings)
    timings["total"] = time.perf_counter() - t_all
    report = {
        "command": "texture",
        "scene": str(args.scene),
        "images": str(args.images) if args.images else "scene",
        **report,
        "visibility_stats": getattr(vis, "stats", {}),
        "timings_s": {k: round(v, 4) for k, v in timings.items()},
    }
    write_json(out / "report.json", report)
    s = report["selection"]
    msg = (f"textured {s['faces']} faces ({s['unseen_faces']} unseen, {s['transitions']} image transitions, "
           f"{tm.stats['charts']} charts, atlas {tm.atlas_size}^2) in {timings['total']:.2f} s -> {out}")
    if report["seams"]:
        msg += f"; seams: mean {report['seams']['mean']:.2f}, p99 {report['seams']['p99']:.2f}, >5: {report['seams']['frac_above_5']:.3f}"
    print(msg)
    print("timings (s): " + ", ".join(f"{k} {v:.2f}" for k, v in timings.items()))
    return 0


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "texture",
        help="select one image per face, bake a texture atlas, export GLB/OBJ (+report.json)",
        description="Per-face image selection (largest-area, random, mrf) using the visibility filters, a texture "
        "atlas cut from the images at their own resolution, and OBJ+MTL+PNG / GLB export.",
    )
    add_scene_arguments(p)
    add_texture_arguments(p)
    p.set_defaults(func=run)
    return p


__all__ = ["add_texture_arguments", "parse_formats", "prepare_out_dir", "register", "run", "seam_summary",
           "texture_and_export", "to_seam_mesh", "write_selection_picture"]
