"""What a command writes on the terminal besides its results: its log, the library's warnings grouped
one line per kind at its end, -q's silence, and ``--progress-lines``."""

from __future__ import annotations

import argparse
import logging
import os
import re
import sys
import warnings
from contextlib import contextmanager, redirect_stdout
from typing import Iterator


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


def add_progress_argument(p: argparse.ArgumentParser) -> None:
    """``--progress-lines``: machine-readable progress on stderr (``run``, ``texture``, ``correct``)."""
    from .._shared.progress import LINE_PREFIX

    p.add_argument("--progress-lines", action="store_true",
                   help=f"write machine-readable progress lines to stderr, '{LINE_PREFIX} PERCENT TEXT' (PERCENT an "
                   "integer 0-100 that never decreases), for programs that run this command (the MeshLab plugin)")


def progress_from_args(args: argparse.Namespace):
    """The :func:`o3d_seqcc._shared.progress.progress_lines` context of ``--progress-lines`` (a no-op without it),
    with the command's plan (:data:`o3d_seqcc._shared.progress.PLANS`)."""
    import sys

    from .._shared.progress import PLANS, progress_lines

    on = getattr(args, "progress_lines", False)
    return progress_lines(sys.stderr if on else None, PLANS.get(getattr(args, "command", ""), ()))
