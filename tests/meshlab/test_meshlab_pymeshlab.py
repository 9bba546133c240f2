"""MeshLab agrees with us, and our filters run on a pymeshlab.MeshSet as MeshLab's own do.

- conventions: MeshLab's own ``compute_color_from_active_rasters_projection`` on a project we
  wrote colours the mesh as our projection does; a project pymeshlab saved loads in ours with the
  same cameras;
- filters (``meshlab_filters.apply``): parameter list, defaults = the library's, errors, and the
  two jobs on a MeshSet against known answers (ground truth of the synthetic scene, the library
  run on the same scene).
"""

from __future__ import annotations

import inspect
import os
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import numpy as np
import pymeshlab
import pytest
import trimesh

import meshlab_filters as mf
import o3d_seqcc as sc
from o3d_seqcc import pipeline
from o3d_seqcc.geometry.camera import project_points
from o3d_seqcc.errors import InputError
from o3d_seqcc.imaging.arrays import delta_e_2000, img_as_float, sample_colors
from o3d_seqcc.io.images import read_image
from o3d_seqcc.io.meshlab import MeshLayer, save_mlp
from o3d_seqcc.scene import Scene, View
from o3d_seqcc.texturing import TextureSettings

# --------------------------------------------------------------------------------------------
# conventions
# --------------------------------------------------------------------------------------------

# runs MeshLab's projection filter on a project (needs GL: a subprocess under xvfb-run)
_PROJECT_COLOURS = """
import sys, numpy as np, pymeshlab
ms = pymeshlab.MeshSet()
ms.load_project(sys.argv[1])
ms.compute_color_from_active_rasters_projection(blankcolor=pymeshlab.Color(255, 0, 255, 255))
np.save(sys.argv[2], ms.current_mesh().vertex_color_matrix())
"""


def _meshlab_colours(project: Path, out: Path) -> np.ndarray:
    from benchmarks.peers import QT_ENV, XVFB_ARGS, meshlab_available

    reason = meshlab_available()
    if reason:
        pytest.skip(reason)
    proc = subprocess.run([*XVFB_ARGS, sys.executable, "-c", _PROJECT_COLOURS, str(project), str(out)],
                          env={**os.environ, **QT_ENV}, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return np.load(out)


def test_meshlab_projection_colours_vertices_like_ours(tmp_path):
    """MeshLab's ``compute_color_from_active_rasters_projection`` on a project we wrote gives each
    vertex the colour our projection finds (``project_points``, vertices visible in the view).

    Measured (synthetic room, one 320 x 240 view, ground-truth image): mean CIEDE2000 0.25 with
    nearest-pixel sampling (MeshLab's), 1.89 bilinear; with the plain convention (no half-pixel
    shift) 3.90 and 3.50."""
    sc.make_synthetic_scene(tmp_path / "S", n_views=1, width=320, height=240, photometric="none")
    scene = sc.load_scene(tmp_path / "S")
    project = save_mlp(scene, tmp_path / "one_raster.mlp")
    ml = _meshlab_colours(project.resolve(), tmp_path / "ml.npy")[:, :3]

    vis = sc.compute_visibility(scene, split_faces=False)  # MeshLab colours the input mesh's vertices
    v = scene.views[0]
    assert len(ml) == len(vis.mesh.vertices)
    seen = np.zeros(len(ml), bool)
    seen[vis.mesh.faces[vis.usable[0]].ravel()] = True
    coloured = ~np.all(np.abs(ml - [1.0, 0.0, 1.0]) < 1e-6, axis=1)  # MeshLab leaves blankcolor where unseen
    both = seen & coloured
    assert seen.sum() > 1000 and both.sum() > 0.8 * seen.sum()
    uv, _ = project_points(vis.mesh.vertices[both], v.intrinsic, v.extrinsic)
    img = img_as_float(v.load_image())
    de_nearest = delta_e_2000(sample_colors(img, uv, interpolation="nearest"), ml[both]).mean()
    de_bilinear = delta_e_2000(sample_colors(img, uv, interpolation="bilinear"), ml[both]).mean()
    assert de_bilinear < 3.0  # the criterion
    assert de_nearest < 1.0   # the same pixels as MeshLab's (a half-pixel slip gives ~3.9)


def _rot(c: float, s: float, axis: int) -> np.ndarray:
    R = np.eye(3)
    i, j = [k for k in range(3) if k != axis]
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def test_project_saved_by_pymeshlab_loads_in_ours(tmp_path):
    """Ours -> pymeshlab ``load_project`` / ``save_project`` -> ``o3d_seqcc.load_scene``: the same cameras.

    MeshLab keeps cameras in float32 and writes 6 significant digits, so the cameras are chosen
    exactly representable there (rotations with entries like 0.48, pixel size 1/32 mm): the
    comparison is then exact to 1e-6, and any change of convention on pymeshlab's side (axes,
    translation sign, principal point origin) shows."""
    views = []
    rots = [_rot(0.6, 0.8, 2) @ _rot(0.8, 0.6, 0), _rot(0.8, -0.6, 1) @ _rot(0.6, 0.8, 0), _rot(0.0, 1.0, 2)]
    for k, (R, C, (w, h), f, c) in enumerate(zip(
            rots, [(0.25, -1.5, 2.125), (1.0, 0.5, -0.75), (-2.5, 0.125, 1.5)],
            [(640, 480), (320, 240), (200, 150)], [(500.0, 500.0), (250.0, 312.5), (160.0, 160.0)],
            [(319.5, 239.5), (150.25, 130.75), (99.5, 74.5)])):
        ext = np.eye(4)
        ext[:3, :3] = R
        ext[:3, 3] = -R @ np.array(C)
        K = np.array([[f[0], 0, c[0]], [0, f[1], c[1]], [0, 0, 1]])
        img = tmp_path / f"v{k}.png"
        sc.io.images.write_image(img, np.zeros((h, w, 3), np.uint8))
        views.append(View(name=f"v{k}", image=img, intrinsic=K, extrinsic=ext, width=w, height=h))
    trimesh.creation.box().export(tmp_path / "box.ply")
    scene = Scene(mesh=tmp_path / "box.ply", views=tuple(views))
    ours = save_mlp(scene, tmp_path / "ours.mlp", pixel_size_mm=1 / 32)
    ms = pymeshlab.MeshSet()
    ms.load_project(str(ours.resolve()))
    assert ms.raster_number() == 3
    (tmp_path / "sub").mkdir()
    theirs = tmp_path / "sub" / "saved_by_pymeshlab.mlp"
    ms.save_project(str(theirs.resolve()))
    assert 'BinaryData="0"' in theirs.read_text()  # pymeshlab's own writer, not ours
    back = sc.load_scene(theirs, allow_unseen=True)  # a box and cameras chosen for exact numbers, not a view of it
    assert back.names == scene.names and back.mesh.resolve() == scene.mesh.resolve()
    for a, b in zip(scene.views, back.views):
        assert (b.width, b.height) == (a.width, a.height) and b.image.resolve() == a.image.resolve()
        np.testing.assert_allclose(b.intrinsic, a.intrinsic, atol=1e-6, rtol=0)
        np.testing.assert_allclose(b.extrinsic, a.extrinsic, atol=1e-6, rtol=0)


# --------------------------------------------------------------------------------------------
# filters: parameters and errors
# --------------------------------------------------------------------------------------------


def test_parameter_list_is_the_library_defaults(capsys):
    assert mf.filter_list() == ["seqcc_color_correct_rasters", "seqcc_texture_from_rasters"]
    cc = mf.get_filter("seqcc_color_correct_rasters")
    lib = inspect.signature(pipeline.correct_scene).parameters
    for p in cc.parameters:
        if p.keyword in lib:
            assert p.default == lib[p.keyword].default, p.name
    assert cc.parameter("tnpm").keyword == "t_npm" and cc.parameter("graphweight").values == ("paper", "log")
    tx = mf.get_filter("seqcc_texture_from_rasters")
    ts = TextureSettings()
    for fld in fields(TextureSettings):
        p = tx.parameter(fld.name.replace("_", ""))
        assert (p.keyword, p.default) == (fld.name, getattr(ts, fld.name))
    assert tx.parameter("formats").default == ",".join(pipeline.DEFAULT_FORMATS)
    for f in (cc, tx):
        assert all(p.description and p.label for p in f.parameters)
        assert len({p.name for p in f.parameters}) == len(f.parameters)
        mf.print_filter_parameter_list(f.name)
        text = capsys.readouterr().out
        assert text.startswith(f"{f.name} filter") and text == mf.filter_parameter_text(f.name)
        for p in f.parameters:
            assert f"\t{p.name} : {p.type.__name__} = {p.default!r}" in text
    assert "\tmethod : str = 'seqcc-global' (or int = " in mf.filter_parameter_text(cc.name)  # the default
    with pytest.raises(InputError, match="seqcc_color_correct_rasters, seqcc_texture_from_rasters"):
        mf.print_filter_parameter_list("compute_color_from_active_rasters_projection")


def test_apply_rejects_bad_calls(tmp_path):
    ms = pymeshlab.MeshSet()
    with pytest.raises(InputError, match="unknown MeshLab filter 'seqcc_colour'.*valid: seqcc_color_correct_rasters"):
        mf.apply(ms, "seqcc_colour")
    with pytest.raises(TypeError, match=r"unknown parameter\(s\) \['t_npm'\]; valid: reference, method, tnpm"):
        mf.apply(ms, "seqcc_color_correct_rasters", t_npm=50)
    with pytest.raises(InputError, match="'method'.*'fancy' is not a possible value.*'seqcc'"):
        mf.apply(ms, "seqcc_color_correct_rasters", method="fancy")
    with pytest.raises(InputError, match="enum index 99 out of range"):
        mf.apply(ms, "seqcc_texture_from_rasters", selection=99)
    with pytest.raises(InputError, match="'tnpm' must be an int or 'auto', got '50'"):
        mf.apply(ms, "seqcc_color_correct_rasters", tnpm="50")
    with pytest.raises(InputError, match="must be a pymeshlab.MeshSet"):
        mf.apply("project.mlp", "seqcc_color_correct_rasters")
    with pytest.raises(InputError, match="holds no mesh"):
        mf.apply(ms, "seqcc_color_correct_rasters", savedir=str(tmp_path / "x"))
    trimesh.creation.box().export(tmp_path / "box.ply")
    ms.load_new_mesh(str(tmp_path / "box.ply"))
    with pytest.raises(InputError, match="holds no rasters"):
        mf.apply(ms, "seqcc_texture_from_rasters", savedir=str(tmp_path / "x"))
    assert not (tmp_path / "x").exists()


# --------------------------------------------------------------------------------------------
# filters: the jobs on a MeshSet
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    root = tmp_path_factory.mktemp("meshset")
    syn = sc.make_synthetic_scene(root / "S", n_views=4, width=96, height=72, cell_size=0.15, seed=1)
    return syn, sc.load_scene(root / "S")


def test_color_correct_rasters_on_a_meshset(small, tmp_path):
    """The MeshSet's rasters are replaced by corrected ones (closer to the ground truth), its mesh
    layer (placed by a matrix) is kept, and the written project is what the MeshSet holds."""
    syn, scene = small
    M = np.eye(4)
    M[:3, :3] = _rot(0.6, 0.8, 2)
    M[:3, 3] = [0.5, -1.0, 0.25]
    mesh = trimesh.load(scene.mesh, process=False)
    local = np.c_[mesh.vertices, np.ones(len(mesh.vertices))] @ np.linalg.inv(M).T
    trimesh.Trimesh(local[:, :3], mesh.faces, process=False).export(tmp_path / "placed.ply")
    project = save_mlp(scene, tmp_path / "in.mlp", layers=[MeshLayer(tmp_path / "placed.ply", label="room", matrix=M)])
    ms = pymeshlab.MeshSet()
    ms.load_project(str(project.resolve()))
    out = mf.apply(ms, "seqcc_color_correct_rasters", tnpm=20, metrics=False, savedir=str(tmp_path / "cc"))

    assert (ms.mesh_number(), ms.raster_number()) == (1, len(scene.views))
    layer = ms.current_mesh()
    assert layer.label() == "room"
    np.testing.assert_allclose(layer.transform_matrix(), M, atol=1e-6)
    np.testing.assert_allclose(layer.transformed_vertex_matrix(), mesh.vertices, atol=1e-5)
    ms.save_project(str((tmp_path / "resaved.mlp").resolve()))
    resaved = sc.load_scene(tmp_path / "resaved.mlp")  # what the MeshSet now holds
    assert resaved.names == scene.names == list(out["images"])
    for v, w in zip(scene.views, resaved.views):
        assert w.image.resolve() == Path(out["images"][v.name]).resolve()
        np.testing.assert_allclose(w.extrinsic, v.extrinsic @ M, atol=1e-5)  # load_mlp folds the placement in
    assert out["reference"] == "v00" and out["unreachable"] == []
    for i, v in enumerate(scene.views[1:], start=1):
        gt = img_as_float(syn.load_gt(i))
        before = delta_e_2000(img_as_float(v.load_image()), gt).mean()
        after = delta_e_2000(img_as_float(read_image(out["images"][v.name])), gt).mean()
        assert after < 3.0 and after < 0.4 * before, (v.name, before, after)
    assert (tmp_path / "cc" / "report.json").is_file()


def test_texture_from_rasters_on_a_meshset(small, tmp_path):
    """The textured mesh becomes a new, current layer; the job is the library's with the given
    parameters (same selection as ``pipeline.texture`` on the MeshSet's scene)."""
    from meshlab_filters.meshset import meshset_scene

    syn, scene = small
    ms = pymeshlab.MeshSet()
    ms.load_project(str(save_mlp(scene, tmp_path / "in.mlp").resolve()))
    out = mf.apply(ms, "seqcc_texture_from_rasters", colorcorrection=False, selection="largest-area", atlassize=256,
                   seams=False, formats="glb", savedir=str(tmp_path / "tex"))
    assert (ms.mesh_number(), ms.raster_number()) == (2, len(scene.views))
    m = ms.current_mesh()
    assert m.id() == out["mesh_id"] and m.label().endswith("_textured") and m.has_wedge_tex_coord()
    assert m.face_number() == out["faces"] >= len(trimesh.load(scene.mesh, process=False).faces)  # parts of faces
    assert len(m.textures()) == 1 and out["reference"] is None
    assert {"glb", "meshlab_mesh", "meshlab_project"} <= set(out["files"]) and "obj" not in out["files"]
    fresh = pymeshlab.MeshSet()
    fresh.load_project(str((tmp_path / "in.mlp").resolve()))
    (tmp_path / "ref").mkdir()
    ref = pipeline.texture(meshset_scene(fresh, tmp_path / "ref"), selection="largest-area", atlas_size=256, seams=False)
    np.testing.assert_array_equal(np.load(tmp_path / "tex" / "selection.npy"), ref.selection)
    assert out["atlas_size"] == ref.textured.atlas_size
