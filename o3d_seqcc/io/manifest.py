"""The manifest of an output folder (``.o3d_seqcc.json``): what o3d_seqcc wrote there, written and read back.

The manifest is a JSON object ``{"format": "o3d_seqcc.output/1", "command": ..., "files": [...]}``
listing every entry the command wrote, relative to the folder (:func:`listing`'s form: files,
symbolic links and empty folders as ``name/``). :mod:`o3d_seqcc.io.output` replaces and deletes
only what it lists, so nothing read back from it is trusted (:func:`own_files`): an entry that is
absolute, not normalised, outside the folder or reached through a symbolic link makes the folder
foreign, with the entry named.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path, PurePosixPath
from typing import Any

from ..errors import InputError

__all__ = ["MANIFEST", "MANIFEST_FORMAT", "listing", "manifest_bytes", "own_files", "untrusted_entry"]

#: file name of the manifest in an output folder
MANIFEST = ".o3d_seqcc.json"
#: its format tag
MANIFEST_FORMAT = "o3d_seqcc.output/1"


def manifest_bytes(command: str, files: list[str]) -> bytes:
    """The manifest of ``command``'s output listing ``files`` (relative POSIX paths), as UTF-8 JSON."""
    return (json.dumps({"format": MANIFEST_FORMAT, "command": command, "files": files}, indent=1) + "\n").encode("utf-8")


def own_files(out: Path) -> set[str] | None:
    """Relative paths listed in ``out``'s manifest, or None without a readable manifest.

    Nothing read back is trusted: every entry must be a relative, normalised POSIX path inside the
    folder that reaches its file through no symbolic link (:func:`untrusted_entry`).

    Raises
    ------
    InputError
        An entry is not: the folder is treated as foreign (``--overwrite`` refuses it), the entry named.
    """
    try:
        data = json.loads((out / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("format") != MANIFEST_FORMAT or not isinstance(data.get("files"), list):
        return None
    for entry in data["files"]:
        why = untrusted_entry(out, entry)
        if why:
            raise InputError(
                f"{out / MANIFEST} lists {entry!r:.200}, {why}: o3d-seqcc never writes such an entry, so this folder "
                "is not treated as one of its outputs and nothing in it or outside it is replaced or deleted; "
                "choose another --out, or check the folder and remove it yourself")
    return set(data["files"])


def untrusted_entry(out: Path, entry: Any) -> str:
    """Why a manifest entry cannot be one o3d-seqcc wrote ("" when it can)."""
    if not isinstance(entry, str) or not entry:
        return "which is not a file name"
    if any(ord(c) < 32 for c in entry) or "\\" in entry:
        return "which holds control characters or backslashes"
    p = PurePosixPath(entry)
    if p.is_absolute() or entry.startswith("/") or re.match(r"^[A-Za-z]:", entry):
        return "an absolute path"
    if any(part in ("..", ".") for part in entry.split("/")) or p.as_posix() != entry.rstrip("/") or "//" in entry:
        return "a path that is not normalised or leaves the folder"
    if entry == MANIFEST:
        return "the manifest itself"
    parts = p.parts
    for i in range(1, len(parts)):  # the entry's folders: real folders inside this one, not links elsewhere
        if (out.joinpath(*parts[:i])).is_symlink():
            return f"which passes through the symbolic link {'/'.join(parts[:i])}"
    return ""


def listing(folder: Path) -> list[str]:
    """Every entry under ``folder`` that holds data, relative: files, symbolic links (never followed), other
    non-folders, and empty folders (``name/``)."""
    out = []
    for root, dirs, files in os.walk(folder):
        rel = Path(root).relative_to(folder)
        for d in list(dirs):
            if os.path.islink(os.path.join(root, d)):  # a link to a folder is an entry, not a folder of ours
                dirs.remove(d)
                files.append(d)
        out += [(rel / f).as_posix() for f in files]
        if not files and not dirs and root != str(folder):
            out.append(rel.as_posix() + "/")
    return sorted(out)
