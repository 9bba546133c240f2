"""Output folders written all at once, never over the user's data.

Every command (and every ``save`` of the library's results) writes through
:func:`output_folder`, a transaction:

1. **Checks before any work** (:func:`check_output`): ``out`` must not be a file, must not be or
   contain any input (the scene file, mesh, images, depth maps, point clouds), must not lie
   under a file; an existing ``out`` is replaced only with ``overwrite=True`` and only when it
   is empty or holds nothing but what o3d_seqcc wrote there (the manifest ``.o3d_seqcc.json``
   lists those files). A symbolic link ``out`` is followed: its target is the output folder.
2. **A lock** (``.<name>.o3d_seqcc.lock`` beside ``out``, ``fcntl.flock``, with the owner's PID):
   a second run on the same ``out`` fails at once with a clear message.
3. **Staging**: everything is written into a hidden staging folder beside ``out``
   (``.<name>.o3d_seqcc-<pid>.staging``), then fsynced; the manifest is written last.
4. **Swap**: with two renames the staging folder becomes ``out`` and the previous ``out`` (moved
   aside to ``.<name>.o3d_seqcc-<pid>.old``) is removed. A crash before the swap leaves the previous
   output untouched; a crash between the two renames leaves the previous output beside ``out``,
   and the next run puts it back before anything else. Staging folders of dead runs are removed
   by the next run on the same ``out`` (only those: names carry the PID, which must be dead).
"""

from __future__ import annotations

import errno
import fcntl
import json
import logging
import os
import re
import shutil
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable, Iterator

from ..errors import InputError
from .files import atomic_write_bytes, default_mode

__all__ = ["MANIFEST", "add_output_file", "check_output", "output_folder"]

logger = logging.getLogger(__name__)

#: file in every output folder listing what o3d_seqcc wrote there
MANIFEST = ".o3d_seqcc.json"
MANIFEST_FORMAT = "o3d_seqcc.output/1"
#: refuse to start when the output disk has less free space than this (MB)
MIN_FREE_MB = 64


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _own_files(out: Path) -> set[str] | None:
    """Relative paths listed in ``out``'s manifest, or None without a readable manifest."""
    try:
        data = json.loads((out / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("format") != MANIFEST_FORMAT or not isinstance(data.get("files"), list):
        return None
    return {str(f) for f in data["files"]}


def _listing(folder: Path) -> list[str]:
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if not p.is_dir())


def _is_within(child: Path, parent: Path) -> bool:
    return child == parent or parent in child.parents


def check_output(out: str | os.PathLike, *, overwrite: bool = False, inputs: Iterable[str | os.PathLike] = ()) -> Path:
    """Check an output folder before any work; returns the resolved folder.

    Parameters
    ----------
    out : path-like
        Output folder (created later by :func:`output_folder`).
    overwrite : bool, default False
        Allow replacing an existing output of o3d_seqcc.
    inputs : iterable of path-like
        Every file (or folder) the job reads.

    Raises
    ------
    InputError
        ``out`` is a file or lies under one; it is, or contains, an input; it exists without
        ``overwrite``; it holds files o3d_seqcc did not write.
    """
    given = Path(out)
    target = Path(os.path.realpath(given))
    for parent in [target, *target.parents]:
        if parent.exists() and not parent.is_dir():
            raise InputError(f"--out {given}: {parent} is a file, not a folder; choose another output folder")
    for p in inputs:
        real = Path(os.path.realpath(p))
        if _is_within(real, target):
            raise InputError(
                f"--out {given} contains the input {p}: writing the result there would replace the input; "
                "choose an output folder outside the scene's files"
            )
    existing = next(p for p in [target, *target.parents] if p.exists())
    if not os.access(existing, os.W_OK):
        raise InputError(f"--out {given}: cannot write into {existing} (read-only or no permission); choose another "
                         "output folder")
    free_mb = shutil.disk_usage(existing).free / 2**20
    if free_mb < MIN_FREE_MB:
        raise InputError(f"--out {given}: only {free_mb:.0f} MB free on its disk (at least {MIN_FREE_MB} MB needed); "
                         "free some space or choose another output folder")
    if target.exists() and any(target.iterdir()):
        if not overwrite:
            raise InputError(f"output folder {given} exists and is not empty; choose another --out or pass --overwrite")
        own = _own_files(target)
        foreign = [f for f in _listing(target) if f != MANIFEST and (own is None or f not in own)]
        if foreign:
            shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
            raise InputError(
                f"output folder {given} holds files o3d-seqcc did not write ({shown}); --overwrite replaces only "
                "earlier o3d-seqcc outputs: choose an empty or new folder"
            )
    return target


def _sibling(out: Path, pid: int, kind: str) -> Path:
    return out.parent / f".{out.name}.o3d_seqcc-{pid}.{kind}"


def _recover(out: Path) -> None:
    """Remove what dead runs left beside ``out``; put back an output a crash left aside."""
    pattern = re.compile(rf"^\.{re.escape(out.name)}\.o3d_seqcc-(\d+)\.(staging|old)$")
    for p in sorted(out.parent.iterdir()) if out.parent.is_dir() else ():
        m = pattern.match(p.name)
        if not m or _pid_alive(int(m.group(1))) and int(m.group(1)) != os.getpid():
            continue
        if m.group(2) == "old" and not out.exists():
            logger.warning("restoring the previous output %s left aside by an interrupted run", out)
            os.replace(p, out)
        else:
            shutil.rmtree(p, ignore_errors=True)


def _fsync_tree(folder: Path) -> None:
    for root, dirs, files in os.walk(folder):
        for name in files:
            fd = os.open(os.path.join(root, name), os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        fd = os.open(root, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _disk_error(e: OSError, out: Path) -> InputError:
    reason = {errno.ENOSPC: "the disk is full", errno.EROFS: "the file system is read-only",
              errno.EACCES: "permission denied", errno.EDQUOT: "the disk quota is exceeded"}.get(e.errno, e.strerror)
    return InputError(f"cannot write the output folder {out}: {reason} ({e.filename or out}); "
                      "free some space, fix the permissions or choose another --out")


def _acquire(lock_path: Path, target: Path, out) -> "object":
    """Open and exclusively lock ``lock_path`` (retrying when another run removed it meanwhile)."""
    for _ in range(20):
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            lock = open(lock_path, "a+")
        except OSError as e:
            raise _disk_error(e, target) from None
        try:
            fcntl.flock(lock.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.seek(0)
            owner = lock.read().strip() or "?"
            lock.close()
            raise InputError(f"another o3d-seqcc run (pid {owner}) is writing {out}; wait for it or choose another --out")
        try:
            same = os.stat(lock_path).st_ino == os.fstat(lock.fileno()).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return lock
        lock.close()  # the previous holder removed the file between our open and our lock: take the new one
    raise InputError(f"could not lock {lock_path}; another o3d-seqcc run keeps replacing it")


@contextmanager
def output_folder(
    out: str | os.PathLike,
    *,
    overwrite: bool = False,
    inputs: Iterable[str | os.PathLike] = (),
    command: str = "",
) -> Iterator[Path]:
    """Yield an empty staging folder; on success it replaces ``out`` as a whole (see the module docstring).

    Parameters
    ----------
    out : path-like
    overwrite : bool, default False
    inputs : iterable of path-like
        Files the job reads (never inside ``out``).
    command : str
        Recorded in the manifest.

    Raises
    ------
    InputError
        The checks of :func:`check_output`; another run holds ``out``; the disk is full, read-only
        or not writable (the message says which).
    """
    inputs = list(inputs)
    target = check_output(out, overwrite=overwrite, inputs=inputs)
    with _locked(target, out):
        _recover(target)
        check_output(out, overwrite=overwrite, inputs=inputs)  # again, under the lock
        stage = _sibling(target, os.getpid(), "staging")
        try:
            stage.mkdir(mode=0o777)
            os.chmod(stage, default_mode(0o777))
            yield stage
            (stage / MANIFEST).write_bytes(_manifest(command, _listing(stage)))
            _fsync_tree(stage)
            old = None
            if target.exists():
                old = _sibling(target, os.getpid(), "old")
                os.replace(target, old)
            os.replace(stage, target)
            if old is not None:
                shutil.rmtree(old, ignore_errors=True)
        except OSError as e:
            shutil.rmtree(stage, ignore_errors=True)
            raise _disk_error(e, target) from None
        except BaseException:
            shutil.rmtree(stage, ignore_errors=True)
            raise


@contextmanager
def _locked(target: Path, out) -> Iterator[None]:
    """Hold the lock of the output folder ``target`` (``.<name>.o3d_seqcc.lock`` beside it, with our PID)."""
    lock_path = target.parent / f".{target.name}.o3d_seqcc.lock"
    lock = _acquire(lock_path, target, out)
    try:
        lock.seek(0)
        lock.truncate()
        lock.write(str(os.getpid()))
        lock.flush()
        yield
    finally:
        try:
            lock_path.unlink()
        except OSError:
            pass
        lock.close()


def _manifest(command: str, files: list[str]) -> bytes:
    return (json.dumps({"format": MANIFEST_FORMAT, "command": command, "files": files}, indent=1) + "\n").encode("utf-8")


def add_output_file(out: str | os.PathLike, name: str, data: bytes) -> Path:
    """Write (or replace) one file in an existing output folder of o3d_seqcc, and list it in the manifest.

    For what is added to a finished output later (``o3d-seqcc report RUN_DIR`` writes
    ``report.html``), so that ``--overwrite`` still recognises the whole folder as o3d_seqcc's.
    The file and the manifest are each replaced atomically, under the folder's lock.

    Raises
    ------
    InputError
        ``out`` is not an output folder of o3d_seqcc (no manifest), or another run holds it.
    """
    given = Path(out)
    target = Path(os.path.realpath(given))
    own = _own_files(target) if target.is_dir() else None
    if own is None:
        raise InputError(f"{given} is not an o3d-seqcc output folder (no {MANIFEST}); give the --out folder of a run")
    if Path(name).is_absolute() or ".." in Path(name).parts or name == MANIFEST:
        raise ValueError(f"add_output_file: {name!r} must be a plain relative path inside the folder")
    with _locked(target, given):
        try:
            path = atomic_write_bytes(target / name, data)
            command = json.loads((target / MANIFEST).read_text(encoding="utf-8")).get("command", "")
            atomic_write_bytes(target / MANIFEST, _manifest(command, sorted(own | {Path(name).as_posix()})))
        except OSError as e:
            raise _disk_error(e, target) from None
    return path
