"""A GLB for a game engine: the whole job on a scene, one glTF 2.0 binary out, checked by the Khronos validator.

What it shows: o3d_seqcc.pipeline.run colour-corrects the photos and textures the mesh
(per-face view selection, an xatlas-packed atlas within the --atlas-size budget, seam leveling);
RunResult.save writes only the GLB (Y-up, plus report.json and a MeshLab project); the Khronos
glTF-Validator checks the file when it is installed (./dev.sh setup installs it), and the
atlas figures an engine user cares about are printed (size, pages, texel density, coverage,
vertices, the up-axis rotation).

How to run (from any folder):

    python examples/game_engine_glb.py                         # the built-in synthetic room
    python examples/game_engine_glb.py --scene path/to/scene   # any scene o3d-seqcc reads
    python examples/game_engine_glb.py --atlas-size 4096 --texture-format jpg --out my_asset

Output: --out (default ./engine_asset)/mesh.glb.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import o3d_seqcc
from o3d_seqcc.io.gltf_validator import find_validator, validate_glb


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", help="a scene (scene.json, .mlp, COLMAP, ...); default: a small synthetic room")
    ap.add_argument("--mesh", help="mesh file, for scenes that carry none (RGB-D folders, COLMAP, Meshroom)")
    ap.add_argument("--out", type=Path, default=Path("engine_asset"), help="output folder (replaced if it exists)")
    ap.add_argument("--atlas-size", type=int, default=2048, help="largest atlas side in texels (default 2048)")
    ap.add_argument("--texture-format", default="png", choices=("png", "jpg", "webp"), help="texture images (default png)")
    args = ap.parse_args()

    if args.scene is None:
        root = Path(tempfile.mkdtemp(prefix="o3d_seqcc_room_"))
        scene = o3d_seqcc.make_synthetic_scene(root / "room", n_views=12, width=320, height=240).scene
    else:
        scene = o3d_seqcc.load_scene(args.scene, mesh=args.mesh)
    result = o3d_seqcc.pipeline.run(scene, atlas_size=args.atlas_size)  # t_npm="auto": any scene, any mesh
    result.save(args.out, overwrite=True, formats="glb", selection_view="none", up_axis="y",
                texture_format=args.texture_format)
    glb = args.out / "mesh.glb"
    a = result.textured.stats
    report = json.loads((args.out / "report.json").read_text())
    print(f"{glb}: {glb.stat().st_size / 2**20:.1f} MB, {a['pages']} page(s) of {a['atlas_size']}^2 at "
          f"{a['texels_per_pixel']:.2f} texels per photo pixel, {100 * a['coverage']:.0f} % of it covered by triangles, "
          f"{a['charts']} charts, {a['vertices_out']} vertices ({a['vertices_out'] / a['vertices_in']:.2f}x the input), "
          f"seams mean {result.seams.mean:.2f} (CIEDE2000)")
    o = report["export"]["orientation"]
    print(f"up axis: the scene's {o['nearest_axis']} ({o['angle_deg']:.1f} deg off, from the cameras) is the GLB's +Y, "
          f"rotation {o['rotation']}")
    if find_validator() is None:
        print("Khronos glTF validator not installed: skipped (./dev.sh setup installs it)")
        return 0
    issues = validate_glb(glb)
    print(f"Khronos glTF validator: {issues['numErrors']} errors, {issues['numWarnings']} warnings")
    return 0 if issues["numErrors"] == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
