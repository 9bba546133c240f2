"""Open3D objects in, an Open3D textured mesh out: the Fountain scene through o3d_seqcc's Open3D front door.

What it shows: the photos, cameras, depth maps and mesh are read with Open3D's own readers
(read_image, read_pinhole_camera_trajectory, read_triangle_mesh), colour-corrected with
o3d_seqcc.correct_images (Open3D images back), and textured with o3d_seqcc.texture_mesh (an
o3d.t.geometry.TriangleMesh with texture_uvs and the albedo in its material), written with
o3d.t.io.write_triangle_mesh and rendered with Open3D's offscreen renderer to a PNG.

How to run (from any folder):

    python examples/open3d_fountain.py                       # Open3D downloads the Fountain data
    python examples/open3d_fountain.py --data-root DIR       # a local copy (image/, depth/, scene/key.log)
    python examples/open3d_fountain.py --views 8 --show      # fewer views; open a window at the end

The data folder can also come from the environment variable O3D_SEQCC_FOUNTAIN. Outputs go to
--out (default ./fountain_open3d): textured.obj (+ .mtl, texture), render.png.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
import open3d as o3d

import o3d_seqcc


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data-root", default=os.environ.get("O3D_SEQCC_FOUNTAIN"),
                    help="Fountain folder (default: $O3D_SEQCC_FOUNTAIN, else Open3D's download)")
    ap.add_argument("--out", type=Path, default=Path("fountain_open3d"), help="output folder")
    ap.add_argument("--views", type=int, default=0, help="use only this many views, evenly spread (0: all)")
    ap.add_argument("--show", action="store_true", help="open an Open3D window on the result")
    args = ap.parse_args()

    try:
        scene = o3d_seqcc.datasets.fountain(args.data_root)  # file names and the mesh; read below with Open3D
    except o3d_seqcc.datasets.DatasetUnavailable as e:  # offline and no copy: say how to run it, in this script's words
        print(f"open3d_fountain.py: {e.cli_message('--data-root DIR')}", file=sys.stderr)
        return 2
    root = Path(scene.views[0].image).parents[1]
    keep = np.arange(len(scene.views))
    if args.views:
        keep = np.unique(np.linspace(0, len(scene.views) - 1, args.views).round().astype(int))
    traj = o3d.io.read_pinhole_camera_trajectory(str(root / "scene" / "key.log"))
    cameras = [traj.parameters[i] for i in keep]
    images = [o3d.io.read_image(str(scene.views[i].image)) for i in keep]
    depths = [o3d.io.read_image(str(scene.views[i].depth)) for i in keep]
    mesh = o3d.io.read_triangle_mesh(str(scene.mesh))
    print(f"{len(images)} views of {images[0].get_max_bound()[0]:.0f}x{images[0].get_max_bound()[1]:.0f}, "
          f"mesh with {len(mesh.triangles)} triangles")

    corrected, report = o3d_seqcc.correct_images(mesh, images, cameras, depths=depths, return_report=True)
    print(f"corrected toward view {report['correction']['reference']}: mean CIEDE2000 between views "
          f"{report['metrics']['before']['ciede2000']['mean']:.2f} -> {report['metrics']['after']['ciede2000']['mean']:.2f}")

    textured = o3d_seqcc.texture_mesh(mesh, corrected, cameras, depths=depths, correct=False)
    args.out.mkdir(parents=True, exist_ok=True)
    o3d.t.io.write_triangle_mesh(str(args.out / "textured.obj"), textured)

    import open3d.visualization.rendering as rendering

    k = len(cameras) // 2
    intr = cameras[k].intrinsic
    renderer = rendering.OffscreenRenderer(intr.width, intr.height)
    material = rendering.MaterialRecord()
    material.shader = "defaultUnlit"
    material.albedo_img = o3d.geometry.Image(textured.material.texture_maps["albedo"].as_tensor().numpy())
    renderer.scene.add_geometry("fountain", textured, material)
    renderer.setup_camera(intr.intrinsic_matrix, cameras[k].extrinsic, intr.width, intr.height)
    o3d.io.write_image(str(args.out / "render.png"), renderer.render_to_image())
    renderer.scene.clear_geometry()
    print(f"wrote {args.out / 'textured.obj'} and {args.out / 'render.png'} (Open3D render from view {k})")
    if args.show:
        o3d.visualization.draw(textured)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
