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
        mod = importlib.import_module(f"{__name__}.{name}")
        doc = (mod.__doc__ or "").strip()
        p = sub.add_parser(name, help=doc.split("\n", 1)[0].rstrip("."), description=doc,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        mod.add_arguments(p)
        p.set_defaults(func=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``o3d-seqcc`` console script; returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse: --help (0) or a usage error (2, message already printed)
        return int(e.code or 0)
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
