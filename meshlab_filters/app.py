"""The MeshLab application itself, run headless on a project: opened, drawn, photographed.

:func:`screenshot_meshlab` starts a private virtual X display (``Xvfb -displayfd``, with GLX),
opens the project in MeshLab (optionally at a camera given by a view-state file,
:func:`write_view_state`), waits until MeshLab's log reports every mesh layer opened
(``LOG: 0 Opened mesh ...``; its output is made line-buffered with ``stdbuf``) and the window
has looked the same for a second, saves a screenshot of the window and stops MeshLab. The window
title names the project from the start, so it proves nothing by itself. A MeshLab that dies while
loading (e.g. MeshLab 2020.09 on any OBJ layer) raises with the end of its log.

Needs the Debian / Ubuntu packages ``meshlab xvfb xdotool imagemagick`` (and coreutils'
``stdbuf``; ``./dev.sh`` installs them). MeshLab's settings go to a temporary home, so runs do
not depend on earlier ones.
"""

from __future__ import annotations

import logging
import os
import select
import shutil
import subprocess
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from o3d_seqcc.errors import InputError
from o3d_seqcc.io.files import atomic_write_bytes
from o3d_seqcc.io.meshlab import vcg_camera_attributes
from o3d_seqcc.scene import View

__all__ = ["MeshLabShot", "TOOLS", "missing_tools", "screenshot_meshlab", "write_view_state"]

logger = logging.getLogger(__name__)

#: program -> Debian package
TOOLS = {"meshlab": "meshlab", "Xvfb": "xvfb", "xdotool": "xdotool", "import": "imagemagick", "stdbuf": "coreutils"}
#: identical window captures, 0.5 s apart, that count as drawn
SETTLED_FRAMES = 3


@dataclass(frozen=True)
class MeshLabShot:
    """What :func:`screenshot_meshlab` saw.

    Attributes
    ----------
    png : pathlib.Path
        The screenshot of MeshLab's window.
    title : str
        The window title (MeshLab 2020.09: ``MeshLab 2020.09 - [/abs/project.mlp]``).
    image : (H, W, 3) uint8
        The screenshot as captured (before the palette reduction of ``png``).
    log : str
        MeshLab's standard output and error (``LOG: 0 Opened mesh ...`` per layer).
    seconds : float
        From start to screenshot.
    """

    png: Path
    title: str
    image: np.ndarray
    log: str
    seconds: float


def missing_tools() -> list[str]:
    """The Debian packages whose programs :func:`screenshot_meshlab` needs and cannot find."""
    return [pkg for prog, pkg in TOOLS.items() if shutil.which(prog) is None]


def write_view_state(view: View, path: str | os.PathLike, *, scene_diagonal: float) -> Path:
    """Write a MeshLab view-state file (``<!DOCTYPE ViewState>``) that puts MeshLab's camera at ``view``.

    MeshLab reads it when given on its command line after the project (``meshlab p.mlp v.xml``),
    as the file its *Copy shot* command writes.

    Parameters
    ----------
    view : View
        Camera to look through.
    path : path-like
        Output ``.xml``.
    scene_diagonal : float
        Bounding-box diagonal of what is shown (sets the trackball scale as MeshLab's own raster
        view does, ``3 / diagonal``, and the clipping planes).

    Returns
    -------
    pathlib.Path
    """
    if not scene_diagonal > 0:
        raise InputError(f"scene_diagonal must be > 0, got {scene_diagonal}")
    root = ET.Element("project")
    ET.SubElement(root, "VCGCamera", vcg_camera_attributes(view))
    ET.SubElement(root, "ViewSettings", TrackScale=repr(3.0 / scene_diagonal), NearPlane=repr(0.01 * scene_diagonal),
                  FarPlane=repr(10.0 * scene_diagonal))
    text = "<!DOCTYPE ViewState>\n" + ET.tostring(root, encoding="unicode") + "\n"
    return atomic_write_bytes(Path(path), text.encode("utf-8"))


def _start_xvfb(size: tuple[int, int], log: Path, timeout: float) -> tuple[subprocess.Popen, str]:
    """A private X server with GLX on the first free display; returns it and ``":N"``."""
    r, w = os.pipe()
    with open(log, "wb") as err:
        proc = subprocess.Popen(["Xvfb", "-displayfd", str(w), "-screen", "0", f"{size[0]}x{size[1]}x24",
                                 "+extension", "GLX", "-nolisten", "tcp"],
                                pass_fds=(w,), stdout=subprocess.DEVNULL, stderr=err)
    os.close(w)
    text, deadline = b"", time.monotonic() + timeout
    try:
        # Xvfb writes the number, then a newline: closing the pipe before the newline kills it
        while not text.endswith(b"\n") and time.monotonic() < deadline:
            ready, _, _ = select.select([r], [], [], max(0.0, deadline - time.monotonic()))
            chunk = os.read(r, 64) if ready else b""
            if not chunk:
                break
            text += chunk
    finally:
        os.close(r)
    number = text.decode().strip()
    if not number.isdigit():
        _stop(proc)
        raise RuntimeError(f"Xvfb did not start within {timeout:.0f} s: {log.read_text(errors='replace')[-500:]}")
    return proc, f":{number}"


def _run(cmd: list[str], env: dict, *, binary: bool = False) -> str | bytes:
    res = subprocess.run(cmd, env=env, capture_output=True, timeout=30)
    return res.stdout if binary else res.stdout.decode(errors="replace").strip()


def _grab(window: str, env: dict) -> np.ndarray | None:
    import cv2

    data = _run(["import", "-window", window, "png:-"], env, binary=True)
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR) if data else None
    return None if img is None else img[..., ::-1].copy()


def _stop(proc: subprocess.Popen | None) -> None:
    if proc is not None and proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def screenshot_meshlab(
    project: str | os.PathLike,
    png: str | os.PathLike,
    *,
    view: str | os.PathLike | None = None,
    size: tuple[int, int] = (1280, 1024),
    timeout: float = 120.0,
    colors: int | None = 256,
) -> MeshLabShot:
    """Open ``project`` in the MeshLab application on a virtual display and save a screenshot of its window.

    Parameters
    ----------
    project : path-like
        A MeshLab project (``.mlp``) or mesh file.
    png : path-like
        Output PNG (written atomically).
    view : path-like, optional
        View-state file (:func:`write_view_state`): MeshLab's camera; default MeshLab's own (for a
        project with rasters: the current raster's camera).
    size : (int, int), default (1280, 1024)
        Virtual screen size (MeshLab opens an 853 x 795 window on it).
    timeout : float, default 120
        Seconds to wait for the project to load and the drawing to settle.
    colors : int or None, default 256
        Save the PNG with an adaptive palette of this many colours (a screenshot stays well under
        300 KB); None keeps full RGB.

    Returns
    -------
    MeshLabShot

    Raises
    ------
    InputError
        ``project`` or ``view`` not found.
    RuntimeError
        A needed program is missing (the message names the packages), MeshLab exited while
        loading (with the end of its log), or the timeout passed.
    """
    project = Path(project).resolve()
    if not project.is_file():
        raise InputError(f"project: {project} not found")
    if view is not None and not Path(view).is_file():
        raise InputError(f"view: {view} not found; write one with write_view_state(...)")
    missing = missing_tools()
    if missing:
        raise RuntimeError(f"cannot run MeshLab headless: install {' '.join(missing)} (apt-get install -y "
                           f"{' '.join(missing)})")
    t0 = time.perf_counter()
    xvfb = app = None
    with tempfile.TemporaryDirectory(prefix="seqcc_meshlab_app_") as home:
        os.chmod(home, 0o700)
        log_path = Path(home) / "meshlab.log"
        try:
            xvfb, display = _start_xvfb(size, Path(home) / "xvfb.log", timeout=30)
            env = {**os.environ, "DISPLAY": display, "HOME": home, "XDG_CONFIG_HOME": home, "XDG_RUNTIME_DIR": home,
                   "QT_QPA_PLATFORM": "xcb"}
            env.pop("QT_PLUGIN_PATH", None)  # Debian's MeshLab uses the system Qt and its own plugins
            cmd = ["stdbuf", "-oL", "-eL", "meshlab", str(project)] + ([str(Path(view).resolve())] if view else [])
            with open(log_path, "wb") as log:
                app = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, cwd=home)
            window, title, image, same = "", "", None, 0
            layers = _mesh_layers(project)
            deadline = time.perf_counter() + timeout
            while same < SETTLED_FRAMES - 1:
                if app.poll() is not None:
                    tail = "\n".join(log_path.read_text(errors="replace").splitlines()[-8:])
                    raise RuntimeError(f"MeshLab exited with code {app.returncode} while opening {project}:\n{tail}")
                if time.perf_counter() > deadline:
                    raise RuntimeError(f"MeshLab did not finish drawing {project} within {timeout:.0f} s "
                                       f"(window {title!r}, {log_path.read_text(errors='replace').count('Opened mesh')}"
                                       f" of {layers} mesh layers opened)")
                time.sleep(0.5)
                if not window:
                    window = (_run(["xdotool", "search", "--onlyvisible", "--name", "^MeshLab"], env).split()
                              or [""])[0]
                    continue
                if log_path.read_text(errors="replace").count("Opened mesh") < layers:
                    continue
                title = _run(["xdotool", "getwindowname", window], env)
                last, image = image, _grab(window, env)
                same = same + 1 if (image is not None and last is not None and image.shape == last.shape
                                    and np.array_equal(image, last)) else 0
            seconds = time.perf_counter() - t0
        finally:
            _stop(app)
            _stop(xvfb)
        log_text = log_path.read_text(errors="replace") if log_path.is_file() else ""
    out = _save_png(image, Path(png), colors)
    logger.info("MeshLab opened %s (%s) in %.1f s -> %s", project, title, seconds, out)
    return MeshLabShot(png=out, title=title, image=image, log=log_text, seconds=seconds)


def _mesh_layers(project: Path) -> int:
    """Mesh layers MeshLab will open: the ``MLMesh`` elements of a project, 1 for a mesh file."""
    if project.suffix.lower() != ".mlp":
        return 1
    text = project.read_text(encoding="utf-8", errors="replace").replace("<!DOCTYPE MeshLabDocument>", "")
    try:
        return len(ET.fromstring(text).findall("./MeshGroup/MLMesh"))
    except ET.ParseError:
        raise InputError(f"project: {project} is not a valid MeshLab project XML") from None


def _save_png(image: np.ndarray, path: Path, colors: int | None) -> Path:
    import io

    from PIL import Image

    im = Image.fromarray(image)
    if colors:
        im = im.quantize(int(colors), dither=Image.Dither.NONE)
    buf = io.BytesIO()
    im.save(buf, format="PNG", optimize=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_bytes(path, buf.getvalue())
