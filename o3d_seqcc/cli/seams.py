"""Seam metric of a textured mesh: CIEDE2000 across interior edges (mean, p99, share > 5).

For every interior edge on a UV seam, samples both adjacent faces' textures --offset texels
inside the edge (edges inside a chart, with the same UVs on both sides, are continuous and count
0) and reports the CIEDE2000 between the two sides: mean, median, 99th percentile, share of
edges above 5. Works on any textured OBJ/GLB (or a mesh with vertex colours).
"""

from __future__ import annotations

import argparse
import json

from ..io.files import write_json
from ..seams import seam_metric
from .common import refuse_input_overwrite


def run(args: argparse.Namespace) -> int:
    if args.json:
        refuse_input_overwrite(args.json, [args.mesh], "--json")
    report = seam_metric(args.mesh, offset=args.offset, samples_per_edge=args.samples_per_edge)
    d = {"mesh": str(args.mesh), **report.to_dict()}
    if args.json:
        write_json(args.json, d)
    print(json.dumps(d, indent=1))
    return 0




def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("mesh", help="textured mesh: OBJ (+MTL+image), GLB/glTF, or PLY with vertex colours")
    p.add_argument("--json", metavar="FILE", help="also write the figures to this JSON file")
    p.add_argument("--offset", type=float, default=0.5,
                   help="distance of the samples from the edge, in texels inward in each face's own UVs (default 0.5)")
    p.add_argument("--samples-per-edge", type=int, default=4, help="samples along each edge (default 4)")
