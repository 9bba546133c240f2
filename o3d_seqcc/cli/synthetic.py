"""Generate a synthetic textured room scene with known photometric changes.

Renders a closed room with furniture, textured with photos, from N cameras; writes scene.json,
mesh.ply, images/, gt/ (unchanged renders), depth/, face_ids/, points/, synthetic.json.
"""

from __future__ import annotations

import argparse

from ..synthetic import PHOTOMETRIC_MODES, make_synthetic_scene
from ..synthetic.room import LAYOUTS
from .parser import library_default


def add_synthetic_arguments(p: argparse.ArgumentParser, *, defaults: dict | None = None) -> None:
    """Generator options shared by ``synthetic`` and ``demo`` (defaults: the generator's, updated by ``defaults``)."""
    d = {**library_default(make_synthetic_scene), **(defaults or {})}
    p.add_argument("--views", type=int, default=d["n_views"], help=f"number of views (default {d['n_views']})")
    p.add_argument("--width", type=int, default=d["width"], help=f"image width in pixels (default {d['width']})")
    p.add_argument("--height", type=int, default=d["height"], help=f"image height in pixels (default {d['height']})")
    p.add_argument("--seed", type=int, default=d["seed"], help="random seed for cameras and photometric changes")
    p.add_argument("--photometric", choices=PHOTOMETRIC_MODES, default=d["photometric"],
                   help="per-view exposure / white balance / gamma / S-curve changes ('camera') or none")
    p.add_argument("--cell-size", type=float, default=d["cell_size"],
                   help=f"mesh tessellation cell size in metres (default {d['cell_size']})")
    p.add_argument("--layout", choices=LAYOUTS, default=d["layout"],
                   help=f"camera layout: one ring looking out, or two rings looking up and down (default {d['layout']})")
    p.add_argument("--seen-only", action=argparse.BooleanOptionalAction, default=d["seen_only"],
                   help="keep only the faces some camera sees, as a scan's mesh does")
    p.add_argument("--overwrite", action="store_true", help="write into a non-empty output folder")


def scene_options(args: argparse.Namespace) -> dict:
    """The generator's options from the parsed arguments."""
    return {"n_views": args.views, "width": args.width, "height": args.height, "seed": args.seed,
            "photometric": args.photometric, "cell_size": args.cell_size, "layout": args.layout,
            "seen_only": args.seen_only}


def _origin(text: str) -> tuple[float, float, float]:
    try:
        xyz = tuple(float(x) for x in text.split(","))
    except ValueError:
        xyz = ()
    if len(xyz) != 3:
        raise argparse.ArgumentTypeError(f"give three numbers X,Y,Z (metres), not {text!r}")
    return xyz  # type: ignore[return-value]


def run(args: argparse.Namespace) -> int:
    syn = make_synthetic_scene(args.out, overwrite=args.overwrite, origin=args.origin, **scene_options(args))
    m = syn.metadata
    print(
        f"synthetic scene: {m['n_views']} views {m['width']}x{m['height']}, {m['n_faces']} faces, "
        f"photometric={m['photometric']}, seed={m['seed']} -> {syn.root / 'scene.json'}"
    )
    return 0




def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("out", help="output folder (must be empty or absent unless --overwrite)")
    add_synthetic_arguments(p)
    p.add_argument("--origin", type=_origin, default=library_default(make_synthetic_scene)["origin"], metavar="X,Y,Z",
                   help="world coordinates of the room's corner, e.g. 500000,4000000,100 (UTM-like; default the origin)")
