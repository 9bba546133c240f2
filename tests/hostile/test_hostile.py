"""Hostile inputs, round 2 (issue 25): one case table per class, each case refused with a message or handled.

Classes: data loss (the one output guard), the file-reading layer (regular files, any path bytes,
budgets from headers, complete files, sane values), signals / working directory / worker errors,
far-away junk, library arguments and owned arrays, the report's inputs, EXIF orientation and
duplicate JSON keys. Cases that crashed or hung the process before (a segfault on a non-UTF-8 path,
a FIFO among RGB-D images) run in a subprocess with a timeout. ``pytest -m hostile`` runs them
alone (about a minute); ``benchmarks/hostile_inputs.py`` is the CLI sweep with the same classes.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import textwrap
import threading
import time
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

import o3d_seqcc as sc
from o3d_seqcc import InputError
from o3d_seqcc.cli import main
from _cli_cases import default_signals
from o3d_seqcc.io.output import output_folder

pytestmark = pytest.mark.hostile

REPO = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)}
RUN = ["--t-npm", "10", "--atlas-size", "512", "--no-seams", "--selection-view", "none"]


def checksums(folder: Path) -> dict[str, str]:
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file() and not p.is_symlink()}


def python(code: str, *, cwd: Path | None = None, timeout: float = 60) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter (for what crashed or hung the process before), its signals at their default
    action (:func:`default_signals`: a run started in the background must not ignore the Ctrl-C a test sends)."""
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=ENV, cwd=cwd, capture_output=True,
                          text=True, errors="replace", timeout=timeout, preexec_fn=default_signals)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("hostile")
    sc.make_synthetic_scene(root / "S", n_views=3, width=64, height=48, seed=0, cell_size=0.25)
    return root / "S"


@pytest.fixture
def S(tiny, tmp_path) -> Path:
    dst = tmp_path / "S"
    shutil.copytree(tiny, dst)
    return dst


@pytest.fixture(scope="module")
def run_dir(tiny, tmp_path_factory) -> Path:
    """A finished ``run`` output of the tiny scene."""
    out = tmp_path_factory.mktemp("hostile_run") / "out"
    assert main(["-q", "run", str(tiny), "--out", str(out), *RUN]) == 0
    return out


def _beside(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# ---------------------------------------------------------------------------------------- 1. data loss
def test_report_output_never_replaces_an_input(S, run_dir, tmp_path, capsys):
    out = tmp_path / "run"
    shutil.copytree(run_dir, out)
    rep = json.loads((out / "report.json").read_text())
    rep["scene_path"], rep["mesh"] = str(S / "scene.json"), str(S / "mesh.ply")
    (out / "report.json").write_text(json.dumps(rep))
    before = checksums(S)
    for victim in (S / "scene.json", S / "images" / "v01.png", S / "mesh.ply", out / "report.json"):
        assert main(["-q", "report", str(out), "--output", str(victim)]) == 2
        err = capsys.readouterr().err
        assert "--output" in err and ("is the input" in err or "output folder" in err), err
    assert checksums(S) == before


def test_swap_refuses_to_delete_what_it_did_not_stage(tmp_path):
    out = tmp_path / "o"
    with output_folder(out) as st:
        (st / "a.txt").write_text("first run")
    with pytest.raises(InputError, match=r"changed while this run was writing it: .*notes\.txt"):
        with output_folder(out, overwrite=True) as st:
            (st / "a.txt").write_text("second run")
            (out / "notes.txt").write_text("another program wrote this meanwhile")
    assert (out / "notes.txt").read_text().startswith("another program")
    assert (out / "a.txt").read_text() == "first run"  # nothing replaced
    assert _beside(tmp_path) == ["o"]  # no staging folder, no lock, no old copy left


@pytest.mark.parametrize("order", ["outer first", "inner first"])
def test_lock_covers_nested_outputs(tmp_path, order):
    outer, inner = tmp_path / "A", tmp_path / "A" / "sub"
    first, second = (outer, inner) if order == "outer first" else (inner, outer)
    with output_folder(first) as st:
        (st / "x").write_text("1")
        with pytest.raises(InputError, match=r"another o3d-seqcc run \(pid \d+\) is writing"):
            with output_folder(second):
                pass
    assert (first / "x").read_text() == "1"


def test_overwrite_never_removes_a_link_it_did_not_write(S, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["-q", "correct", str(S), "--out", str(out), "--t-npm", "10", "--no-metrics"]) == 0
    keep = tmp_path / "elsewhere"
    keep.mkdir()
    (out / "link").symlink_to(keep, target_is_directory=True)
    (out / "file_link").symlink_to(S / "scene.json")
    assert main(["-q", "correct", str(S), "--out", str(out), "--overwrite", "--t-npm", "10", "--no-metrics"]) == 2
    assert "did not write (file_link, link)" in capsys.readouterr().err
    assert (out / "link").is_symlink() and (out / "file_link").is_symlink()


def test_symlinked_out_writes_a_project_that_loads_through_the_link(S, tmp_path):
    target = tmp_path / "disk" / "results"
    target.mkdir(parents=True)
    link = tmp_path / "link"
    link.symlink_to(target, target_is_directory=True)
    assert main(["-q", "correct", str(S), "--out", str(link), "--t-npm", "10", "--no-metrics"]) == 0
    for p in (link / "project.mlp", link / "scene.json"):
        scene = sc.load_scene(p)
        assert len(scene.views) == 3 and Path(scene.mesh).resolve() == (S / "mesh.ply").resolve()


def test_json_outputs_never_replace_a_file_of_an_output_folder(run_dir, tmp_path, capsys):
    out = tmp_path / "run"
    shutil.copytree(run_dir, out)
    before = checksums(out)
    assert main(["-q", "seams", str(out / "mesh.glb"), "--json", str(out / "report.json")]) == 2
    assert "is a file of the o3d-seqcc output folder" in capsys.readouterr().err
    assert main(["-q", "seams", str(out / "mesh.obj"), "--json", str(out / "mesh.png")]) == 2  # the OBJ's texture
    assert "is the input" in capsys.readouterr().err
    assert checksums(out) == before


def test_a_failed_run_removes_the_folders_it_created(S, tmp_path, monkeypatch):
    import o3d_seqcc.run_folder.write as rw

    def boom(*a, **k):
        raise RuntimeError("disk exploded")

    monkeypatch.setattr(rw, "html_report", boom)  # correct's page
    with pytest.raises(RuntimeError):
        main(["-q", "correct", str(S), "--out", str(tmp_path / "new" / "deep" / "o"), "--t-npm", "10",
              "--no-metrics"])
    assert _beside(tmp_path) == ["S"]


# ---------------------------------------------------------------------------------------- 2. the file layer
def test_non_utf8_folder_names_work(S, tmp_path):
    r = python(f"""
        import os, shutil, sys
        import o3d_seqcc as sc
        from o3d_seqcc.io.depth import read_depth
        from o3d_seqcc.io.images import read_image
        src = os.fsencode({str(S)!r})
        dst = os.fsencode({str(tmp_path)!r}) + b"/sc\\xe9ne"
        shutil.copytree(src, dst)
        scene = sc.load_scene(os.fsdecode(dst))
        img = scene.views[0].load_image(); d = scene.views[0].load_depth(); m = scene.load_mesh()
        print(img.shape, d.shape, len(m.faces))
    """)
    assert r.returncode == 0, r.stderr[-2000:]  # was -11: OpenCV's imread(str(path)) segfaults on such names
    assert "(48, 64, 3) (48, 64)" in r.stdout


def _rgbd(root: Path, n: int = 2) -> Path:
    """An RGB-D folder of ``n`` 640x480 photos (the size of the default intrinsic: every photo is checked, the
    others give the size)."""
    (root / "image").mkdir(parents=True)
    (root / "scene").mkdir()
    for i in range(n):
        cv2.imwrite(str(root / "image" / f"{i:06d}.png"), np.full((480, 640, 3), 100, np.uint8))
    (root / "scene" / "key.log").write_text("".join(f"{i} {i} {i + 1}\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"
                                                    for i in range(n)))
    return root


def test_fifo_among_rgbd_images_is_refused_without_hanging(S, tmp_path):
    root = _rgbd(tmp_path / "rgbd")
    (root / "image" / "000000.png").unlink()
    os.mkfifo(root / "image" / "000000.png")
    r = python(f"""
        import o3d_seqcc as sc
        from o3d_seqcc import InputError
        try:
            sc.load_scene({str(root)!r}, mesh={str(S / "mesh.ply")!r})
        except InputError as e:
            print("InputError:", e)
    """, timeout=30)
    assert "InputError:" in r.stdout and "FIFO" in r.stdout and "000000.png" in r.stdout, r.stdout + r.stderr


def _png_declaring(path: Path, w: int, h: int, *, channels: int = 3, bits: int = 8) -> None:
    """A small PNG whose IHDR declares w x h (a bomb header), with a short zlib stream of zeros."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    colour = {1: 0, 3: 2}[channels]
    data = zlib.compress(b"\0" * (1 + channels * bits // 8 * w) * 16, 9)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, bits, colour, 0, 0, 0))
                     + chunk(b"IDAT", data) + chunk(b"IEND", b""))


def _ply(path: Path, header_counts: tuple[int, int], verts: list[str], faces: list[str]) -> None:
    path.write_text("ply\nformat ascii 1.0\n"
                    f"element vertex {header_counts[0]}\nproperty double x\nproperty double y\nproperty double z\n"
                    f"element face {header_counts[1]}\nproperty list uchar int vertex_indices\nend_header\n"
                    + "".join(v + "\n" for v in verts) + "".join(f + "\n" for f in faces))


def _binary_ply_declaring(path: Path, n: int) -> None:
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
                     b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n" % n)


def _far_vertex(path: Path) -> None:
    m = sc.load_mesh(path)
    v = np.array(m.vertices)
    v[5] = [1e300, 0.0, 0.0]
    _ply(path, (len(v), len(m.faces)), [f"{x:.17g} {y:.17g} {z:.17g}" for x, y, z in v], [f"3 {a} {b} {c}" for a, b, c in m.faces])


def _edit(S: Path, fn) -> None:
    doc = json.loads((S / "scene.json").read_text())
    fn(doc)
    (S / "scene.json").write_text(json.dumps(doc))


def _bomb_in_rgbd(S: Path) -> Path:
    root = _rgbd(S.parent / "rgbd")
    _png_declaring(root / "image" / "000000.png", 60000, 60000)
    return root


def _device_image(S: Path) -> None:
    (S / "images" / "v01.png").unlink()
    (S / "images" / "v01.png").symlink_to("/dev/zero")


def _dup_keys(S: Path) -> None:
    text = (S / "scene.json").read_text()
    (S / "scene.json").write_text(text.replace('"views":', '"views": [], "views":', 1))


def _dup_view_keys(S: Path) -> None:
    doc = json.loads((S / "scene.json").read_text())
    text = json.dumps(doc).replace('"name": "v01"', '"name": "v01", "name": "v02"', 1)
    (S / "scene.json").write_text(text)


#: (id, prepare(S) -> path to load or None for S, regex the InputError must match); load_scene must refuse
LOADER_CASES = [
    ("rgbd image header 60000x60000", _bomb_in_rgbd, r"000000\.png is 60000x60000 = 3600 Mpx, over the limit"),
    ("depth PNG declaring 20000x20000", lambda S: _png_declaring(S / "depth" / "v01.png", 20000, 20000, channels=1,
                                                               bits=16), r"depth map .*v01\.png is 20000x20000 = 400 Mpx"),
    ("depth PNG cut short", lambda S: (S / "depth" / "v02.png").write_bytes((S / "depth" / "v02.png").read_bytes()[:300]),
     r"depth map .*v02\.png is truncated"),
    ("PLY header declaring 2e9 vertices", lambda S: _binary_ply_declaring(S / "mesh.ply", 2 * 10**9),
     r"mesh .*mesh\.ply: its header declares 2000000000 vertex elements"),
    ("ASCII PLY declaring 10x the vertices it holds", lambda S: _ply(S / "mesh.ply", (40, 1), ["0 0 0", "1 0 0", "0 1 0"],
                                                                    ["3 0 1 2"]), r"declares 40 vertex elements"),
    ("vertex at 1e300", lambda S: _far_vertex(S / "mesh.ply"), r"mesh .*mesh\.ply has 1 vertices with beyond \+-1e\+12 "
     r"coordinates \(vertex 5 at \(1e\+300"),
    ("image is /dev/zero", _device_image, r"v01\.png is a character device, not a regular file"),
    ("mesh is a FIFO", lambda S: ((S / "mesh.ply").unlink(), os.mkfifo(S / "mesh.ply")),
     r"mesh .*mesh\.ply is a FIFO \(named pipe\), not a regular file"),
    ("depth map is a folder", lambda S: ((S / "depth" / "v00.png").unlink(), (S / "depth" / "v00.png").mkdir()),
     r"depth map .*v00\.png is a folder"),
    ("duplicate keys in scene.json", _dup_keys, r"scene\.json: the key 'views' appears twice"),
    ("duplicate keys in a view", _dup_view_keys, r"scene\.json: the key 'name' appears twice"),
]


@pytest.mark.parametrize("name, prep, match", LOADER_CASES, ids=[c[0] for c in LOADER_CASES])
def test_loader_refuses(S, name, prep, match):
    target = prep(S)
    t = time.perf_counter()
    with pytest.raises(InputError, match=match):
        sc.load_scene(target if isinstance(target, Path) else S, mesh=S / "mesh.ply" if isinstance(target, Path) else None)
    assert time.perf_counter() - t < 10  # from headers: nothing decoded, nothing allocated


def test_max_image_pixels_applies_to_depth_maps(S, capsys):
    assert main(["-q", "--max-image-pixels", "2000", "info", str(S)]) == 2
    assert "over the limit of 2000 pixels" in capsys.readouterr().err
    from o3d_seqcc.io.depth import read_depth
    from o3d_seqcc.io.raster_checks import set_max_image_pixels

    old = set_max_image_pixels(1000)
    try:
        with pytest.raises(InputError, match=r"depth map .* 3072 pixels, over the limit of 1000"):
            read_depth(S / "depth" / "v00.png", 1000.0)
    finally:
        set_max_image_pixels(old)


def _jpeg_with_thumbnail(path: Path) -> int:
    """A camera-like JPEG: an EXIF APP1 holding a complete thumbnail JPEG, then the main image; returns
    the offset just past the thumbnail's end-of-image marker."""
    rng = np.random.default_rng(0)
    thumb = cv2.imencode(".jpg", rng.integers(0, 255, (120, 160, 3), np.uint8), [cv2.IMWRITE_JPEG_QUALITY, 90])[1]
    main_img = cv2.imencode(".jpg", rng.integers(0, 255, (480, 640, 3), np.uint8), [cv2.IMWRITE_JPEG_QUALITY, 95])[1]
    thumb, main_img = thumb.tobytes(), main_img.tobytes()
    # TIFF header, IFD0 without entries pointing to IFD1, IFD1 = JPEGInterchangeFormat (offset, length)
    ifd1 = 8 + 2 + 4
    data_off = ifd1 + 2 + 2 * 12 + 4
    tiff = (b"II*\0" + struct.pack("<I", 8) + struct.pack("<H", 0) + struct.pack("<I", ifd1) + struct.pack("<H", 2)
            + struct.pack("<HHII", 0x0201, 4, 1, data_off) + struct.pack("<HHII", 0x0202, 4, 1, len(thumb))
            + struct.pack("<I", 0) + thumb)
    app1 = b"Exif\0\0" + tiff
    out = main_img[:2] + b"\xff\xe1" + struct.pack(">H", len(app1) + 2) + app1 + main_img[2:]
    path.write_bytes(out)
    return 2 + 4 + 6 + data_off + len(thumb)


def test_cut_jpeg_with_a_thumbnail_end_marker_in_its_tail_is_truncated(S, tmp_path, capsys):
    jpg = S / "images" / "v01.jpg"
    thumb_end = _jpeg_with_thumbnail(jpg)
    data = jpg.read_bytes()
    cut = thumb_end + 60000  # the thumbnail's EOI lies in the last 64 KB of the cut file
    assert len(data) > cut + 1000
    jpg.write_bytes(data[:cut])
    from o3d_seqcc.io.images import check_image_file, read_image

    for fn in (check_image_file, read_image):
        with pytest.raises(InputError, match=r"v01\.jpg is truncated"):
            fn(jpg)
    jpg.write_bytes(data)  # the whole file is fine
    assert check_image_file(jpg)[:2] == (640, 480) and read_image(jpg).shape == (480, 640, 3)


def test_point_clouds_drop_points_that_are_not_finite(S):
    import open3d as o3d

    pts = np.random.default_rng(0).random((50, 3))
    pts[3] = np.nan
    pts[7] = [1e300, 0, 0]
    o3d.io.write_point_cloud(str(S / "p.ply"), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts)))
    view = sc.load_scene(S).views[0]
    from dataclasses import replace

    with pytest.warns(sc.errors.O3dSeqccWarning, match=r"p\.ply: 2 of 50 points are not finite"):
        got = replace(view, point_cloud=S / "p.ply").load_points()
    assert got.shape == (48, 3) and np.isfinite(got).all()


# -------------------------------------------------------------------------- 3. signals, cwd, worker errors
@pytest.mark.parametrize("sig", ["SIGTERM", "SIGHUP"])
def test_termination_while_staging_cleans_up(tmp_path, sig):
    out = tmp_path / "o"
    p = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import time
        from o3d_seqcc.io.output import output_folder
        with output_folder({str(out)!r}) as st:
            (st / "half.txt").write_text("x")
            print("staging", flush=True)
            time.sleep(30)
    """)], env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_signals)
    assert p.stdout.readline().strip() == "staging"
    assert any(n.endswith(".staging") for n in os.listdir(tmp_path))
    p.send_signal(getattr(signal, sig))
    p.communicate(timeout=20)
    assert _beside(tmp_path) == []  # no staging folder, no lock, no output


def test_a_signal_inside_the_saves_thread_start_leaves_no_staging_folder(S, tmp_path):
    # SIGTERM inside ThreadPoolExecutor.submit's Thread.start left a worker that shutdown(wait=True) did not join:
    # it wrote the mesh files into the staging folder while the guard removed it (1 run in 80 under load, in CI).
    # Here the signal is made to land there every time; held() around the submits defers it past them.
    out = tmp_path / "o"
    r = python(f"""
        import os, signal, threading
        import o3d_seqcc as sc
        from o3d_seqcc._shared.interrupts import Terminated, interruptible
        res = sc.pipeline.run({str(S)!r}, t_npm=10, atlas_size=512)
        start, sent = threading.Thread.start, []
        def signalling_start(self):
            start(self)
            if self.name.startswith("o3d_seqcc-save") and not sent:
                sent.append(signal.SIGTERM)
                os.kill(os.getpid(), signal.SIGTERM)
                sum(range(10 ** 5))  # the handler runs here, inside start
        threading.Thread.start = signalling_start
        try:
            with interruptible():
                res.save({str(out)!r}, selection_view="none")
            print("saved")
        except Terminated as e:
            print("terminated", e.name, len(sent))
    """, timeout=180)
    assert r.stdout.strip() == "terminated SIGTERM 1", r.stdout + r.stderr
    assert _beside(tmp_path) == ["S"]  # no staging folder written into after its removal, no lock, no output


def test_cli_terminated_exit_code_and_cleanup(S, tmp_path):
    out = tmp_path / "o"
    p = subprocess.Popen([sys.executable, "-m", "o3d_seqcc", "run", str(S), "--out", str(out), *RUN], env=ENV,
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    t0 = time.perf_counter()
    while not any(n.endswith(".staging") for n in os.listdir(tmp_path)) and time.perf_counter() - t0 < 60:
        time.sleep(0.01)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 128 + signal.SIGTERM and "terminated (SIGTERM)" in err, err
    assert _beside(tmp_path) == ["S"]


def test_deleted_working_directory_is_a_clear_message(S, tmp_path):
    gone = tmp_path / "gone"
    gone.mkdir()
    r = python(f"""
        import os, subprocess, sys
        os.chdir({str(gone)!r}); os.rmdir({str(gone)!r})
        r = subprocess.run([sys.executable, "-m", "o3d_seqcc", "info", {str(S)!r}], capture_output=True, text=True)
        print(r.returncode); print(r.stderr)
    """)
    code, _, err = r.stdout.partition("\n")
    assert code == "2" and "working directory no longer exists" in err, r.stdout + r.stderr


def test_no_task_still_runs_when_a_worker_raises():
    from o3d_seqcc._shared.parallel import LocalExecutor

    running, lock = [0], threading.Lock()

    def task(i):
        with lock:
            running[0] += 1
        try:
            if i == 0:
                raise InputError("bad input in task 0")
            time.sleep(0.3)
            return i
        finally:
            with lock:
                running[0] -= 1

    with pytest.raises(InputError, match="task 0"):
        LocalExecutor(4).map(task, range(12))
    assert running[0] == 0  # native code in a still-running task aborts the interpreter at exit


# ---------------------------------------------------------------------------------------- 4. far-away junk
def _with_junk(S: Path, kind: str) -> int:
    m = sc.load_mesh(S / "mesh.ply")
    v, f, n = np.array(m.vertices), np.array(m.faces), len(m.vertices)
    if kind == "triangle":
        jv, jf = np.array([[1e5, 0, 0], [1e5 + 1, 0, 0], [1e5, 1, 0]]), np.array([[0, 1, 2]])
    else:  # a 200 m sheet of 10 m cells
        g = np.stack(np.meshgrid(np.arange(21) * 10.0, np.arange(21) * 10.0, indexing="ij"), -1).reshape(-1, 2)
        jv = np.c_[g[:, 0] + 1e5, g[:, 1], np.zeros(len(g))]
        idx = np.arange(441).reshape(21, 21)
        q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
        jf = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    _ply(S / "mesh.ply", (n + len(jv), len(f) + len(jf)), [f"{x:.17g} {y:.17g} {z:.17g}" for x, y, z in np.vstack([v, jv])],
         [f"3 {a} {b} {c}" for a, b, c in np.vstack([f, jf + n])])
    return len(jf)


@pytest.mark.parametrize("kind", ["triangle", "sheet"])
def test_far_junk_does_not_veto_or_change_the_scene(S, kind):
    clean = sc.compute_visibility(sc.load_scene(S))
    n = _with_junk(S, kind)
    with pytest.warns(sc.errors.O3dSeqccWarning, match=rf"{n} faces? of the mesh .*mesh\.ply lie far from everything"):
        vis = sc.compute_visibility(sc.load_scene(S))
    assert vis.stats["usable"] == clean.stats["usable"] and vis.stats["valid"] == clean.stats["valid"]
    assert len(vis.mesh.faces) == len(clean.mesh.faces) and np.ptp(vis.mesh.vertices, axis=0).max() < 100
    from o3d_seqcc.visibility.refine import coverage  # junk dropped, then the faces split: not counted as unseen input faces

    none = np.full(len(vis.mesh.faces), -1)
    assert coverage(vis, none)["input_faces"] == coverage(clean, none)["input_faces"] == coverage(clean, none)[
        "unseen_input_faces"]


# ---------------------------------------------------------------------------------------- 5. library arguments
def _front_door(S: Path):
    import open3d as o3d

    scene = sc.load_scene(S)
    mesh = o3d.io.read_triangle_mesh(str(scene.mesh))
    images = [v.load_image() for v in scene.views]
    return mesh, images, ([v.intrinsic for v in scene.views], [v.extrinsic for v in scene.views])


ARG_CASES = [
    ("run(123)", lambda S: sc.pipeline.run(123), r"scene must be a Scene or the path of a scene .*, got 123 \(int\)"),
    ("run(None)", lambda S: sc.pipeline.run(None), r"scene must be .* got None"),
    ("texture(b'x')", lambda S: sc.pipeline.texture(3.5), r"scene must be .* got 3\.5 \(float\)"),
    ("correct_scene(mesh=5)", lambda S: sc.pipeline.correct_scene(S, mesh=5), r"mesh must be the path of a mesh file"),
    ("atlas_size='big'", lambda S: sc.pipeline.run(S, atlas_size="big"),
     r"atlas_size \(--atlas-size\) must be 'auto' or an integer >= 8, got 'big'"),
    ("smoothness='x'", lambda S: sc.pipeline.texture(S, smoothness="x"), r"smoothness must be a number"),
    ("settings=dict", lambda S: sc.pipeline.texture(S, settings={"atlas_size": 512}), r"settings must be a RunSettings, .*TextureSettings or None, got dict"),
    ("texture(images=[1,2,3])", lambda S: sc.pipeline.texture(S, images=[1, 2, 3]), r"images\[0\] must be a \(48, 64, 3\)"),
    ("client=5", lambda S: sc.pipeline.run(S, client=5), r"client must be a dask.distributed.Client"),
    ("float images in 0..255", lambda S: (lambda m, i, c: sc.correct_images(m, [x.astype(np.float32) for x in i], c))(
        *_front_door(S)), r"images\[0\] is a float image with values in \[\d+, \d+\]; float images must be in \[0, 1\]"),
    ("all-NaN float images", lambda S: (lambda m, i, c: sc.correct_images(m, [np.full(x.shape, np.nan) for x in i], c))(
        *_front_door(S)), r"images\[0\] holds NaN or infinite values"),
    ("depth_scale='mm'", lambda S: (lambda m, i, c: sc.texture_mesh(m, i, c, depth_scale="mm"))(*_front_door(S)),
     r"depth_scale must be a positive number"),
]


@pytest.mark.parametrize("name, call, match", ARG_CASES, ids=[c[0] for c in ARG_CASES])
def test_library_arguments_are_named(S, name, call, match):
    with pytest.raises(InputError, match=match):
        call(S)


def test_results_own_their_arrays_and_every_result_saves(S, tmp_path):
    mesh, images, cams = _front_door(S)
    tm, res = sc.texture_mesh(mesh, images, cams, t_npm=10, atlas_size=512, seams=False, return_result=True)
    before = np.array(res.scene.mesh.vertices)
    np.asarray(mesh.vertices)[:] += 1.0  # the caller edits its mesh
    assert np.array_equal(res.scene.mesh.vertices, before)
    assert not np.shares_memory(res.scene.mesh.vertices, np.asarray(mesh.vertices))
    with pytest.warns(sc.errors.O3dSeqccWarning, match=r"no MeshLab project written: the scene's images are in "
                                                      r"memory"):  # the rest is written; the project needs image files
        res.save(tmp_path / "textured")  # the documented res.save(OUT): it failed blaming the images
    assert (tmp_path / "textured" / "mesh.glb").is_file() and (tmp_path / "textured" / "report.html").is_file()
    from o3d_seqcc.open3d_api import scene_from_open3d

    scene, _ = scene_from_open3d(mesh, images, cams)
    sc.pipeline.correct_scene(scene, t_npm=10, metrics=False).save(tmp_path / "corrected")  # in-memory mesh
    back = sc.load_scene(tmp_path / "corrected")
    assert len(back.views) == 3 and (tmp_path / "corrected" / "mesh.ply").is_file()


# ---------------------------------------------------------------------------------------- 6. report inputs
def _set(d: dict, dotted: str, value) -> None:
    *path, last = dotted.split(".")
    for k in path:
        d = d[k]
    d[last] = value


REPORT_CASES = [
    ("string in a count", "metrics.before.max_per_pair", "<script>alert(1)</script>",
     r"'metrics\.before\.max_per_pair' must be an integer or null, got '<script>"),
    ("string in a figure", "atlas.coverage", "<b>full</b>", r"'atlas\.coverage' must be a finite number or null"),
    ("list for an object", "correction", [], r"'correction' must be an object or null, got \[\]"),
    ("number for a name", "selection.picture_view", 3, r"'selection\.picture_view' must be a string, got 3"),
    ("NaN in a table", "metrics.after.psnr.mean", float("nan"), r"'metrics\.after\.psnr\.mean' must be a finite number"),
    ("a rotation of strings", "export.orientation.rotation", [["a"] * 3] * 3, r"'export\.orientation\.rotation' must be"),
    ("unknown correction option", "correction.settings.options", {"rm_rf": 1}, r"\['rm_rf'\], not options of the method"),
    ("pages 'many'", "atlas.pages", "many", r"'atlas\.pages' must be an integer, got 'many'"),
]


def _report_copy(run_dir: Path, tmp_path: Path) -> Path:
    out = tmp_path / "run"
    shutil.copytree(run_dir, out)
    return out


@pytest.mark.parametrize("name, field, value, match", REPORT_CASES, ids=[c[0] for c in REPORT_CASES])
def test_report_json_fields_are_validated(run_dir, tmp_path, name, field, value, match):
    out = _report_copy(run_dir, tmp_path)
    rep = json.loads((out / "report.json").read_text())
    if not rep.get("metrics"):
        rep["metrics"] = {"before": {"psnr": {}, "ciede2000": {}}, "after": {"psnr": {}, "ciede2000": {}}}
    _set(rep, field, value)
    (out / "report.json").write_text(json.dumps(rep))
    html = (out / "report.html").read_bytes()
    with pytest.raises(InputError, match=match):
        sc.regenerate_report(out)
    assert (out / "report.html").read_bytes() == html and b"<script>alert" not in html


@pytest.mark.parametrize("damage", ["truncated report.json", "truncated selection.npy", "selection of floats",
                                    "view index out of range", "duplicate keys"])
def test_damaged_run_files_are_messages(run_dir, tmp_path, damage):
    out = _report_copy(run_dir, tmp_path)
    sel = np.load(out / "selection.npy")
    if damage == "truncated report.json":
        (out / "report.json").write_bytes((out / "report.json").read_bytes()[:500])
        match = r"report\.json: not valid JSON"
    elif damage == "truncated selection.npy":
        (out / "selection.npy").write_bytes((out / "selection.npy").read_bytes()[:300])
        match = r"selection\.npy is truncated"
    elif damage == "selection of floats":
        np.save(out / "selection.npy", sel.astype(np.float64))
        match = r"selection\.npy holds a float64 array"
    elif damage == "view index out of range":
        sel[0] = 99
        np.save(out / "selection.npy", sel)
        match = r"selection\.npy holds view indices -1\.\.99 for 3 views"
    else:
        text = (out / "report.json").read_text()
        (out / "report.json").write_text(text.replace('"command":', '"command": "run", "command":', 1))
        match = r"the key 'command' appears twice"
    with pytest.raises(InputError, match=match):
        sc.regenerate_report(out)


def test_report_escapes_every_string_it_writes(run_dir, tmp_path, tiny):
    out = _report_copy(run_dir, tmp_path)
    rep = json.loads((out / "report.json").read_text())
    evil = "<img src=x onerror=alert(1)>"
    rep["scene"] = evil
    rep["texture_settings"]["selection"] = evil
    rep["timings_s"][evil] = 1.0
    rep["atlas"]["packer"] = evil
    (out / "report.json").write_text(json.dumps(rep))
    page = sc.regenerate_report(out, scene=tiny).read_text()
    assert evil not in page and "&lt;img src=x onerror=alert(1)&gt;" in page


# ---------------------------------------------------------------------------------------- 7. EXIF orientation
def test_exif_orientation_is_warned_about_once(S):
    from PIL import Image

    img = Image.open(S / "images" / "v01.png").convert("RGB")
    exif = Image.Exif()
    exif[0x0112] = 6
    img.save(S / "images" / "v01.jpg", exif=exif.tobytes(), quality=95)
    _edit(S, lambda d: d["views"][1].update(image="images/v01.jpg"))
    with pytest.warns(sc.errors.O3dSeqccWarning, match=r"v01\.jpg has EXIF orientation 6 \(rotate 90 clockwise\), "
                                                      r"which is not applied") as record:
        scene = sc.load_scene(S)
        px = scene.views[1].load_image()
    assert px.shape == (48, 64, 3)  # the stored pixels, as the cameras were registered on them
    assert sum("EXIF orientation" in str(w.message) for w in record) == 1


_CALLBACK_SIGINT = """
    import os, signal, sys, time, weakref
    from o3d_seqcc._shared.interrupts import interruptible
    # a weakref callback from importlib's own file and name, as _get_module_lock's: Python drops what it raises
    space = {}
    exec(compile("def cb(ref):\\n    os.kill(os.getpid(), signal.SIGINT)\\n    sum(range(10 ** 6))\\n",
                 "<frozen importlib._bootstrap>", "exec"), {"os": os, "signal": signal}, space)

    class Module:
        pass

    def run():
        m = Module()
        ref = weakref.ref(m, space["cb"])
        del m  # the callback runs here; the SIGINT's handler runs inside it
        time.sleep(0.5)
        print("went on", ref() is None)

    try:
        with {guard}:
            run()
    except KeyboardInterrupt:
        print("interrupted")
"""


@pytest.mark.parametrize("guard, expected", [("interruptible()", "interrupted"), ("open(os.devnull)", "went on True")])
def test_ctrl_c_inside_importlibs_lock_callback_is_not_dropped(guard, expected):
    # CI under load: a Ctrl-C 0.25 s into `o3d-seqcc info` landed in importlib's module-lock weakref callback,
    # Python printed "Exception ignored in: <function _get_module_lock.<locals>.cb>" and the command went on
    # (exit 0). The signal is made to land there every time; without interruptible() it is dropped.
    r = python(_CALLBACK_SIGINT.replace("{guard}", guard), timeout=60)
    assert r.stdout.strip() == expected, r.stdout + r.stderr
    assert ("Exception ignored" in r.stderr) == (expected != "interrupted"), r.stderr


_CUT_SHORT = """
import sys
import open3d as o3d
import o3d_seqcc.cli as cli

class Holder:
    pass

def cut_short(argv=None):  # a stage that holds an Open3D tensor in a cycle when Ctrl-C lands
    h = Holder()
    h.self = h
    h.tensor = o3d.core.Tensor.ones((4,))
    raise KeyboardInterrupt

cli._main = cut_short
if sys.argv[1] == "console":
    cli.console_main()
else:
    sys.exit(cli.main())
"""


@pytest.mark.parametrize("entry, code", [("console", 130), ("sys.exit(main())", 1)])
def test_ctrl_c_exits_130_though_open3d_still_holds_tensors(tmp_path, entry, code):
    # CI under load: `o3d-seqcc correct` interrupted at 0.9 s printed "interrupted" and exited 1 in 4 runs of 10:
    # Open3D's MemoryManagerStatistic destructor ends a process that still holds tensor allocations with status 1,
    # after main() returned 130. The console entry (console_main) ends the process before the C++ destructors; the
    # plain sys.exit(main()) shows the exit status it had.
    script = tmp_path / "cut_short.py"
    script.write_text(_CUT_SHORT)
    r = subprocess.run([sys.executable, str(script), entry], env=ENV, capture_output=True, text=True, timeout=120,
                       preexec_fn=default_signals)
    assert r.returncode == code, (r.returncode, r.stdout[-2000:], r.stderr[-2000:])
    assert "o3d-seqcc: interrupted" in r.stderr
