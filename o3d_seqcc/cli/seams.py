"""Seam metric of a textured mesh: CIEDE2000 across interior edges (mean, p99, share > 5).

For every interior edge on a UV seam, samples both adjacent faces' textures --offset texels
inside the edge (edges inside a chart, with the same UVs on both sides, are continuous and count
0) and reports the CIEDE2000 between the two sides: mean, median, 99th percentile, share of
edges above 5. Works on any textured OBJ/GLB (or a mesh with vertex colours).
"""

from __future__ import annotations

import argparse
import json
import os
import re
from pathlib import Path

from ..io.output import write_output_json
from ..evaluation.seams import seam_metric
from .scene_flags import refuse_input_overwrite


def _mesh_files(mesh: str) -> list[Path]:
    """The mesh and the files it names (an OBJ's material libraries and their texture images)."""
    p = Path(mesh)
    out = [p]
    if p.suffix.lower() == ".obj" and p.is_file():
        names = re.findall(rb"^\s*mtllib\s+(.+?)\s*$", p.read_bytes()[:1 << 20], flags=re.M)
        for m in (p.parent / os.fsdecode(n) for n in names):
            out.append(m)
            if m.is_file():
                maps = re.findall(rb"^\s*map_\w+\s+(?:-\S+\s+\S+\s+)*(.+?)\s*$", m.read_bytes()[:1 << 20], flags=re.M)
                out += [p.parent / os.fsdecode(t) for t in maps]
    return out


def run(args: argparse.Namespace) -> int:
    inputs = _mesh_files(args.mesh)
    if args.json:
        refuse_input_overwrite(args.json, inputs, "--json")
    report = seam_metric(args.mesh, offset=args.offset, samples_per_edge=args.samples_per_edge)
    d = {"mesh": str(args.mesh), **report.to_dict()}
    if args.json:
        write_output_json(args.json, d, inputs=inputs)
    print(json.dumps(d, indent=1))
    return 0




def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("mesh", help="textured mesh: OBJ (+MTL+image), GLB/glTF, or PLY with vertex colours")
    p.add_argument("--json", metavar="FILE", help="also write the figures to this JSON file")
    p.add_argument("--offset", type=float, default=0.5,
                   help="distance of the samples from the edge, in texels inward in each face's own UVs (default 0.5)")
    p.add_argument("--samples-per-edge", type=int, default=4, help="samples along each edge (default 4)")
