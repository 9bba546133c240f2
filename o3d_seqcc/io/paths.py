"""Paths named by scene files: a one-file format's file in a folder, relative paths joined as the OS does."""

from __future__ import annotations

import logging
import os
from pathlib import Path

__all__ = ["find_file", "join_path"]

logger = logging.getLogger(__name__)


def find_file(path: Path, *, name: str, suffix: str) -> Path | None:
    """``path`` when it is a file ending in ``suffix``, ``path / name`` when ``path`` is a folder holding it, else None.

    The ``detect`` step of the scene formats that are one file (``scene.json``, ``cameras.sfm``).
    """
    path = Path(path)
    if path.is_dir():
        return path / name if (path / name).is_file() else None
    return path if path.is_file() and path.suffix.lower() == suffix else None


def join_path(root: str | os.PathLike, rel: str) -> Path:
    """``root / rel`` normalised, with ``..`` resolved as the operating system does.

    ``os.path.normpath`` drops ``x/..`` by text; when ``root`` lies under a symbolic link that
    is wrong (``link/../a`` is ``a`` beside the link's *target*). A relative path with ``..``
    under a linked folder is therefore joined to the folder's real path, so a project or
    manifest written in an output folder reached through a link loads through that link.
    """
    rel_parts = Path(rel).parts
    if ".." in rel_parts and not Path(rel).is_absolute():
        real = os.path.realpath(root)
        if real != os.path.abspath(root):
            return Path(os.path.normpath(os.path.join(real, rel)))
    return Path(os.path.normpath(Path(root) / rel))
