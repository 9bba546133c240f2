"""The ``o3d-seqcc`` parser: the global options, one sub-command per command module, and the one
command a command line names (so only that command's modules are imported)."""

from __future__ import annotations

import argparse
import importlib
from typing import Sequence

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
        mod = importlib.import_module(f"{__package__}.{name}")
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
