"""The native MeshLab plugin (meshlab_filters/plugin/, built and installed by ./dev.sh setup) in meshlabserver.

meshlabserver runs under a virtual display with GLX (it needs an OpenGL context even to list the
filters). The filter scripts are run with a desktop-like environment (no venv on PATH, no
O3D_SEQCC_EXECUTABLE): the plugin must find the o3d-seqcc it was built with by itself.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import o3d_seqcc as sc
from meshlab_filters.native import CORRECT_TITLE, TEXTURE_TITLE, cli_arguments, filter_script, native_filters
from o3d_seqcc.io.meshlab import load_mlp, save_mlp

PLUGIN = Path("/usr/lib/x86_64-linux-gnu/meshlab/plugins/libfilter_o3d_seqcc.so")
XVFB = ["xvfb-run", "-a", "-s", "-screen 0 1280x1024x24 +extension GLX"]
# a desktop session's PATH: no virtual environment on it
DESKTOP_PATH = "/usr/local/bin:/usr/bin:/bin"

pytestmark = pytest.mark.skipif(
    not PLUGIN.is_file() or shutil.which("meshlabserver") is None or shutil.which("xvfb-run") is None,
    reason=f"the MeshLab plugin is not built ({PLUGIN} missing; ./dev.sh setup builds and installs it, CI does)")


def meshlabserver(args: list[str], tmp_path: Path, *, desktop: bool = True, timeout: float = 600) -> tuple[int, str]:
    """Run meshlabserver headless; returns (exit code, stdout + stderr)."""
    home = tmp_path / "home"
    home.mkdir(exist_ok=True)
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "VIRTUAL_ENV", "O3D_SEQCC_EXECUTABLE",
                                                             "PYTHONPATH", "QT_PLUGIN_PATH")}
    env.update(HOME=str(home), XDG_RUNTIME_DIR=str(home), QT_QPA_PLATFORM="xcb")
    if desktop:
        env["PATH"] = DESKTOP_PATH
    r = subprocess.run([*XVFB, "meshlabserver", *args], env=env, cwd=tmp_path, capture_output=True, text=True,
                       timeout=timeout)
    return r.returncode, r.stdout + r.stderr


@pytest.fixture(scope="module")
def room(tmp_path_factory) -> Path:
    """A synthetic room's MeshLab project: project.mlp (mesh + 6 registered rasters)."""
    root = tmp_path_factory.mktemp("plugin_room")
    scene = sc.make_synthetic_scene(root / "room", n_views=6, width=128, height=96, seed=3, seen_only=True,
                                    cell_size=0.2)
    return _float_cameras(save_mlp(sc.load_scene(scene.root), root / "room" / "project.mlp"))


def _float_cameras(project: Path) -> Path:
    """Round the project's camera numbers to float32, in place.

    Debian's MeshLab holds a raster's shot in single precision, so the plugin hands o3d-seqcc the cameras rounded
    to float32 (written with 9 digits: exactly). A project whose numbers are floats already is the same project in
    MeshLab and in `o3d-seqcc`, so their outputs can be compared byte for byte.
    """
    import xml.etree.ElementTree as ET

    tree = ET.parse(project)
    for cam in tree.getroot().iter("VCGCamera"):
        for key, value in cam.attrib.items():
            if key not in ("CameraType", "ViewportPx"):
                cam.set(key, " ".join(f"{np.float32(float(x)):.9g}" for x in value.split()))
    tree.write(project, encoding="utf-8")
    return project


def _sections(dump: str) -> dict[str, str]:
    parts = re.split(r"\n\\section f\d+ ", dump)
    return {p.split(" \n", 1)[0].strip(): p for p in parts[1:]}


def test_meshlabserver_lists_both_filters_with_their_parameters(tmp_path):
    code, log = meshlabserver(["-d", str(tmp_path / "dump.txt")], tmp_path)
    assert code == 0, log[-3000:]
    sections = _sections((tmp_path / "dump.txt").read_text(errors="replace"))
    types = {"bool": "Bool", "int": "Int", "float": "Float", "string": "String", "enum": "Enum", "raster": "Enum"}
    for f in native_filters():
        assert f["title"] in sections, sorted(sections)[-5:]
        rows = re.findall(r"<TR><TD> \\c (\w+)  </TD> <TD> (.*?) </TD> <TD><i> (.*?) -- </i></TD> </TR>",
                          sections[f["title"]])
        # every parameter of the table generated from the library, in order, with its label and help text
        assert rows == [(types[p["kind"]], p["label"], p["tooltip"]) for p in f["parameters"]]
        assert "Dal'Col" in sections[f["title"]]
    texture = {p["name"]: p for p in native_filters()[1]["parameters"]}
    assert {"reference", "method", "tnpm", "selection", "atlassize", "texelsperpixel", "savedir"} <= set(texture)
    from o3d_seqcc.texturing import TextureSettings

    assert texture["atlassize"]["default"] == str(TextureSettings().atlas_size)  # the library's default
    assert "Problem" not in log


def test_texture_filter_script_matches_o3d_seqcc_run(room, tmp_path):
    """The .mlx runs headless; the textured layer has the selection `o3d-seqcc run` makes on the project."""
    values = {"tnpm": 30, "atlassize": 512, "savedir": str(tmp_path / "textured")}
    (tmp_path / "tex.mlx").write_text(filter_script((TEXTURE_TITLE, values)))
    out_ply = tmp_path / "out.ply"
    code, log = meshlabserver(["-p", str(room), "-s", str(tmp_path / "tex.mlx"), "-o", str(out_ply), "-m", "wt"],
                              tmp_path)
    assert code == 0, log[-4000:]
    # the o3d-seqcc it was built with, found without PATH; the command line is cli_arguments'
    ran = re.search(r"o3d_seqcc: running (\S+) -v (.*) --progress-lines", log)
    assert ran and os.path.isabs(ran.group(1)) and not ran.group(1).startswith(tuple(DESKTOP_PATH.split(":")))
    args = cli_arguments(TEXTURE_TITLE, values)
    assert ran.group(2).split() == [args[0], ran.group(2).split()[1], *args[1:]]
    # progress streamed to meshlabserver's progress callback, in order, up to 100
    percents = [int(p) for p in re.findall(r"^(\d+)% o3d_seqcc run: ", log, re.M)]
    assert len(percents) >= 5 and percents == sorted(percents) and percents[-1] == 100
    assert "added layer 'mesh_textured'" in log and "Problem with filter" not in log

    out = tmp_path / "textured"
    assert (out / "mesh_meshlab.ply").is_file() and (out / "report.json").is_file()
    # meshlabserver saved the new, current layer: a textured mesh whose texture is in the output folder
    header = out_ply.read_bytes()[:600].decode("latin-1")
    texture = re.search(r"comment TextureFile (\S+)", header).group(1)
    assert Path(texture).is_file() and Path(texture).parent == out
    assert "property list uchar float texcoord" in header

    # `o3d-seqcc run` on the project, with the options the plugin passed
    cli = tmp_path / "cli"
    cmd = [sys.executable, "-m", "o3d_seqcc", "-q", args[0], str(room), *args[1:]]
    cmd[cmd.index("--out") + 1] = str(cli)
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    ours, theirs = np.load(out / "selection.npy"), np.load(cli / "selection.npy")
    assert ours.shape == theirs.shape  # one view per face of the mesh after faces no photo holds whole are split
    assert json.loads((cli / "report.json").read_text())["selection"]["input_faces"] == len(load_mlp_faces(room))
    np.testing.assert_array_equal(ours, theirs)
    assert len(np.unique(ours[ours >= 0])) >= 3  # a real selection: several rasters used


def load_mlp_faces(project: Path) -> np.ndarray:
    import trimesh

    return trimesh.load(load_mlp(project).mesh, process=False).faces


def test_correction_then_texture_script_replaces_the_rasters(room, tmp_path):
    script = filter_script((CORRECT_TITLE, {"tnpm": 30, "savedir": "corrected"}),
                           (TEXTURE_TITLE, {"colorcorrection": False, "atlassize": 512, "savedir": "textured"}))
    (tmp_path / "both.mlx").write_text(script)
    project = save_mlp(load_mlp(room), tmp_path / "room.mlp")  # the relative output folders go next to it
    code, log = meshlabserver(["-p", str(project), "-s", str(tmp_path / "both.mlx"), "-w", str(tmp_path / "out.mlp")],
                              tmp_path)
    assert code == 0, log[-4000:]
    corrected = tmp_path / "corrected"  # relative: next to the project
    assert " -v correct " in log and " -v texture " in log  # colour correction off: o3d-seqcc texture
    saved = load_mlp(tmp_path / "out.mlp")
    names = load_mlp(room).names
    assert [v.image for v in saved.views] == [corrected / "images" / f"{n}.png" for n in names]
    # the images are the ones `o3d-seqcc correct` writes for the project
    args = cli_arguments(CORRECT_TITLE, {"tnpm": 30, "savedir": str(tmp_path / "cli")})
    r = subprocess.run([sys.executable, "-m", "o3d_seqcc", "-q", args[0], str(room), *args[1:]], capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    for n in names:
        assert (corrected / "images" / f"{n}.png").read_bytes() == (tmp_path / "cli" / "images" / f"{n}.png").read_bytes()
    # the texturing that followed used the corrected rasters
    assert (tmp_path / "textured" / "mesh_meshlab.ply").is_file()
    textured = load_mlp(tmp_path / "textured" / "project.mlp")
    assert [v.image for v in textured.views] == [corrected / "images" / f"{n}.png" for n in names]


def test_failures_show_the_message_not_only_problem_with_filter(room, tmp_path):
    (tmp_path / "tex.mlx").write_text(filter_script((TEXTURE_TITLE, {"savedir": str(tmp_path / "t")})))
    # a mesh without rasters: the plugin's own message
    code, log = meshlabserver(["-i", str(room.parent / "mesh.ply"), "-s", str(tmp_path / "tex.mlx")], tmp_path)
    assert code != 0 and "Problem with filter" in log
    assert "o3d_seqcc: the document has no rasters: the filter needs registered photos" in log
    assert not (tmp_path / "t").exists()
    # o3d-seqcc's own error, with the dialog's names for the options
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "keep.txt").write_text("not ours")
    code, log = meshlabserver(["-p", str(room), "-s", str(tmp_path / "tex.mlx")], tmp_path)
    assert code != 0
    assert f"o3d_seqcc: output folder {tmp_path / 't'} exists and is not empty; choose another 'Output folder' " \
           "or pass 'Overwrite'" in log
    assert (tmp_path / "t" / "keep.txt").read_text() == "not ours"
    (tmp_path / "bad.mlx").write_text(filter_script((TEXTURE_TITLE, {"savedir": str(tmp_path / "u"), "tnpm": -3})))
    code, log = meshlabserver(["-p", str(room), "-s", str(tmp_path / "bad.mlx")], tmp_path)
    assert code != 0 and ("o3d_seqcc: argument 'Minimum overlap per graph edge': give 'auto' or a positive integer, "
                          "not '-3'") in log


MESHLAB_2025 = os.environ.get("O3D_SEQCC_MESHLAB_2025_SRC", "")


@pytest.mark.skipif(not (Path(MESHLAB_2025) / "src" / "common" / "plugins" / "interfaces" / "filter_plugin.h").is_file(),
                    reason="O3D_SEQCC_MESHLAB_2025_SRC is not a MeshLab 2025.07 source tree (git clone --recursive "
                    "--branch MeshLab-2025.07 https://github.com/cnr-isti-vclab/meshlab): no registry provides its "
                    "headers, so CI cannot build the plugin for pymeshlab")
def test_the_same_plugin_built_for_pymeshlab_runs_in_pymeshlab(room, tmp_path):
    """README's recipe: the plugin's sources against MeshLab 2025.07's headers and pymeshlab's library."""
    import pymeshlab

    lib = Path(pymeshlab.__file__).parent / "lib"
    plugin_src = Path(__file__).resolve().parents[2] / "meshlab_filters" / "plugin"
    exe = shutil.which("o3d-seqcc") or str(Path(sys.executable).parent / "o3d-seqcc")
    cfg = subprocess.run(["cmake", "-S", str(plugin_src), "-B", str(tmp_path / "b"), f"-DMESHLAB_SRC={MESHLAB_2025}/src",
                          "-DMESHLAB_SCALAR=double", f"-DMESHLAB_LIB_DIR={lib}", f"-DO3D_SEQCC_PYTHON={sys.executable}",
                          f"-DO3D_SEQCC_EXECUTABLE={exe}"], capture_output=True, text=True)
    assert cfg.returncode == 0, cfg.stdout[-2000:] + cfg.stderr[-2000:]
    build = subprocess.run(["cmake", "--build", str(tmp_path / "b"), "-j2"], capture_output=True, text=True)
    assert build.returncode == 0, build.stdout[-3000:]
    code = f"""
import pymeshlab
pymeshlab.load_plugin({str(tmp_path / 'b' / 'libfilter_o3d_seqcc.so')!r})
ms = pymeshlab.MeshSet()
ms.load_project({str(room)!r})
ms.apply_filter("seqcc_texture_from_rasters", tnpm=30, atlassize=512, savedir={str(tmp_path / 'out')!r})
print("layers", ms.mesh_number(), ms.current_mesh().label(), ms.current_mesh().has_wedge_tex_coord())
try:
    ms.apply_filter("seqcc_texture_from_rasters", tnpm=-3, savedir={str(tmp_path / 'bad')!r})
except pymeshlab.PyMeshLabException as e:
    print("error:", e)
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "layers 2 mesh_textured True" in r.stdout
    assert "'Minimum overlap per graph edge': give 'auto' or a positive integer, not '-3'" in r.stdout
    assert (tmp_path / "out" / "mesh_meshlab.ply").is_file()
