"""The ``o3d-seqcc`` command line: :func:`main`, its exit codes and error messages.

Each sub-command lives in its own module of this package, named after it: the module docstring
is the command's help (first line) and description, ``add_arguments(parser)`` declares its
options and ``run(args) -> exit code`` calls the library and prints. The harness around them:
:mod:`.parser` (the parser, the global options, the command a command line names),
:mod:`.console` (the log, the grouped warnings, -q, progress lines), :mod:`.runtime` (the
process: exit, malloc, open3d's import, the environment, the Dask client); the options several
commands share are in :mod:`.scene_flags`, :mod:`.correction_flags` and :mod:`.texture_flags`.
"""

from __future__ import annotations

import sys

from ..errors import InputError
from .console import WarningLog as WarningLog
from .console import _logging, _quiet
from .parser import COMMANDS as COMMANDS
from .parser import build_parser as build_parser
from .parser import command_of as command_of
from .runtime import MALLOC_ARENAS as MALLOC_ARENAS
from .runtime import _client, _environment_problem, _executor, _freeze_at_exit
from .runtime import _fewer_malloc_arenas as _fewer_malloc_arenas
from .runtime import _open3d_without_dash as _open3d_without_dash


def console_main() -> None:
    """The ``o3d-seqcc`` console script and ``python -m o3d_seqcc``: :func:`main` on ``sys.argv``, then exit.

    After Ctrl-C, SIGTERM or SIGHUP (exit codes 128 and above) the process runs Python's exit handlers, flushes its
    streams and ends with that code there, before the C++ libraries' static destructors: Open3D's
    (``MemoryManagerStatistic``) ends a process that still holds tensor allocations with exit status 1, and a
    stage cut short leaves some held (the frames of its traceback, kept by :func:`.runtime._freeze_at_exit`;
    4 runs in 10 of ``correct`` interrupted at 0.9 s under load exited 1 instead of 130). Other exits are
    ``sys.exit``'s, as before.
    """
    code = main()
    if code >= 128:
        import atexit
        import os

        atexit._run_exitfuncs()
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):  # a closed or broken stream: nothing more to say
                pass
        os._exit(code)
    sys.exit(code)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the command line (the console script calls it through :func:`console_main`); returns the
    exit code."""
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


def _main(argv: list[str] | None) -> int:
    """Parse ``argv``, run its command in the log, -q, jobs, progress and scheduler set-up; errors as exit codes
    (2: bad input or usage, 1: a file system error, 130: interrupted)."""
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
        from .console import progress_from_args

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
    console_main()
