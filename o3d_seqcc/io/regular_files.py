"""Opening input files: regular files only, found without blocking, read through their descriptor.

:func:`open_regular` is how every image, depth map, mask, mesh, point cloud and JSON file is
opened (the first step of the file layer, see :mod:`o3d_seqcc.io`): a FIFO, a device, a socket or
a folder is an error naming it, found without blocking (opened non-blocking and checked with
``fstat``: a named pipe never hangs a run); any path bytes work, since the file is read through its
descriptor.
"""

from __future__ import annotations

import logging
import os
import stat
from typing import BinaryIO

from ..errors import InputError

__all__ = ["file_size", "open_regular"]

logger = logging.getLogger(__name__)


def _kind(mode: int) -> str:
    kinds = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
             (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a folder"))
    return next((name for test, name in kinds if test(mode)), "not a regular file")


def open_regular(path: str | os.PathLike, what: str = "file") -> BinaryIO:
    """Open ``path`` for reading in binary mode, refusing anything but a regular file, without blocking.

    Parameters
    ----------
    path : path-like
        Any path (bytes that are not UTF-8 included).
    what : str
        What the file is, for messages ("image", "depth map", "mesh", ...).

    Returns
    -------
    file object
        Opened ``rb``; close it (``with open_regular(p) as f: ...``).

    Raises
    ------
    InputError
        Missing, unreadable, or a FIFO / device / socket / folder (found with ``fstat`` on a
        descriptor opened non-blocking: a named pipe with no writer is refused at once).
    """
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise InputError(f"{what} not found: {path} (check the path)") from None
    except PermissionError:
        raise InputError(f"cannot read {what} {path}: permission denied (fix its permissions)") from None
    except OSError as e:
        raise InputError(f"cannot open {what} {path}: {e.strerror}; give a regular file") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputError(f"{what} {path} is {_kind(st.st_mode)}, not a regular file; give the {what} file itself")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def file_size(f: BinaryIO) -> int:
    """The size in bytes of the open file ``f`` (``fstat`` of its descriptor)."""
    return os.fstat(f.fileno()).st_size
