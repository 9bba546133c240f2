"""Texturing peers for side-by-side comparison: mvs-texturing's texrecon, MeshLab via pymeshlab, Open3D.

- :func:`build_texrecon` / :func:`run_texrecon`: mvs-texturing's ``texrecon`` (Waechter et al.
  2014), built once from the source archives in ``../shared/peers/mvs-texturing`` into a cache
  (``.cache/`` of the repository, or ``$O3D_SEQCC_PEER_CACHE``), run on a scene converted to its
  scene-folder format (:func:`write_texrecon_scene`: ``view_NNNN.cam`` + image, a welded PLY).

- :func:`run_meshlab`: MeshLab's ``compute_texcoord_parametrization_and_texture_from_registered_rasters``
  (colour correction on) on a MeshLab project written from the scene. pymeshlab's raster
  filters need an OpenGL context, so the filter runs in a **subprocess** (a crash cannot kill
  the caller) under ``xvfb-run -a -s "-screen 0 1280x1024x24 +extension GLX"`` with
  ``QT_PLUGIN_PATH=/usr/lib/x86_64-linux-gnu/qt5/plugins QT_QPA_PLATFORM=xcb`` (the pymeshlab
  wheel ships no Qt platform plugin). Debian packages: xvfb, xauth, libgl1-mesa-dri,
  libglx-mesa0, libqt5gui5.
- :func:`run_open3d`: Open3D's ``t.geometry.TriangleMesh.compute_uvatlas`` then
  ``project_images_to_albedo`` (which blends all images per texel).

Both filters need an edge-manifold mesh: duplicate vertices are merged and non-manifold edges
removed first (MeshLab: ``meshing_remove_duplicate_vertices``, ``meshing_repair_non_manifold_edges``,
``meshing_repair_non_manifold_vertices``; Open3D: ``remove_duplicated_vertices``,
``remove_non_manifold_edges``). Both write a textured OBJ (+MTL+PNG).
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from o3d_seqcc.errors import InputError
from o3d_seqcc.io.images import write_image
from o3d_seqcc.io.json_files import write_json
from o3d_seqcc.io.meshlab import CENTER_SHIFT, save_mlp
from o3d_seqcc.scene import Scene

__all__ = [
    "CACHE_ENV",
    "ChildRun",
    "PeerResult",
    "SOURCES_ENV",
    "TEXRECON_APT",
    "XVFB_ARGS",
    "build_texrecon",
    "meshlab_available",
    "peer_cache_dir",
    "run_measured",
    "run_meshlab",
    "run_open3d",
    "run_ours",
    "run_texrecon",
    "texrecon_binary",
    "texrecon_cam",
    "texrecon_sources",
    "texrecon_unavailable",
    "write_texrecon_scene",
    "write_welded_ply",
]

logger = logging.getLogger(__name__)

#: Command prefix giving pymeshlab a virtual X display with GLX.
XVFB_ARGS = ("xvfb-run", "-a", "-s", "-screen 0 1280x1024x24 +extension GLX")
#: Environment for pymeshlab's Qt (the wheel ships no platform plugin).
QT_ENV = {"QT_PLUGIN_PATH": "/usr/lib/x86_64-linux-gnu/qt5/plugins", "QT_QPA_PLATFORM": "xcb"}


@dataclass(frozen=True)
class PeerResult:
    """Output of a peer texturing run.

    Attributes
    ----------
    name : str
        ``"texrecon"``, ``"ours"``, ``"ours-texture"``, ``"meshlab"`` or ``"open3d"``.
    mesh : pathlib.Path
        Textured OBJ (with its MTL and PNG next to it).
    texture : pathlib.Path
        The texture image.
    seconds : float
        Wall time of the texturing itself (MeshLab: the filter; Open3D: uvatlas + albedo).
    total_seconds : float
        Wall time of the whole run (loading, mesh clean-up, writing; MeshLab: the subprocess).
    info : dict
        Details: faces after clean-up, per-step timings, filter parameters.
    peak_rss : int or None
        Peak resident set size in bytes of the largest process of the run (a child process's
        ``wait4`` rusage, as ``/usr/bin/time -v`` reports it); None when the peer ran in this
        process.
    """

    name: str
    mesh: Path
    texture: Path
    seconds: float
    total_seconds: float
    info: dict = field(default_factory=dict)
    peak_rss: int | None = None


def meshlab_available() -> str | None:
    """None when the MeshLab peer can run here, else the reason it cannot."""
    if shutil.which("xvfb-run") is None:
        return "xvfb-run not found (apt-get install xvfb xauth libgl1-mesa-dri libglx-mesa0 libqt5gui5)"
    try:
        import importlib.util

        if importlib.util.find_spec("pymeshlab") is None:
            return "pymeshlab is not installed"
    except Exception as e:  # pragma: no cover
        return f"pymeshlab cannot be imported: {e}"
    if not Path(QT_ENV["QT_PLUGIN_PATH"], "platforms").is_dir():
        return f"no Qt platform plugins in {QT_ENV['QT_PLUGIN_PATH']} (apt-get install libqt5gui5)"
    return None


def _image_files(scene: Scene, images: Sequence[Any] | None, folder: Path) -> list[Path]:
    """Image files per view: the views' own, given paths, or given arrays written as PNG."""
    if images is None:
        return [v.image for v in scene.views]
    if len(images) != len(scene.views):
        raise InputError(f"images: {len(images)} given for {len(scene.views)} views; give one per view")
    out = []
    for v, img in zip(scene.views, images):
        if isinstance(img, (str, os.PathLike)):
            out.append(Path(img))
        else:
            arr = np.asarray(img)
            if arr.dtype != np.uint8:
                arr = np.clip(np.rint(arr / 257.0), 0, 255).astype(np.uint8) if arr.dtype == np.uint16 else arr
            out.append(write_image(folder / f"{v.name}.png", arr))
    return out


def _prepare_out(out_dir: str | os.PathLike, overwrite: bool) -> Path:
    out = Path(out_dir).resolve()
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise InputError(f"output folder {out} exists and is not empty; pass overwrite=True or another folder")
    out.mkdir(parents=True, exist_ok=True)
    return out


def run_meshlab(
    scene: Scene,
    out_dir: str | os.PathLike,
    *,
    images: Sequence[Any] | None = None,
    texture_size: int = 2048,
    colorcorrection: bool = True,
    texture_gutter: int = 4,
    timeout: float = 1800.0,
    overwrite: bool = False,
    center_shift: tuple[float, float] = CENTER_SHIFT,
) -> PeerResult:
    """Texture the scene's mesh with MeshLab's raster-based filter, in a headless subprocess.

    Parameters
    ----------
    scene : Scene
    out_dir : path-like
        Output folder (``project.mlp``, ``meshlab.obj/.mtl``, ``meshlab_texture.png``).
    images : sequence of path-like or (H, W, 3) uint8 arrays, optional
        One image per view instead of the views' own (e.g. colour-corrected images); arrays
        are written as PNG into ``out_dir/images``.
    texture_size : int, default 2048
        Side of the square texture.
    colorcorrection : bool, default True
        The filter's own colour correction between rasters.
    texture_gutter : int, default 4
        Gutter in texels.
    timeout : float, default 1800
        Seconds before the subprocess is killed.
    overwrite : bool, default False
        Allow a non-empty ``out_dir``.
    center_shift : (float, float), default o3d_seqcc.io.meshlab.CENTER_SHIFT
        Half-pixel convention of the cameras written to the project (see :mod:`o3d_seqcc.io.meshlab`).

    Returns
    -------
    PeerResult

    Raises
    ------
    RuntimeError
        The subprocess failed (its stderr tail is in the message) or xvfb-run is missing.
    """
    reason = meshlab_available()
    if reason:
        raise RuntimeError(f"MeshLab peer unavailable: {reason}")
    out = _prepare_out(out_dir, overwrite)
    t0 = time.perf_counter()
    files = _image_files(scene, images, out / "images")
    mlp = save_mlp(scene, out / "project.mlp", images=files, center_shift=center_shift)
    job = {
        "project": str(mlp),
        "out_mesh": str(out / "meshlab.obj"),
        "texture_name": "meshlab_texture.png",
        "texture_size": int(texture_size),
        "colorcorrection": bool(colorcorrection),
        "texture_gutter": int(texture_gutter),
        "result": str(out / "meshlab_result.json"),
    }
    job_path = write_json(out / "meshlab_job.json", job)
    env = {**os.environ, **QT_ENV}
    cmd = [*XVFB_ARGS, sys.executable, str(Path(__file__).with_name("_meshlab_worker.py")), str(job_path)]
    logger.info("running MeshLab: %s", " ".join(cmd))
    try:
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout, cwd=out)
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"MeshLab texturing timed out after {timeout:.0f} s") from None
    total = time.perf_counter() - t0
    res_path = Path(job["result"])
    if proc.returncode != 0 or not res_path.is_file():
        tail = "\n".join((proc.stderr or "").strip().splitlines()[-15:])
        raise RuntimeError(f"MeshLab texturing failed (exit {proc.returncode}):\n{tail}")
    res = json.loads(res_path.read_text())
    return PeerResult(
        name="meshlab",
        mesh=Path(job["out_mesh"]),
        texture=out / job["texture_name"],
        seconds=float(res["filter_seconds"]),
        total_seconds=total,
        info=res,
    )


def _write_textured_obj(path: Path, vertices: np.ndarray, faces: np.ndarray, corner_uv: np.ndarray, texture: np.ndarray) -> Path:
    """OBJ + MTL + PNG from per-corner UVs (F, 3, 2), OBJ convention (v up)."""
    import trimesh
    from PIL import Image

    F = len(faces)
    key = np.concatenate([faces.reshape(-1, 1).astype(np.float64), corner_uv.reshape(-1, 2)], axis=1)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    v = vertices[uniq[:, 0].astype(np.int64)]
    visual = trimesh.visual.TextureVisuals(uv=uniq[:, 1:], image=Image.fromarray(texture))
    mesh = trimesh.Trimesh(v, inv.reshape(F, 3), visual=visual, process=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh.export(path)
    return path


def run_open3d(
    scene: Scene,
    out_dir: str | os.PathLike,
    *,
    images: Sequence[Any] | None = None,
    texture_size: int = 2048,
    gutter: float = 1.0,
    max_stretch: float = 1.0 / 6.0,
    overwrite: bool = False,
) -> PeerResult:
    """Texture the scene's mesh with Open3D: ``compute_uvatlas`` + ``project_images_to_albedo``.

    Parameters
    ----------
    scene : Scene
    out_dir : path-like
        Output folder (``open3d.obj`` + MTL + PNG).
    images : sequence of path-like or (H, W, 3) uint8 arrays, optional
        One image per view instead of the views' own.
    texture_size : int, default 2048
    gutter, max_stretch : float
        ``compute_uvatlas`` options (Open3D's defaults).
    overwrite : bool, default False

    Returns
    -------
    PeerResult
    """
    import open3d as o3d

    from o3d_seqcc.io.images import read_image

    out = _prepare_out(out_dir, overwrite)
    t0 = time.perf_counter()
    legacy = o3d.io.read_triangle_mesh(str(scene.mesh), enable_post_processing=False)
    n_in = len(legacy.triangles)
    legacy.triangle_uvs = o3d.utility.Vector2dVector()
    legacy.textures = []
    legacy.remove_duplicated_vertices()
    legacy.remove_non_manifold_edges()
    legacy.remove_unreferenced_vertices()
    mesh = o3d.t.geometry.TriangleMesh.from_legacy(legacy)
    if images is None:
        arrays = [v.load_image() for v in scene.views]
    else:
        if len(images) != len(scene.views):
            raise InputError(f"images: {len(images)} given for {len(scene.views)} views")
        arrays = [read_image(p) if isinstance(p, (str, os.PathLike)) else np.asarray(p) for p in images]
    arrays = [a if a.dtype == np.uint8 else np.clip(np.rint(a / 257.0), 0, 255).astype(np.uint8) for a in arrays]
    o3d_images = [o3d.t.geometry.Image(np.ascontiguousarray(a)) for a in arrays]
    Ks = [o3d.core.Tensor(np.asarray(v.intrinsic)) for v in scene.views]
    Es = [o3d.core.Tensor(np.asarray(v.extrinsic)) for v in scene.views]
    t1 = time.perf_counter()
    stretch, n_charts, _ = mesh.compute_uvatlas(size=int(texture_size), gutter=float(gutter), max_stretch=float(max_stretch))
    t2 = time.perf_counter()
    albedo = mesh.project_images_to_albedo(o3d_images, Ks, Es, tex_size=int(texture_size), update_material=True)
    t3 = time.perf_counter()
    tex = np.ascontiguousarray(albedo.as_tensor().numpy()[..., :3])
    if tex.dtype != np.uint8:
        tex = np.clip(np.rint(tex * (255.0 if tex.dtype.kind == "f" else 1.0)), 0, 255).astype(np.uint8)
    obj = _write_textured_obj(
        out / "open3d.obj",
        mesh.vertex.positions.numpy().astype(np.float64),
        mesh.triangle.indices.numpy().astype(np.int64),
        mesh.triangle.texture_uvs.numpy().astype(np.float64),
        tex,
    )
    tex_files = sorted(out.glob("*.png"))
    total = time.perf_counter() - t0
    info = {
        "faces_in": n_in,
        "faces_textured": int(mesh.triangle.indices.shape[0]),
        "uvatlas_seconds": t2 - t1,
        "albedo_seconds": t3 - t2,
        "uvatlas_stretch": float(stretch),
        "uvatlas_charts": int(n_charts),
        "texture_size": int(texture_size),
    }
    write_json(out / "open3d_result.json", info)
    return PeerResult(
        name="open3d",
        mesh=obj,
        texture=tex_files[0] if tex_files else obj,
        seconds=t3 - t1,
        total_seconds=total,
        info=info,
    )


# ---------------------------------------------------------------------------------------------
# child processes: wall time and peak RSS of a whole run


@dataclass(frozen=True)
class ChildRun:
    """A finished child process.

    Attributes
    ----------
    cmd : list of str
    returncode : int
    seconds : float
        Wall time from start to exit.
    peak_rss : int
        Peak resident set size in bytes of the largest process of its tree ("Maximum resident set
        size" of ``/usr/bin/time``: ``wait4``'s ``ru_maxrss`` of the command and every descendant
        it waited for, each on its own).
    cpu_seconds : float
        User + system CPU time of the command and its waited-for descendants.
    stdout, stderr : pathlib.Path
        Files holding the child's output.
    """

    cmd: list
    returncode: int
    seconds: float
    peak_rss: int
    cpu_seconds: float
    stdout: Path
    stderr: Path

    def tail(self, n: int = 15) -> str:
        """The last ``n`` lines of stderr (stdout when stderr is empty), colour codes removed."""
        import re

        text = self.stderr.read_text(errors="replace").strip() or self.stdout.read_text(errors="replace").strip()
        lines = [ln for ln in re.sub(r"\x1b\[[0-9;]*m", "", text).splitlines() if ln.strip()]
        return "\n".join(lines[-n:])


#: A launcher for when /usr/bin/time is missing: a small Python (no site) that forks the command,
#: so the command's peak RSS does not include this process's (a forked child's ``ru_maxrss`` starts
#: at its parent's RSS), and writes "wall maxrss_kB user sys" as GNU time's ``-f "%e %M %U %S"``.
_LAUNCHER = (
    "import os, sys, time\n"
    "t = time.perf_counter()\n"
    "pid = os.fork()\n"
    "if pid == 0:\n"
    "    os.execvp(sys.argv[2], sys.argv[2:])\n"
    "_, st, ru = os.wait4(pid, 0)\n"
    "open(sys.argv[1], 'w').write('%f %d %f %f\\n' % (time.perf_counter() - t, ru.ru_maxrss, ru.ru_utime, ru.ru_stime))\n"
    "sys.exit(os.waitstatus_to_exitcode(st) & 255)\n"
)


def run_measured(
    cmd: Sequence[str],
    *,
    log_prefix: str | os.PathLike,
    cwd: str | os.PathLike | None = None,
    env: dict | None = None,
    timeout: float | None = None,
) -> ChildRun:
    """Run ``cmd`` as a child process and measure its wall time, CPU time and peak RSS.

    The command runs under ``/usr/bin/time`` (GNU time; a small Python launcher where it is
    missing): measured from this process directly, a child's peak RSS would include this
    process's own (Linux starts a forked child's ``ru_maxrss`` at its parent's RSS).

    Parameters
    ----------
    cmd : sequence of str
    log_prefix : path-like
        The child's stdout / stderr go to ``LOG_PREFIX.stdout`` / ``LOG_PREFIX.stderr``, the
        rusage to ``LOG_PREFIX.rusage``.
    cwd, env : optional
        As for :class:`subprocess.Popen`.
    timeout : float, optional
        Seconds before the child's process group is killed (``returncode`` is then negative).

    Returns
    -------
    ChildRun
    """
    import signal

    log_prefix = Path(log_prefix)
    log_prefix.parent.mkdir(parents=True, exist_ok=True)
    out_path, err_path = Path(f"{log_prefix}.stdout"), Path(f"{log_prefix}.stderr")
    ru_path = Path(f"{log_prefix}.rusage")
    ru_path.unlink(missing_ok=True)
    cmd = list(map(str, cmd))
    if Path("/usr/bin/time").is_file():
        full = ["/usr/bin/time", "-f", "%e %M %U %S", "-o", str(ru_path), *cmd]
    else:
        full = [sys.executable, "-S", "-c", _LAUNCHER, str(ru_path), *cmd]
    with open(out_path, "wb") as fo, open(err_path, "wb") as fe:
        t0 = time.perf_counter()
        proc = subprocess.Popen(full, cwd=cwd, env=env, stdout=fo, stderr=fe, stdin=subprocess.DEVNULL,
                                start_new_session=True)
        try:
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            rc = -int(signal.SIGKILL)
        seconds = time.perf_counter() - t0
    peak, cpu = 0, float("nan")
    if ru_path.is_file():  # GNU time prepends "Command exited with non-zero status N" on failures
        last = ru_path.read_text().strip().splitlines()[-1].split()
        if len(last) == 4:
            peak, cpu = int(float(last[1])) * 1024, float(last[2]) + float(last[3])
    return ChildRun(cmd=cmd, returncode=rc, seconds=seconds, peak_rss=peak, cpu_seconds=cpu, stdout=out_path,
                    stderr=err_path)


# ---------------------------------------------------------------------------------------------
# texrecon (mvs-texturing): build once, convert a scene, run

REPO = Path(__file__).resolve().parents[1]
#: Environment variable naming the cache folder of built peers (default: the repository's ``.cache/``).
CACHE_ENV = "O3D_SEQCC_PEER_CACHE"
#: Environment variable naming the folder of mvs-texturing's source archives.
SOURCES_ENV = "O3D_SEQCC_PEER_SOURCES"
#: The app and the three sources its CMake would download with ExternalProject (folder in elibs/).
TEXRECON_ARCHIVES = {"mvs-texturing.tar.gz": None, "mapmap_cpu.tar.gz": "mapmap", "rayint.tar.gz": "rayint",
                     "mve.tar.gz": "mve"}
#: Debian packages the build needs.
TEXRECON_APT = ("cmake", "build-essential", "libpng-dev", "libjpeg-dev", "libtiff-dev", "libtbb-dev", "libeigen3-dev")
_EIGEN = Path("/usr/include/eigen3")


def peer_cache_dir(cache_dir: str | os.PathLike | None = None) -> Path:
    """The folder built peers are cached in: ``cache_dir``, else ``$O3D_SEQCC_PEER_CACHE``, else ``REPO/.cache``."""
    if cache_dir is None:
        cache_dir = os.environ.get(CACHE_ENV) or (REPO / ".cache")
    return Path(cache_dir).expanduser().resolve()


def texrecon_sources(sources: str | os.PathLike | None = None) -> Path:
    """The folder of mvs-texturing's archives: ``sources``, else ``$O3D_SEQCC_PEER_SOURCES``, else ``../shared/peers/mvs-texturing``."""
    if sources is None:
        sources = os.environ.get(SOURCES_ENV) or (REPO.parent / "shared" / "peers" / "mvs-texturing")
    return Path(sources).expanduser().resolve()


def texrecon_unavailable(sources: str | os.PathLike | None = None) -> str | None:
    """None when texrecon's sources are present, else the reason it cannot be built here."""
    src = texrecon_sources(sources)
    missing = [a for a in TEXRECON_ARCHIVES if not (src / a).is_file()]
    if missing:
        return (f"mvs-texturing sources not found ({src} lacks {', '.join(missing)}; see ../shared/peers/README.md, "
                f"or set {SOURCES_ENV})")
    return None


def _sources_key(src: Path) -> str:
    import hashlib

    h = hashlib.sha256()
    for a in TEXRECON_ARCHIVES:
        h.update(a.encode())
        h.update(hashlib.sha256((src / a).read_bytes()).digest())
    return h.hexdigest()[:12]


def _texrecon_dir(src: Path, cache: Path) -> Path:
    return cache / "texrecon" / _sources_key(src)


_BINARY = Path("mvs-texturing", "build", "apps", "texrecon", "texrecon")


def texrecon_binary(*, sources: str | os.PathLike | None = None, cache_dir: str | os.PathLike | None = None) -> Path | None:
    """The cached texrecon binary built from these sources, or None when it is not built yet."""
    src = texrecon_sources(sources)
    if texrecon_unavailable(src):
        return None
    d = _texrecon_dir(src, peer_cache_dir(cache_dir))
    b = d / _BINARY
    return b if (d / "build.json").is_file() and b.is_file() else None


def _missing_packages() -> list[str]:
    if shutil.which("dpkg-query") is None:
        return []  # not Debian: let CMake say what is missing
    out = []
    for p in TEXRECON_APT:
        r = subprocess.run(["dpkg-query", "-W", "-f=${Status}", p], capture_output=True, text=True)
        if r.returncode != 0 or "install ok installed" not in r.stdout:
            out.append(p)
    return out


def _install_packages(install: bool) -> None:
    missing = _missing_packages()
    if not missing:
        return
    cmd = ["apt-get", "install", "-y", "--no-install-recommends", *missing]
    if not install or os.geteuid() != 0 or shutil.which("apt-get") is None:
        raise RuntimeError(f"texrecon's build needs Debian packages {' '.join(missing)}: run `sudo {' '.join(cmd)}`")
    logger.warning("installing %s for texrecon's build", " ".join(missing))
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if r.returncode != 0:  # stale package lists: update once and retry
        subprocess.run(["apt-get", "update"], env=env, capture_output=True, text=True)
        r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"`{' '.join(cmd)}` failed:\n" + "\n".join(r.stderr.strip().splitlines()[-10:]))


def _unpack(archive: Path, dest: Path) -> None:
    """Unpack an archive holding one top folder into ``dest`` (which must not exist)."""
    import tarfile

    tmp = dest.parent / f".unpack-{dest.name}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    with tarfile.open(archive) as tf:
        if hasattr(tarfile, "data_filter"):
            tf.extractall(tmp, filter="data")
        else:  # pragma: no cover - Python < 3.11.4
            tf.extractall(tmp)
    tops = [p for p in tmp.iterdir()]
    if len(tops) != 1 or not tops[0].is_dir():
        raise RuntimeError(f"{archive}: expected one top folder, found {[p.name for p in tops]}")
    tops[0].rename(dest)
    tmp.rmdir()


def _patch_elibs(cmakelists: Path) -> None:
    """Build the local copies: each ExternalProject's download lines -> ``DOWNLOAD_COMMAND ""``."""
    import re

    text = cmakelists.read_text()
    text, n = re.subn(r"^\s*(GIT_REPOSITORY|GIT_TAG|URL|URL_MD5)\s+\S+\s*\n", "", text, flags=re.M)
    text, k = re.subn(r"^(\s*)(SOURCE_DIR\s+\S+\s*\n)", r'\1DOWNLOAD_COMMAND ""\n\1\2', text, flags=re.M)
    if n < 4 or k != 4:
        raise RuntimeError(f"{cmakelists}: unexpected layout (removed {n} download lines, patched {k} projects of 4)")
    cmakelists.write_text(text)


def build_texrecon(
    *,
    sources: str | os.PathLike | None = None,
    cache_dir: str | os.PathLike | None = None,
    jobs: int | None = None,
    install_packages: bool = True,
    force: bool = False,
) -> Path:
    """Build mvs-texturing's ``texrecon`` once from the local source archives; return the binary.

    The four archives (the app, mapmap, rayint, mve; ``../shared/peers/README.md``) are unpacked
    into a staging folder, the sources mapmap / rayint / mve go to the app's ``elibs/``, Debian's
    Eigen 3.4 stands in for the one elibs would download (``elibs/eigen`` a symlink to
    ``/usr/include/eigen3``), every ExternalProject's download lines become
    ``DOWNLOAD_COMMAND ""``, and ``cmake -DCMAKE_BUILD_TYPE=Release`` + ``make -jN`` build it (about
    7 minutes on 2 cores). The finished tree is swapped into
    ``CACHE/texrecon/<hash of the archives>/`` with a ``build.json``; later calls return the
    cached binary at once. A lock keeps two processes from building at the same time. No
    change is made to texrecon's C++.

    Parameters
    ----------
    sources : path-like, optional
        Folder of the archives (default :func:`texrecon_sources`).
    cache_dir : path-like, optional
        Cache folder (default :func:`peer_cache_dir`: ``$O3D_SEQCC_PEER_CACHE`` or the
        repository's ``.cache/``).
    jobs : int, optional
        Parallel compile jobs (default: the number of CPUs).
    install_packages : bool, default True
        When Debian packages are missing (:data:`TEXRECON_APT`) and this process is root,
        install them with ``apt-get``; otherwise fail naming them.
    force : bool, default False
        Rebuild even when a cached build exists.

    Returns
    -------
    pathlib.Path
        The ``texrecon`` executable.

    Raises
    ------
    RuntimeError
        Sources absent (the message says where they were looked for), packages missing, or the
        build failed (the tail of its log is in the message; the log stays in the staging folder).
    """
    import fcntl

    src = texrecon_sources(sources)
    reason = texrecon_unavailable(src)
    if reason:
        raise RuntimeError(reason)
    cache = peer_cache_dir(cache_dir)
    final = _texrecon_dir(src, cache)
    if not force and (b := texrecon_binary(sources=src, cache_dir=cache)) is not None:
        return b
    final.parent.mkdir(parents=True, exist_ok=True)
    with open(final.parent / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another process may be building the same sources
        if not force and (b := texrecon_binary(sources=src, cache_dir=cache)) is not None:
            return b
        _install_packages(install_packages)
        if not _EIGEN.is_dir():
            raise RuntimeError(f"{_EIGEN} not found: apt-get install libeigen3-dev")
        stage = final.parent / f".build-{final.name}-{os.getpid()}"
        shutil.rmtree(stage, ignore_errors=True)
        stage.mkdir()
        t0 = time.perf_counter()
        app = stage / "mvs-texturing"
        _unpack(src / "mvs-texturing.tar.gz", app)
        for archive, name in TEXRECON_ARCHIVES.items():
            if name:
                _unpack(src / archive, app / "elibs" / name)
        (app / "elibs" / "eigen").symlink_to(_EIGEN, target_is_directory=True)
        _patch_elibs(app / "elibs" / "CMakeLists.txt")
        jobs = int(jobs or os.cpu_count() or 2)
        log = stage / "build.log"
        logger.warning("building texrecon from %s into %s (about 7 minutes on 2 cores; log %s)", src, final, log)
        with open(log, "wb") as fh:
            for cmd in (["cmake", "-S", str(app), "-B", str(app / "build"), "-DCMAKE_BUILD_TYPE=Release"],
                        ["cmake", "--build", str(app / "build"), "--", f"-j{jobs}"]):
                fh.write(("$ " + " ".join(cmd) + "\n").encode())
                fh.flush()
                r = subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, cwd=app)
                if r.returncode != 0:
                    break
        binary = stage / _BINARY
        if r.returncode != 0 or not binary.is_file():
            tail = "\n".join(log.read_text(errors="replace").strip().splitlines()[-20:])
            raise RuntimeError(f"texrecon build failed (exit {r.returncode}); log {log}:\n{tail}")
        seconds = time.perf_counter() - t0
        write_json(stage / "build.json", {
            "sources": str(src), "key": final.name, "archives": list(TEXRECON_ARCHIVES), "jobs": jobs,
            "build_seconds": round(seconds, 1), "binary": str(final / _BINARY),
            "built": time.strftime("%Y-%m-%d %H:%M:%S"),
        })
        if final.exists():  # a stale, incomplete build (no build.json) or force=True
            shutil.rmtree(final)
        stage.rename(final)
        logger.warning("texrecon built in %.0f s: %s", seconds, final / _BINARY)
        return final / _BINARY


def texrecon_cam(view: Any, *, align_texels: bool = True) -> str:
    """The two lines of texrecon's ``.cam`` file for a view (its scene-folder format).

    Line 1: ``tx ty tz R00 R01 R02 R10 ... R22`` (world to camera, OpenCV axes: the extrinsic's
    translation, then its rotation row by row). Line 2: ``f d0 d1 paspect ppx ppy``. mve's
    ``CameraInfo::fill_calibration`` makes the pixel matrix ``[[f W, 0, ppx W], [0, f W paspect,
    ppy H]]`` for a landscape image (``W / H * paspect >= 1``) and ``[[f H / paspect, 0, ppx W],
    [0, f H, ppy H]]`` otherwise, and texrecon subtracts half a pixel after projecting (its pixel
    centres at integers, as ours): so ``f = fx / W`` (landscape) or ``fy / H`` (portrait),
    ``paspect = fy / fx``, ``ppx = (cx + 0.5) / W``, ``ppy = (cy + 0.5) / H``; no distortion.

    Half a texel more, by default. texrecon copies each patch's photo pixels into the atlas
    unresampled, with texture coordinates ``(projected pixel centre + patch offset) / atlas size``
    (``TextureAtlas::insert``), while OBJ / OpenGL readers (and our renders) put texel ``j``'s
    centre at ``(j + 0.5) / size``: with the exact principal point every viewer shows texrecon's
    texture half a texel (half a photo pixel) up and left of the photo. Measured on Fountain 16k,
    over the faces texrecon textured from the photo rendered (13 photos with >= 15k such pixels),
    gradient similarity with the photo with no shift forgiven
    (``o3d_seqcc.evaluation.render.gradient_similarity(..., max_shift=0)``): exact principal point 0.63-0.86
    at the photo's camera, 0.947-0.965 with the render's camera moved by (-0.5, -0.5) px; with
    this compensation 0.951-0.965 at the camera, 0.65-0.79 moved by -0.5 or +0.5 px.
    ``align_texels=True`` gives texrecon the principal point half a pixel
    further (``ppx = (cx + 1) / W``, ``ppy = (cy + 1) / H``), so its texture coordinates are
    where readers look (its visibility and data terms then see the camera half a pixel off,
    which is below their resolution); ``False`` writes the exact camera.

    Parameters
    ----------
    view : View
        Pinhole camera (intrinsic without skew, world-to-camera extrinsic in OpenCV axes).
    align_texels : bool, default True
        Compensate texrecon's half-texel texture-coordinate offset (see above).

    Returns
    -------
    str
        Two lines, newline-terminated, in shortest round-trip float notation.
    """
    K = np.asarray(view.intrinsic, dtype=np.float64)
    E = np.asarray(view.extrinsic, dtype=np.float64)
    W, H = int(view.width), int(view.height)
    if abs(K[0, 1]) > 1e-9 * abs(K[0, 0]):
        raise InputError(f"view {view.name!r}: texrecon's cameras have no skew (intrinsic[0][1] = {K[0, 1]})")
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    paspect = fy / fx
    f = fx / W if W / H * paspect >= 1.0 else fy / H
    nums1 = [*E[:3, 3], *E[:3, :3].reshape(-1)]
    c = 1.0 if align_texels else 0.5
    nums2 = [f, 0.0, 0.0, paspect, (cx + c) / W, (cy + c) / H]
    return " ".join(repr(float(x)) for x in nums1) + "\n" + " ".join(repr(float(x)) for x in nums2) + "\n"


def write_welded_ply(vertices: np.ndarray, faces: np.ndarray, path: str | os.PathLike) -> dict:
    """Write a mesh with identical vertices merged (texrecon needs shared vertices) as binary PLY.

    A triangle soup (every face with its own three vertices, as Fountain's 16k-face mesh) gives
    texrecon no adjacent faces: it would make one texture patch per face. Vertices at the same
    position (:func:`o3d_seqcc.geometry.meshops.weld_vertices`) are merged and faces left degenerate by the
    merge dropped. The file holds ``float x, y, z`` and ``list uchar int vertex_indices`` only.

    Parameters
    ----------
    vertices : (N, 3) float array
    faces : (F, 3) int array
    path : path-like

    Returns
    -------
    dict
        ``vertices_in``, ``vertices``, ``faces_in``, ``faces`` (after welding) and ``kept``
        ((F_kept,) int64 ids of the input faces written, in order).
    """
    from o3d_seqcc.io.atomic import atomic_write_bytes
    from o3d_seqcc.geometry.meshops import weld_vertices

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    ids = weld_vertices(v)
    n = int(ids.max()) + 1 if len(ids) else 0
    first = np.full(n, -1, dtype=np.int64)
    first[ids[::-1]] = np.arange(len(ids))[::-1]  # first input vertex of each welded one
    wf = ids[f]
    kept = np.flatnonzero((wf[:, 0] != wf[:, 1]) & (wf[:, 1] != wf[:, 2]) & (wf[:, 0] != wf[:, 2]))
    wf = wf[kept]
    header = (f"ply\nformat binary_little_endian 1.0\ncomment welded by o3d_seqcc benchmarks/peers.py\n"
              f"element vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
              f"element face {len(wf)}\nproperty list uchar int vertex_indices\nend_header\n").encode("ascii")
    rec = np.empty(len(wf), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    rec["n"] = 3
    rec["i"] = wf
    atomic_write_bytes(path, header + v[first].astype("<f4").tobytes() + rec.tobytes())
    return {"vertices_in": int(len(v)), "vertices": n, "faces_in": int(len(f)), "faces": int(len(wf)), "kept": kept}


def write_texrecon_scene(
    scene: Scene,
    folder: str | os.PathLike,
    *,
    images: Sequence[Any] | None = None,
    align_texels: bool = True,
) -> dict:
    """Convert a scene for texrecon: a scene folder (``view_NNNN.cam`` + image per view) and a welded PLY.

    Image files that texrecon reads (``.jpg``, ``.jpeg``, ``.png``) are copied byte for byte;
    other files and in-memory images are written as PNG. Fixed-width names, because texrecon
    pairs a ``.cam`` with the image whose name starts like it (``view_1`` would match
    ``view_10.jpg``).

    Parameters
    ----------
    scene : Scene
    folder : path-like
        Receives ``images/`` (the scene folder) and ``mesh.ply``; must be empty or absent.
    images : sequence of path-like or (H, W, 3) arrays, optional
        One image per view instead of the views' own.
    align_texels : bool, default True
        See :func:`texrecon_cam`.

    Returns
    -------
    dict
        ``images`` (the scene folder), ``mesh`` (the PLY), ``names`` (texrecon name per view, in
        view order), the welding counts of :func:`write_welded_ply` and ``seconds``.
    """
    t0 = time.perf_counter()
    out = _prepare_out(folder, overwrite=False)
    imgs = out / "images"
    imgs.mkdir()
    if images is not None and len(images) != len(scene.views):
        raise InputError(f"images: {len(images)} given for {len(scene.views)} views; give one per view")
    names = []
    for i, v in enumerate(scene.views):
        name = f"view_{i:04d}"
        src = v.image if images is None else images[i]
        if isinstance(src, (str, os.PathLike)) and Path(src).suffix.lower() in (".jpg", ".jpeg", ".png"):
            shutil.copyfile(src, imgs / f"{name}{Path(src).suffix.lower()}")
        else:
            from o3d_seqcc.io.images import read_image

            if src is None:
                arr = v.load_image()
            else:
                arr = read_image(src) if isinstance(src, (str, os.PathLike)) else np.asarray(src)
            if arr.dtype != np.uint8:
                arr = np.clip(np.rint(arr / 257.0), 0, 255).astype(np.uint8)
            write_image(imgs / f"{name}.png", arr)
        (imgs / f"{name}.cam").write_text(texrecon_cam(v, align_texels=align_texels))
        names.append(name)
    m = scene.load_mesh()
    weld = write_welded_ply(m.vertices, m.faces, out / "mesh.ply")
    return {"images": imgs, "mesh": out / "mesh.ply", "names": names, **weld, "seconds": time.perf_counter() - t0}


def run_texrecon(
    scene: Scene,
    out_dir: str | os.PathLike,
    *,
    images: Sequence[Any] | None = None,
    options: Sequence[str] = (),
    binary: str | os.PathLike | None = None,
    align_texels: bool = True,
    timeout: float = 3600.0,
    overwrite: bool = False,
) -> PeerResult:
    """Texture the scene's mesh with texrecon (its defaults unless ``options``), in a child process.

    Parameters
    ----------
    scene : Scene
    out_dir : path-like
        Output folder: ``input/`` (the converted scene, :func:`write_texrecon_scene`) and
        ``texrecon.obj`` / ``.mtl`` / ``texrecon_material*_map_Kd.png`` (texrecon's output).
    images : sequence of path-like or (H, W, 3) arrays, optional
        One image per view instead of the views' own.
    options : sequence of str
        Extra texrecon options (e.g. ``["--keep_unseen_faces"]``); none = its defaults.
    binary : path-like, optional
        The executable (default: :func:`build_texrecon`'s cached build, built if absent).
    align_texels : bool, default True
        Compensate texrecon's half-texel texture coordinates (:func:`texrecon_cam`).
    timeout : float, default 3600
    overwrite : bool, default False

    Returns
    -------
    PeerResult
        ``seconds`` and ``peak_rss``: texrecon's own process (the conversion is not counted;
        ``total_seconds`` adds it); ``info``: the conversion counts, texrecon's pages.

    Raises
    ------
    RuntimeError
        No sources / build failed / texrecon failed (its output's tail in the message).
    """
    exe = Path(binary) if binary is not None else build_texrecon()
    out = _prepare_out(out_dir, overwrite)
    for p in list(out.glob("texrecon*")) + [out / "input"]:  # only what this function writes
        if p.is_dir():
            shutil.rmtree(p)
        elif p.exists():
            p.unlink()
    conv = write_texrecon_scene(scene, out / "input", images=images, align_texels=align_texels)
    cmd = [str(exe), *options, str(conv["images"]), str(conv["mesh"]), str(out / "texrecon")]
    logger.info("running texrecon: %s", " ".join(cmd))
    run = run_measured(cmd, log_prefix=out / "texrecon_log", cwd=out, timeout=timeout)
    obj = out / "texrecon.obj"
    if run.returncode != 0 or not obj.is_file():
        raise RuntimeError(f"texrecon failed (exit {run.returncode}):\n{run.tail()}")
    pages = sorted(out.glob("texrecon*_map_Kd.png"))
    info = {k: v for k, v in conv.items() if k != "kept"}
    info.update({"images": str(conv["images"]), "mesh": str(conv["mesh"]), "convert_seconds": conv["seconds"],
                 "pages": [p.name for p in pages], "cpu_seconds": run.cpu_seconds, "cmd": run.cmd})
    return PeerResult(name="texrecon", mesh=obj, texture=pages[0] if pages else obj, seconds=run.seconds,
                      total_seconds=run.seconds + conv["seconds"], info=info, peak_rss=run.peak_rss)


# ---------------------------------------------------------------------------------------------
# whole runs in child processes: ours (`o3d-seqcc run`), MeshLab and Open3D


def run_ours(
    scene_path: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    mesh: str | os.PathLike | None = None,
    args: Sequence[str] = (),
    timeout: float = 3600.0,
    command: str = "run",
) -> PeerResult:
    """``o3d-seqcc run SCENE [--mesh MESH] --out OUT --overwrite [ARGS]`` in a child process (defaults unless ``args``).

    ``command="texture"``: ``o3d-seqcc texture`` instead, the same texturing from the photos as
    taken (no colour correction): what the correction's change of the photos' contrast costs the
    sharpness measured against the photos.

    The child is ``python -m o3d_seqcc`` of this interpreter, so it runs the o3d_seqcc this
    process imports (``PYTHONPATH`` is passed on).

    Returns
    -------
    PeerResult
        ``mesh``: ``OUT/mesh.obj``; ``seconds`` = ``total_seconds``: the command's wall time;
        ``peak_rss``; ``info``: ``report`` (OUT/report.json), ``rotation`` (the export's up-axis
        rotation, ``p_file = R @ p_scene``).
    """
    out = Path(out_dir).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    if command not in ("run", "texture"):
        raise ValueError(f"command must be 'run' or 'texture', got {command!r}")
    cmd = [sys.executable, "-m", "o3d_seqcc", command, str(scene_path), *(["--mesh", str(mesh)] if mesh else []),
           "--out", str(out), "--overwrite", *args]
    run = run_measured(cmd, log_prefix=out.parent / f"{out.name}_log", timeout=timeout)
    if run.returncode != 0 or not (out / "report.json").is_file():
        raise RuntimeError(f"o3d-seqcc {command} failed (exit {run.returncode}):\n{run.tail()}")
    rep = json.loads((out / "report.json").read_text())
    rotation = (rep.get("export") or {}).get("orientation", {}).get("rotation", np.eye(3).tolist())
    obj = out / "mesh.obj"
    pages = sorted(out.glob("mesh*.png")) + sorted(out.glob("mesh*.jpg"))
    return PeerResult(name="ours" if command == "run" else "ours-texture", mesh=obj if obj.is_file() else out / "mesh.glb", texture=pages[0] if pages else obj,
                      seconds=run.seconds, total_seconds=run.seconds, peak_rss=run.peak_rss,
                      info={"report": str(out / "report.json"), "rotation": rotation, "cpu_seconds": run.cpu_seconds,
                            "cmd": run.cmd, "timings_s": rep.get("timings_s"), "atlas": rep.get("atlas")})


def run_peer_measured(
    name: str,
    scene_path: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    mesh: str | os.PathLike | None = None,
    timeout: float = 3600.0,
) -> PeerResult:
    """The whole run of MeshLab (:func:`run_meshlab`) or Open3D (:func:`run_open3d`) in a child process.

    The child (this file's ``_child`` entry) loads the scene, runs the peer with its defaults and
    writes the :class:`PeerResult` as JSON; this adds the child's wall time (``total_seconds``:
    loading, the peer, writing) and peak RSS.
    """
    if name not in ("meshlab", "open3d"):
        raise InputError(f"unknown peer {name!r}; valid: meshlab, open3d")
    out = Path(out_dir).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    result = out.parent / f"{out.name}_result.json"
    result.unlink(missing_ok=True)
    cmd = [sys.executable, str(Path(__file__).resolve()), "_child", name, str(scene_path), str(out), str(result),
           *(["--mesh", str(mesh)] if mesh else [])]
    run = run_measured(cmd, log_prefix=out.parent / f"{out.name}_log", timeout=timeout)
    if run.returncode != 0 or not result.is_file():
        raise RuntimeError(f"{name} failed (exit {run.returncode}):\n{run.tail()}")
    r = json.loads(result.read_text())
    return PeerResult(name=name, mesh=Path(r["mesh"]), texture=Path(r["texture"]), seconds=float(r["seconds"]),
                      total_seconds=run.seconds, peak_rss=run.peak_rss,
                      info={**r["info"], "cpu_seconds": run.cpu_seconds, "cmd": run.cmd})


def _child(argv: Sequence[str]) -> int:
    """``peers.py _child meshlab|open3d SCENE OUT RESULT.json [--mesh MESH]``: one peer run (see :func:`run_peer_measured`)."""
    import argparse

    from o3d_seqcc import load_scene

    ap = argparse.ArgumentParser(prog="peers.py _child")
    ap.add_argument("peer", choices=("meshlab", "open3d"))
    ap.add_argument("scene")
    ap.add_argument("out")
    ap.add_argument("result")
    ap.add_argument("--mesh")
    a = ap.parse_args(argv)
    scene = load_scene(a.scene, mesh=a.mesh) if a.mesh else load_scene(a.scene)
    fn = run_meshlab if a.peer == "meshlab" else run_open3d
    r = fn(scene, a.out, overwrite=True)
    write_json(a.result, {"name": r.name, "mesh": str(r.mesh), "texture": str(r.texture), "seconds": r.seconds,
                          "total_seconds": r.total_seconds, "info": r.info})
    return 0


# ---------------------------------------------------------------------------------------------
# the benchmark: texrecon, ours, MeshLab and Open3D on Fountain, one run

DATA = REPO.parent / "shared" / "datasets" / "fountain_small"
#: Fountain meshes: key -> path relative to the data folder.
MESHES = {"16k": "scene/mesh_decimated_uv_blender.ply", "300k": "scene/tsdf_mesh.ply"}
#: synthetic scenes (key -> ``o3d-seqcc synthetic`` options), made once under ``--out``; timed, not rendered
SYNTHETIC = {"6mp": ("--views", "10", "--width", "3000", "--height", "2000", "--seen-only")}
#: "ours-texture": ``o3d-seqcc texture`` (ours without the colour correction, the photos as taken)
TOOLS = ("texrecon", "ours", "ours-texture", "meshlab", "open3d")
DEFAULT_VIEWS = (0, 5, 10, 15, 17, 20, 25, 30)
#: Fixed crops of the picture: (mesh, view, x, y, w, h, what); artefact windows are added per mesh.
CROPS = (
    ("16k", 17, 215, 50, 220, 70, '"HAROLD HATCH" lettering'),
    ("16k", 0, 150, 150, 220, 70, "lettering under the ship"),
    ("16k", 10, 224, 73, 220, 70, "the basin: a ghost of the faucet (an occluder seen from another photo)"),
    ("300k", 17, 215, 50, 220, 70, '"HAROLD HATCH" lettering'),
    ("300k", 10, 200, 40, 220, 70, "basin rim and tiles"),
)


def synthetic_scene(key: str, out: Path) -> Path:
    """The synthetic scene ``key`` of :data:`SYNTHETIC` (made once as ``out/<key>_scene``)."""
    folder = out / f"{key}_scene"
    if not (folder / "scene.json").is_file():
        subprocess.run([sys.executable, "-m", "o3d_seqcc", "-q", "synthetic", str(folder), *SYNTHETIC[key], "--overwrite"],
                       check=True)
    return folder


def _run_tool(tool: str, key: str, scene: Scene, data: Path, mesh: Path, out: Path, args) -> PeerResult:
    d = out / key / tool
    if tool == "texrecon":
        return run_texrecon(scene, d, overwrite=True, align_texels=not args.texrecon_exact_cameras)
    if tool in ("ours", "ours-texture"):
        return run_ours(data, d, mesh=None if key in SYNTHETIC else mesh, command="run" if tool == "ours" else "texture",
                        args=shlex.split(args.ours_args))
    return run_peer_measured(tool, data, d, mesh=mesh)


def _error_line(text: str) -> str:
    """The line of an error message that says what went wrong (colour codes removed)."""
    import re

    lines = [ln.strip() for ln in re.sub(r"\x1b\[[0-9;]*m", "", text).splitlines() if ln.strip()] or ["failed"]
    named = [ln for ln in lines if "rror" in ln or "refuse" in ln]
    line = (named or lines)[-1]
    return line if len(line) <= 300 else line[:80] + " ... " + line[-200:]


def _fmt(x: float | None, spec: str = ".2f") -> str:
    return "-" if x is None or (isinstance(x, float) and not np.isfinite(x)) else format(x, spec)


def _timing_row(p: list) -> dict:
    import statistics

    return {"wall": statistics.median(x.total_seconds for x in p), "wall_runs": [x.total_seconds for x in p],
            "peak_rss": statistics.median(x.peak_rss for x in p), "peak_rss_runs": [x.peak_rss for x in p],
            "cpu_seconds": statistics.median(x.info.get("cpu_seconds", float("nan")) for x in p),
            "mesh_file": str(p[-1].mesh)}


def _print_timing(key: str, res: dict) -> None:
    print(f"\n== {key}: {res['faces']} faces ({res['vertices']} vertices): wall time and peak RSS")
    print(f"  {'tool':<10}{'wall s':>8}{'runs':>26}{'RSS MB':>8}{'CPU s':>7}")
    for t, r in res["tools"].items():
        if "error" in r:
            print(f"  {t:<10} failed: {r['error']}")
            continue
        runs = ",".join(f"{x:.1f}" for x in r["wall_runs"])
        print(f"  {t:<10}{r['wall']:8.2f}{runs:>26}{r['peak_rss'] / 1e6:8.0f}{r['cpu_seconds']:7.1f}")
    o, x = res["tools"].get("ours", {}), res["tools"].get("texrecon", {})
    if "wall" in o and "wall" in x:
        print(f"  ours / texrecon: wall {o['wall'] / x['wall']:.2f}x, peak RSS {o['peak_rss'] / x['peak_rss']:.2f}x")


def _print_mesh(key: str, res: dict, views: list[int]) -> None:
    tools = [t for t in res["tools"] if "error" not in res["tools"][t]]
    print(f"\n== Fountain {key}: {res['faces']} faces ({res['vertices']} vertices), views {' '.join(f'{k:02d}' for k in views)}")
    for metric, title in (("sharpness", "sharpness of the render / the photo's (variance of the Laplacian; 1 = as sharp)"),
                          ("gsim", "gradient similarity with the photo (1 = the photo's gradients, in place within 3 px)")):
        print(f"{title}, on the pixels every tool covers:")
        print(f"  {'tool':<16}" + "".join(f"{'v' + format(k, '02d'):>7}" for k in views) + f"{'median':>8}")
        for t in tools:
            vals = [res["tools"][t][metric][k] for k in views]
            print(f"  {t:<16}" + "".join(f"{v:7.2f}" for v in vals) + f"{np.median(vals):8.2f}")
        for a in ("ours", "ours-texture"):
            if a in tools and "texrecon" in tools:
                r = [res["tools"][a][metric][k] / res["tools"]["texrecon"][metric][k] for k in views]
                print(f"  {a + '/texrecon':<16}" + "".join(f"{v:7.2f}" for v in r) + f"{np.median(r):8.2f}")
    print("  common mask pixels: " + " ".join(f"v{k:02d} {res['mask_pixels'][k]}" for k in views))
    hdr = (f"  {'tool':<10}{'seams':>7}{'>5':>8}{'faces out':>11}{'missing':>9}{'area':>7}{'atlas Mtx':>10}{'pages':>6}"
           f"{'tex/px':>7}{'wall s':>8}{'runs':>20}{'RSS MB':>8}{'CPU s':>7}")
    print(hdr)
    for t, r in res["tools"].items():
        if "error" in r:
            print(f"  {t:<10} failed: {r['error']}")
            continue
        runs = ",".join(f"{x:.1f}" for x in r["wall_runs"])
        print(f"  {t:<10}{r['seam_mean']:7.3f}{r['seam_gt5']:8.4f}{r['faces_out']:11d}{r['faces_missing']:9d}"
              f"{100 * r['area_missing']:6.1f}%{r['texels'] / 1e6:10.2f}{r['pages']:6d}{_fmt(r['texels_per_pixel']):>7}"
              f"{r['wall']:8.2f}{runs:>20}{r['peak_rss'] / 1e6:8.0f}{r['cpu_seconds']:7.1f}")
    if "ours" in res["tools"] and "texrecon" in res["tools"] and "error" not in res["tools"]["ours"] \
            and "error" not in res["tools"]["texrecon"]:
        o, x = res["tools"]["ours"], res["tools"]["texrecon"]
        print(f"  ours / texrecon: seam mean {o['seam_mean'] / max(x['seam_mean'], 1e-12):.2f}, wall "
              f"{o['wall'] / x['wall']:.2f}x, peak RSS {o['peak_rss'] / x['peak_rss']:.2f}x")


def _measure_module():
    """``benchmarks/_peers_measure.py``, imported as ``benchmarks._peers_measure`` or as this script's sibling."""
    import importlib

    if __package__:
        return importlib.import_module(f"{__package__}._peers_measure")
    here = str(Path(__file__).resolve().parent)
    if here not in sys.path:
        sys.path.insert(0, here)
    return importlib.import_module("_peers_measure")


def _crops_picture(path: Path, crops: list, quality: int) -> Path:
    """Rows of crops (photo | tools) under a title line each, as one JPEG."""
    import cv2

    pm = _measure_module()
    rows = []
    for row in crops:
        tiles = [pm.label(t, text) for t, text in row["tiles"]]
        strip = np.concatenate(tiles, axis=1)
        title = np.full((22, strip.shape[1], 3), 255, np.uint8)
        cv2.putText(title, row["title"], (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        rows.append(np.concatenate([title, strip], axis=0))
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0)), constant_values=255) for r in rows]
    img = np.concatenate(rows, axis=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    from o3d_seqcc.io.atomic import atomic_write_bytes

    return atomic_write_bytes(path, buf.tobytes())


def main(argv: Sequence[str] | None = None) -> int:
    import argparse
    import statistics

    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["_child"]:
        return _child(argv[1:])
    ap = argparse.ArgumentParser(
        prog="benchmarks/peers.py",
        description="texrecon (mvs-texturing), ours (o3d-seqcc run), MeshLab and Open3D on Fountain 16k / 300k, "
                    "each with its defaults, measured the same way in one run.",
    )
    ap.add_argument("--data", default=str(DATA), help="fountain_small folder (default ../shared/datasets/fountain_small)")
    ap.add_argument("--meshes", default="16k,300k",
                    help=f"comma-separated among {', '.join([*MESHES, *SYNTHETIC])} (default 16k,300k; {', '.join(SYNTHETIC)}: "
                    "a synthetic room of 10 photos of 3000 x 2000, wall time and peak RSS only)")
    ap.add_argument("--timing-only", action="store_true",
                    help="wall time and peak RSS only: no renders, no quality measures, no crops")
    ap.add_argument("--tools", default=",".join(TOOLS), help=f"comma-separated among {', '.join(TOOLS)}")
    ap.add_argument("--views", default=",".join(map(str, DEFAULT_VIEWS)), help="view indices rendered and scored")
    ap.add_argument("--repeat", type=int, default=1,
                    help="runs of each tool, alternating the order (wall time: median; default 1)")
    ap.add_argument("--out", default="/tmp/o3d_seqcc_peers", help="working folder for the tools' outputs")
    ap.add_argument("--json", help="write every figure to this JSON file")
    ap.add_argument("--crops", default=None,
                    help="side-by-side crops picture (JPEG), default OUT/peers_crops.jpg; docs/peers_crops.jpg in the README")
    ap.add_argument("--supersample", type=int, default=3, help="rays per pixel per axis of the renders (default 3)")
    ap.add_argument("--cache-dir", help=f"where texrecon is built and cached (default ${CACHE_ENV} or the repository's .cache/)")
    ap.add_argument("--sources", help=f"mvs-texturing's archives (default ${SOURCES_ENV} or ../shared/peers/mvs-texturing)")
    ap.add_argument("--build-only", action="store_true", help="build (or find) texrecon, print its path and exit")
    ap.add_argument("--measure-only", action="store_true",
                    help="measure the outputs (and timings) an earlier run left in --out, without running the tools")
    ap.add_argument("--ours-args", default="",
                    help="extra arguments of ours / ours-texture, one string (e.g. \"--no-local-leveling\"): a variant "
                         "measured against the same peers; the defaults without it")
    ap.add_argument("--texrecon-exact-cameras", action="store_true",
                    help="give texrecon the exact principal point (its texture is then half a texel off; see texrecon_cam)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    if args.cache_dir:
        os.environ[CACHE_ENV] = str(Path(args.cache_dir).resolve())
    if args.sources:
        os.environ[SOURCES_ENV] = str(Path(args.sources).resolve())

    tools = [t.strip() for t in args.tools.split(",") if t.strip()]
    keys = [k.strip() for k in args.meshes.split(",") if k.strip()]
    bad = [t for t in tools if t not in TOOLS] + [k for k in keys if k not in MESHES and k not in SYNTHETIC]
    if bad or args.repeat < 1:
        print(f"unknown {bad}; tools: {', '.join(TOOLS)}; meshes: {', '.join(MESHES)}; --repeat >= 1", file=sys.stderr)
        return 2
    notes = []
    build = None
    if "texrecon" in tools or args.build_only:
        reason = texrecon_unavailable()
        if reason:
            print(f"texrecon skipped: {reason}", file=sys.stderr)
            notes.append(f"texrecon skipped: {reason}")
            tools = [t for t in tools if t != "texrecon"]
            if args.build_only:
                return 1
        else:
            cached = texrecon_binary() is not None
            t0 = time.perf_counter()
            exe = build_texrecon()
            info = json.loads((exe.parents[4] / "build.json").read_text())
            build = {"binary": str(exe), "cached": cached, "build_seconds": info.get("build_seconds"),
                     "seconds_now": time.perf_counter() - t0}
            print(f"texrecon: {exe} ({'cached' if cached else 'built now'}; its build took {info.get('build_seconds')} s)")
            if args.build_only:
                return 0
    if "meshlab" in tools and (reason := meshlab_available()):
        print(f"MeshLab skipped: {reason}", file=sys.stderr)
        notes.append(f"MeshLab skipped: {reason}")
        tools = [t for t in tools if t != "meshlab"]
    data = Path(args.data).resolve()
    if not (data / "scene" / "key.log").is_file():
        print(f"Fountain not found at {data} (--data)", file=sys.stderr)
        return 1

    from o3d_seqcc import load_scene
    from o3d_seqcc.evaluation.render import raycast

    pm = _measure_module()
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    views_idx = [int(x) for x in args.views.split(",") if x.strip()]
    report = {"tools": tools, "views": views_idx, "repeat": args.repeat, "supersample": args.supersample, "texrecon": build,
              "load_average_start": os.getloadavg(), "meshes": {}, "notes": notes,
              "texrecon_cameras": "exact" if args.texrecon_exact_cameras else "aligned texels (texrecon_cam)"}
    crops_rows = []
    for key in keys:
        timing_only = args.timing_only or key in SYNTHETIC
        if key in SYNTHETIC:
            data_k = synthetic_scene(key, out)
            mesh, scene = data_k / "mesh.ply", load_scene(data_k)
        else:
            data_k, mesh = data, data / MESHES[key]
            scene = load_scene(data, mesh=mesh)
        mesh_in = scene.load_mesh()
        views = {k: scene.views[k] for k in views_idx if k < len(scene.views)}
        res = {"mesh": str(mesh), "faces": int(len(mesh_in.faces)), "vertices": int(len(mesh_in.vertices)), "tools": {}}
        runs: dict[str, list[PeerResult]] = {t: [] for t in tools}
        errors: dict[str, str] = {}
        runs_file = out / key / "runs.json"
        if args.measure_only:  # the runs of an earlier invocation with the same --out
            if not runs_file.is_file():
                print(f"--measure-only: {runs_file} not found (run without it first)", file=sys.stderr)
                return 1
            saved = json.loads(runs_file.read_text())
            errors = {t: e for t, e in saved["errors"].items() if t in tools}
            for t in tools:
                runs[t] = [PeerResult(name=d["name"], mesh=Path(d["mesh"]), texture=Path(d["texture"]), seconds=d["seconds"],
                                      total_seconds=d["total_seconds"], info=d["info"], peak_rss=d["peak_rss"])
                           for d in saved["runs"].get(t, [])]
        for r in range(0 if args.measure_only else args.repeat):
            for tool in (tools if r % 2 == 0 else tools[::-1]):
                if tool in errors:
                    continue
                print(f"[{key}] run {r + 1}/{args.repeat}: {tool} ...", flush=True)
                try:
                    runs[tool].append(_run_tool(tool, key, scene, data_k, mesh, out, args))
                except (RuntimeError, InputError) as e:
                    errors[tool] = _error_line(str(e))
                    print(f"[{key}] {tool} failed: {errors[tool]}", flush=True)
                    continue
                p = runs[tool][-1]
                print(f"[{key}]   {tool}: {p.total_seconds:.1f} s, peak RSS {p.peak_rss / 1e6:.0f} MB", flush=True)
        if not args.measure_only:
            write_json(runs_file, {"errors": errors, "runs": {t: [
                {"name": p.name, "mesh": str(p.mesh), "texture": str(p.texture), "seconds": p.seconds,
                 "total_seconds": p.total_seconds, "peak_rss": p.peak_rss, "info": p.info} for p in ps]
                for t, ps in runs.items()}})
        if timing_only:
            res["tools"] = {t: _timing_row(runs[t]) if runs[t] and t not in errors else {"error": errors.get(t, "no run")}
                            for t in tools}
            report["meshes"][key] = res
            _print_timing(key, res)
            continue
        photos = {k: v.load_image() for k, v in views.items()}
        scene_hits = {k: raycast(mesh_in, v).mask for k, v in views.items()}
        loaded, renders, hits = {}, {}, {}
        for tool in tools:
            if tool in errors or not runs[tool]:
                res["tools"][tool] = {"error": errors.get(tool, "no run")}
                continue
            p = runs[tool][-1]
            loaded[tool] = pm.load_output(p.mesh, p.info.get("rotation"))
            renders[tool], hits[tool] = pm.render_views(loaded[tool], views, args.supersample)
        masks = {}
        for k in views:
            m = scene_hits[k].copy()
            for tool in loaded:
                m &= hits[tool][k].mask
            masks[k] = m
        res["mask_pixels"] = {k: int(m.sum()) for k, m in masks.items()}
        for tool, tm in loaded.items():
            p = runs[tool]
            row = pm.measure_tool(tm, mesh_in, views, hits[tool], masks, photos, renders[tool])
            row.update(pm.atlas_texels(p[-1].mesh))
            row.update({"wall": statistics.median(x.total_seconds for x in p), "wall_runs": [x.total_seconds for x in p],
                        "peak_rss": statistics.median(x.peak_rss for x in p), "peak_rss_runs": [x.peak_rss for x in p],
                        "cpu_seconds": statistics.median(x.info.get("cpu_seconds", float("nan")) for x in p),
                        "mesh_file": str(p[-1].mesh),
                        "tool_seconds": statistics.median(x.seconds for x in p)})
            if tool == "texrecon":
                row["convert_seconds"] = p[-1].info.get("convert_seconds")
            res["tools"][tool] = row
        report["meshes"][key] = res
        _print_mesh(key, res, views_idx)
        # crops: the fixed ones for this mesh, then where texrecon's render most exceeds the photo's detail
        order = [t for t in ("ours", "ours-texture", "texrecon", "meshlab", "open3d") if t in loaded]
        spec = [(k, x, y, w, h, what) for (m, k, x, y, w, h, what) in CROPS if m == key and k in views]
        if "texrecon" in loaded and "ours" in loaded:
            # the view where texrecon's sharpness lead over ours is least backed by the second measure,
            # and there the window (of the 12 with the most Laplacian energy above the photo's) where
            # texrecon's render is least like the photo
            tx, us = res["tools"]["texrecon"], res["tools"]["ours"]
            k_art = max(views, key=lambda k: (tx["sharpness"][k] - us["sharpness"][k]) - (tx["gsim"][k] - us["gsim"][k]))
            x, y = pm.artefact_window(renders["texrecon"][k_art], photos[k_art], masks[k_art], (220, 70))
            spec.append((k_art, x, y, 220, 70, "texrecon's detail above the photo's, least like the photo"))
        for k, x, y, w, h, what in spec:
            tiles = [(pm.crop_tile(photos[k], x, y, w, h, 2), f"photo {k:02d}")]
            for t in order:
                r = res["tools"][t]
                tiles.append((pm.crop_tile(renders[t][k], x, y, w, h, 2),
                              f"{t}  sharp {r['sharpness'][k]:.2f}  gsim {r['gsim'][k]:.2f}"))
            crops_rows.append({"title": f"Fountain {key}, view {k:02d}, x {x} y {y} ({w}x{h} px, 2x): {what}",
                               "tiles": tiles, "mesh": key, "view": k, "box": [x, y, w, h]})
    report["load_average_end"] = os.getloadavg()
    if crops_rows:
        cpath = Path(args.crops) if args.crops else out / "peers_crops.jpg"
        _crops_picture(cpath, crops_rows, 80)
        report["crops"] = {"file": str(cpath), "rows": [{k: v for k, v in r.items() if k != "tiles"} for r in crops_rows]}
        print(f"\ncrops: {cpath} ({cpath.stat().st_size / 1e6:.2f} MB)")
    for n in notes:
        print("note:", n)
    print(f"load average: start {report['load_average_start'][0]:.2f}, end {report['load_average_end'][0]:.2f} (2 cores)")
    if args.json:
        write_json(args.json, report)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
