"""A sub-pixel mesh (issue 36): 2.2M faces seen by 8 photos of 160 x 120, where every face is smaller than a pixel.

The synthetic room (:func:`o3d_seqcc.synthetic.make_synthetic_scene`, 8 photos of 160 x 120, cells of 3.5 cm:
135k faces) subdivided twice at the edge midpoints (Open3D's ``subdivide_midpoint``: 2.16M faces, the same
surface), then ``o3d-seqcc run`` with its defaults, as a user would, in a child process under ``/usr/bin/time -v``.
Printed: peak RSS and wall of the whole process, the command's stage timings and its sub-pixel warning. The
issue's target: under 3 GB and 90 s.

Usage::

    .venv/bin/python benchmarks/subpixel.py [--out /tmp/o3d_seqcc_subpixel] [--subdivide 2]
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=Path("/tmp/o3d_seqcc_subpixel"))
    p.add_argument("--subdivide", type=int, default=2, help="midpoint subdivisions of the 135k-face room (x4 each)")
    args = p.parse_args(argv)
    import open3d as o3d

    from o3d_seqcc.synthetic import make_synthetic_scene

    args.out.mkdir(parents=True, exist_ok=True)
    syn = make_synthetic_scene(args.out / "room", n_views=8, width=160, height=120, seed=0, cell_size=0.035,
                               overwrite=True)
    m = o3d.io.read_triangle_mesh(str(syn.root / "mesh.ply"))
    fine = m.subdivide_midpoint(args.subdivide)
    mesh = args.out / "room_fine.ply"
    o3d.io.write_triangle_mesh(str(mesh), fine)
    exe = shutil.which("o3d-seqcc", path=str(Path(sys.executable).parent)) or "o3d-seqcc"
    cmd = ["/usr/bin/time", "-v", exe, "run", str(syn.root / "scene.json"), "--mesh", str(mesh), "--out",
           str(args.out / "run"), "--overwrite"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    text = r.stdout + r.stderr
    if r.returncode:
        print(text[-3000:])
        return r.returncode
    peak = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", text).group(1)) / 1024
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): ([\d:.]+)", text).group(1)
    parts = [float(x) for x in wall.split(":")]
    seconds = sum(v * 60 ** i for i, v in enumerate(reversed(parts)))
    timings = re.search(r"timings \(s\): (.*)", text)
    warned = [line for line in text.splitlines() if "smaller than a pixel" in line]
    print(f"sub-pixel room: {len(m.triangles)} faces subdivided {args.subdivide}x -> {len(fine.triangles)} faces, "
          f"8 photos of 160x120")
    print(f"o3d-seqcc run: peak RSS {peak:.0f} MB, wall {seconds:.1f} s (targets: 3072 MB, 90 s)")
    print(f"stages: {timings.group(1) if timings else '?'}")
    print(f"warning: {warned[0].strip() if warned else 'none'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
