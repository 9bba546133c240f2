"""The ``o3d-seqcc`` command line.

Each sub-command lives in its own module of this package and exposes
``register(subparsers) -> argparse.ArgumentParser`` that sets ``func`` (a callable taking the
parsed ``argparse.Namespace`` and returning an exit code) with ``set_defaults``.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from ..errors import InputError

# sub-command modules, in the order --help lists them
COMMANDS: tuple[str, ...] = ("info", "mappings", "correct", "seams", "evaluate", "texture", "run", "demo", "synthetic")


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="o3d-seqcc",
        description="Sequential pairwise colour correction and texture mapping of registered photos onto a mesh.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    parser.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")
    parser.add_argument(
        "-j", "--jobs", type=int, default=-1,
        help="parallel workers (joblib threads) for per-view and per-edge work (default -1: all cores)",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``o3d-seqcc`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING if args.quiet else (logging.INFO if args.verbose <= 1 else logging.DEBUG)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    from joblib import parallel_config

    try:
        with parallel_config(n_jobs=args.jobs):
            return int(args.func(args) or 0)
    except InputError as e:
        print(f"o3d-seqcc {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
