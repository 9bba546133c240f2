"""The MeshLab application (Debian's ``meshlab``) opens the project.mlp our ``--out`` holds."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

import o3d_seqcc as sc
from meshlab_filters import missing_tools, screenshot_meshlab, write_view_state
from o3d_seqcc import pipeline


def test_meshlab_application_opens_our_output(tmp_path):
    if shutil.which("meshlab") is None:
        pytest.skip("the MeshLab application is not installed (apt-get install meshlab; ./dev.sh installs it)")
    assert missing_tools() == []  # xvfb, xdotool, imagemagick come with it in dev.sh
    sc.make_synthetic_scene(tmp_path / "S", n_views=3, width=96, height=72, cell_size=0.15, seed=1)
    res = pipeline.run(tmp_path / "S", t_npm=20, atlas_size=256, seams=False)
    files = res.save(tmp_path / "O", save_images=True, selection_view="none")
    project = Path(files["meshlab_project"]).resolve()
    mesh = trimesh.load(res.scene.mesh, process=False)
    view = write_view_state(res.scene.views[res.correction.reference], tmp_path / "view.xml",
                            scene_diagonal=float(np.linalg.norm(np.ptp(mesh.vertices, axis=0))))

    shot = screenshot_meshlab(project, tmp_path / "shot.png", view=view, timeout=90)

    assert str(project) in shot.title  # MeshLab names the project once it has loaded it
    assert shot.log.count("Opened mesh") == 1 and "mesh_meshlab.ply" in shot.log
    h, w, _ = shot.image.shape
    gl = shot.image[h // 10: h * 8 // 10, : w // 2].reshape(-1, 3)  # the 3D view: the textured room
    assert gl.std(axis=0).mean() > 20 and len(np.unique(gl, axis=0)) > 200
    assert shot.png.is_file() and shot.png.stat().st_size < 300_000
