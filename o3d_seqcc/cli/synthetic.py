"""Generate a synthetic textured room scene with known photometric changes.

Renders a closed room with furniture, textured with photos, from N cameras; writes scene.json,
mesh.ply, images/, gt/ (unchanged renders), depth/, face_ids/, points/, synthetic.json.
"""

from __future__ import annotations

import argparse

from ..synthetic import DEFAULT_CELL_SIZE, PHOTOMETRIC_MODES, make_synthetic_scene


def add_synthetic_arguments(p: argparse.ArgumentParser, *, views: int = 12) -> None:
    """Generator options shared by ``synthetic`` and ``demo``."""
    p.add_argument("--views", type=int, default=views, help=f"number of views (default {views})")
    p.add_argument("--width", type=int, default=320, help="image width in pixels (default 320)")
    p.add_argument("--height", type=int, default=240, help="image height in pixels (default 240)")
    p.add_argument("--seed", type=int, default=0, help="random seed for cameras and photometric changes (default 0)")
    p.add_argument(
        "--photometric",
        choices=PHOTOMETRIC_MODES,
        default="camera",
        help="per-view exposure / white balance / gamma / S-curve changes ('camera', default) or none",
    )
    p.add_argument(
        "--cell-size",
        type=float,
        default=DEFAULT_CELL_SIZE,
        help=f"mesh tessellation cell size in metres (default {DEFAULT_CELL_SIZE})",
    )
    p.add_argument("--overwrite", action="store_true", help="write into a non-empty output folder")


def run(args: argparse.Namespace) -> int:
    syn = make_synthetic_scene(args.out, n_views=args.views, width=args.width, height=args.height, seed=args.seed,
                               photometric=args.photometric, overwrite=args.overwrite, cell_size=args.cell_size)
    m = syn.metadata
    print(
        f"synthetic scene: {m['n_views']} views {m['width']}x{m['height']}, {m['n_faces']} faces, "
        f"photometric={m['photometric']}, seed={m['seed']} -> {syn.root / 'scene.json'}"
    )
    return 0




def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("out", help="output folder (must be empty or absent unless --overwrite)")
    add_synthetic_arguments(p)
