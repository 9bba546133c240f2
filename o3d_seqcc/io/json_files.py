"""JSON files: written atomically with numpy values converted, read back refusing duplicate keys."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from .atomic import atomic_write_bytes
from .regular_files import open_regular

__all__ = ["parse_json", "read_json", "to_jsonable", "write_json"]

logger = logging.getLogger(__name__)


def to_jsonable(o: Any) -> Any:
    """Convert numpy arrays / scalars, paths, tuples and non-string dict keys to JSON types."""
    if isinstance(o, dict):
        return {str(k): to_jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [to_jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    return o


def write_json(path: str | os.PathLike, obj: Any, *, indent: int | None = 1) -> Path:
    """Serialise ``obj`` as JSON and write it atomically; numpy scalars/arrays are converted."""

    text = json.dumps(to_jsonable(obj), indent=indent, allow_nan=False)
    return atomic_write_bytes(path, (text + "\n").encode("utf-8"))


def parse_json(text: str, where: str | os.PathLike) -> Any:
    """``json.loads`` that refuses duplicate keys (which would silently keep the last one).

    Raises
    ------
    InputError
        Not valid JSON, or an object with the same key twice (named, with ``where``).
    """
    def pairs(items: list) -> dict:
        out: dict = {}
        for k, v in items:
            if k in out:
                raise InputError(f"{where}: the key {k!r} appears twice in one JSON object (only one value can "
                                 "count); remove the duplicate")
            out[k] = v
        return out

    try:
        return json.loads(text, object_pairs_hook=pairs)
    except (json.JSONDecodeError, RecursionError) as e:
        raise InputError(f"{where}: not valid JSON ({e})") from None


def read_json(path: str | os.PathLike, what: str = "JSON file") -> Any:
    """Read a UTF-8 JSON file (regular files only; duplicate keys refused, see :func:`parse_json`)."""
    path = Path(path)
    with open_regular(path, what) as f:
        raw = f.read()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start}); save it as UTF-8") from None
    return parse_json(text, path)
