"""The process a command runs in: the interpreter's exit, glibc's malloc arenas, ``import open3d``
without ``dash``, the environment checked before any work, and the Dask client of ``--scheduler``."""

from __future__ import annotations

import atexit
import gc
import os
import sys
from contextlib import contextmanager
from typing import Iterator


def _client(address: str | None):
    """A Dask client for ``--scheduler`` (or ``O3D_SEQCC_SCHEDULER``), None for local threads."""
    import os

    from .._shared.parallel import SCHEDULER_ENV, connect

    option = "--scheduler"
    if not address:
        address, option = os.environ.get(SCHEDULER_ENV, "").strip() or None, SCHEDULER_ENV
    return None if address is None else connect(address, option=option)


def _executor(client):
    """The executor context of the stages' tasks: ``client``'s cluster, or local threads when None."""
    from .._shared.parallel import use

    return use(client)


def _freeze_at_exit() -> None:
    """Let the interpreter's exit skip its cyclic garbage collections (registered once, run at exit).

    At exit CPython clears every module and collects the cycles among the objects left, several
    full passes over the ~10^6 objects of NumPy, SciPy, OpenCV and Open3D's modules: 0.15-0.3 s
    of a command's run, after its output is complete. :func:`gc.freeze` in an :mod:`atexit`
    handler moves them to the permanent generation first, which those passes do not visit;
    everything else happens as before (atexit handlers, logging's flush, the standard streams'
    flush, objects freed by reference counting; only cycles are left to the operating system).
    """
    global _FREEZE_REGISTERED
    if not _FREEZE_REGISTERED:
        _FREEZE_REGISTERED = True
        atexit.register(gc.freeze)


_FREEZE_REGISTERED = False

#: glibc malloc arenas a command uses (``MALLOC_ARENA_MAX`` in the environment overrides it)
MALLOC_ARENAS = 2


def _fewer_malloc_arenas() -> None:
    """Let glibc's malloc keep :data:`MALLOC_ARENAS` arenas instead of eight per core (Linux; before any thread).

    Each thread that allocates while another holds an arena gets an arena of its own, and memory
    freed in an arena mostly stays with the process: a run's worker threads (visibility, bake,
    save) left hundreds of megabytes of freed pages resident. With two arenas the 300k Fountain
    run peaked at 1217 MB instead of 1479 MB, with no more CPU time (numpy's arrays are few and
    large; Python's small objects do not use malloc's arenas). Set before the command starts
    threads; a ``MALLOC_ARENA_MAX`` the user set is left as it is.
    """
    if not sys.platform.startswith("linux") or "MALLOC_ARENA_MAX" in os.environ:
        return
    try:
        import ctypes

        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc (or no mallopt): nothing to set
        return
    mallopt(-8, MALLOC_ARENAS)  # M_ARENA_MAX (malloc.h)


class _DashForward:
    """Stands for ``dash``'s ``html`` / ``dcc`` / ``Dash`` in Open3D's ``draw_plotly`` module: the real one is
    imported when first used (``open3d.visualization.draw_plotly_server`` still works)."""

    def __init__(self, module: str, attr: str | None = None) -> None:
        self._where = (module, attr)

    def _target(self):
        import importlib

        if getattr(sys.modules.get("dash"), "_o3d_seqcc_stub", False):
            del sys.modules["dash"]
        module, attr = self._where
        m = importlib.import_module(module)
        return m if attr is None else getattr(m, attr)

    def __getattr__(self, name: str):
        return getattr(self._target(), name)

    def __call__(self, *args, **kwargs):
        return self._target()(*args, **kwargs)


@contextmanager
def _open3d_without_dash() -> Iterator[None]:
    """While a command runs, ``import open3d`` does not import ``dash``.

    Open3D's ``visualization`` imports Plotly's ``dash`` web framework at start-up (for
    ``draw_plotly_server``, which no command calls): about 0.6 s of a quiet machine's 2 s import of
    open3d, 2-6 s on a loaded one (issue 21). A stand-in module holds the three names Open3D takes
    from it, each importing the real one when used, and leaves ``sys.modules`` when the command
    ends. Nothing changes when open3d or dash is already imported.
    """
    import types

    if "open3d" in sys.modules or "dash" in sys.modules:
        yield
        return
    stub = types.ModuleType("dash", "stand-in for dash while open3d is imported by o3d-seqcc (see cli._open3d_without_dash)")
    stub._o3d_seqcc_stub = True
    stub.html, stub.dcc, stub.Dash = _DashForward("dash.html"), _DashForward("dash.dcc"), _DashForward("dash", "Dash")
    sys.modules["dash"] = stub
    try:
        yield
    finally:
        if sys.modules.get("dash") is stub:
            del sys.modules["dash"]


def _environment_problem() -> str | None:
    """What makes any run fail before it starts (a deleted working directory), as a message; also lets
    paths whose bytes are not UTF-8 print as they are (like ``ls``) instead of failing."""
    import os

    for stream in (sys.stdout, sys.stderr):
        if getattr(stream, "errors", None) == "strict" and hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="surrogateescape")
    try:
        os.getcwd()
    except (FileNotFoundError, PermissionError, OSError):
        return ("the current working directory no longer exists (deleted or moved, or not readable); change to an "
                "existing folder (cd) and run the command again")
    return None
