"""Screenshots of the native MeshLab plugin at work: its Filters > Texture menu entry, its dialog, its result.

What it shows: Debian's MeshLab with a synthetic room's project (a mesh and 8 registered photos);
the plugin's "Seamless texture from rasters (o3d_seqcc)" picked from the Filters > Texture menu
(with its tooltip), its parameter dialog (the library's defaults and help texts), and the
textured mesh it adds as a new, current layer, seen through one of the photos' cameras. MeshLab
runs on a private virtual display (Xvfb) and is driven with the keyboard and the mouse the way a
user would (xdotool); docs/meshlab_plugin_menu.png, docs/meshlab_plugin_dialog.png and
docs/meshlab_plugin_result.jpg were made this way. By hand, in a desktop session:

    o3d-seqcc synthetic room --views 8 --seen-only && python -c "import o3d_seqcc as sc; \\
        sc.io.meshlab.save_mlp(sc.load_scene('room'), 'room/project.mlp')"
    meshlab room/project.mlp            # Filters > Texture > Seamless texture from rasters (o3d_seqcc), Apply

How to run (from any folder; needs the plugin, which ./dev.sh setup builds and installs, and the
Debian/Ubuntu packages meshlab xvfb xdotool imagemagick):

    python examples/meshlab_plugin_screenshots.py [--docs DIR] [--out DIR]
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import o3d_seqcc as sc
from meshlab_filters import MeshLabSession, save_screenshot, write_view_state
from meshlab_filters.native import TEXTURE_TITLE
from o3d_seqcc.io.meshlab import save_mlp

PLUGIN = Path("/usr/lib/x86_64-linux-gnu/meshlab/plugins/libfilter_o3d_seqcc.so")
# keyboard path to the filter in MeshLab 2020.09 (checked afterwards against MeshLab's log): the Filters menu
# (Alt+L), Texture is its last-but-one submenu, the filter its 7th entry from the end (alphabetical order)
MENU_KEYS = ("Up", "Up", "Right", *["Up"] * 7)
HIGHLIGHT = (48, 140, 198)  # the selected menu entry's colour (Qt's default style on Debian)


def _highlight(screen: np.ndarray) -> np.ndarray:
    """Where the screen shows the selection colour (menu entries, the layer dialog's current rows)."""
    return np.abs(screen.astype(int) - HIGHLIGHT).sum(axis=2) < 30


def _press(ml: MeshLabSession, key: str, timeout: float = 6.0) -> tuple[int, int, int]:
    """Press ``key`` in an open menu and wait for the entry it selects: (x, y0, y1) of the new highlight.

    A loaded machine draws menus late and a key sent before the menu shows is lost: then it is sent again.
    """
    before = _highlight(ml.grab(screen=True))
    for _ in range(2):
        ml.key(key, delay=0.2)
        deadline = time.perf_counter() + timeout
        while time.perf_counter() < deadline:
            new = _highlight(ml.grab(screen=True)) & ~before
            ys, xs = np.nonzero(new)
            if ys.size > 200:  # a menu entry's bar, not a few pixels of a redrawn icon
                return int(np.median(xs)), int(ys.min()), int(ys.max())
            time.sleep(0.3)
    raise RuntimeError(f"MeshLab's menu did not react to {key}")


def _content_box(image: np.ndarray) -> tuple[int, int, int, int]:
    """Bounding box (x0, y0, x1, y1) of what is not the black root window."""
    ys, xs = np.nonzero(image.max(axis=2) > 0)
    return int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1


def run(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--docs", type=Path, default=None, help="folder for the three pictures (default: OUT)")
    p.add_argument("--out", type=Path, default=None, help="working folder (default: a temporary one)")
    args = p.parse_args(argv)
    if not PLUGIN.is_file():
        print(f"{PLUGIN} not found: build and install the plugin first (./dev.sh setup)", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory(prefix="meshlab_plugin_shots_") as tmp:
        work = (args.out or Path(tmp)).resolve()
        docs = (args.docs or work).resolve()
        room = sc.make_synthetic_scene(work / "room", n_views=8, width=320, height=240, seed=2, seen_only=True,
                                       overwrite=True)
        scene = sc.load_scene(room.root)
        project = save_mlp(scene, work / "room" / "project.mlp")
        out = work / "room" / "seqcc_textured"  # the filter's default output folder: next to the project
        if out.exists():
            shutil.rmtree(out)
        import trimesh

        mesh = trimesh.load(scene.mesh, process=False)
        # photo 3's camera, 1.5 m further back and with a wider lens: the wall it sees and what is around
        v = scene.views[3]
        centre = -v.rotation.T @ v.translation - 1.5 * (v.rotation.T @ [0.0, 0.0, 1.0])
        ext = v.extrinsic.copy()
        ext[:3, 3] = -v.rotation @ centre
        K = v.intrinsic.copy()
        K[:2, :2] *= 0.6
        view = write_view_state(replace(v, extrinsic=ext, intrinsic=K), work / "view.xml",
                                scene_diagonal=float(np.linalg.norm(np.ptp(mesh.vertices, axis=0))))
        t0 = time.perf_counter()
        with MeshLabSession(project, view=view, window=(1240, 900)) as ml:
            ml.settled()
            # 1. Filters > Texture > the filter, the mouse on it for its tooltip (the filter's description)
            ml.move(*ml.size)  # the pointer away from where the menus open
            ml.key("alt+l", delay=2.0)
            for key in MENU_KEYS:
                x, y0, y1 = _press(ml, key)
            ml.move(x, (y0 + y1) // 2)
            time.sleep(2.5)
            menu = ml.grab(screen=True)
            bx0, by0, bx1, by1 = _content_box(menu)
            save_screenshot(menu[by0:by1, bx0:bx1], docs / "meshlab_plugin_menu.png", colors=128)
            # 2. its dialog (a dock floating over the window): the library's parameters, defaults and help texts
            ml.key("Return", delay=1.0)
            dx, dy, dw, dh = ml.find(TEXTURE_TITLE)
            time.sleep(1.5)
            dialog = ml.grab(screen=True)
            wx0, wy0, wx1, wy1 = _content_box(dialog)
            save_screenshot(dialog[wy0:wy1, wx0:wx1], docs / "meshlab_plugin_dialog.png", colors=128)
            # 3. Apply (the dialog's bottom-right button), then the new layer
            ml.click(dx + dw * 3 // 4, dy + dh - 24)
            log = ml.wait_log("o3d_seqcc: running", timeout=30)
            if " -v run " not in log:
                raise RuntimeError("the menu entry reached is not the plugin's texture filter (MeshLab's menus differ "
                                   "from 2020.09's): adjust MENU_KEYS")
            ml.wait_log("o3d_seqcc: added layer", timeout=900, fail="Filter failed")
            ml.click(dx + dw // 4, dy + dh - 24)  # Close
            ml.move(*ml.size)
            result = ml.settled(screen=True)
            save_screenshot(result[wy0:wy1, wx0:wx1], docs / "meshlab_plugin_result.jpg", quality=85)
        for name in ("meshlab_plugin_menu.png", "meshlab_plugin_dialog.png", "meshlab_plugin_result.jpg"):
            print(f"{docs / name} ({(docs / name).stat().st_size // 1024} KB)")
        print(f"MeshLab ran {TEXTURE_TITLE!r} from its Filters > Texture menu in {time.perf_counter() - t0:.1f} s; "
              f"the new layer's files are in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(run())
