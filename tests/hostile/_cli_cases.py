"""Three hundred bad inputs, faults and hostile files on the CLI, as a table: what each case does, the command, the outcome.

The cases of ``tests/hostile/test_cli_sweep.py`` (run by pytest, marker ``hostile``; ``benchmarks/hostile_inputs.py``
runs them and prints the tried / handled table). A small synthetic scene (6 views 160x120) and one ``run`` output of
it are made once per session; every case works on a fresh copy of the scene in its own folder and runs ``python -m
o3d_seqcc ...`` in a subprocess. The cases are the reproductions of issue 10's nine groups (inputs deleted, input
images overwritten, decompression bombs, partial outputs, truncated images, stale or lost results, tracebacks
instead of messages, writes outside ``--out``, argument checks), a broader set of bad inputs (wrong types and ranges
for every ``scene.json`` field, missing and broken files, bad meshes, bad flags and values for each command) and
issue 25's round 2 (groups R1-R7: every output path through the one guard, the one file-reading layer, signals /
working directory / worker errors, far-away junk, what ``report`` reads, EXIF orientation and duplicate JSON keys).

One :class:`Case` per row of :data:`CASES`: ``group``, ``name``, ``prep`` (the input mutation, on the case's copy),
``args`` (the command line) and ``kind`` with ``names`` (the expected outcome), or ``run`` for a case that drives
the processes itself (kills, concurrency, signals). :func:`run_case` checks one case and says whether it was handled.

"Handled" means, for a case that must be refused (``kind="error"``): exit code 1 or 2, no ``Traceback`` on stderr,
an error message that names the file or argument at fault (one of ``names``), the input files' checksums unchanged,
nothing new in the case's folder (hidden files included: no staging folder or lock left) and no output folder or
file created. A case that must succeed (a symlinked ``--out``, an ``--overwrite`` with fewer formats, warnings, ...)
has its own check, described next to it; an "either" case may succeed or be refused but must not crash, change an
input or write outside its output; a "warn" case must succeed with a warning naming the input at fault. Every
case's folder is also scanned for report pages holding markup a case injected (unsafe HTML).

Not a case, a note: 8 small photos on a 2.2M-face mesh took 118 s and 5.6 GB (heavy but bounded).
Known limit: ``import o3d_seqcc`` is now cheap (the scene model is imported on first use), so Ctrl-C
0.25 s after the start reaches ``main``'s handler; on a machine so loaded (load 8-10 on 2 cores) that
Python's own start-up takes longer, a Ctrl-C before ``main`` still prints Python's traceback (exit -2).
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
import tempfile
import time
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

REPO = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)}
FAST = ["--t-npm", "50"]
TEX = ["--atlas-size", "1024", "--no-seams", "--selection-view", "none"]


# -- helpers ------------------------------------------------------------------------------------------------------


def checksums(folder: Path) -> dict[str, str]:
    """sha256 of every file under ``folder`` (symlinks not followed; FIFOs and devices named, never read)."""
    import stat
    out = {}
    for root, dirs, files in os.walk(folder):
        for f in files:
            p = Path(root) / f
            rel = p.relative_to(folder).as_posix()
            mode = os.lstat(p).st_mode
            out[rel] = ("link" if stat.S_ISLNK(mode) else hashlib.sha256(p.read_bytes()).hexdigest()
                        if stat.S_ISREG(mode) else f"special {stat.S_IFMT(mode)}")
    return out


def listing(folder: Path) -> list[str]:
    """Names in ``folder``, hidden ones included."""
    return sorted(p.name for p in folder.iterdir())


CWD = [tempfile.gettempdir()]  # the sweep's folder once it exists: relative paths written by a case land there


def cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "o3d_seqcc", *map(str, args)], env=ENV, capture_output=True,
                          text=True, errors="replace", timeout=timeout, cwd=CWD[0])


def default_signals() -> None:
    """A child's SIGINT, SIGTERM and SIGHUP at their default action, as in a terminal.

    Under ``nohup`` (or another parent that ignores SIGHUP) a child inherits the ignored disposition, and
    o3d-seqcc rightly keeps a SIGHUP its caller ignores; a background job of a non-interactive shell (``cmd &``)
    ignores SIGINT, and Python then installs no KeyboardInterrupt handler. The signal cases test the terminal's
    case.
    """
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)


def popen(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "o3d_seqcc", *map(str, args)], env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, errors="replace", cwd=CWD[0], preexec_fn=default_signals)


def message(err: str) -> str:
    """The error line of stderr (argparse prints its usage first), else the first non-empty line."""
    lines = [ln.strip() for ln in err.splitlines() if ln.strip()]
    for ln in lines:
        if "error" in ln.lower() and not ln.startswith("usage:"):
            return ln
    return lines[0] if lines else ""


def edit_scene(s: Path, fn: Callable[[dict], None]) -> None:
    doc = json.loads((s / "scene.json").read_text())
    fn(doc)
    (s / "scene.json").write_text(json.dumps(doc))


def view_set(i: int, **kw) -> Callable[[dict], None]:
    return lambda d: d["views"][i].update(kw)


def view_del(i: int, key: str) -> Callable[[dict], None]:
    return lambda d: d["views"][i].pop(key)


def png_declaring(path: Path, w: int, h: int, size: int = 420_000) -> None:
    """A PNG whose header declares ``w`` x ``h`` RGB pixels, with a ~``size`` byte zlib stream of zeros."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    comp = zlib.compressobj(9)
    row = b"\0" * (1 + 3 * w)
    data, rows = b"", 0
    while len(data) < size and rows < h:
        data += comp.compress(row * 64)
        rows += 64
    data += comp.flush()
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", data) + chunk(b"IEND", b""))


def ply(path: Path, verts: list[str], faces: list[str]) -> None:
    path.write_text("ply\nformat ascii 1.0\n"
                    f"element vertex {len(verts)}\nproperty float x\nproperty float y\nproperty float z\n"
                    f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
                    + "".join(v + "\n" for v in verts) + "".join(f + "\n" for f in faces))


def image_as_jpeg(s: Path, view: int = 2) -> Path:
    import cv2
    img = cv2.imread(str(s / "images" / f"v{view:02d}.png"))
    jpg = s / "images" / f"v{view:02d}.jpg"
    cv2.imwrite(str(jpg), img, [cv2.IMWRITE_JPEG_QUALITY, 95])
    (s / "images" / f"v{view:02d}.png").unlink()
    edit_scene(s, view_set(view, image=f"images/v{view:02d}.jpg"))
    return jpg


def truncate(path: Path, frac: float = 0.5) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * frac)])


def resize_image(path: Path, w: int, h: int) -> None:
    import cv2
    cv2.imwrite(str(path), cv2.resize(cv2.imread(str(path), cv2.IMREAD_UNCHANGED), (w, h)))


# -- cases --------------------------------------------------------------------------------------------------------


@dataclass
class Ctx:
    """One case's folder: ``d`` holds ``S`` (a fresh copy of the scene) and ``out`` (not created)."""

    d: Path
    S: Path
    out: Path
    inputs: dict = field(default_factory=dict)
    before: list = field(default_factory=list)


@dataclass
class Case:
    group: str
    name: str
    args: Callable[[Ctx], list] | None = None  # CLI arguments (expect refusal unless kind says otherwise)
    names: tuple = ()  # one of these must appear in stderr (the file or argument at fault)
    prep: Callable[[Ctx], None] | None = None
    kind: str = "error"  # "error", "either", "warn" (exit 0 and a warning naming it), or "custom" (run(ctx) ->
    # (ok, message[, categories]))
    run: Callable[[Ctx], tuple] | None = None
    serial: bool = False
    allowed: tuple = ()  # names that may appear beside the output (e.g. the target of a dangling --out symlink)


CASES: list[Case] = []


def case(group, name, args=None, names=(), prep=None, kind="error", run=None, serial=False, allowed=()):
    CASES.append(Case(group, name, args, tuple(names), prep, kind, run, serial, tuple(allowed)))


def whole(out: Path) -> bool:
    """``out`` is a complete output: its manifest lists exactly the files present, report.json among them."""
    try:
        listed = set(json.loads((out / ".o3d_seqcc.json").read_text())["files"])
    except (OSError, ValueError, KeyError, TypeError):
        return False
    present = set(checksums(out)) - {".o3d_seqcc.json"}
    return listed == present and "report.json" in present


def clean_beside(c: Ctx, allowed: set) -> bool:
    return set(listing(c.d)) <= allowed


def checked_ok(r: subprocess.CompletedProcess) -> tuple[bool, str]:
    return r.returncode == 0 and "Traceback" not in r.stderr, message(r.stderr) or f"exit {r.returncode}"


G1, G2, G3, G4, G5, G6, G7, G8, G9 = ("1 input deleted", "2 inputs overwritten", "3 decompression bomb",
                                      "4 partial output", "5 truncated image", "6 stale/lost results",
                                      "7 traceback", "8 writes outside --out", "9 checks")
GS, GF, GM, GC = "scene.json fields", "files", "meshes", "CLI flags"


def _unrelated(c: Ctx) -> None:
    (c.d / "unrelated.txt").write_text("keep me")


# 1. the input is deleted
for cmd, extra in (("correct", FAST), ("run", FAST + TEX), ("texture", TEX)):
    case(G1, f"{cmd} x --out x --overwrite", lambda c, cmd=cmd, extra=extra: [cmd, c.S, "--out", c.S, "--overwrite", *extra],
         ["contains", "input", "scene"])
    case(G1, f"{cmd} P/in --out P --overwrite", lambda c, cmd=cmd, extra=extra: [cmd, c.S, "--out", c.d, "--overwrite", *extra],
         ["contains", "input"], prep=_unrelated)
case(G1, "correct --out S/images --overwrite", lambda c: ["correct", c.S, "--out", c.S / "images", "--overwrite", *FAST],
     ["images", "input"])
case(G1, "correct --out S/depth --overwrite", lambda c: ["correct", c.S, "--out", c.S / "depth", "--overwrite", *FAST],
     ["depth", "input"])
case(G1, "correct --out S/mesh.ply --overwrite", lambda c: ["correct", c.S, "--out", c.S / "mesh.ply", "--overwrite", *FAST],
     ["mesh.ply"])
case(G1, "correct --out S/new (inside the scene folder)", lambda c: ["correct", c.S, "--out", c.S / "new", *FAST],
     ["input", "inside"], kind="either")
case(G1, "mappings --out S/mesh.ply --overwrite", lambda c: ["mappings", c.S, "--out", c.S / "mesh.ply", "--overwrite"],
     ["mesh.ply", ".npz"])
case(G1, "mappings --out S/scene.json --overwrite", lambda c: ["mappings", c.S, "--out", c.S / "scene.json", "--overwrite"],
     ["scene.json", ".npz"])
case(G1, "correct --mesh outside, --out its folder", lambda c: ["correct", c.S, "--mesh", c.d / "m" / "mesh.ply",
                                                                "--out", c.d / "m", "--overwrite", *FAST],
     ["input", "contains"], prep=lambda c: ((c.d / "m").mkdir(), shutil.move(str(c.S / "mesh.ply"), c.d / "m" / "mesh.ply")))
case(G1, "synthetic into the scene folder", lambda c: ["synthetic", c.S, "--views", "3", "--width", "64", "--height", "48"],
     [str(Path("S")), "exists", "not empty"])
case(G1, "evaluate --json over scene.json", lambda c: ["evaluate", c.S, "--json", c.S / "scene.json"],
     ["scene.json", "json"])
case(G1, "seams --json over the mesh", lambda c: ["seams", c.S / "mesh.ply", "--json", c.S / "mesh.ply"],
     ["mesh.ply"])

# 2. input images overwritten
case(G2, "run y --out y --overwrite --save-images", lambda c: ["run", c.S, "--out", c.S, "--overwrite", "--save-images", *FAST, *TEX],
     ["contains", "input"])
case(G2, "run --out S/images --overwrite --save-images",
     lambda c: ["run", c.S, "--out", c.S / "images", "--overwrite", "--save-images", *FAST, *TEX], ["images", "input"])
case(G2, "texture --images S/images --out S/images --overwrite",
     lambda c: ["texture", c.S, "--images", c.S / "images", "--out", c.S / "images", "--overwrite", *TEX], ["images", "input"])

# 3. decompression bombs
for cmd, extra in (("info", []), ("correct", ["--out", "OUT", *FAST]), ("run", ["--out", "OUT", *FAST, *TEX]),
                   ("texture", ["--out", "OUT", *TEX]), ("evaluate", []), ("mappings", ["--out", "OUT.npz"])):
    case(G3, f"{cmd}: 420 KB PNG declaring 12000x12000",
         lambda c, cmd=cmd, extra=extra: [cmd, c.S, *[str(c.out) + e[3:] if e.startswith("OUT") else e for e in extra]],
         ["v01.png", "over the limit"], prep=lambda c: png_declaring(c.S / "images" / "v01.png", 12000, 12000))
case(G3, "correct: bomb with width/height 12000 in scene.json", lambda c: ["correct", c.S, "--out", c.out, *FAST],
     ["v01", "over the limit"], prep=lambda c: (png_declaring(c.S / "images" / "v01.png", 12000, 12000),
                                                edit_scene(c.S, view_set(1, width=12000, height=12000))))
case(G3, "correct: PNG declaring 40000x40000 (over Pillow's limit)", lambda c: ["correct", c.S, "--out", c.out, *FAST],
     ["v01.png"], prep=lambda c: png_declaring(c.S / "images" / "v01.png", 40000, 40000, size=60_000))
case(G3, "correct: depth PNG declaring 12000x12000", lambda c: ["correct", c.S, "--out", c.out, *FAST],
     ["v03.png", "depth"], prep=lambda c: png_declaring(c.S / "depth" / "v03.png", 12000, 12000))
case(G3, "info --max-image-pixels 1000", lambda c: ["--max-image-pixels", "1000", "info", c.S], ["over the limit"])
case(G3, "--max-image-pixels -1", lambda c: ["--max-image-pixels", "-1", "info", c.S], ["--max-image-pixels", "max_image_pixels"])
case(G3, "--max-image-pixels abc", lambda c: ["--max-image-pixels", "abc", "info", c.S], ["--max-image-pixels"])


# 4. partial outputs
def _kill(c: Ctx, cmd: list, sig: int, frac: float, previous: bool) -> tuple[bool, str]:
    """Start ``cmd`` (its --out is c.out), kill it after ``frac`` of a full run; then check and re-run."""
    if previous:
        r = cli(*cmd)
        if r.returncode:
            return False, "first run failed: " + message(r.stderr)
    prev = checksums(c.out) if c.out.exists() else None
    beside = set(listing(c.d))
    t = time.perf_counter()
    r = cli(*cmd, "--overwrite")  # a full run to time it
    full = time.perf_counter() - t
    if r.returncode:
        return False, "full run failed: " + message(r.stderr)
    if not previous:
        shutil.rmtree(c.out)
    else:
        prev = checksums(c.out)
    p = popen(*cmd, "--overwrite")
    time.sleep(full * frac)
    p.send_signal(sig)
    _, err = p.communicate()
    now = checksums(c.out) if c.out.exists() else None
    state = "intact" if now == prev else "whole" if whole(c.out) else "partial"
    visible_ok = {n for n in listing(c.d) if not n.startswith(".")} <= {n for n in beside if not n.startswith(".")} | {c.out.name}
    r2 = cli(*cmd, "--overwrite")
    clean = set(listing(c.d)) <= beside | {c.out.name}
    ok = (state != "partial" and visible_ok and r2.returncode == 0 and whole(c.out) and clean
          and "Traceback" not in err and "Traceback" not in r2.stderr)
    return ok, (f"killed (exit {p.returncode}) after {full * frac:.1f} s -> {state}; leftovers "
                f"{sorted(set(listing(c.d)) - beside - {c.out.name}) or 'none'}; re-run exit {r2.returncode}"
                + (" " + message(err) if "Traceback" in err else ""))


case(G4, "run SIGKILL at 60 % (no previous output)", kind="custom", serial=True,
     run=lambda c: _kill(c, ["run", c.S, "--out", c.out, "--format", "glb,obj", *FAST, *TEX], signal.SIGKILL, 0.6, False))
case(G4, "run SIGINT at 70 % (previous output)", kind="custom", serial=True,
     run=lambda c: _kill(c, ["run", c.S, "--out", c.out, "--save-images", *FAST, *TEX], signal.SIGINT, 0.7, True))
case(G4, "correct SIGKILL at 50 % (previous output)", kind="custom", serial=True,
     run=lambda c: _kill(c, ["correct", c.S, "--out", c.out, *FAST], signal.SIGKILL, 0.5, True))
case(G4, "texture SIGINT at 80 %", kind="custom", serial=True,
     run=lambda c: _kill(c, ["texture", c.S, "--out", c.out, *TEX], signal.SIGINT, 0.8, False))


def _fail_then_rerun(c: Ctx) -> tuple[bool, str]:
    r = cli("run", c.S, "--out", c.out, "--atlas-size", "0", *FAST)
    if r.returncode == 0 or c.out.exists() or "Traceback" in r.stderr:
        return False, f"--atlas-size 0: exit {r.returncode}, out exists {c.out.exists()}"
    r2 = cli("run", c.S, "--out", c.out, *FAST, *TEX)
    return r2.returncode == 0 and whole(c.out), f"refused ({message(r.stderr)}); re-run exit {r2.returncode}"


def _late_failure(c: Ctx) -> tuple[bool, str]:
    r = cli("run", c.S, "--out", c.out, *FAST, "--atlas-size", "64", "--overflow", "error", "--no-seams")
    if "Traceback" in r.stderr or (r.returncode == 0 and not whole(c.out)) or (r.returncode and c.out.exists()):
        return False, f"exit {r.returncode}: {message(r.stderr)}"
    return True, f"exit {r.returncode}: {message(r.stderr)}"


case(G4, "run --atlas-size 0, then run again", kind="custom", run=_fail_then_rerun)
case(G4, "run --overflow error on a tiny atlas (fails after loading)", kind="custom", run=_late_failure)


def _leftover_hidden(c: Ctx) -> tuple[bool, str]:
    """A stale hidden staging folder of a dead run beside --out is cleaned by the next run."""
    r = cli("correct", c.S, "--out", c.out, *FAST)
    p = popen("correct", c.S, "--out", c.out, "--overwrite", *FAST)
    time.sleep(1.2)
    p.kill()
    p.communicate()
    r2 = cli("correct", c.S, "--out", c.out, "--overwrite", *FAST)
    left = [n for n in listing(c.d) if n not in ("S", c.out.name)]
    return r.returncode == 0 and r2.returncode == 0 and not left and whole(c.out), f"left beside: {left or 'nothing'}"


case(G4, "correct kill -9 at 1.2 s leaves nothing after the next run", kind="custom", run=_leftover_hidden, serial=True)

# 5. truncated images
for fmt in ("jpeg", "png"):
    for cmd, extra in (("info", []), ("correct", ["--out", "OUT", *FAST]), ("run", ["--out", "OUT", *FAST, *TEX])):
        def _prep(c, fmt=fmt):
            p = image_as_jpeg(c.S) if fmt == "jpeg" else c.S / "images" / "v02.png"
            truncate(p, 0.6)
        case(G5, f"{cmd}: truncated {fmt.upper()}",
             lambda c, cmd=cmd, extra=extra: [cmd, c.S, *[c.out if e == "OUT" else e for e in extra]],
             ["v02."], prep=_prep)
case(G5, "correct: empty (0-byte) image", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["v02.png"],
     prep=lambda c: (c.S / "images" / "v02.png").write_bytes(b""))
case(G5, "correct: image of random bytes", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["v02.png"],
     prep=lambda c: (c.S / "images" / "v02.png").write_bytes(os.urandom(5000)))
case(G5, "correct: image is a text file", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["v02.png"],
     prep=lambda c: (c.S / "images" / "v02.png").write_text("hello"))
case(G5, "correct: PNG header only", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["v02.png"],
     prep=lambda c: truncate(c.S / "images" / "v02.png", 0.02))
case(G5, "info: image of random bytes", lambda c: ["info", c.S], ["v02.png"],
     prep=lambda c: (c.S / "images" / "v02.png").write_bytes(os.urandom(5000)))
case(G5, "correct: truncated depth PNG", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["v03.png"],
     prep=lambda c: truncate(c.S / "depth" / "v03.png", 0.5))


# 6. stale or lost results
def _fewer_formats(c: Ctx) -> tuple[bool, str]:
    r1 = cli("run", c.S, "--out", c.out, "--format", "glb,obj", "--save-images", *FAST, *TEX)
    r2 = cli("run", c.S, "--out", c.out, "--overwrite", "--format", "glb", *FAST, *TEX)
    stale = sorted(n for n in checksums(c.out) if n.endswith((".obj", ".mtl")) or n.startswith("images/"))
    ok = r1.returncode == 0 and r2.returncode == 0 and not stale and whole(c.out)
    return ok, f"exits {r1.returncode}/{r2.returncode}; stale files {stale or 'none'}"


def _concurrent(c: Ctx) -> tuple[bool, str]:
    a = popen("correct", c.S, "--out", c.out, *FAST)
    time.sleep(0.3)
    b = popen("correct", c.S, "--out", c.out, *FAST)
    ea, eb = a.communicate()[1], b.communicate()[1]
    codes = sorted([a.returncode, b.returncode])
    tb = "Traceback" in ea + eb
    # one succeeds; the other fails clearly (or waits for the lock and then refuses the non-empty folder)
    ok = codes[0] == 0 and codes[1] in (1, 2) and not tb and whole(c.out) and clean_beside(c, {"S", c.out.name})
    return ok, f"exits {a.returncode}/{b.returncode}; " + (message(eb) if b.returncode else message(ea))


def _holds_lock(a: subprocess.Popen, out: Path, timeout: float = 120) -> bool:
    """Wait until ``a`` holds ``out``'s lock (its PID in ``.<out>.o3d_seqcc.lock``), then stop it there (SIGSTOP)."""
    lock = out.parent / f".{out.name}.o3d_seqcc.lock"
    end = time.monotonic() + timeout
    while time.monotonic() < end and a.poll() is None:
        try:
            if lock.read_text().strip() == str(a.pid):
                os.kill(a.pid, signal.SIGSTOP)
                return True
        except OSError:
            pass
        time.sleep(0.002)
    return False


def _concurrent_overwrite(c: Ctx) -> tuple[bool, str]:
    cli("correct", c.S, "--out", c.out, *FAST)
    a = popen("correct", c.S, "--out", c.out, "--overwrite", *FAST)
    # the second run while the first writes: the first is held inside its save (a save takes a fraction of a second,
    # so starting the second a little later left the two overlapping only by chance)
    held = _holds_lock(a, c.out)
    b = popen("correct", c.S, "--out", c.out, "--overwrite", "--method", "none")
    if held:
        eb = b.communicate()[1]
        os.kill(a.pid, signal.SIGCONT)
        ea = a.communicate()[1]
    else:
        ea, eb = a.communicate()[1], b.communicate()[1]
    ok = ("Traceback" not in ea + eb and whole(c.out) and clean_beside(c, {"S", c.out.name})
          and (0 in (a.returncode, b.returncode)) and all(x in (0, 1, 2) for x in (a.returncode, b.returncode))
          and (a.returncode != 0 or b.returncode != 0 or "wait" in (ea + eb).lower()))
    return ok, f"exits {a.returncode}/{b.returncode}; " + (message(eb) or message(ea))


case(G6, "run --overwrite --format glb after glb,obj --save-images", kind="custom", run=_fewer_formats)
case(G6, "two concurrent correct --out same", kind="custom", run=_concurrent, serial=True)
case(G6, "two concurrent correct --out same --overwrite", kind="custom", run=_concurrent_overwrite, serial=True)
case(G6, "--overwrite into a folder of foreign files", lambda c: ["correct", c.S, "--out", c.out, "--overwrite", *FAST],
     ["not written by o3d-seqcc", "foreign", "o3d-seqcc", str("out")],
     prep=lambda c: (c.out.mkdir(), (c.out / "thesis.tex").write_text("years of work")))
case(G6, "existing non-empty --out without --overwrite", lambda c: ["correct", c.S, "--out", c.out, *FAST],
     ["--overwrite", "exists"], prep=lambda c: (c.out.mkdir(), (c.out / "a.txt").write_text("x")))
case(G6, "mappings onto an existing .npz without --overwrite", lambda c: ["mappings", c.S, "--out", c.d / "m.npz"],
     ["m.npz", "--overwrite"], prep=lambda c: (c.d / "m.npz").write_bytes(b"old"))

# 7. tracebacks instead of messages


def _readonly(c: Ctx) -> None:
    (c.d / "ro").mkdir()
    os.chmod(c.d / "ro", 0o555)


def _readonly_run(c: Ctx) -> tuple[bool, str]:
    out = c.d / "ro" / "o"
    r = cli("correct", c.S, "--out", out, *FAST)
    os.chmod(c.d / "ro", 0o755)
    if os.geteuid() == 0:  # root ignores the mode bits: success is right
        return r.returncode == 0 and "Traceback" not in r.stderr, f"(root: permissions not enforced) exit {r.returncode}"
    return (r.returncode in (1, 2) and "Traceback" not in r.stderr and "ro" in r.stderr and not out.exists(),
            message(r.stderr))


case(G7, "read-only output parent", kind="custom", prep=_readonly, run=_readonly_run)
case(G7, "--out under a file", lambda c: ["correct", c.S, "--out", c.d / "afile" / "sub", *FAST], ["afile"],
     prep=lambda c: (c.d / "afile").write_text("x"))
case(G7, "run --out under a file", lambda c: ["run", c.S, "--out", c.d / "afile" / "sub", *FAST, *TEX], ["afile"],
     prep=lambda c: (c.d / "afile").write_text("x"))
case(G7, "mappings --out <folder>", lambda c: ["mappings", c.S, "--out", c.d], [".npz", "--out"])
case(G7, "mappings --out with no .npz suffix", lambda c: ["mappings", c.S, "--out", c.d / "m"], [".npz", "--out"])
case(G7, '"mesh": null', lambda c: ["info", c.S], ["mesh"], prep=lambda c: edit_scene(c.S, lambda d: d.update(mesh=None)))
case(G7, "non-UTF-8 scene.json", lambda c: ["info", c.S], ["scene.json", "UTF-8"],
     prep=lambda c: (c.S / "scene.json").write_bytes(b'{"format": "o3d_seqcc.scene/1", "mesh": "\xff\xfe"}'))
case(G7, "non-UTF-8 scene.json (correct)", lambda c: ["correct", c.S, "--out", c.out], ["scene.json", "UTF-8"],
     prep=lambda c: (c.S / "scene.json").write_bytes(b"\xff\xfe\x00{"))
case(G7, "NUL in a view name (correct)", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["name", "control"],
     prep=lambda c: edit_scene(c.S, view_set(0, name="a\x00b")))
case(G7, "300-character view name (run --save-images)", lambda c: ["run", c.S, "--out", c.out, "--save-images", *FAST, *TEX],
     ["name", "300"], prep=lambda c: edit_scene(c.S, view_set(0, name="n" * 300)))


def _colmap(c: Ctx, cams: str, imgs: str) -> None:
    m = c.d / "colmap"
    m.mkdir()
    (m / "cameras.txt").write_text(cams)
    (m / "images.txt").write_text(imgs)
    (m / "points3D.txt").write_text("")


case(G7, "COLMAP cameras.txt: width 'forty-eight'", lambda c: ["info", c.d / "colmap", "--mesh", c.S / "mesh.ply"],
     ["cameras.txt"], prep=lambda c: _colmap(c, "1 PINHOLE 64 forty-eight 1 1 1 1\n", "1 1 0 0 0 0 0 0 1 a.png\n\n"))
case(G7, "COLMAP cameras.txt: too few parameters", lambda c: ["info", c.d / "colmap", "--mesh", c.S / "mesh.ply"],
     ["cameras.txt"], prep=lambda c: _colmap(c, "1 PINHOLE 64 48 1\n", "1 1 0 0 0 0 0 0 1 a.png\n\n"))
case(G7, "COLMAP cameras.txt: unknown model", lambda c: ["info", c.d / "colmap", "--mesh", c.S / "mesh.ply"],
     ["cameras.txt", "FISHY"], prep=lambda c: _colmap(c, "1 FISHY 64 48 1 1 1 1\n", "1 1 0 0 0 0 0 0 1 a.png\n\n"))
case(G7, "COLMAP images.txt: non-numeric pose", lambda c: ["info", c.d / "colmap", "--mesh", c.S / "mesh.ply"],
     ["images.txt"], prep=lambda c: _colmap(c, "1 PINHOLE 64 48 1 1 1 1\n", "1 one 0 0 0 0 0 0 1 a.png\n\n"))
case(G7, "COLMAP images.txt: unknown camera id", lambda c: ["info", c.d / "colmap", "--mesh", c.S / "mesh.ply"],
     ["images.txt", "camera"], prep=lambda c: _colmap(c, "1 PINHOLE 64 48 1 1 1 1\n", "1 1 0 0 0 0 0 0 7 a.png\n\n"))
case(G7, "COLMAP images.txt: zero quaternion", lambda c: ["info", c.d / "colmap", "--mesh", c.S / "mesh.ply"],
     ["images.txt", "quaternion", "a.png"], prep=lambda c: _colmap(c, "1 PINHOLE 64 48 1 1 1 1\n", "1 0 0 0 0 0 0 0 1 a.png\n\n"))
case(G7, "COLMAP images.txt: truncated line", lambda c: ["info", c.d / "colmap", "--mesh", c.S / "mesh.ply"],
     ["images.txt"], prep=lambda c: _colmap(c, "1 PINHOLE 64 48 1 1 1 1\n", "1 1 0 0\n\n"))


def _rgbd(c: Ctx, log: str, n: int = 1) -> None:
    import cv2
    import numpy as np
    r = c.d / "rgbd"
    (r / "image").mkdir(parents=True)
    (r / "scene").mkdir()
    for i in range(n):
        cv2.imwrite(str(r / "image" / f"{i:06d}.png"), np.full((48, 64, 3), 100, np.uint8))
    (r / "scene" / "key.log").write_text(log)


case(G7, "singular pose in key.log", lambda c: ["info", c.d / "rgbd", "--mesh", c.S / "mesh.ply"], ["key.log", "singular"],
     prep=lambda c: _rgbd(c, "0 0 1\n" + "0 0 0 0\n" * 3 + "0 0 0 1\n"))
case(G7, "key.log with 3 lines", lambda c: ["info", c.d / "rgbd", "--mesh", c.S / "mesh.ply"], ["key.log"],
     prep=lambda c: _rgbd(c, "0 0 1\n1 0 0 0\n0 1 0 0\n"))
case(G7, "key.log with text in the matrix", lambda c: ["info", c.d / "rgbd", "--mesh", c.S / "mesh.ply"], ["key.log"],
     prep=lambda c: _rgbd(c, "0 0 1\n1 0 0 x\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"))
case(G7, "key.log: 2 poses for 1 image", lambda c: ["info", c.d / "rgbd", "--mesh", c.S / "mesh.ply"], ["key.log", "poses"],
     prep=lambda c: _rgbd(c, ("0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n") * 2))


def _sigint_import(c: Ctx, delay: float = 0.25) -> tuple[bool, str]:
    p = popen("info", c.S)
    time.sleep(delay)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate()
    ok = "Traceback" not in err and p.returncode in (0, 130, -2, 2, 1)
    return ok, f"exit {p.returncode}: {message(err) or '(no message)'}"


case(G7, "SIGINT at 0.25 s (during import)", kind="custom", run=_sigint_import)
case(G7, "SIGINT at 0.55 s (open3d's import)", kind="custom", run=lambda c: _sigint_import(c, 0.55))
def _sigint_at(delay: float) -> Callable[[Ctx], tuple]:
    def run(c: Ctx) -> tuple[bool, str]:
        p = popen("correct", c.S, "--out", c.out, *FAST)
        time.sleep(delay)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate()
        ok = ("Traceback" not in err and p.returncode in (0, 130, -2) and (p.returncode == 0 or not c.out.exists())
              and clean_beside(c, {"S", c.out.name}))
        return ok, f"exit {p.returncode}: {message(err) or '(no message)'}"
    return run


case(G7, "SIGINT during loading (0.9 s)", kind="custom", run=_sigint_at(0.9))

# 8. writes outside --out


def _symlinked_out(c: Ctx) -> tuple[bool, str]:
    target = c.d / "disk" / "results"
    target.mkdir(parents=True)
    link = c.d / "out"
    link.symlink_to(target, target_is_directory=True)
    r1 = cli("correct", c.S, "--out", link, *FAST)
    r2 = cli("correct", c.S, "--out", link, "--overwrite", *FAST)
    ok = (r1.returncode == 0 and r2.returncode == 0 and link.is_symlink() and whole(target)
          and listing(c.d) == ["S", "disk", "out"] and listing(c.d / "disk") == ["results"])
    return ok, f"exits {r1.returncode}/{r2.returncode}; beside: {listing(c.d)} disk/: {listing(c.d / 'disk')}"


def _images_symlink(c: Ctx) -> tuple[bool, str]:
    r1 = cli("run", c.S, "--out", c.out, *FAST, *TEX)
    elsewhere = c.d / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "keep.png").write_bytes(b"not ours")
    (c.out / "images").symlink_to(elsewhere, target_is_directory=True)
    r2 = cli("run", c.S, "--out", c.out, "--overwrite", "--save-images", *FAST, *TEX)
    ok = listing(elsewhere) == ["keep.png"] and (elsewhere / "keep.png").read_bytes() == b"not ours"
    return ok and "Traceback" not in r2.stderr, f"exits {r1.returncode}/{r2.returncode}; elsewhere/: {listing(elsewhere)}"


def _name_traversal(c: Ctx) -> tuple[bool, str]:
    r = cli("run", c.S, "--out", c.out, "--save-images", *FAST, *TEX)
    escaped = [p for p in (c.d / "escaped.png", c.d.parent / "escaped.png", c.out.parent / "escaped.png") if p.exists()]
    ok = not escaped and "Traceback" not in r.stderr and (r.returncode == 0 or not c.out.exists())
    return ok, f"exit {r.returncode}: {message(r.stderr) or 'accepted'}; escaped files: {escaped or 'none'}"


def _dotdot_out(c: Ctx) -> tuple[bool, str]:
    r = cli("correct", c.S, "--out", c.S / ".." / "o2", *FAST)
    ok = r.returncode == 0 and whole(c.d / "o2") and listing(c.d) == ["S", "o2"]
    return ok, f"exit {r.returncode}; beside: {listing(c.d)}"


case(G8, "symlinked --out (twice, --overwrite)", kind="custom", run=_symlinked_out)
case(G8, "OUT/images symlink with --save-images", kind="custom", run=_images_symlink)
case(G8, "view named ../../escaped with --save-images", kind="custom", run=_name_traversal,
     prep=lambda c: edit_scene(c.S, view_set(0, name="../../escaped")))
case(G8, "--out S/../o2", kind="custom", run=_dotdot_out)
case(G8, "--out is a symlink to the scene folder", lambda c: ["correct", c.S, "--out", c.d / "ln", "--overwrite", *FAST],
     ["input", "contains"], prep=lambda c: (c.d / "ln").symlink_to(c.S, target_is_directory=True))
case(G8, "--out is a dangling symlink", kind="either", args=lambda c: ["correct", c.S, "--out", c.d / "dl", *FAST],
     names=["dl"], prep=lambda c: (c.d / "dl").symlink_to(c.d / "nowhere"), allowed=["nowhere"])

# 9. checks
for v in ("-5", "0", "abc", "1.5"):
    case(G9, f"correct --t-npm {v}", lambda c, v=v: ["correct", c.S, "--out", c.out, "--t-npm", v], ["t_npm", "--t-npm"])
case(G9, '"width": "160"', lambda c: ["info", c.S], ["width"], prep=lambda c: edit_scene(c.S, view_set(0, width="160")))


def _warn_once(c: Ctx) -> tuple[bool, str]:
    r = cli("run", c.S, "--out", c.out, *TEX, "--t-npm", "100000", "--method", "none")
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    dup = sorted({ln for ln in lines if lines.count(ln) > 1})
    return r.returncode == 0 and not dup, f"exit {r.returncode}; {len(lines)} stderr lines, repeated: {dup or 'none'}"


case(G9, "warnings printed once", kind="custom", run=_warn_once)
case(G9, "info on a wrong-size image (correct rejects it)", lambda c: ["info", c.S], ["v02.png", "v02"],
     prep=lambda c: resize_image(c.S / "images" / "v02.png", 200, 100))
case(G9, "info on a truncated PNG (correct rejects it)", lambda c: ["info", c.S], ["v04.png"],
     prep=lambda c: truncate(c.S / "images" / "v04.png", 0.7))

# scene.json: every field, wrong types and ranges
SJ = [
    ("format missing", lambda d: d.pop("format"), ["format"], "either"),
    ("format 'foo/9'", lambda d: d.update(format="foo/9"), ["format", "foo/9"], "error"),
    ("format 5", lambda d: d.update(format=5), ["format"], "error"),
    ("mesh missing", lambda d: d.pop("mesh"), ["mesh"], "error"),
    ("mesh 5", lambda d: d.update(mesh=5), ["mesh"], "error"),
    ("mesh ''", lambda d: d.update(mesh=""), ["mesh"], "error"),
    ("mesh nope.ply", lambda d: d.update(mesh="nope.ply"), ["nope.ply"], "error"),
    ("mesh is a folder", lambda d: d.update(mesh="images"), ["images"], "error"),
    ("mesh [list]", lambda d: d.update(mesh=["mesh.ply"]), ["mesh"], "error"),
    ("views missing", lambda d: d.pop("views"), ["views"], "error"),
    ("views []", lambda d: d.update(views=[]), ["views"], "error"),
    ("views 'x'", lambda d: d.update(views="x"), ["views"], "error"),
    ("views [5]", lambda d: d.update(views=[5]), ["view"], "error"),
    ("views {}", lambda d: d.update(views={}), ["views"], "error"),
    ("top level is a list", None, ["scene.json"], "error"),
    ("not JSON", None, ["scene.json"], "error"),
    ("empty file", None, ["scene.json"], "error"),
    ("name missing", view_del(0, "name"), ["name"], "either"),
    ("name 5", view_set(0, name=5), ["name"], "error"),
    ("name ''", view_set(0, name=""), ["name"], "error"),
    ("name null", view_set(0, name=None), ["name"], "error"),
    ("duplicate names", view_set(1, name="v00"), ["v00", "duplicate"], "error"),
    ("name with a slash", view_set(0, name="a/b"), ["a/b", "name"], "error"),
    ("name with a newline", view_set(0, name="a\nb"), ["name", "control"], "error"),
    ("image missing", view_del(0, "image"), ["image"], "error"),
    ("image null", view_set(0, image=None), ["image"], "error"),
    ("image 5", view_set(0, image=5), ["image"], "error"),
    ("image nope.png", view_set(0, image="images/nope.png"), ["nope.png"], "error"),
    ("image is a folder", view_set(0, image="images"), ["images"], "error"),
    ("image is the mesh", view_set(0, image="mesh.ply"), ["mesh.ply"], "error"),
    ("width -160", view_set(0, width=-160), ["width"], "error"),
    ("width 0", view_set(0, width=0), ["width"], "error"),
    ("width 160.5", view_set(0, width=160.5), ["width"], "error"),
    ("width true", view_set(0, width=True), ["width"], "error"),
    ("width null", view_set(0, width=None), ["width"], "error"),
    ("width 200 (image is 160)", view_set(0, width=200), ["width", "v00", "160"], "error"),
    ("width 1e12", view_set(0, width=1e12), ["width"], "error"),
    ("height '120'", view_set(0, height="120"), ["height"], "error"),
    ("height -1", view_set(0, height=-1), ["height"], "error"),
    ("height missing", view_del(0, "height"), ["height"], "either"),
    ("intrinsic missing", view_del(0, "intrinsic"), ["intrinsic"], "error"),
    ("intrinsic 2x2", view_set(0, intrinsic=[[1, 0], [0, 1]]), ["intrinsic"], "error"),
    ("intrinsic ragged", view_set(0, intrinsic=[[1, 2], [3]]), ["intrinsic"], "error"),
    ("intrinsic strings", view_set(0, intrinsic=[["a"] * 3] * 3), ["intrinsic"], "error"),
    ("intrinsic NaN", view_set(0, intrinsic=[[float("nan"), 0, 80], [0, 128, 60], [0, 0, 1]]), ["intrinsic"], "error"),
    ("intrinsic zero focal", view_set(0, intrinsic=[[0, 0, 80], [0, 0, 60], [0, 0, 1]]), ["intrinsic", "focal"], "error"),
    ("intrinsic negative focal", view_set(0, intrinsic=[[-128, 0, 80], [0, -128, 60], [0, 0, 1]]), ["intrinsic", "focal"],
     "either"),
    ("intrinsic null", view_set(0, intrinsic=None), ["intrinsic"], "error"),
    ("extrinsic missing", view_del(0, "extrinsic"), ["extrinsic"], "error"),
    ("extrinsic 3x3", view_set(0, extrinsic=[[1, 0, 0], [0, 1, 0], [0, 0, 1]]), ["extrinsic"], "error"),
    ("extrinsic strings", view_set(0, extrinsic=[["x"] * 4] * 4), ["extrinsic"], "error"),
    ("extrinsic Infinity", view_set(0, extrinsic=[[float("inf"), 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
     ["extrinsic"], "error"),
    ("extrinsic all zeros (singular)", view_set(0, extrinsic=[[0] * 4] * 4), ["extrinsic", "singular", "v00"], "error"),
    ("extrinsic bottom row 0 0 0 0", view_set(0, extrinsic=[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 0]]),
     ["extrinsic", "v00"], "error"),
    ("depth nope.png", view_set(0, depth="depth/nope.png"), ["nope.png"], "error"),
    ("depth 5", view_set(0, depth=5), ["depth"], "error"),
    ("depth_scale -1", view_set(0, depth_scale=-1), ["depth_scale"], "error"),
    ("depth_scale 0", view_set(0, depth_scale=0), ["depth_scale"], "error"),
    ("depth_scale 'x'", view_set(0, depth_scale="x"), ["depth_scale"], "error"),
    ("unknown extra key", view_set(0, colour="blue"), ["colour"], "either"),
]


def _sj_prep(name, fn):
    def prep(c: Ctx) -> None:
        if name == "top level is a list":
            (c.S / "scene.json").write_text("[1, 2]")
        elif name == "not JSON":
            (c.S / "scene.json").write_text('{"format": "o3d_seqcc.scene/1", "mesh": ')
        elif name == "empty file":
            (c.S / "scene.json").write_text("")
        else:
            edit_scene(c.S, fn)
    return prep


for nm, fn, tokens, kind in SJ:
    case(GS, nm, lambda c: ["correct", c.S, "--out", c.out, *FAST], tokens, prep=_sj_prep(nm, fn), kind=kind)

# files
case(GF, "scene folder missing", lambda c: ["correct", c.d / "nope", "--out", c.out], ["nope"])
case(GF, "scene path is the mesh file", lambda c: ["correct", c.S / "mesh.ply", "--out", c.out], ["mesh.ply"])
case(GF, "empty folder", lambda c: ["info", c.d / "empty"], ["empty"], prep=lambda c: (c.d / "empty").mkdir())
case(GF, "scene.json missing", lambda c: ["info", c.S], ["S", "scene"], prep=lambda c: (c.S / "scene.json").unlink())
case(GF, "scene.json is a folder", lambda c: ["info", c.S], ["scene.json"],
     prep=lambda c: ((c.S / "scene.json").unlink(), (c.S / "scene.json").mkdir()))
case(GF, "image file deleted", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["v03.png"],
     prep=lambda c: (c.S / "images" / "v03.png").unlink())
case(GF, "depth file deleted", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["v03.png"],
     prep=lambda c: (c.S / "depth" / "v03.png").unlink())
case(GF, "image wrong size (320x240)", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["v02"],
     prep=lambda c: resize_image(c.S / "images" / "v02.png", 320, 240))
case(GF, "depth wrong size (80x60)", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["v02"],
     prep=lambda c: resize_image(c.S / "depth" / "v02.png", 80, 60))
case(GF, "image unreadable (chmod 000)", kind="either", args=lambda c: ["correct", c.S, "--out", c.out, *FAST],
     names=["v02.png"], prep=lambda c: os.chmod(c.S / "images" / "v02.png", 0))
case(GF, "scene given as a .mlp that is not XML", lambda c: ["info", c.d / "p.mlp"], ["p.mlp"],
     prep=lambda c: (c.d / "p.mlp").write_text("<MeshLabProject><broken"))
case(GF, "--mesh nope.ply", lambda c: ["info", c.S, "--mesh", c.d / "nope.ply"], ["nope.ply"])
case(GF, "--depth-dir nope", lambda c: ["info", c.S, "--depth-dir", c.d / "nope"], ["nope", "depth"], kind="either")
case(GF, "--masks nope", lambda c: ["info", c.S, "--masks", c.d / "nope"], ["nope", "masks"])
case(GF, "--masks with a mask of the wrong size", lambda c: ["info", c.S, "--masks", c.d / "m"], ["v02", "m/v02.png"],
     prep=lambda c: ((c.d / "m").mkdir(), shutil.copy(c.S / "images" / "v02.png", c.d / "m"),
                     resize_image(c.d / "m" / "v02.png", 20, 10)))
case(GF, "texture --images nope", lambda c: ["texture", c.S, "--images", c.d / "nope", "--out", c.out, *TEX], ["nope"])
case(GF, "texture --images with a missing image", lambda c: ["texture", c.S, "--images", c.d / "imgs", "--out", c.out, *TEX],
     ["v05", "imgs"], prep=lambda c: (shutil.copytree(c.S / "images", c.d / "imgs"), (c.d / "imgs" / "v05.png").unlink()))
case(GF, "seams on a mesh without texture", lambda c: ["seams", c.S / "mesh.ply"], ["mesh.ply", "texture"])
case(GF, "seams on a missing file", lambda c: ["seams", c.d / "nope.glb"], ["nope.glb"])
case(GF, "seams on a garbage .glb", lambda c: ["seams", c.d / "x.glb"], ["x.glb"],
     prep=lambda c: (c.d / "x.glb").write_bytes(b"glTF" + os.urandom(200)))
case(GF, "report on a missing folder", lambda c: ["report", c.d / "nope"], ["nope"])
case(GF, "report on the scene folder (not an output)", lambda c: ["report", c.S], ["report.json", "S"])
case(GF, "report on an output with a broken report.json", lambda c: ["report", c.d / "o"], ["report.json"],
     prep=lambda c: ((c.d / "o").mkdir(), (c.d / "o" / "report.json").write_text("{broken")))
case(GF, "evaluate --json into a missing folder", lambda c: ["evaluate", c.S, "--json", c.d / "no" / "x.json"], ["x.json", "no"],
     kind="either", allowed=["no"])

# meshes


def _mesh(fn: Callable[[Path], None]) -> Callable[[Ctx], None]:
    return lambda c: fn(c.S / "mesh.ply")


TRI = ["0 0 0", "1 0 0", "0 1 0", "1 1 0"]
MESHES = [
    ("empty file", _mesh(lambda p: p.write_bytes(b""))),
    ("random bytes", _mesh(lambda p: p.write_bytes(os.urandom(3000)))),
    ("text, not PLY", _mesh(lambda p: p.write_text("hello mesh"))),
    ("truncated binary PLY", _mesh(lambda p: truncate(p, 0.5))),
    ("header only, 0 vertices", _mesh(lambda p: ply(p, [], []))),
    ("vertices, no faces", _mesh(lambda p: ply(p, TRI, []))),
    ("NaN vertices", _mesh(lambda p: ply(p, ["nan nan nan", *TRI[1:]], ["3 0 1 2", "3 1 3 2"]))),
    ("Inf vertex", _mesh(lambda p: ply(p, ["inf 0 0", *TRI[1:]], ["3 0 1 2", "3 1 3 2"]))),
    ("face index out of range", _mesh(lambda p: ply(p, TRI, ["3 0 1 99"]))),
    ("negative face index", _mesh(lambda p: ply(p, TRI, ["3 0 -1 2"]))),
    ("header declares more vertices than present", _mesh(lambda p: p.write_text(
        "ply\nformat ascii 1.0\nelement vertex 100\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n"))),
    ("all faces degenerate", _mesh(lambda p: ply(p, TRI, ["3 0 0 0", "3 1 1 1"]))),
    ("mesh outside every camera", _mesh(lambda p: ply(p, ["1000 1000 1000", "1001 1000 1000", "1000 1001 1000"],
                                                      ["3 0 1 2"]))),
]
for nm, prep in MESHES:
    kind = "either" if nm in ("all faces degenerate", "mesh outside every camera") else "error"
    case(GM, f"correct: {nm}", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["mesh.ply", "mesh"], prep=prep, kind=kind)
case(GM, "run: NaN vertices", lambda c: ["run", c.S, "--out", c.out, *FAST, *TEX], ["mesh.ply"],
     prep=_mesh(lambda p: ply(p, ["nan nan nan", *TRI[1:]], ["3 0 1 2", "3 1 3 2"])))
case(GM, "texture: face index out of range", lambda c: ["texture", c.S, "--out", c.out, *TEX], ["mesh.ply"],
     prep=_mesh(lambda p: ply(p, TRI, ["3 0 1 99"])))
case(GM, "info: empty mesh", lambda c: ["info", c.S], ["mesh.ply"], prep=_mesh(lambda p: p.write_bytes(b"")))
case(GM, "mesh with a .stl suffix that is PLY", lambda c: ["info", c.S], ["mesh.stl", "mesh"], kind="either",
     prep=lambda c: (shutil.move(str(c.S / "mesh.ply"), c.S / "mesh.stl"), edit_scene(c.S, lambda d: d.update(mesh="mesh.stl"))))

# CLI flags
FLAGS = [
    ("no arguments", lambda c: [], ["command", "usage", "required"]),
    ("unknown command", lambda c: ["frobnicate"], ["frobnicate"]),
    ("info without a scene", lambda c: ["info"], ["scene"]),
    ("correct without --out", lambda c: ["correct", c.S], ["--out"]),
    ("correct --method best", lambda c: ["correct", c.S, "--out", c.out, "--method", "best"], ["--method", "best"]),
    ("correct --reference nope", lambda c: ["correct", c.S, "--out", c.out, "--reference", "nope"], ["nope", "reference"]),
    ("correct --reference 99", lambda c: ["correct", c.S, "--out", c.out, "--reference", "99"], ["99", "reference"]),
    ("correct --reference -1", lambda c: ["correct", c.S, "--out", c.out, "--reference", "-1"], ["-1", "reference"]),
    ("correct --mappings bogus", lambda c: ["correct", c.S, "--out", c.out, "--mappings", "bogus"], ["--mappings"]),
    ("correct --graph-weight bogus", lambda c: ["correct", c.S, "--out", c.out, "--graph-weight", "bogus"], ["--graph-weight"]),
    ("correct --seed abc", lambda c: ["correct", c.S, "--out", c.out, "--seed", "abc"], ["--seed"]),
    ("correct --seed -1", lambda c: ["correct", c.S, "--out", c.out, "--seed", "-1"], ["seed"]),
    ("correct --depth-scale -1", lambda c: ["correct", c.S, "--out", c.out, "--depth-scale", "-1"], ["depth_scale", "--depth-scale"]),
    ("correct --depth-scale nan", lambda c: ["correct", c.S, "--out", c.out, "--depth-scale", "nan"], ["depth_scale", "--depth-scale"]),
    ("-j 0", lambda c: ["-j", "0", "info", c.S], ["jobs", "-j"]),
    ("-j abc", lambda c: ["-j", "abc", "info", c.S], ["-j", "jobs"]),
    ("--out ''", lambda c: ["correct", c.S, "--out", ""], ["--out", "out"]),
    ("mappings --mode bogus", lambda c: ["mappings", c.S, "--out", c.d / "m.npz", "--mode", "bogus"], ["--mode"]),
    ("mappings --max-angle -5", lambda c: ["mappings", c.S, "--out", c.d / "m.npz", "--max-angle", "-5"], ["max_angle", "--max-angle"]),
    ("mappings --max-angle abc", lambda c: ["mappings", c.S, "--out", c.d / "m.npz", "--max-angle", "abc"], ["--max-angle"]),
    ("mappings --depth-tol -1", lambda c: ["mappings", c.S, "--out", c.d / "m.npz", "--depth-tol", "-1"], ["depth_tol", "--depth-tol"]),
    ("mappings --occlusion-tol nan", lambda c: ["mappings", c.S, "--out", c.d / "m.npz", "--occlusion-tol", "nan"],
     ["occlusion_tol", "--occlusion-tol"]),
    ("mappings --plot v00,nope", lambda c: ["mappings", c.S, "--out", c.d / "m.npz", "--plot", "v00,nope"], ["nope", "--plot"]),
    ("mappings --plot a", lambda c: ["mappings", c.S, "--out", c.d / "m.npz", "--plot", "a"], ["--plot", "plot"]),
    ("mappings --disable bogus", lambda c: ["mappings", c.S, "--out", c.d / "m.npz", "--disable", "bogus"], ["--disable"]),
    ("mappings --out x.txt", lambda c: ["mappings", c.S, "--out", c.d / "x.txt"], [".npz", "x.txt"]),
    ("seams --offset -1", lambda c: ["seams", c.d / "o" / "mesh.glb", "--offset", "-1"], ["offset"]),
    ("seams --samples-per-edge 0", lambda c: ["seams", c.d / "o" / "mesh.glb", "--samples-per-edge", "0"], ["samples"]),
    ("evaluate --holdout 2", lambda c: ["evaluate", c.S, "--holdout", "2"], ["holdout"]),
    ("evaluate --holdout -0.5", lambda c: ["evaluate", c.S, "--holdout", "-0.5"], ["holdout"]),
    ("evaluate --blur -1", lambda c: ["evaluate", c.S, "--blur", "-1"], ["blur"]),
    ("evaluate --min-n 0", lambda c: ["evaluate", c.S, "--min-n", "0"], ["min_n", "--min-n"]),
    ("evaluate --method bogus", lambda c: ["evaluate", c.S, "--method", "bogus"], ["--method", "bogus"]),
    ("evaluate --reference nope --method seqcc", lambda c: ["evaluate", c.S, "--method", "seqcc", "--reference", "nope"], ["nope"]),
    ("texture --format bogus", lambda c: ["texture", c.S, "--out", c.out, "--format", "bogus"], ["format", "bogus"]),
    ("texture --format ''", lambda c: ["texture", c.S, "--out", c.out, "--format", ""], ["format"]),
    ("texture --format glb,,obj", lambda c: ["texture", c.S, "--out", c.out, "--format", "glb,,obj"], ["format"]),
    ("texture --atlas-size 0", lambda c: ["texture", c.S, "--out", c.out, "--atlas-size", "0"], ["atlas"]),
    ("texture --atlas-size -5", lambda c: ["texture", c.S, "--out", c.out, "--atlas-size", "-5"], ["atlas"]),
    ("texture --atlas-size 100000", lambda c: ["texture", c.S, "--out", c.out, "--atlas-size", "100000"], ["atlas"]),
    ("texture --texel-scale 0", lambda c: ["texture", c.S, "--out", c.out, "--texel-scale", "0"], ["texel"]),
    ("texture --padding -1", lambda c: ["texture", c.S, "--out", c.out, "--padding", "-1"], ["padding"]),
    ("texture --overflow bogus", lambda c: ["texture", c.S, "--out", c.out, "--overflow", "bogus"], ["--overflow"]),
    ("texture --selection bogus", lambda c: ["texture", c.S, "--out", c.out, "--selection", "bogus"], ["--selection"]),
    ("texture --smoothness -1", lambda c: ["texture", c.S, "--out", c.out, "--smoothness", "-1"], ["smoothness"]),
    ("texture --local-band -1", lambda c: ["texture", c.S, "--out", c.out, "--local-band", "-1"], ["local_band", "--local-band"]),
    ("texture --selection-view bogus", lambda c: ["texture", c.S, "--out", c.out, "--selection-view", "bogus"],
     ["selection", "bogus"]),
    ("texture --fallback bogus", lambda c: ["texture", c.S, "--out", c.out, "--fallback", "bogus"], ["--fallback"]),
    ("run --format glb,foo", lambda c: ["run", c.S, "--out", c.out, "--format", "glb,foo"], ["format", "foo"]),
    ("run --method nope", lambda c: ["run", c.S, "--out", c.out, "--method", "nope"], ["--method", "nope"]),
    ("run --leveling-smoothness -1", lambda c: ["run", c.S, "--out", c.out, "--leveling-smoothness", "-1"], ["leveling"]),
    ("run --reference nope", lambda c: ["run", c.S, "--out", c.out, "--reference", "nope"], ["nope"]),
    ("demo --scene bogus", lambda c: ["demo", "bogus", "--out", c.out], ["bogus"]),
    ("synthetic --views 0", lambda c: ["synthetic", c.d / "syn", "--views", "0"], ["views"]),
    ("synthetic --views -3", lambda c: ["synthetic", c.d / "syn", "--views", "-3"], ["views"]),
    ("synthetic --width 0", lambda c: ["synthetic", c.d / "syn", "--width", "0"], ["width"]),
    ("synthetic --width abc", lambda c: ["synthetic", c.d / "syn", "--width", "abc"], ["--width"]),
    ("synthetic --height 100000", lambda c: ["synthetic", c.d / "syn", "--height", "100000", "--width", "100000"],
     ["height", "width", "limit", "pixels"]),
    ("--max-image-pixels 0", lambda c: ["--max-image-pixels", "0", "info", c.S], ["max-image-pixels", "max_image_pixels"]),
]
# harmless if accepted (--plot a: 'a' is a folder for the plots, written where asked)
EITHER_FLAGS = {"correct --seed -1", "-j 0", "evaluate --min-n 0", "texture --format glb,,obj", "mappings --plot a"}
for nm, fn, tokens in FLAGS:
    case(GC, nm, fn, tokens, kind="either" if nm in EITHER_FLAGS else "error", allowed=["m.npz"])


# -- round 2 (issue 25): the classes an independent sweep found ---------------------------------------------------
# Each case names what it checks; "warn" cases must succeed with a warning naming the input at fault. Every case's
# folder is also scanned for report pages holding the markup a case injected (UNSAFE): 0 allowed.

import numpy as np  # noqa: E402

GR1, GR2, GR3, GR4, GR6, GR7 = ("R1 output guard", "R2 file layer", "R3 process", "R4 far junk", "R6 report inputs",
                                "R7 exif / json")
UNSAFE = ("<script>alert(", "<img src=x onerror")
RUN0 = [None]  # a finished `run` output of the sweep's scene, made once by main()


def _run_copy(c: Ctx) -> Path:
    dst = c.d / "run"
    shutil.copytree(RUN0[0], dst, symlinks=True)
    rep = json.loads((dst / "report.json").read_text())
    rep["scene_path"], rep["mesh"] = str(c.S / "scene.json"), str(c.S / "mesh.ply")  # this case's copy
    (dst / "report.json").write_text(json.dumps(rep))
    return dst


def _edit_report(fn: Callable[[dict], None]) -> Callable[[Ctx], None]:
    def prep(c: Ctx) -> None:
        run = _run_copy(c)
        rep = json.loads((run / "report.json").read_text())
        fn(rep)
        (run / "report.json").write_text(json.dumps(rep))
    return prep


def _set(path: str, value) -> Callable[[dict], None]:
    def fn(d: dict) -> None:
        *keys, last = path.split(".")
        for k in keys:
            d = d[k]
        d[last] = value
    return fn


# R1: every output goes through the one guard
for victim, where in (("S/scene.json", lambda c: c.S / "scene.json"), ("S/images/v01.png", lambda c: c.S / "images" / "v01.png"),
                      ("S/mesh.ply", lambda c: c.S / "mesh.ply"), ("RUN/report.json", lambda c: c.d / "run" / "report.json"),
                      ("RUN/selection.npy", lambda c: c.d / "run" / "selection.npy")):
    case(GR1, f"report RUN --output {victim}", lambda c, where=where: ["report", c.d / "run", "--output", where(c)],
         ["--output"], prep=_run_copy, allowed=["run"])
case(GR1, "report RUN --output FIFO", lambda c: ["report", c.d / "run", "--output", c.d / "pipe.html"], ["pipe.html"],
     prep=lambda c: (_run_copy(c), os.mkfifo(c.d / "pipe.html")), allowed=["run"])
case(GR1, "seams RUN/mesh.obj --json RUN/mesh.png", lambda c: ["seams", c.d / "run" / "mesh.obj", "--json",
                                                              c.d / "run" / "mesh.png"], ["mesh.png"], prep=_run_copy)
case(GR1, "evaluate --json RUN/report.json", lambda c: ["evaluate", c.S, "--json", c.d / "run" / "report.json"],
     ["report.json"], prep=_run_copy)
case(GR1, "mappings --plot v00,v01 whose figure would replace an input", lambda c: [
    "mappings", c.S, "--out", c.S / "images" / "m.npz", "--plot", "v00,v01"], ["m_v00_v01.png", "--plot"],
     prep=lambda c: (shutil.move(str(c.S / "images" / "v02.png"), c.S / "images" / "m_v00_v01.png"),
                     edit_scene(c.S, view_set(2, image="images/m_v00_v01.png"))))


def _staged(c: Ctx, cmd: list, timeout: float = 120) -> subprocess.Popen | None:
    """Start ``cmd`` and wait until its staging folder beside c.out exists (None: it never did)."""
    p = popen(*cmd)
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < timeout and p.poll() is None:
        if any(n.startswith(f".{c.out.name}.o3d_seqcc-") and n.endswith(".staging") for n in os.listdir(c.d)):
            return p
        time.sleep(0.005)
    return p if p.poll() is None else None


def _writer_during_staging(c: Ctx) -> tuple:
    r = cli("correct", c.S, "--out", c.out, *FAST)
    before = checksums(c.out)
    p = _staged(c, ["correct", c.S, "--out", c.out, "--overwrite", *FAST])
    if p is None:
        return False, "the second run never staged", {"other"}
    (c.out / "notes.txt").write_text("written by another program while o3d-seqcc staged")
    _, err = p.communicate()
    kept = (c.out / "notes.txt").is_file() and all(checksums(c.out).get(k) == v for k, v in before.items())
    ok = r.returncode == 0 and p.returncode == 2 and "changed while this run was writing" in err and kept \
        and listing(c.d) == ["S", "out"]
    cats = set() if ok else {"damage"} if not kept else {"other"}
    return ok, f"exit {p.returncode}: {message(err)}; notes.txt kept {kept}; beside {listing(c.d)}", cats


def _nested(c: Ctx) -> tuple:
    a = popen("correct", c.S, "--out", c.out, *FAST)
    b = popen("correct", c.S, "--out", c.out / "sub", *FAST)
    ea, eb = a.communicate()[1], b.communicate()[1]
    lost = b.returncode == 0 and not whole(c.out / "sub")
    ok = (not lost and "Traceback" not in ea + eb and 0 in (a.returncode, b.returncode)
          and {a.returncode, b.returncode} <= {0, 2} and set(listing(c.d)) <= {"S", "out"})
    return ok, (f"exits {a.returncode}/{b.returncode}; sub whole {whole(c.out / 'sub')}; "
                f"{message(ea) if a.returncode else message(eb) if b.returncode else 'both accepted'}"), \
        ({"damage"} if lost else set()) | ({"traceback"} if "Traceback" in ea + eb else set())


def _user_link(c: Ctx) -> tuple:
    cli("correct", c.S, "--out", c.out, *FAST)
    keep = c.d / "keep"
    keep.mkdir()
    (keep / "thesis.tex").write_text("years of work")
    (c.out / "mine").symlink_to(keep, target_is_directory=True)
    r = cli("correct", c.S, "--out", c.out, "--overwrite", *FAST)
    ok = r.returncode == 2 and "mine" in r.stderr and (c.out / "mine").is_symlink() and (keep / "thesis.tex").is_file()
    return ok, f"exit {r.returncode}: {message(r.stderr)}", set() if ok else {"damage"}


def _linked_out(c: Ctx) -> tuple:
    target = c.d / "disk" / "results"
    target.mkdir(parents=True)
    (c.d / "link").symlink_to(target, target_is_directory=True)
    r = cli("run", c.S, "--out", c.d / "link", *FAST, *TEX)
    r2 = cli("info", c.d / "link" / "project.mlp")
    ok = r.returncode == 0 and r2.returncode == 0 and "Traceback" not in r.stderr + r2.stderr
    return ok, f"run exit {r.returncode}; info link/project.mlp exit {r2.returncode} {message(r2.stderr)}", \
        set() if ok else {"other"}


case(GR1, "a file written into --out while the run stages", kind="custom", run=_writer_during_staging, serial=True)
case(GR1, "correct --out A and --out A/sub at once", kind="custom", run=_nested, serial=True)
case(GR1, "--overwrite with a user's link in --out", kind="custom", run=_user_link)
case(GR1, "--out is a link: project.mlp loads through it", kind="custom", run=_linked_out)


# R2: one file-reading layer
def _non_utf8(c: Ctx) -> tuple:
    src = os.fsencode(str(c.S))
    dst = os.fsencode(str(c.d)) + b"/sc\xe9ne"
    shutil.copytree(src, dst)
    name = os.fsdecode(dst)
    r1 = cli("info", name)
    r2 = cli("run", name, "--out", c.out, *FAST, *TEX)
    ok = r1.returncode == 0 and r2.returncode == 0 and whole(c.out) and "Traceback" not in r1.stderr + r2.stderr
    cats = set() if ok else {"crash"} if r2.returncode < 0 else {"traceback"} if "Traceback" in r2.stderr else {"other"}
    return ok, f"info exit {r1.returncode}, run exit {r2.returncode} {message(r2.stderr)}", cats


case(GR2, "run on a folder named sc\\xe9ne (not UTF-8)", kind="custom", run=_non_utf8)
case(GR2, "RGB-D folder with a FIFO among its images", lambda c: ["info", c.d / "rgbd", "--mesh", c.S / "mesh.ply"],
     ["000000.png", "FIFO"], prep=lambda c: (_rgbd(c, "0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n" * 1),
                                            (c.d / "rgbd" / "image" / "000000.png").unlink(),
                                            os.mkfifo(c.d / "rgbd" / "image" / "000000.png")))
case(GR2, "RGB-D image header declaring 60000x60000", lambda c: ["info", c.d / "rgbd", "--mesh", c.S / "mesh.ply"],
     ["000000.png", "over the limit"], prep=lambda c: (_rgbd(c, "0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"),
                                                       png_declaring(c.d / "rgbd" / "image" / "000000.png", 60000, 60000,
                                                                     size=30_000)))
case(GR2, "RGB-D image over --max-image-pixels 100", lambda c: ["--max-image-pixels", "100", "info", c.d / "rgbd", "--mesh",
                                                                c.S / "mesh.ply"], ["000000.png", "over the limit"],
     prep=lambda c: _rgbd(c, "0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"))


def _depth_bomb(c: Ctx) -> None:
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    comp = zlib.compressobj(9)
    data = b"".join(comp.compress(b"\0" * (1 + 2 * 20000) * 64) for _ in range(300)) + comp.flush()
    (c.S / "depth" / "v03.png").write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 20000, 20000, 16, 0,
                                                                                               0, 0, 0))
                                            + chunk(b"IDAT", data) + chunk(b"IEND", b""))


case(GR2, "correct: 16-bit depth PNG declaring 20000x20000", lambda c: ["correct", c.S, "--out", c.out, *FAST],
     ["v03.png", "over the limit"], prep=_depth_bomb)
case(GR2, "PLY header declaring 2e9 vertices", lambda c: ["info", c.S], ["mesh.ply", "2000000000"],
     prep=lambda c: (c.S / "mesh.ply").write_bytes(
         b"ply\nformat binary_little_endian 1.0\nelement vertex 2000000000\nproperty float x\nproperty float y\n"
         b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"))
case(GR2, "mesh vertex at 1e300", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["mesh.ply", "1e+300"],
     prep=_mesh(lambda p: p.write_text(
         "ply\nformat ascii 1.0\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\n"
         "element face 2\nproperty list uchar int vertex_indices\nend_header\n1e300 0 0\n1 0 0\n0 1 0\n1 1 0\n"
         "3 0 1 2\n3 1 3 2\n")))


def _cut_jpeg_with_thumbnail(c: Ctx) -> None:
    import cv2
    import numpy as np
    rng = np.random.default_rng(0)
    thumb = cv2.imencode(".jpg", rng.integers(0, 255, (120, 160, 3), np.uint8))[1].tobytes()
    img = cv2.imencode(".jpg", rng.integers(0, 255, (120, 160, 3), np.uint8), [cv2.IMWRITE_JPEG_QUALITY, 100])[1].tobytes()
    ifd1, data_off = 14, 14 + 2 + 24 + 4
    tiff = (b"II*\0" + struct.pack("<IHI", 8, 0, ifd1) + struct.pack("<H", 2) + struct.pack("<HHII", 0x0201, 4, 1, data_off)
            + struct.pack("<HHII", 0x0202, 4, 1, len(thumb)) + struct.pack("<I", 0) + thumb)
    app1 = b"Exif\0\0" + tiff
    data = img[:2] + b"\xff\xe1" + struct.pack(">H", len(app1) + 2) + app1 + img[2:]
    jpg = c.S / "images" / "v02.jpg"
    jpg.write_bytes(data[:12 + data_off + len(thumb) + (len(img) - 2) // 2])  # the main image cut in half
    (c.S / "images" / "v02.png").unlink()
    edit_scene(c.S, view_set(2, image="images/v02.jpg"))


case(GR2, "JPEG cut in half, its EXIF thumbnail's end marker in the tail", lambda c: ["correct", c.S, "--out", c.out,
                                                                                      *FAST], ["v02.jpg", "truncated"],
     prep=_cut_jpeg_with_thumbnail)
case(GR2, "image is /dev/zero", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["v01.png", "device"],
     prep=lambda c: ((c.S / "images" / "v01.png").unlink(), (c.S / "images" / "v01.png").symlink_to("/dev/zero")))
case(GR2, "mesh is a FIFO", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["mesh.ply", "FIFO"],
     prep=lambda c: ((c.S / "mesh.ply").unlink(), os.mkfifo(c.S / "mesh.ply")))
case(GR2, "depth map is a FIFO", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["v04.png", "FIFO"],
     prep=lambda c: ((c.S / "depth" / "v04.png").unlink(), os.mkfifo(c.S / "depth" / "v04.png")))


def _nan_cloud(c: Ctx) -> None:
    rows = [f"{x} {y} {z}" for x, y, z in np.random.default_rng(0).random((20, 3)) * 3] + ["nan nan nan", "1e300 0 0"]
    (c.S / "p.ply").write_text("ply\nformat ascii 1.0\nelement vertex 22\nproperty double x\nproperty double y\n"
                               "property double z\nend_header\n" + "\n".join(rows) + "\n")
    edit_scene(c.S, lambda d: (d["views"][1].update(point_cloud="p.ply"), d["views"][1].pop("depth")))  # used for depth


case(GR2, "point cloud with NaN and 1e300 points", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["p.ply", "2 of 22"],
     prep=_nan_cloud, kind="warn")


# R3: signals, the working directory, worker errors
def _signal_while_staging(cmd: str, sig: int) -> Callable[[Ctx], tuple]:
    def run(c: Ctx) -> tuple:
        args = [cmd, c.S, "--out", c.out, *FAST] + (TEX if cmd == "run" else [])
        p = _staged(c, args)
        if p is None:
            return False, "never staged", {"other"}
        p.send_signal(sig)
        _, err = p.communicate()
        left = [n for n in listing(c.d) if n != "S"]
        ok = p.returncode == 128 + sig and not left and "Traceback" not in err
        return ok, f"exit {p.returncode}: {message(err)}; left {left or 'nothing'}", \
            set() if ok else {"beside"} if left else {"traceback"} if "Traceback" in err else {"other"}
    return run


case(GR3, "run: SIGTERM while staging", kind="custom", run=_signal_while_staging("run", signal.SIGTERM), serial=True)
case(GR3, "correct: SIGHUP while staging", kind="custom", run=_signal_while_staging("correct", signal.SIGHUP), serial=True)


def _deleted_cwd(c: Ctx) -> tuple:
    gone = c.d / "gone"
    gone.mkdir()
    code = (f"import os, subprocess, sys\nos.chdir({str(gone)!r}); os.rmdir({str(gone)!r})\n"
            f"r = subprocess.run([sys.executable, '-m', 'o3d_seqcc', 'info', {str(c.S)!r}], capture_output=True, text=True)\n"
            "print(r.returncode); print(r.stderr)")
    r = subprocess.run([sys.executable, "-c", code], env=ENV, capture_output=True, text=True, timeout=60)
    rc, _, err = r.stdout.partition("\n")
    ok = rc == "2" and "working directory" in err
    return ok, f"exit {rc}: {message(err)}", set() if ok else {"crash"}


def _three_channel_depth(c: Ctx) -> None:
    import cv2
    d = cv2.imread(str(c.S / "depth" / "v03.png"), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(c.S / "depth" / "v03.png"), np.dstack([d, d, d]))  # right size, 3 channels: refused in a worker


def _worker_error_j8(c: Ctx) -> tuple:
    codes = []
    for _ in range(6):
        r = cli("-j", "8", "correct", c.S, "--out", c.out, *FAST)
        codes.append(r.returncode)
        if r.returncode != 2 or "terminate called" in r.stderr or "Traceback" in r.stderr:
            return False, f"exit {r.returncode}: {message(r.stderr)}", {"crash"}
    return c.out.exists() is False, f"6 runs, exits {codes}", set()


case(GR3, "a deleted working directory", kind="custom", run=_deleted_cwd)
case(GR3, "-j 8 with an error in a worker thread (6 runs)", kind="custom", prep=_three_channel_depth,
     run=_worker_error_j8, serial=True)


# R4: far-away junk
def _junk(sheet: bool) -> Callable[[Ctx], None]:
    def prep(c: Ctx) -> None:
        import open3d as o3d
        m = o3d.io.read_triangle_mesh(str(c.S / "mesh.ply"))
        v, f = np.asarray(m.vertices), np.asarray(m.triangles)
        if sheet:
            g = np.stack(np.meshgrid(np.arange(21) * 10.0, np.arange(21) * 10.0, indexing="ij"), -1).reshape(-1, 2)
            jv = np.c_[g[:, 0] + 1e5, g[:, 1], np.zeros(len(g))]
            idx = np.arange(441).reshape(21, 21)
            q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
            jf = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
        else:
            jv, jf = np.array([[1e5, 0, 0], [1e5 + 1, 0, 0], [1e5, 1, 0]]), np.array([[0, 1, 2]])
        m2 = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.vstack([v, jv])),
                                       o3d.utility.Vector3iVector(np.vstack([f, jf + len(v)])))
        m2.compute_vertex_normals()
        o3d.io.write_triangle_mesh(str(c.S / "mesh.ply"), m2)
    return prep


def _junk_run(c: Ctx) -> tuple:
    r = cli("run", c.S, "--out", c.out, *FAST, *TEX)
    ok = r.returncode == 0 and whole(c.out) and "lie far from everything the photos see" in r.stderr
    tpp = None
    if ok:
        tpp = json.loads((c.out / "report.json").read_text())["atlas"]["texels_per_pixel"]
        ok = tpp >= 0.9 * RUN0_TPP[0]
    return ok, f"exit {r.returncode}; texels/pixel {tpp} (clean {RUN0_TPP[0]}); {message(r.stderr)[:90]}", \
        set() if ok else {"unnamed"} if r.returncode == 0 else {"other"}


RUN0_TPP = [None]
case(GR4, "run: one junk triangle 100 km away", kind="custom", prep=_junk(False), run=_junk_run)
case(GR4, "run: a 200 m junk sheet 100 km away", kind="custom", prep=_junk(True), run=_junk_run)


# R6: what `report` reads
for nm, fn in (("string in a count (max_per_pair '<script>')", _set("metrics.before.max_per_pair", "<script>alert(1)</script>")),
               ("string in a figure (atlas.coverage)", _set("atlas.coverage", "<img src=x onerror=alert(1)>")),
               ("list for an object (correction)", _set("correction", [])),
               ("pages 'many'", _set("atlas.pages", "many")),
               ("unknown correction option", _set("correction.settings.options", {"rm_rf": 1})),
               ("rotation of strings", _set("export.orientation.rotation", [["a"] * 3] * 3))):
    case(GR6, f"report: {nm}", lambda c: ["report", c.d / "run"], ["report.json"], prep=_edit_report(fn), allowed=["run"])
case(GR6, "report: markup in every string it shows", lambda c: ["report", c.d / "run", "--scene", c.S], ["report"],
     prep=_edit_report(lambda r: (r.update(scene="<script>alert(1)</script>"),
                                  r["texture_settings"].update(selection="<img src=x onerror=alert(1)>"),
                                  r["timings_s"].update({"<script>alert(2)</script>": 1.0}))), kind="either",
     allowed=["run"])
for nm, prep in (("truncated report.json", lambda c: truncate(_run_copy(c) / "report.json", 0.4)),
                 ("truncated selection.npy", lambda c: truncate(_run_copy(c) / "selection.npy", 0.3)),
                 ("selection.npy of floats", lambda c: (lambda r: np.save(r / "selection.npy", np.load(
                     r / "selection.npy").astype(float)))(_run_copy(c))),
                 ("selection.npy index 99", lambda c: (lambda r, s: (s.__setitem__(0, 99), np.save(r / "selection.npy", s)))(
                     _run_copy(c), np.load(RUN0[0] / "selection.npy"))),
                 ("report.json is a FIFO", lambda c: (lambda r: ((r / "report.json").unlink(), os.mkfifo(r / "report.json")))(
                     _run_copy(c))),
                 ("selection.npy is a FIFO", lambda c: (lambda r: ((r / "selection.npy").unlink(),
                                                                    os.mkfifo(r / "selection.npy")))(_run_copy(c))),
                 ("duplicate keys in report.json", lambda c: (lambda r: (r / "report.json").write_text(
                     (r / "report.json").read_text().replace('"command":', '"command": "x", "command":', 1)))(_run_copy(c)))):
    case(GR6, f"report: {nm}", lambda c: ["report", c.d / "run"], ["report.json", "selection.npy"], prep=prep,
         allowed=["run"])


# R7: EXIF orientation, duplicate JSON keys
def _rotated_jpeg(c: Ctx) -> None:
    from PIL import Image
    im = Image.open(c.S / "images" / "v01.png").convert("RGB")
    exif = Image.Exif()
    exif[0x0112] = 6
    im.save(c.S / "images" / "v01.jpg", exif=exif.tobytes(), quality=95)
    (c.S / "images" / "v01.png").unlink()
    edit_scene(c.S, view_set(1, image="images/v01.jpg"))


case(GR7, "JPEG with EXIF orientation 6", lambda c: ["correct", c.S, "--out", c.out, *FAST], ["v01.jpg", "orientation"],
     prep=_rotated_jpeg, kind="warn")
case(GR7, "scene.json with 'views' twice", lambda c: ["info", c.S], ["scene.json", "views", "twice"],
     prep=lambda c: (c.S / "scene.json").write_text((c.S / "scene.json").read_text().replace('"views":', '"views": [], "views":', 1)))
case(GR7, "a view with 'name' twice", lambda c: ["info", c.S], ["scene.json", "name", "twice"],
     prep=lambda c: (c.S / "scene.json").write_text(json.dumps(json.loads((c.S / "scene.json").read_text())).replace(
         '"name": "v01"', '"name": "v01", "name": "v09"', 1)))



# -- running ------------------------------------------------------------------------------------------------------


#: per case index, what went wrong: traceback, crash (a signal or an abort), hang, damage (an input changed or
#: data lost), beside (files left beside or written outside the output), unsafe-html, unnamed (no message or
#: warning naming the input at fault), other
CATEGORIES: dict[int, set] = {}
KINDS = ("traceback", "crash", "hang", "damage", "beside", "unsafe-html", "unnamed", "other")


def _category(problem: str) -> str:
    for key, cat in (("traceback", "traceback"), ("timed out", "hang"), ("input changed", "damage"),
                     ("written:", "beside"), ("new files beside", "beside"), ("unsafe", "unsafe-html"),
                     ("names none", "unnamed"), ("no warning", "unnamed")):
        if key in problem:
            return cat
    if problem.startswith("exit -") or problem.startswith("exit 13") or problem.startswith("exit 139"):
        return "crash"
    return "other"


def _unsafe_html(folder: Path) -> bool:
    """A report page under ``folder`` holds markup a case injected, unescaped."""
    for root, dirs, files in os.walk(folder):
        for f in files:
            p = Path(root) / f
            if f.endswith(".html") and not p.is_symlink() and p.is_file():
                text = p.read_text(errors="replace")
                if any(u in text for u in UNSAFE):
                    return True
    return False


def _warning(err: str, names: tuple) -> str:
    for ln in err.splitlines():
        if "warn" in ln.lower() and any(t.lower() in ln.lower() for t in names):
            return ln.split("O3dSeqccWarning:")[-1].strip()
    return ""


def run_case(cs: Case, scene: Path, root: Path, index: int) -> tuple[bool, str]:
    d = root / f"c{index:03d}"
    d.mkdir()
    c = Ctx(d=d, S=d / "S", out=d / "out")
    shutil.copytree(scene, c.S, symlinks=True)
    try:
        if cs.prep:
            cs.prep(c)
        inputs = checksums(c.S)
        before = listing(d)
        if cs.kind == "custom":
            ok, msg, *cats = cs.run(c)
            cats = set(cats[0]) if cats else (set() if ok else {_category(msg.lower())})
            if checksums(c.S) != inputs:
                ok, msg = False, "INPUT CHANGED; " + msg
                cats.add("damage")
            if _unsafe_html(d):
                ok, msg = False, "UNSAFE HTML; " + msg
                cats.add("unsafe-html")
            CATEGORIES[index] = cats
            return ok, msg
        r = cli(*cs.args(c))
        err = r.stderr
        msg = message(err) or f"(exit {r.returncode}, no message)"
        problems = []
        if "Traceback" in err:
            problems.append("traceback")
        now = checksums(c.S)
        if any(now.get(k) != v for k, v in inputs.items()) or any(
                not k.startswith("new/") for k in set(now) - set(inputs)):
            problems.append("input changed")
        after = listing(d)
        new = sorted(set(after) - set(before))
        if _unsafe_html(d):
            problems.append("unsafe HTML")
        if cs.kind in ("either", "warn") and r.returncode == 0:
            new = [n for n in new if (n != "out" or whole(c.out)) and n not in cs.allowed]
            if new and new != ["out"]:
                problems.append(f"new files beside the output: {new}")
            if cs.kind == "warn" and not any(t.lower() in err.lower() for t in cs.names):
                problems.append("no warning naming " + "/".join(cs.names))
            CATEGORIES[index] = {_category(p) for p in problems}
            shown = ("accepted (exit 0)" if cs.kind == "either" else "warned: " + _warning(err, cs.names))
            return not problems, (shown if not problems else "; ".join(problems))
        if r.returncode not in (1, 2):
            problems.append(f"exit {r.returncode}")
        if new:
            problems.append(f"written: {new}")
        low = err.lower()
        if cs.names and not any(t.lower() in low for t in cs.names):
            problems.append("message names none of " + "/".join(cs.names))
        CATEGORIES[index] = {_category(p) for p in problems}
        return not problems, (msg if not problems else "; ".join(problems) + " | " + msg)
    except subprocess.TimeoutExpired:
        CATEGORIES[index] = {"hang"}
        return False, "timed out"
    except Exception as e:  # noqa: BLE001 - a broken case is reported, never fatal
        CATEGORIES[index] = {"other"}
        return False, f"case error: {type(e).__name__}: {e}"
    finally:
        for p in (d / "ro",):
            if p.exists():
                os.chmod(p, 0o755)
        if (c.S / "images" / "v02.png").exists():
            os.chmod(c.S / "images" / "v02.png", 0o644)
