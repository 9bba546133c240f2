"""The ``o3d-seqcc`` command line.

Each sub-command lives in its own module of this package, named after it: the module docstring
is the command's help (first line) and description, ``add_arguments(parser)`` declares its
options and ``run(args) -> exit code`` calls the library and prints.
"""

from __future__ import annotations

import argparse
import atexit
import gc
import importlib
import logging
import os
import re
import sys
import warnings
from contextlib import contextmanager, redirect_stdout
from typing import Iterator, Sequence

from ..errors import InputError

# sub-command modules, in the order --help lists them
COMMANDS: tuple[str, ...] = ("info", "mappings", "correct", "seams", "evaluate", "texture", "run", "report", "demo",
                             "synthetic")


def _add_global_options(p: argparse.ArgumentParser, *, suppress: bool) -> None:
    """Options accepted before or after the command (``o3d-seqcc -q run ...`` and ``o3d-seqcc run ... -q``)."""
    from ..io.raster_checks import MAX_IMAGE_PIXELS

    d = (lambda v: argparse.SUPPRESS) if suppress else (lambda v: v)
    p.add_argument("-v", "--verbose", action="count", default=d(0),
                   help="more log output: -v the library's progress messages, -vv debug")
    p.add_argument("-q", "--quiet", action="store_true", default=d(False),
                   help="print nothing but errors (no summary, no warnings, no progress)")
    p.add_argument("-j", "--jobs", type=int, default=d(-1),
                   help="parallel workers (joblib threads) for per-view and per-edge work (default -1: all cores)")
    p.add_argument("--scheduler", default=d(None), metavar="ADDRESS",
                   help="run the per-view and per-edge tasks on a Dask cluster: its scheduler's address, e.g. "
                   "tcp://HOST:8786 (default: the environment variable O3D_SEQCC_SCHEDULER, else this machine's "
                   "threads); every worker must read the scene's files at the same paths")
    p.add_argument("--max-image-pixels", type=int, default=d(MAX_IMAGE_PIXELS), metavar="N",
                   help=f"refuse images with more pixels than N before decoding them (default {MAX_IMAGE_PIXELS})")


class _Parser(argparse.ArgumentParser):
    """The top-level parser: an option the command does not know is an error in that command's own usage.

    argparse hands a sub-command's unknown options to the top-level parser, whose usage says
    nothing about them; here the sub-command's parser reports them, with the closest option it
    has ("did you mean --t-npm?").
    """

    def parse_args(self, args=None, namespace=None):  # noqa: D102 - argparse's
        import difflib

        ns, extra = self.parse_known_args(args, namespace)
        if extra:
            sub = ns._subparsers[ns.command]
            known = [o for a in sub._actions for o in a.option_strings]
            hints = []
            for word in extra:
                if word.startswith("-"):
                    close = difflib.get_close_matches(word.split("=", 1)[0], known, n=1, cutoff=0.75)
                    if close:
                        hints.append(f"{word.split('=', 1)[0]}: did you mean {close[0]}?")
            sub.error(f"unrecognized arguments: {' '.join(extra)}" + (f" ({'; '.join(hints)})" if hints else ""))
        return ns


def build_parser(*, commands: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``o3d-seqcc`` parser: the global options and one sub-command per :data:`COMMANDS` entry.

    ``commands`` (default: all) limits the sub-commands to those named: a command line that names
    its command is parsed by a parser holding that one (:func:`command_of`), so starting
    ``o3d-seqcc run`` does not import every other command's modules (the demo's, the synthetic
    scenes', the mappings' file format, ...); its options, help and errors are the same.
    """
    from .. import __version__

    parser = _Parser(
        prog="o3d-seqcc",
        description="Sequential pairwise colour correction and texture mapping of registered photos onto a mesh.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    _add_global_options(parser, suppress=False)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS if commands is None else [c for c in COMMANDS if c in commands]:
        mod = importlib.import_module(f"{__name__}.{name}")
        doc = (mod.__doc__ or "").strip()
        p = sub.add_parser(name, help=doc.split("\n", 1)[0].rstrip("."), description=doc,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        mod.add_arguments(p)
        _add_global_options(p, suppress=True)
        p.set_defaults(func=mod.run)
    parser.set_defaults(_subparsers=sub.choices)
    return parser


#: global options that take a value (the word after them is no command)
_VALUED = ("-j", "--jobs", "--scheduler", "--max-image-pixels")


def command_of(argv: Sequence[str]) -> str | None:
    """The command a command line names, when only global options come before it (else None: parse it all).

    ``["-q", "-j", "2", "run", "scene"]`` -> ``"run"``; ``["--help"]``, ``["bogus"]`` or an option
    it does not know before the command -> None (the whole parser then reports it as before).
    """
    words = list(argv)
    i = 0
    while i < len(words):
        w = words[i]
        if w in COMMANDS:
            return w
        if w in _VALUED:
            i += 2
        elif w.split("=", 1)[0] in _VALUED[1:] or w in ("-q", "--quiet", "-v", "--verbose", "-vv") or (
                w.startswith("-j") and w[2:].lstrip("-").isdigit()):
            i += 1
        else:
            return None
    return None


class WarningLog(logging.Handler):
    """Warnings a person reads: collected while a command runs, printed at its end one line per kind.

    A kind is a message with its quoted names and numbers blanked out, so the same warning about
    16 views is one line: ``o3d-seqcc run: warning (16 times): view 'v00' ...; also 'v01', 'v02',
    ... (13 more)``. Library warnings come from :func:`warnings.warn`
    (:class:`~o3d_seqcc.errors.O3dSeqccWarning` and third-party ones, through :meth:`showwarning`)
    and from the package's loggers at WARNING; Python's ``file:line: Category:`` prefix never shows.
    """

    _QUOTED = re.compile(r"'[^'\s]*'|\"[^\"\s]*\"")  # a repr'd name (no blank inside: "view's" is no quote)
    _PATH = re.compile(r"\S*/\S*")
    _NUMBER = re.compile(r"(?<![A-Za-z_])[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?%?")

    def __init__(self, prog: str) -> None:
        super().__init__(logging.WARNING)
        self.prog = prog
        self.kinds: dict[str, list[str]] = {}

    def add(self, message: str) -> None:
        text = " ".join(str(message).split())
        key = self._NUMBER.sub("#", self._PATH.sub("…", self._QUOTED.sub("'…'", text)))
        self.kinds.setdefault(key, []).append(text)

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.add(record.getMessage())
        except Exception:  # pragma: no cover - a broken format string must not break the command
            self.handleError(record)

    def showwarning(self, message, category, filename, lineno, file=None, line=None) -> None:
        from ..errors import O3dSeqccWarning

        ours = issubclass(category, O3dSeqccWarning)
        self.add(str(message) if ours else f"{category.__name__}: {message}")

    def lines(self) -> list[str]:
        out = []
        for texts in self.kinds.values():
            first, n = texts[0], len(texts)
            if n == 1:
                out.append(f"{self.prog}: warning: {first}")
                continue
            names = list(dict.fromkeys(m.group(0) for t in texts[1:] for m in [self._QUOTED.search(t)] if m))
            also = ""
            if names and self._QUOTED.search(first) and names[0] != self._QUOTED.search(first).group(0):
                shown = ", ".join(names[:5])
                also = f"; also {shown}" + (f" ({len(names) - 5} more)" if len(names) > 5 else "")
            out.append(f"{self.prog}: warning ({n} times): {first}{also}")
        return out


@contextmanager
def _logging(verbose: int, quiet: bool, prog: str = "o3d-seqcc") -> Iterator[None]:
    """Our log for the duration of a command, then the logging and warnings state as it was.

    -q: errors only (nothing else on stderr, nothing on stdout: see :func:`_quiet`). Otherwise
    warnings (the library's :func:`warnings.warn` and its loggers at WARNING) are printed at the
    end, one line per kind with a count (:class:`WarningLog`); -v streams the library's INFO
    messages as they come, -vv DEBUG. Third-party loggers are untouched (WARNING, Python's
    default).
    """
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    stream = logging.StreamHandler(sys.stderr)
    stream.setFormatter(logging.Formatter(f"{prog}: %(message)s"))
    stream.addFilter(lambda r: r.levelno != logging.WARNING)  # warnings go to the grouped lines
    grouped = WarningLog(prog)
    lg = logging.getLogger("o3d_seqcc")
    saved = (lg.level, lg.propagate)
    lg.setLevel(level)
    lg.propagate = False
    lg.addHandler(stream)
    if not quiet:
        lg.addHandler(grouped)
    from ..errors import O3dSeqccWarning

    with warnings.catch_warnings():
        warnings.filterwarnings("always", category=O3dSeqccWarning)  # every one counts in the grouped line
        warnings.showwarning = grouped.showwarning if not quiet else (lambda *a, **k: None)
        try:
            yield
        finally:
            lg.removeHandler(stream)
            lg.removeHandler(grouped)
            lg.setLevel(saved[0])
            lg.propagate = saved[1]
            for line in grouped.lines():
                print(line, file=sys.stderr)


@contextmanager
def _quiet(quiet: bool) -> Iterator[None]:
    """With -q, nothing on standard output (ours, or a compiled library's), until the block ends."""
    if not quiet:
        yield
        return
    sys.stdout.flush()
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # a captured or replaced sys.stdout without a file
        fd = None
    saved = os.dup(fd) if fd is not None else None
    try:
        with open(os.devnull, "w") as null, redirect_stdout(null):
            if saved is not None:
                os.dup2(null.fileno(), fd)
            yield
    finally:
        if saved is not None:
            os.dup2(saved, fd)
            os.close(saved)


def _client(address: str | None):
    """A Dask client for ``--scheduler`` (or ``O3D_SEQCC_SCHEDULER``), None for local threads."""
    import os

    from .._shared.parallel import SCHEDULER_ENV, connect

    option = "--scheduler"
    if not address:
        address, option = os.environ.get(SCHEDULER_ENV, "").strip() or None, SCHEDULER_ENV
    return None if address is None else connect(address, option=option)


def _executor(client):
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


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``o3d-seqcc`` console script; returns the exit code."""
    _freeze_at_exit()
    _fewer_malloc_arenas()
    problem = _environment_problem()
    if problem:
        print(f"o3d-seqcc: error: {problem}", file=sys.stderr)
        return 2
    from .._shared.interrupts import Terminated, interruptible

    try:
        with interruptible(), _open3d_without_dash():  # SIGTERM / SIGHUP clean up like Ctrl-C
            return _main(argv)
    except Terminated as e:
        print(f"o3d-seqcc: terminated ({e.name})", file=sys.stderr)
        return 128 + e.signum
    except KeyboardInterrupt:
        print("o3d-seqcc: interrupted", file=sys.stderr)
        return 130


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


def _main(argv: list[str] | None) -> int:
    from .._shared.interrupts import Terminated

    try:
        command = command_of(sys.argv[1:] if argv is None else argv)
        parser = build_parser() if command is None else build_parser(commands=[command])
        try:
            args = parser.parse_args(argv)
        except SystemExit as e:  # argparse: --help (0) or a usage error (2, message already printed)
            return int(e.code or 0)
        from joblib import parallel_config

        from ..io.raster_checks import set_max_image_pixels
        from .._shared.progress import show_progress
        from .common import progress_from_args

        try:
            old = set_max_image_pixels(args.max_image_pixels)
            client = None
            try:
                bars = sys.stderr.isatty() and not args.quiet
                with _logging(args.verbose, args.quiet, f"o3d-seqcc {args.command}"), _quiet(args.quiet), \
                        parallel_config(n_jobs=args.jobs), show_progress(bars), progress_from_args(args):
                    client = _client(args.scheduler)
                    with _executor(client):
                        return int(args.func(args) or 0)
            finally:
                set_max_image_pixels(old)
                if client is not None:
                    client.close()
        except InputError as e:
            print(f"o3d-seqcc {args.command}: error: {e}", file=sys.stderr)
            return 2
        except OSError as e:
            print(f"o3d-seqcc {args.command}: error: {e}", file=sys.stderr)
            return 1
    except Terminated:
        raise
    except KeyboardInterrupt:
        print("o3d-seqcc: interrupted", file=sys.stderr)
        return 130
    except ImportError as e:  # Ctrl-C while a compiled module (open3d) initialises is re-raised as ImportError
        if isinstance(e.__cause__ or e.__context__, KeyboardInterrupt):
            print("o3d-seqcc: interrupted", file=sys.stderr)
            return 130
        raise


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
