"""A moving occluder the mesh lacks: how many faces show it in the texture, with the masks and without (issue 37).

Usage::

    .venv/bin/python benchmarks/occluder.py [--width 320] [--height 240] [--cell 0.06] [--keep DIR] [--json FILE]

The scene (:mod:`o3d_seqcc.synthetic.occluder`): the synthetic room, 16 photos (320x240, 46k faces by default,
``photometric="none"`` so that the occluder's colour in the photos is exactly its own), and a person-sized box
(0.5 x 0.5 x 1.8 m, saturated magenta) ray-cast into 2 neighbouring photos but absent from the mesh; the
scene has no depth maps, so the depth-consistency filter cannot catch the box. The masks are the same render
(0 = the box). Both runs are ``o3d-seqcc run`` with its defaults (outlier removal on), through
:func:`o3d_seqcc.cli.main`:

- **without masks**: ``o3d-seqcc run OCC/scene.json --out A`` (only the outlier removal can drop the box);
- **with masks**: ``o3d-seqcc run OCC/scene.json --masks OCC/masks --out B``.

Printed: the faces of each written ``mesh.obj`` whose mean texel colour is within CIEDE2000 10 of the box's
(the rule; :func:`~o3d_seqcc.synthetic.occluder.occluder_faces`), the faces with at least half / any of their
texels within 10, their share of the surface area, and the same count on the room without the box (the rule's
false positives: the room's photos come no closer than CIEDE2000 ~15 to the box colour).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from o3d_seqcc.cli import main  # noqa: E402
from o3d_seqcc.synthetic import make_synthetic_scene  # noqa: E402
from o3d_seqcc.synthetic.occluder import add_occluder, occluder_faces  # noqa: E402
from o3d_seqcc.texturing import load_textured_mesh  # noqa: E402


def run(args: argparse.Namespace, root: Path) -> dict:
    room = make_synthetic_scene(root / "room", n_views=16, width=args.width, height=args.height,
                                cell_size=args.cell, photometric="none")
    occ = add_occluder(room, root / "occluder")
    out: dict = {"views": list(occ.views), "box_pixels": occ.pixels, "faces_in_mesh": room.metadata["n_faces"],
                 "runs": {}}
    commands = {
        "without masks": ["run", str(occ.root / "scene.json"), "--out", str(root / "without")],
        "with masks": ["run", str(occ.root / "scene.json"), "--masks", str(occ.masks), "--out", str(root / "with")],
        "room without the box": ["run", str(room.root / "scene.json"), "--out", str(root / "room_run")],
    }
    for name, cmd in commands.items():
        t = time.perf_counter()
        if main(["-q", *cmd]) != 0:
            raise SystemExit(f"o3d-seqcc {' '.join(cmd)} failed")
        counts = occluder_faces(load_textured_mesh(Path(cmd[cmd.index("--out") + 1]) / "mesh.obj"), occ.colour)
        out["runs"][name] = {"command": "o3d-seqcc " + " ".join(cmd), **counts,
                             "seconds": round(time.perf_counter() - t, 2)}
    return out


def main_() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--height", type=int, default=240)
    p.add_argument("--cell", type=float, default=0.06, help="the room's cell size in metres (0.06: 46k faces)")
    p.add_argument("--keep", help="write the scenes and runs here (default: a temporary folder)")
    p.add_argument("--json", help="also write the numbers as JSON to this file")
    args = p.parse_args()
    if args.keep:
        res = run(args, Path(args.keep))
    else:
        with tempfile.TemporaryDirectory() as tmp:
            res = run(args, Path(tmp))
    print(f"occluder in {', '.join(res['views'])} ({res['box_pixels']} px), room of {res['faces_in_mesh']} faces")
    print(f"{'run':22s} {'faces (mean colour)':>20s} {'>= half texels':>15s} {'any texel':>10s} {'area':>8s} "
          f"{'faces':>7s} {'s':>6s}")
    for name, r in res["runs"].items():
        print(f"{name:22s} {r['mean_colour']:20d} {r['half_texels']:15d} {r['any_texel']:10d} "
              f"{100 * r['area']:7.2f}% {r['faces']:7d} {r['seconds']:6.1f}")
    for name, r in res["runs"].items():
        print(f"  {name}: {r['command']}")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main_())
