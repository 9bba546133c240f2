"""Screenshot of the MeshLab application with the output of ``o3d-seqcc run`` on a small synthetic scene.

What it shows: Debian's MeshLab opening the project.mlp that `o3d-seqcc run` writes: the
textured mesh as a layer (seen through the reference camera) and the corrected rasters listed in
the layer panel. MeshLab runs headless on a private virtual display (Xvfb) and the picture is a
screenshot of its window (docs/meshlab_project.png was made this way). The same, in a shell:

    o3d-seqcc synthetic S --views 6 --width 160 --height 120
    o3d-seqcc run S --out O --save-images
    meshlab O/project.mlp view.xml      # view.xml: the reference camera

How to run (from any folder; needs the Debian/Ubuntu packages meshlab xvfb xdotool imagemagick,
which ./dev.sh installs):

    python examples/meshlab_screenshot.py [--png docs/meshlab_project.png] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import trimesh

from meshlab_filters import load_mlp, screenshot_meshlab, write_view_state
from o3d_seqcc.cli import main as o3d_seqcc


def run(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--out", type=Path, default=None, help="working folder (default: a temporary one)")
    p.add_argument("--png", type=Path, default=None, help="screenshot (default: OUT/meshlab_project.png)")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="meshlab_screenshot_") as tmp:
        work = (args.out or Path(tmp)).resolve()
        png = (args.png or work / "meshlab_project.png").resolve()
        S, O = work / "S", work / "O"
        if o3d_seqcc(["-q", "synthetic", str(S), "--views", "6", "--width", "160", "--height", "120",
                      "--overwrite"]) != 0:
            return 1
        if o3d_seqcc(["-q", "run", str(S), "--out", str(O), "--save-images", "--overwrite"]) != 0:
            return 1
        project = O / "project.mlp"
        scene = load_mlp(project)
        reference = json.loads((O / "report.json").read_text())["correction"]["reference"]
        mesh = trimesh.load(scene.mesh, process=False)
        view = write_view_state(scene.views[scene.index(reference)], work / "view.xml",
                                scene_diagonal=float(np.linalg.norm(np.ptp(mesh.vertices, axis=0))))
        shot = screenshot_meshlab(project, png, view=view)
        print(f"{shot.title}: loaded in {shot.seconds:.1f} s -> {shot.png} ({shot.png.stat().st_size // 1024} KB)")
    return 0


if __name__ == "__main__":
    sys.exit(run())
