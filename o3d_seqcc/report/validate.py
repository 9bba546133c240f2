"""What ``o3d-seqcc report RUN_DIR`` reads from an output folder, checked before the page is drawn.

An output folder is ours, but its files may have been edited, cut short or replaced since: the
reader trusts nothing. :func:`read_report_json` checks ``report.json`` against the fields the page
uses (containers are objects, counts are integers, figures are numbers, names are strings,
``correction.settings.options`` are options of the recorded method), so a wrong type is an
:class:`~o3d_seqcc.errors.InputError` naming the field, never a traceback, and no string put into
a numeric field can reach the HTML (the page escapes every string it writes; numbers it formats).
:func:`read_selection` checks ``selection.npy`` from its header (a 1-D integer array of one view
index per face, in range) before loading it. :func:`page_bytes` encodes the page: a path whose
bytes are not UTF-8 is written as its escaped bytes (``sc\\xe9ne``), never a crash.
"""

from __future__ import annotations

import inspect
import os
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import InputError, warn
from ..io.json_files import read_json
from ..io.regular_files import open_regular
from .schema import upgrade

__all__ = ["page_bytes", "read_report_json", "read_selection", "validate_report"]


def _is_num(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x)


def _is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _check(kind: str) -> Callable[[Any], bool]:
    return {
        "dict": lambda x: isinstance(x, dict),
        "dict?": lambda x: x is None or isinstance(x, dict),
        "str": lambda x: isinstance(x, str),
        "str?": lambda x: x is None or isinstance(x, str),
        "int": _is_int,
        "int?": lambda x: x is None or _is_int(x),
        "npm": lambda x: x == "auto" or _is_int(x),
        "num": _is_num,
        "num?": lambda x: x is None or _is_num(x),
        "list": lambda x: isinstance(x, list),
        "3x3": lambda x: isinstance(x, list) and len(x) == 3 and all(
            isinstance(r, list) and len(r) == 3 and all(_is_num(v) for v in r) for r in x),
        "3x3?": lambda x: x is None or _check("3x3")(x),
    }[kind]


_KINDS = {
    "dict": "an object", "dict?": "an object or null", "str": "a string", "str?": "a string or null",
    "int": "an integer", "int?": "an integer or null", "npm": "an integer or \"auto\"", "num": "a finite number", "num?": "a finite number or null",
    "list": "a list", "3x3": "a 3x3 list of numbers", "3x3?": "a 3x3 list of numbers or null",
}

_STATS = ("mean", "weighted_mean", "std")
#: (dotted path with * for any key, kind): every field the page or the reader uses
RULES: tuple[tuple[str, str], ...] = (
    ("schema", "str"), ("command", "str"), ("scene", "str"), ("scene_path", "str?"), ("mesh", "str?"), ("images", "str"),
    ("scene_options", "dict"), ("views", "list"), ("views.*", "str"),
    # a correct report.json of schema 1 (before report.schema): its correction at the top level
    ("reference", "str"), ("method", "str?"), ("mappings", "str?"), ("graph_weight", "str"), ("t_npm", "npm"),
    ("seed", "int"),
    ("correction", "dict?"), ("correction.method", "str"), ("correction.reference", "str"),
    ("correction.reference_index", "int?"), ("correction.graph_edges", "list"),
    ("correction.t_npm", "int"), ("correction.mappings", "str?"), ("correction.settings", "dict"),
    ("correction.settings.t_npm", "npm"), ("correction.settings.seed", "int"),
    ("correction.settings.interpolation", "str"), ("correction.settings.graph_weight", "str"),
    ("correction.settings.options", "dict"), ("correction.timings_s", "dict"), ("correction.timings_s.*", "num"),
    ("correction.n_graph_edges", "int"), ("correction.unreachable", "list"), ("correction.unreachable.*", "str"),
    ("correction.edge_residuals", "list"), ("correction.edge_residuals.*", "dict"),
    ("correction.edge_residuals.*.before", "num"), ("correction.edge_residuals.*.after", "num"),
    ("correction.out_of_line", "list"), ("correction.out_of_line.*", "str"),
    ("metrics", "dict?"), ("metrics.before", "dict"), ("metrics.after", "dict"), ("metrics.contrast", "dict"),
    *((f"metrics.{w}.{m}", "dict") for w in ("before", "after") for m in ("psnr", "ciede2000")),
    *((f"metrics.{w}.{m}.{s}", "num?") for w in ("before", "after") for m in ("psnr", "ciede2000") for s in _STATS),
    *((f"metrics.{w}.{k}", "int") for w in ("before", "after") for k in ("n_pairs", "n_mappings", "n_scored")),
    ("metrics.before.max_per_pair", "int?"), ("metrics.after.max_per_pair", "int?"),
    ("metrics.contrast.*", "dict?"), ("metrics.contrast.*.mean", "num?"), ("metrics.contrast.*.min", "num?"),
    ("timings_s", "dict"), ("timings_s.*", "num"), ("timings", "dict"), ("timings.*", "num"),
    ("texture_settings", "dict?"), ("selection", "dict?"), ("selection.picture_view", "str"),
    ("selection.seed", "int"), ("selection.method", "str"),
    ("atlas", "dict?"), ("atlas.atlas_size", "int"), ("atlas.pages", "int"), ("atlas.texels_per_pixel", "num?"),
    ("atlas.coverage", "num?"), ("atlas.page_width", "int?"), ("atlas.page_height", "int?"),
    ("atlas.texture_memory", "dict?"), ("atlas.texture_memory.gpu_bytes", "int"),
    ("atlas.texture_memory.pages", "list"), ("atlas.texture_memory.pages.*", "dict"),
    *((f"atlas.texture_memory.pages.*.{k}", "int") for k in ("width", "height", "gpu_bytes")),
    ("atlas.texture_memory.pages.*.coverage", "num"),
    ("seams", "dict?"), ("seams.*", "num?"), ("seams_original_images", "dict?"), ("seams_original_images.*", "num?"),
    ("export", "dict?"), ("export.orientation", "dict"), ("export.orientation.rotation", "3x3?"),
    ("export.orientation.applies_to", "list"), ("export.orientation.applies_to.*", "str"),
    ("selection_seams", "dict?"), ("visibility_stats", "dict?"), ("files", "dict"),
)
#: fields that must be there when their parent is (what the page indexes without a default)
REQUIRED: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("metrics.before", ("psnr", "ciede2000", "n_pairs", "n_mappings")),
    ("metrics.after", ("psnr", "ciede2000")),
    *((f"metrics.{w}.{m}", _STATS) for w in ("before", "after") for m in ("psnr", "ciede2000")),
)


def _find(d: Any, parts: list[str], prefix: str = "") -> list[tuple[str, Any]]:
    """(dotted path, value) of every field matching ``parts`` (``*``: any key or list index)."""
    if not parts:
        return [(prefix, d)]
    head, rest = parts[0], parts[1:]
    out: list[tuple[str, Any]] = []
    if isinstance(d, dict):
        keys = list(d) if head == "*" else [head] if head in d else []
        for k in keys:
            out += _find(d[k], rest, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(d, list) and head == "*":
        for i, v in enumerate(d):
            out += _find(v, rest, f"{prefix}[{i}]")
    return out


def validate_report(rep: Any, where: str | os.PathLike = "report.json") -> dict:
    """Check a ``report.json`` document against :data:`RULES` and :data:`REQUIRED`; returns it.

    Raises
    ------
    InputError
        Not an object, a field of the wrong type, a required field missing, unknown correction
        options; the message names the field and what it should be.
    """
    if not isinstance(rep, dict):
        raise InputError(f"{where} is not an o3d-seqcc report (not a JSON object); run the command again")
    for path, kind in RULES:
        ok = _check(kind)
        for name, value in _find(rep, path.split(".")):
            if not ok(value):
                raise InputError(f"{where}: {name!r} must be {_KINDS[kind]}, got {_shown(value)}; the file was edited "
                                 "or damaged: run the command again to rewrite the folder")
    for path, keys in REQUIRED:
        for name, value in _find(rep, path.split(".")):
            missing = [k for k in keys if k not in value]
            if missing:
                raise InputError(f"{where}: {name!r} lacks {', '.join(map(repr, missing))}; run the command again")
    correction = rep.get("correction") or {}
    method = correction.get("method") if correction else rep.get("method")
    if method is not None and not (rep.get("reference") or correction.get("reference")):
        raise InputError(f"{where}: a correction ({method!r}) without a 'reference'; run the command again")
    options = (correction.get("settings") or {}).get("options") or {}
    if options:
        from ..correction import METHODS

        params = inspect.signature(METHODS[method]).parameters if method in METHODS else {}
        bad = sorted(k for k in options if k not in params or k in ("scene", "mappings", "images"))
        if bad:
            raise InputError(f"{where}: 'correction.settings.options' has {bad}, not options of the method "
                             f"{method!r}; run the command again")
    return rep


def _shown(value: Any) -> str:
    text = repr(value)
    return (text[:60] + "...") if len(text) > 60 else text


def read_report_json(run_dir: str | os.PathLike) -> dict:
    """``run_dir/report.json``, read (regular file, UTF-8, no duplicate keys), validated and in the current schema.

    A report of an older o3d_seqcc is checked as written (the messages name its fields) and returned
    through :func:`~o3d_seqcc.report.schema.upgrade` (its keys moved where the schema has them).

    Raises
    ------
    InputError
        ``run_dir`` is not a folder or holds no report.json; the file is not valid JSON (cut
        short, edited) or does not pass :func:`validate_report`.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise InputError(f"{run_dir} is not a folder; give the output folder (--out) of o3d-seqcc run, correct or "
                         "texture")
    rj = run_dir / "report.json"
    if not os.path.lexists(rj):
        raise InputError(f"{run_dir} is not an o3d-seqcc output folder (no report.json); give the --out folder of "
                         "o3d-seqcc run, correct or texture")
    try:
        rep = read_json(rj, "report.json")
    except InputError as e:
        raise InputError(f"{e}; run the command again to rewrite the folder") from None
    return upgrade(validate_report(rep, rj))


def read_selection(path: str | os.PathLike, n_faces: int, n_views: int) -> np.ndarray | None:
    """``selection.npy``: one view index per face (-1 = seen by no view), checked from its header first.

    Returns None, with a warning, when it holds another number of faces than the mesh (the
    report then leaves the selection out).

    Raises
    ------
    InputError
        Not a regular file, not a ``.npy`` array, not a 1-D integer array, cut short, or indices
        outside -1..``n_views`` - 1.
    """
    path = Path(path)
    with open_regular(path, "selection.npy") as f:
        size = os.fstat(f.fileno()).st_size
        try:
            fmt = np.lib.format
            version = fmt.read_magic(f)
            header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
            shape, fortran, dtype = header(f)
            offset = f.tell()
        except (ValueError, OSError, EOFError, SyntaxError, TypeError) as e:
            raise InputError(f"{path} is not a numpy .npy array ({e}); run the command again") from None
        if dtype.kind not in "iu" or len(shape) != 1:
            raise InputError(f"{path} holds a {dtype} array of shape {shape}; expected one integer view index per "
                             f"face ({n_faces},); run the command again")
        if shape[0] != n_faces:
            warn(f"{path} has {shape[0]} entries for the {n_faces} faces of the mesh (another mesh?): the selection "
                 "is left out of the report; pass the run's --mesh, or run the command again")
            return None
        if size - offset < shape[0] * dtype.itemsize:
            raise InputError(f"{path} is truncated ({size} bytes for {shape[0]} entries); run the command again")
        sel = np.fromfile(f, dtype=dtype, count=shape[0]).astype(np.int64)
    if len(sel) and (sel.min() < -1 or sel.max() >= n_views):
        raise InputError(f"{path} holds view indices {int(sel.min())}..{int(sel.max())} for {n_views} views "
                         f"(-1..{n_views - 1}); run the command again")
    return sel


def page_bytes(page: str) -> bytes:
    """The page as UTF-8; characters that stand for undecodable path bytes are written as escapes (``\\xe9``)."""
    try:
        return page.encode("utf-8")
    except UnicodeEncodeError:
        return page.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace").encode("utf-8")
