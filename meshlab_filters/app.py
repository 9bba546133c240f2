"""The MeshLab application itself, run headless on a project: opened, drawn, driven, photographed.

:class:`MeshLabSession` starts a private virtual X display (``Xvfb -displayfd``, with GLX), opens
the project in MeshLab (optionally at a camera given by a view-state file,
:func:`write_view_state`), waits until MeshLab's log reports every mesh layer opened
(``LOG: 0 Opened mesh ...``; its output is made line-buffered with ``stdbuf``), and then types
into it and captures its window or the whole screen (menus and dialogs included) with xdotool
and ImageMagick; :func:`screenshot_meshlab` is the one-shot: the window once it has looked the
same for a second. The window title names the project from the start, so it proves nothing by
itself. A MeshLab that dies while loading (e.g. MeshLab 2020.09 on any OBJ layer) raises with the
end of its log. ``examples/meshlab_plugin_screenshots.py`` drives the plugin's filter through the
Filters menu this way.

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
from o3d_seqcc.io.atomic import atomic_write_bytes
from o3d_seqcc.io.meshlab import vcg_camera_attributes
from o3d_seqcc.scene import View

__all__ = ["MeshLabSession", "MeshLabShot", "TOOLS", "missing_tools", "save_screenshot", "screenshot_meshlab",
           "write_view_state"]

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


class MeshLabSession:
    """The MeshLab application on a private virtual display, driven like a user would (xdotool).

    ``with MeshLabSession(project) as ml:`` starts ``Xvfb`` and MeshLab on ``project`` and returns
    once MeshLab's log reports every mesh layer opened and its window is shown; then
    :meth:`key` types into it, :meth:`grab` captures it (or the whole screen, with its menus),
    :meth:`wait_log` waits for a line of its log and :meth:`settled` waits until the window has
    looked the same for a second. Leaving the block stops MeshLab and the display. MeshLab's
    settings go to a temporary home, so sessions do not depend on earlier ones.

    Parameters
    ----------
    project : path-like
        A MeshLab project (``.mlp``) or mesh file.
    view : path-like, optional
        View-state file (:func:`write_view_state`): MeshLab's camera.
    size : (int, int), default (1280, 1024)
        Virtual screen size.
    window : (int, int), optional
        Resize MeshLab's window to this size (default: MeshLab's own, 853 x 795).
    timeout : float, default 120
        Seconds to wait for the project to load.
    """

    def __init__(self, project: str | os.PathLike, *, view: str | os.PathLike | None = None,
                 size: tuple[int, int] = (1280, 1024), window: tuple[int, int] | None = None,
                 timeout: float = 120.0) -> None:
        self.project = Path(project).resolve()
        if not self.project.is_file():
            raise InputError(f"project: {self.project} not found")
        if view is not None and not Path(view).is_file():
            raise InputError(f"view: {view} not found; write one with write_view_state(...)")
        missing = missing_tools()
        if missing:
            raise RuntimeError(f"cannot run MeshLab headless: install {' '.join(missing)} (apt-get install -y "
                               f"{' '.join(missing)})")
        self.view = None if view is None else Path(view).resolve()
        self.size, self.window_size, self.timeout = size, window, timeout
        self.window = ""
        self.env: dict = {}
        self._home: tempfile.TemporaryDirectory | None = None
        self._xvfb = self._app = None
        self._saved_log = ""
        self.t0 = time.perf_counter()

    @property
    def log(self) -> str:
        """MeshLab's standard output and error so far (all of it after the session)."""
        if self._home is None:
            return self._saved_log
        path = Path(self._home.name) / "meshlab.log"
        return path.read_text(errors="replace") if path.is_file() else ""

    def _check_alive(self, doing: str) -> None:
        if self._app is not None and self._app.poll() is not None:
            tail = "\n".join(self.log.splitlines()[-8:])
            raise RuntimeError(f"MeshLab exited with code {self._app.returncode} while {doing}:\n{tail}")

    def __enter__(self) -> "MeshLabSession":
        self._home = tempfile.TemporaryDirectory(prefix="seqcc_meshlab_app_")
        home = self._home.name
        os.chmod(home, 0o700)
        try:
            self._xvfb, display = _start_xvfb(self.size, Path(home) / "xvfb.log", timeout=30)
            self.env = {**os.environ, "DISPLAY": display, "HOME": home, "XDG_CONFIG_HOME": home,
                        "XDG_RUNTIME_DIR": home, "QT_QPA_PLATFORM": "xcb"}
            self.env.pop("QT_PLUGIN_PATH", None)  # Debian's MeshLab uses the system Qt and its own plugins
            cmd = ["stdbuf", "-oL", "-eL", "meshlab", str(self.project)] + ([str(self.view)] if self.view else [])
            with open(Path(home) / "meshlab.log", "wb") as log:
                self._app = subprocess.Popen(cmd, env=self.env, stdout=log, stderr=subprocess.STDOUT, cwd=home)
            layers = _mesh_layers(self.project)
            deadline = time.perf_counter() + self.timeout
            while not self.window or self.log.count("Opened mesh") < layers:
                self._check_alive(f"opening {self.project}")
                if time.perf_counter() > deadline:
                    raise RuntimeError(f"MeshLab did not open {self.project} within {self.timeout:.0f} s "
                                       f"({self.log.count('Opened mesh')} of {layers} mesh layers opened)")
                time.sleep(0.5)
                if not self.window:
                    self.window = (_run(["xdotool", "search", "--onlyvisible", "--name", "^MeshLab"], self.env).split()
                                   or [""])[0]
            if self.window_size:
                self._resize(self.window_size)
            _run(["xdotool", "windowfocus", self.window], self.env)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _resize(self, size: tuple[int, int]) -> None:
        # no --sync (without a window manager no configure event comes back); a window still settling may miss it
        want = f"Geometry: {size[0]}x{size[1]}"
        for _ in range(5):
            _run(["xdotool", "windowsize", self.window, *map(str, size)], self.env)
            time.sleep(1.0)
            if want in _run(["xdotool", "getwindowgeometry", self.window], self.env):
                return
        logger.warning("MeshLab's window was not resized to %dx%d", *size)

    def __exit__(self, *exc) -> None:
        _stop(self._app)
        _stop(self._xvfb)
        self._app = self._xvfb = None
        if self._home is not None:
            self._saved_log = self.log
            self._home.cleanup()
            self._home = None

    def title(self) -> str:
        """The window's title."""
        return _run(["xdotool", "getwindowname", self.window], self.env)

    def key(self, *keys: str, delay: float = 0.3) -> None:
        """Type ``keys`` (xdotool names: ``alt+l``, ``Up``, ``Return``) into the focused window."""
        for k in keys:
            self._check_alive(f"typing {k}")
            _run(["xdotool", "key", "--clearmodifiers", k], self.env)
            time.sleep(delay)

    def move(self, x: int, y: int) -> None:
        """Move the mouse pointer to screen pixel (x, y)."""
        _run(["xdotool", "mousemove", str(int(x)), str(int(y))], self.env)

    def click(self, x: int, y: int) -> None:
        """Left-click at screen pixel (x, y)."""
        self.move(x, y)
        time.sleep(0.3)
        _run(["xdotool", "click", "1"], self.env)

    def find(self, name: str, *, timeout: float = 10.0) -> tuple[int, int, int, int]:
        """Screen geometry (x, y, width, height) of the visible window whose title contains ``name``
        (a dialog, a floating dock); RuntimeError if none shows within ``timeout`` s."""
        import re

        deadline = time.perf_counter() + timeout
        while time.perf_counter() < deadline:
            pattern = re.sub(r"([.^$*+?()\[\]{}|\\])", r"\\\1", name)  # a POSIX regular expression
            for wid in _run(["xdotool", "search", "--onlyvisible", "--name", pattern], self.env).split():
                geo = _run(["xdotool", "getwindowgeometry", wid], self.env)
                m = re.search(r"Position: (\d+),(\d+).*Geometry: (\d+)x(\d+)", geo, re.S)
                if m:
                    return tuple(int(v) for v in m.groups())  # type: ignore[return-value]
            time.sleep(0.3)
        raise RuntimeError(f"no window titled {name!r} showed within {timeout:.0f} s")

    def grab(self, *, screen: bool = False) -> np.ndarray:
        """The window (or the whole screen, with the menus and dialogs over it) as (H, W, 3) uint8 RGB."""
        img = _grab("root" if screen else self.window, self.env)
        if img is None:
            raise RuntimeError("could not capture MeshLab's window (xdotool / imagemagick import failed)")
        return img

    def settled(self, *, screen: bool = False, timeout: float = 60.0) -> np.ndarray:
        """The window's image once it has looked the same for :data:`SETTLED_FRAMES` captures 0.5 s apart."""
        deadline = time.perf_counter() + timeout
        last, same = None, 0
        while same < SETTLED_FRAMES - 1:
            self._check_alive("drawing")
            if time.perf_counter() > deadline:
                raise RuntimeError(f"MeshLab's window did not settle within {timeout:.0f} s")
            time.sleep(0.5)
            image = self.grab(screen=screen)
            same = same + 1 if last is not None and image.shape == last.shape and np.array_equal(image, last) else 0
            last = image
        return last

    def wait_log(self, text: str, *, timeout: float = 600.0, fail: str | None = None) -> str:
        """Wait until MeshLab's log holds ``text`` (RuntimeError after ``timeout`` s or on ``fail``); the log."""
        deadline = time.perf_counter() + timeout
        while True:
            log = self.log
            if text in log:
                return log
            if fail is not None and fail in log:
                raise RuntimeError(f"MeshLab logged {fail!r}:\n" + "\n".join(log.splitlines()[-12:]))
            self._check_alive(f"waiting for {text!r}")
            if time.perf_counter() > deadline:
                raise RuntimeError(f"MeshLab's log did not show {text!r} within {timeout:.0f} s:\n"
                                   + "\n".join(log.splitlines()[-12:]))
            time.sleep(0.5)


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
    session = MeshLabSession(project, view=view, size=size, timeout=timeout)
    with session as ml:
        image = ml.settled(timeout=timeout)
        title = ml.title()
        seconds = time.perf_counter() - ml.t0
    out = save_screenshot(image, png, colors=colors)
    logger.info("MeshLab opened %s (%s) in %.1f s -> %s", session.project, title, seconds, out)
    return MeshLabShot(png=out, title=title, image=image, log=session.log, seconds=seconds)


def _mesh_layers(project: Path) -> int:
    """Mesh layers MeshLab will open: the ``MLMesh`` elements of a project, 1 for a mesh file."""
    if project.suffix.lower() != ".mlp":
        return 1
    text = project.read_text(encoding="utf-8", errors="replace").replace("<!DOCTYPE MeshLabDocument>", "")
    try:
        return len(ET.fromstring(text).findall("./MeshGroup/MLMesh"))
    except ET.ParseError:
        raise InputError(f"project: {project} is not a valid MeshLab project XML") from None


def save_screenshot(image: np.ndarray, path: str | os.PathLike, *, colors: int | None = 256,
                    quality: int = 85) -> Path:
    """Save a screenshot small: PNG with an adaptive palette of ``colors`` (None: full RGB), or JPEG.

    Parameters
    ----------
    image : (H, W, 3) uint8
    path : path-like
        ``.png`` or ``.jpg`` / ``.jpeg`` (written atomically).
    colors : int or None, default 256
        PNG palette size.
    quality : int, default 85
        JPEG quality.

    Returns
    -------
    pathlib.Path
    """
    import io

    from PIL import Image

    path = Path(path)
    im = Image.fromarray(np.ascontiguousarray(image))
    buf = io.BytesIO()
    if path.suffix.lower() in (".jpg", ".jpeg"):
        im.save(buf, format="JPEG", quality=int(quality), optimize=True)
    else:
        if colors:
            im = im.quantize(int(colors), dither=Image.Dither.NONE)
        im.save(buf, format="PNG", optimize=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_bytes(path, buf.getvalue())
