"""The ``o3d-seqcc`` command line.

Each sub-command lives in its own module of this package, named after it: the module docstring
is the command's help (first line) and description, ``add_arguments(parser)`` declares its
options and ``run(args) -> exit code`` calls the library and prints.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from contextlib import contextmanager
from typing import Iterator

from ..errors import InputError

# sub-command modules, in the order --help lists them
COMMANDS: tuple[str, ...] = ("info", "mappings", "correct", "seams", "evaluate", "texture", "run", "report", "demo",
                             "synthetic")


def _add_global_options(p: argparse.ArgumentParser, *, suppress: bool) -> None:
    """Options accepted before or after the command (``o3d-seqcc -q run ...`` and ``o3d-seqcc run ... -q``)."""
    from ..io.files import MAX_IMAGE_PIXELS

    d = (lambda v: argparse.SUPPRESS) if suppress else (lambda v: v)
    p.add_argument("-v", "--verbose", action="count", default=d(0),
                   help="more log output: -v the library's progress messages, -vv debug")
    p.add_argument("-q", "--quiet", action="store_true", default=d(False), help="only errors")
    p.add_argument("-j", "--jobs", type=int, default=d(-1),
                   help="parallel workers (joblib threads) for per-view and per-edge work (default -1: all cores)")
    p.add_argument("--scheduler", default=d(None), metavar="ADDRESS",
                   help="run the per-view and per-edge tasks on a Dask cluster: its scheduler's address, e.g. "
                   "tcp://HOST:8786 (default: the environment variable O3D_SEQCC_SCHEDULER, else this machine's "
                   "threads); every worker must read the scene's files at the same paths")
    p.add_argument("--max-image-pixels", type=int, default=d(MAX_IMAGE_PIXELS), metavar="N",
                   help=f"refuse images with more pixels than N before decoding them (default {MAX_IMAGE_PIXELS})")


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="o3d-seqcc",
        description="Sequential pairwise colour correction and texture mapping of registered photos onto a mesh.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    _add_global_options(parser, suppress=False)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        mod = importlib.import_module(f"{__name__}.{name}")
        doc = (mod.__doc__ or "").strip()
        p = sub.add_parser(name, help=doc.split("\n", 1)[0].rstrip("."), description=doc,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        mod.add_arguments(p)
        _add_global_options(p, suppress=True)
        p.set_defaults(func=mod.run)
    return parser


@contextmanager
def _logging(verbose: int, quiet: bool) -> Iterator[None]:
    """Our log lines on stderr for the duration of a command, then the logging state as it was.

    The package's loggers at WARNING (default), INFO (-v), DEBUG (-vv) or ERROR (-q); third-party
    loggers untouched (WARNING, Python's default); library warnings
    (:class:`~o3d_seqcc.errors.O3dSeqccWarning`) routed through logging so they show once.
    """
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    saved = []
    for name, lvl in (("o3d_seqcc", level), ("py.warnings", max(level, logging.WARNING))):
        lg = logging.getLogger(name)
        saved.append((lg, lg.level, lg.propagate))
        lg.setLevel(lvl)
        lg.propagate = False
        lg.addHandler(handler)
    logging.captureWarnings(True)
    try:
        yield
    finally:
        logging.captureWarnings(False)
        for lg, lvl, prop in saved:
            lg.removeHandler(handler)
            lg.setLevel(lvl)
            lg.propagate = prop


def _client(address: str | None):
    """A Dask client for ``--scheduler`` (or ``O3D_SEQCC_SCHEDULER``), None for local threads."""
    import os

    from ..parallel import SCHEDULER_ENV, connect

    option = "--scheduler"
    if not address:
        address, option = os.environ.get(SCHEDULER_ENV, "").strip() or None, SCHEDULER_ENV
    return None if address is None else connect(address, option=option)


def _executor(client):
    from ..parallel import use

    return use(client)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``o3d-seqcc`` console script; returns the exit code."""
    problem = _environment_problem()
    if problem:
        print(f"o3d-seqcc: error: {problem}", file=sys.stderr)
        return 2
    from ..interrupts import Terminated, interruptible

    try:
        with interruptible():  # SIGTERM / SIGHUP clean up like Ctrl-C
            return _main(argv)
    except Terminated as e:
        print(f"o3d-seqcc: terminated ({e.name})", file=sys.stderr)
        return 128 + e.signum
    except KeyboardInterrupt:
        print("o3d-seqcc: interrupted", file=sys.stderr)
        return 130


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
    from ..interrupts import Terminated

    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as e:  # argparse: --help (0) or a usage error (2, message already printed)
            return int(e.code or 0)
        from joblib import parallel_config

        from ..io.files import set_max_image_pixels
        from ..progress import show_progress

        try:
            old = set_max_image_pixels(args.max_image_pixels)
            client = None
            try:
                bars = sys.stderr.isatty() and not args.quiet
                with _logging(args.verbose, args.quiet), parallel_config(n_jobs=args.jobs), show_progress(bars):
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
