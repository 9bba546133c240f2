"""What the camera check costs and what it catches, on Fountain (33 photos, 16k- and 300k-face meshes).

For each mesh: ``load_scene`` with the check (the default) against the peer ``check_cameras=False``
in the same process (median of ``--repeat`` alternating runs; the mesh file is cached by both),
and ``check_cameras`` alone; then the scene with each camera mistake of issue 20 applied (the
poses inverted, the axes flipped to OpenGL, both, the mesh in millimetres or the cameras in
millimetres) and whether the check names it.

    python benchmarks/camera_check.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # this checkout's package, not whichever one is installed
FOUNTAIN = REPO.parent / "shared" / "datasets" / "fountain_small"
MESHES = ("scene/mesh_decimated_uv_blender.ply", "scene/tsdf_mesh.ply")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    if not (FOUNTAIN / "scene" / "key.log").is_file():
        print(f"fountain data not found at {FOUNTAIN}; nothing to measure")
        return 0
    warnings.simplefilter("ignore")
    from o3d_seqcc import InputError, Scene, load_scene
    from o3d_seqcc.visibility.camera_checks import FLIP, check_cameras

    for mesh in MESHES:
        load_scene(FOUNTAIN, mesh=mesh)  # warm: imports, the mesh cache
        times: dict[str, list[float]] = {"with": [], "without": [], "check": []}
        for _ in range(args.repeat):
            for key, kw in (("with", {}), ("without", {"check_cameras": False})):
                t = time.perf_counter()
                scene = load_scene(FOUNTAIN, mesh=mesh, **kw)
                times[key].append(time.perf_counter() - t)
            t = time.perf_counter()
            rep = check_cameras(scene)
            times["check"].append(time.perf_counter() - t)
        med = {k: statistics.median(v) for k, v in times.items()}
        faces = len(scene.load_mesh().faces)
        print(f"Fountain, {faces} faces: load_scene {med['with']:.2f} s with the check, {med['without']:.2f} s "
              f"without ({med['with'] / med['without']:.2f}x); check_cameras {med['check']:.2f} s "
              f"({1e3 * med['check'] / len(scene.views):.0f} ms per view); front fraction "
              f"{rep.front_fraction:.2f}, {rep.area_seen:.0%} of the mesh seen, no mistake: {rep.mistake is None}")
        mistakes = {
            "camera-to-world as world-to-camera": lambda E: np.linalg.inv(E),
            "OpenGL axes as OpenCV": lambda E: FLIP @ E,
            "NeRF (camera-to-world, OpenGL)": lambda E: np.linalg.inv(FLIP @ E),
            "cameras in mm, mesh in m": lambda E: np.vstack([np.hstack([E[:3, :3], E[:3, 3:] * 1000]), E[3:]]),
            "mesh in mm, cameras in m": lambda E: np.vstack([np.hstack([E[:3, :3], E[:3, 3:] / 1000]), E[3:]]),
        }
        for name, change in mistakes.items():
            bad = Scene(scene.mesh, tuple(replace(v, extrinsic=change(v.extrinsic)) for v in scene.views))
            try:
                check_cameras(bad)
                verdict = "NOT caught"
            except InputError as e:
                verdict = "caught: " + str(e).split(";")[0][:110]
            print(f"  {name}: {verdict}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
