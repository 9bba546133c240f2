"""Every output of every command and library function goes through this one guard.

Output **folders** (``--out`` of ``run`` / ``correct`` / ``texture``, ``synthetic OUT``, every
``save`` of the library's results) are written through :func:`output_folder`, a transaction:

1. **Checks before any work** (:func:`check_output`): ``out`` must not be a file, must not be or
   contain any input (the scene file, mesh, images, depth maps, point clouds), must not lie
   under a file; an existing ``out`` is replaced only with ``overwrite=True`` and only when it
   is empty or holds nothing but what o3d_seqcc wrote there (the manifest ``.o3d_seqcc.json``
   lists those files; a symbolic link, or an empty folder, not listed is not ours either). A
   symbolic link ``out`` is followed: its target is the output folder.
2. **A lock** (``.<name>.o3d_seqcc.lock`` beside ``out``, ``fcntl.flock``, with the owner's PID):
   a second run on the same ``out``, on a folder inside it or on a folder holding it fails at
   once with a clear message.
3. **Staging**: everything is written into a hidden staging folder beside ``out``
   (``.<name>.o3d_seqcc-<pid>.staging``), then fsynced; the manifest is written last. SIGTERM
   and SIGHUP (``docker stop``, systemd, a closed terminal) interrupt it like Ctrl-C
   (:func:`interruptible`): the staging folder and the lock are removed.
4. **Swap**: under the lock, ``out`` is checked again: anything in it that o3d_seqcc did not
   stage (a file another program wrote there meanwhile) stops the swap with a message, and
   nothing is replaced. Then with two renames the staging folder becomes ``out`` and the
   previous ``out`` (moved aside to ``.<name>.o3d_seqcc-<pid>.old``) is removed file by listed
   file. A crash before the swap leaves the previous output untouched; a crash between the two
   renames leaves the previous output beside ``out``, and the next run puts it back before
   anything else. Staging folders of dead runs are removed by the next run on the same ``out``
   (only those: names carry the PID, which must be dead). Folders created to hold ``out`` are
   removed again when the run fails.

Output **files** (``--json``, ``mappings --out FILE.npz``, ``report --output``, ``--plot``) go
through :func:`output_file`: the same input checks (never one of the job's inputs, never a file
of an o3d-seqcc output folder, never a folder, FIFO or device), the same lock, a temporary file
beside it and an atomic rename.
"""

from __future__ import annotations

import errno
import fcntl
import json
import logging
import os
import re
import shutil
import stat
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable, Iterator

from ..errors import InputError, warn
from .._shared.interrupts import Terminated, interruptible
from .atomic import atomic_path, atomic_write_bytes, default_mode
from .manifest import MANIFEST, listing as _listing, manifest_bytes as _manifest, own_files as _own_files

__all__ = ["MANIFEST", "Terminated", "add_output_file", "check_output", "check_output_file", "interruptible",
           "output_file", "output_folder", "write_output_file", "write_output_json"]

logger = logging.getLogger(__name__)

#: file in every output folder listing what o3d_seqcc wrote there
#: refuse to start when the output disk has less free space than this (MB)
MIN_FREE_MB = 64
_LOCK_NAME = re.compile(r"^\..+\.o3d_seqcc\.lock$")


# ------------------------------------------------------------------------------------------ checks
def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _foreign(folder: Path) -> list[str]:
    """What in ``folder`` o3d_seqcc did not write (not listed in its manifest); empty folders and the
    folders of listed files are ours."""
    own = _own_files(folder) or set()
    return [f for f in _listing(folder) if f != MANIFEST and f not in own
            and not (f.endswith("/") and any(o.startswith(f) for o in own))]


def _shown(names: list[str]) -> str:
    return ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")


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
        ``overwrite``; it holds anything o3d_seqcc did not write (symbolic links and empty
        folders included).
    """
    given = Path(out)
    if not str(out):
        raise InputError("--out is empty; give an output folder")
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
    _refuse_nested(target, given)
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
        foreign = _foreign(target)
        if foreign:
            raise InputError(
                f"output folder {given} holds files o3d-seqcc did not write ({_shown(foreign)}); --overwrite replaces "
                "only earlier o3d-seqcc outputs: choose an empty or new folder"
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


# ------------------------------------------------------------------------------------------ locks
def _lock_path(target: Path) -> Path:
    return target.parent / f".{target.name}.o3d_seqcc.lock"


def _held(lock_path: Path) -> str | None:
    """The PID written in a lock file another run holds, or None when nobody holds it."""
    try:
        f = open(lock_path, "r")
    except OSError:
        return None
    try:
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return f.read().strip() or "?"
        fcntl.flock(f.fileno(), fcntl.LOCK_UN)
        return None
    finally:
        f.close()


def _nested_run(target: Path) -> tuple[Path, str] | None:
    """(output, pid) of another run writing a folder that holds ``target`` or lies inside it, else None."""
    for a in target.parents:
        if a.parent == a:
            break
        owner = _held(_lock_path(a))
        if owner is not None:
            return a, owner
    if target.is_dir():
        for root, dirs, files in os.walk(target):
            for name in files:
                if _LOCK_NAME.match(name):
                    owner = _held(Path(root) / name)
                    if owner is not None:
                        return Path(root) / name[1:-len(".o3d_seqcc.lock")], owner
    return None


def _refuse_nested(target: Path, out) -> None:
    nested = _nested_run(target)
    if nested is not None:
        raise InputError(f"another o3d-seqcc run (pid {nested[1]}) is writing {nested[0]}, which "
                         f"{'holds' if _is_within(target, nested[0]) else 'lies inside'} {out}; wait for it or choose "
                         "another output")


def _make_parents(folder: Path) -> list[Path]:
    """Create ``folder`` and its missing parents; the ones created, outermost first."""
    missing = []
    for p in [folder, *folder.parents]:
        if p.exists():
            break
        missing.append(p)
    folder.mkdir(parents=True, exist_ok=True)
    return missing[::-1]


def _remove_created(created: list[Path]) -> None:
    for p in reversed(created):
        try:
            p.rmdir()
        except OSError:
            return


def _acquire(lock_path: Path, target: Path, out) -> "object":
    """Open and exclusively lock ``lock_path`` (retrying when another run removed it meanwhile)."""
    for _ in range(20):
        try:
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
def _locked(target: Path, out) -> Iterator[None]:
    """Hold the lock of the output ``target`` (``.<name>.o3d_seqcc.lock`` beside it, with our PID), after
    checking that no other run writes a folder holding it or inside it. Folders created to hold the
    lock are removed again when the block fails."""
    lock_path = _lock_path(target)
    try:
        created = _make_parents(target.parent)
    except OSError as e:
        raise _disk_error(e, target) from None
    ok = False
    try:
        lock = _acquire(lock_path, target, out)
        try:
            lock.seek(0)
            lock.truncate()
            lock.write(str(os.getpid()))
            lock.flush()
            _refuse_nested(target, out)
            yield
            ok = True
        finally:
            try:
                lock_path.unlink()
            except OSError:
                pass
            lock.close()
    finally:
        if not ok:
            _remove_created(created)


# ------------------------------------------------------------------------------------------ folders
def _changed(given, foreign: list[str]) -> InputError:
    return InputError(
        f"output folder {given} changed while this run was writing it: it now holds {_shown(foreign)}, which "
        "o3d-seqcc did not write (another program?); nothing was replaced and this run's result was discarded: "
        "move those files away (or choose another --out) and run again")


def _remove_old(old: Path, own: set[str]) -> None:
    """Remove the previous output moved aside: only the files its manifest lists, then its empty folders."""
    for rel in sorted(own | {MANIFEST}):
        p = old / rel
        try:
            if p.is_symlink() or not p.is_dir():
                p.unlink()
        except FileNotFoundError:
            pass
    for root, dirs, files in sorted(os.walk(old), key=lambda t: -len(t[0])):
        try:
            os.rmdir(root)
        except OSError:
            pass
    if old.exists():
        warn(f"{old} kept: it holds {_shown(_listing(old))}, which o3d-seqcc did not write (written into the "
             "previous output while this run was finishing); move them where they belong and delete it")


def _swap(stage: Path, target: Path, given) -> None:
    """Replace ``target`` by ``stage``: refuse when ``target`` holds anything not ours; never delete it."""
    old = None
    if target.exists():
        if not target.is_dir() or target.is_symlink():
            raise _changed(given, [target.name])
        foreign = _foreign(target)
        if foreign:
            raise _changed(given, foreign)
        own = _own_files(target) or set()
        old = _sibling(target, os.getpid(), "old")
        os.replace(target, old)
        foreign = _foreign(old)  # written between the check and the move
        if foreign:
            os.replace(old, target)
            raise _changed(given, foreign)
    try:
        os.replace(stage, target)
    except OSError as e:
        if old is not None:
            os.replace(old, target)
        if e.errno in (errno.ENOTEMPTY, errno.EEXIST):
            raise _changed(given, _listing(target) or [target.name]) from None
        raise
    if old is not None:
        _remove_old(old, own)


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
        The checks of :func:`check_output`; another run holds ``out`` (or a folder holding it, or
        one inside it); ``out`` changed while the run was writing (a file o3d_seqcc did not stage
        appeared in it: nothing is replaced); the disk is full, read-only or not writable.
    """
    inputs = list(inputs)
    target = check_output(out, overwrite=overwrite, inputs=inputs)
    with interruptible(), _locked(target, out):
        _recover(target)
        check_output(out, overwrite=overwrite, inputs=inputs)  # again, under the lock
        stage = _sibling(target, os.getpid(), "staging")
        try:
            stage.mkdir(mode=0o777)
            os.chmod(stage, default_mode(0o777))
            yield stage
            (stage / MANIFEST).write_bytes(_manifest(command, _listing(stage)))
            _fsync_tree(stage)
            _swap(stage, target, out)
        except OSError as e:
            shutil.rmtree(stage, ignore_errors=True)
            raise _disk_error(e, target) from None
        except BaseException:
            shutil.rmtree(stage, ignore_errors=True)
            raise


def add_output_file(out: str | os.PathLike, name: str, data: bytes) -> Path:
    """Write (or replace) one file in an existing output folder of o3d_seqcc, and list it in the manifest.

    For what is added to a finished output later (``o3d-seqcc report RUN_DIR`` writes
    ``report.html``), so that ``--overwrite`` still recognises the whole folder as o3d_seqcc's.
    The file and the manifest are each replaced atomically, under the folder's lock.

    Raises
    ------
    InputError
        ``out`` is not an output folder of o3d_seqcc (no manifest), another run holds it, or
        ``name`` is there but not a regular file of ours.
    """
    given = Path(out)
    target = Path(os.path.realpath(given))
    own = _own_files(target) if target.is_dir() else None
    if own is None:
        raise InputError(f"{given} is not an o3d-seqcc output folder (no {MANIFEST}); give the --out folder of a run")
    if Path(name).is_absolute() or ".." in Path(name).parts or name == MANIFEST:
        raise ValueError(f"add_output_file: {name!r} must be a plain relative path inside the folder")
    dest = target / name
    if os.path.lexists(dest) and (dest.is_symlink() or not dest.is_file() or Path(name).as_posix() not in own):
        raise InputError(f"{given / name} exists and is not a file o3d-seqcc wrote; move it away first")
    with interruptible(), _locked(target, given):
        try:
            path = atomic_write_bytes(dest, data)
            command = json.loads((target / MANIFEST).read_text(encoding="utf-8")).get("command", "")
            atomic_write_bytes(target / MANIFEST, _manifest(command, sorted(own | {Path(name).as_posix()})))
        except OSError as e:
            raise _disk_error(e, target) from None
    return path


# ------------------------------------------------------------------------------------------ files
def _output_folder_of(path: Path) -> Path | None:
    """The o3d-seqcc output folder (holding a manifest) that ``path`` lies in, if any."""
    for a in path.parents:
        if (a / MANIFEST).is_file():
            return a
        if a.parent == a:
            break
    return None


def check_output_file(path: str | os.PathLike, *, option: str = "--output", inputs: Iterable = (),
                      overwrite: bool | None = None) -> Path:
    """Check an output file path before any work; returns its real path (the folder resolved).

    Parameters
    ----------
    path : path-like
    option : str
        The option that named it, for messages (``--json``, ``--output``, ...).
    inputs : iterable of path-like
        Every file the job reads (the same file under another name counts: links are resolved).
    overwrite : bool or None
        None: an existing regular file is replaced (the file was named explicitly); False: an
        existing file is refused; True: replaced.

    Raises
    ------
    InputError
        Empty; a folder, FIFO, device or a link to one; under a file; one of ``inputs``; a file
        of an o3d-seqcc output folder (its manifest lists it: another command owns it); exists
        with ``overwrite=False``; its folder is not writable.
    """
    if not str(path):
        raise InputError(f"{option} is empty; give a file name")
    given = Path(path)
    target = Path(os.path.realpath(given))
    for parent in target.parents:
        if parent.exists() and not parent.is_dir():
            raise InputError(f"{option} {given}: {parent} is a file, not a folder; choose another file name")
    if target.exists():
        st = os.stat(target)
        if stat.S_ISDIR(st.st_mode):
            raise InputError(f"{option} {given} is a folder; give a file name")
        if not stat.S_ISREG(st.st_mode):
            raise InputError(f"{option} {given} exists and is not a regular file (a FIFO or a device); choose another "
                             "file name")
        if overwrite is False:
            raise InputError(f"{option} {given} exists; choose another file or pass --overwrite")
    for p in inputs:
        real = Path(os.path.realpath(p))
        same = real == target
        if not same and target.exists() and real.exists():
            try:
                same = os.path.samefile(real, target)
            except OSError:
                same = False
        if same:
            raise InputError(f"{option} {given} is the input {p}: writing there would replace it; choose another file")
    folder = _output_folder_of(target)
    if folder is not None:
        rel = target.relative_to(folder).as_posix()
        if rel == MANIFEST or rel in (_own_files(folder) or set()):
            raise InputError(f"{option} {given} is a file of the o3d-seqcc output folder {folder} (written by its "
                             "command); choose a file outside it, or run that command again")
    _refuse_nested(target, given)
    existing = next(p for p in target.parents if p.exists())
    if not os.access(existing, os.W_OK):
        raise InputError(f"{option} {given}: cannot write into {existing} (read-only or no permission)")
    return target


@contextmanager
def output_file(path: str | os.PathLike, *, option: str = "--output", inputs: Iterable = (),
                overwrite: bool | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` (same suffix); on success it replaces ``path`` atomically.

    The checks of :func:`check_output_file` (again under the lock), the lock of ``path``
    (``.<name>.o3d_seqcc.lock``, as for folders, nested runs included), SIGTERM / SIGHUP handled
    like Ctrl-C; on failure the temporary file, the lock and the folders created for them are
    removed.
    """
    inputs = list(inputs)
    target = check_output_file(path, option=option, inputs=inputs, overwrite=overwrite)
    with interruptible(), _locked(target, path):
        check_output_file(path, option=option, inputs=inputs, overwrite=overwrite)
        try:
            with atomic_path(target) as tmp:
                yield tmp
        except OSError as e:
            raise _disk_error(e, target) from None


def write_output_file(path: str | os.PathLike, data: bytes, *, option: str = "--output", inputs: Iterable = (),
                      overwrite: bool | None = None) -> Path:
    """Write ``data`` to the output file ``path`` through :func:`output_file`; returns ``path``."""
    with output_file(path, option=option, inputs=inputs, overwrite=overwrite) as tmp:
        Path(tmp).write_bytes(data)
    return Path(path)


def write_output_json(path: str | os.PathLike, obj, *, option: str = "--json", inputs: Iterable = ()) -> Path:
    """``obj`` as JSON (numpy types converted, no NaN) to the output file ``path`` (:func:`output_file`)."""
    from .json_files import to_jsonable

    text = json.dumps(to_jsonable(obj), indent=1, allow_nan=False) + "\n"
    return write_output_file(path, text.encode("utf-8"), option=option, inputs=inputs)
