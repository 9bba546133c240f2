"""Write the HTML report of an output folder again (RUN_DIR/report.html).

run, correct and texture (and so demo) already write OUT/report.html: one self-contained page
(images embedded, no external resource, opens offline in any browser) with the paper's figures
for the run: the colour-correction graph and its paths (Figures 4-5), the joint image histograms
and colour mapping functions of the path edges (6-7), the sequential steps of one path (8), the
per-face image selection with a legend (9), all views before and after (10), Table 2 with the
contrast ratio, renders of the textured mesh beside the photos (12-13), the seam metric, timings
and settings.

This command writes it again from an output folder: it reads report.json, selection.npy and the
textured mesh there, reloads the scene from where report.json says (or --scene / --mesh) and
recomputes the visibility, mappings and correction with the recorded settings.
"""

from __future__ import annotations

import argparse

from ..run_folder.read import regenerate_report


def run(args: argparse.Namespace) -> int:
    path = regenerate_report(args.run_dir, scene=args.scene, mesh=args.mesh, output=args.output,
                             image_dir=args.image_dir)
    print(f"report written to {path}")
    return 0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run_dir", metavar="RUN_DIR", help="output folder (--out) of o3d-seqcc run, correct or texture")
    p.add_argument("--scene", help="the scene, when it is no longer where RUN_DIR/report.json says")
    p.add_argument("--mesh", help="the scene's mesh, when it is no longer where RUN_DIR/report.json says")
    p.add_argument("--image-dir", help="the scene's images (COLMAP, Meshroom, OpenMVS), when no longer where the run "
                   "read them")
    p.add_argument("--output", metavar="FILE",
                   help="write the page to FILE instead of RUN_DIR/report.html (the folder is then left as it is)")
