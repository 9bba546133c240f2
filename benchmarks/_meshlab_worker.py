"""Subprocess entry point of :func:`peers.run_meshlab` (benchmarks/peers.py) (needs an X display with GLX).

``python benchmarks/_meshlab_worker.py JOB.json``: loads the MeshLab project named in the
job, makes the mesh manifold, runs
``compute_texcoord_parametrization_and_texture_from_registered_rasters`` and saves a textured
OBJ; writes timings to the job's ``result`` JSON.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path


def main(argv: list[str]) -> int:
    import pymeshlab

    job = json.loads(Path(argv[0]).read_text())
    t0 = time.perf_counter()
    ms = pymeshlab.MeshSet()
    ms.load_project(job["project"])
    faces_in = ms.current_mesh().face_number()
    ms.meshing_remove_duplicate_vertices()
    ms.meshing_repair_non_manifold_edges()
    ms.meshing_repair_non_manifold_vertices()
    ms.meshing_remove_unreferenced_vertices()
    faces_clean = ms.current_mesh().face_number()
    t1 = time.perf_counter()
    params = dict(
        texturesize=job["texture_size"],
        texturename=job["texture_name"],
        colorcorrection=job["colorcorrection"],
        texturegutter=job["texture_gutter"],
    )
    ms.compute_texcoord_parametrization_and_texture_from_registered_rasters(**params)
    t2 = time.perf_counter()
    out = Path(job["out_mesh"])
    ms.save_current_mesh(str(out))
    # MeshLab writes the texture into the current folder; make sure it sits next to the OBJ
    tex = Path(job["texture_name"])
    if tex.is_file() and tex.resolve().parent != out.parent.resolve():
        tex.replace(out.parent / tex.name)
    res = {
        "faces_in": faces_in,
        "faces_textured": faces_clean,
        "rasters": ms.raster_number(),
        "load_clean_seconds": t1 - t0,
        "filter_seconds": t2 - t1,
        "save_seconds": time.perf_counter() - t2,
        "params": params,
    }
    tmp = Path(job["result"] + ".tmp")
    tmp.write_text(json.dumps(res, indent=1))
    tmp.replace(job["result"])
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main(sys.argv[1:]))
