"""SIGTERM and SIGHUP handled like Ctrl-C: what cleans up after a KeyboardInterrupt cleans up after them.

``docker stop``, systemd and a closed terminal send SIGTERM / SIGHUP, whose default action ends the
process at once: a staging folder and a lock would be left beside an output.
:func:`interruptible` turns them into :class:`Terminated` (a ``KeyboardInterrupt``) for the time
of a block; :func:`o3d_seqcc.io.output.output_folder` and the command line enter it.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Iterator

__all__ = ["Terminated", "interruptible"]


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised in the main thread like Ctrl-C's KeyboardInterrupt (``signum`` says which)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = int(signum)

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name


def _raise_terminated(signum: int, frame) -> None:
    raise Terminated(signum)


@contextmanager
def interruptible() -> Iterator[None]:
    """SIGTERM and SIGHUP raise :class:`Terminated` (a KeyboardInterrupt) inside the block, so that what
    cleans up after Ctrl-C (the staging folder, the lock) cleans up after them too.

    Only in the main thread, and only for signals whose handler is the default one (a SIGHUP that
    ``nohup`` ignores stays ignored; a program's own handlers are kept). Re-entrant.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    saved = {}
    for sig in (getattr(signal, "SIGTERM", None), getattr(signal, "SIGHUP", None)):
        if sig is not None and signal.getsignal(sig) is signal.SIG_DFL:
            saved[sig] = signal.signal(sig, _raise_terminated)
    try:
        yield
    finally:
        for sig, old in saved.items():
            signal.signal(sig, old)
