"""Lazy re-exports (PEP 562): a package's public names imported from their modules on first use.

``import o3d_seqcc`` and ``import o3d_seqcc.visibility`` stay cheap (no Open3D, no scikit-learn until a
name that needs them is used), and a package's ``__init__`` never imports its own modules eagerly, so
importing one leaf module (``o3d_seqcc.visibility.depthmaps``) never drags in its siblings.
"""

from __future__ import annotations

import importlib
from typing import Any, Callable, Iterable, Mapping

__all__ = ["lazy_exports"]


def lazy_exports(
    package: str, table: Mapping[str, str], *, submodules: Iterable[str] | Mapping[str, str] = ()
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The ``__getattr__`` / ``__dir__`` pair of a package whose names live in its modules.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    table : mapping of str to str
        Public name -> the module (relative to ``package``, e.g. ``"compute"`` or ``"io.load"``) that
        defines it.
    submodules : iterable of str, or mapping of str to str, keyword-only
        Modules reachable as attributes without an explicit import (``o3d_seqcc.pipeline``); a mapping
        names where each lives (``{"parallel": "_shared.parallel"}``: ``o3d_seqcc._shared.parallel.use``).

    Returns
    -------
    getattr, dir : callable
        Assign them to the package's ``__getattr__`` and ``__dir__``.
    """
    subs = dict(submodules) if isinstance(submodules, Mapping) else {m: m for m in submodules}
    pkg = importlib.import_module(package)

    def __getattr__(name: str) -> Any:
        if name in subs:
            value = importlib.import_module(f".{subs[name]}", package)
        elif name in table:
            value = getattr(importlib.import_module(f".{table[name]}", package), name)
        else:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        setattr(pkg, name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(pkg)) | set(table) | set(subs))

    return __getattr__, __dir__
