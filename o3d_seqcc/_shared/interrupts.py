"""SIGTERM and SIGHUP handled like Ctrl-C: what cleans up after a KeyboardInterrupt cleans up after them.

``docker stop``, systemd and a closed terminal send SIGTERM / SIGHUP, whose default action ends the
process at once: a staging folder and a lock would be left beside an output.
:func:`interruptible` turns them into :class:`Terminated` (a ``KeyboardInterrupt``) for the time
of a block; :func:`o3d_seqcc.io.output.output_folder` and the command line enter it.
:func:`held` makes a short block whole: a signal that arrives inside it is raised when it ends
(``ThreadPoolExecutor.submit`` interrupted inside ``Thread.start`` leaves a running worker that
``shutdown(wait=True)`` does not join: it went on writing into a staging folder being removed).
"""

from __future__ import annotations

import _thread
import signal
import threading
from contextlib import contextmanager
from typing import Iterator

__all__ = ["Terminated", "held", "interruptible"]

_HOLD = {"depth": 0, "pending": None}  # held() blocks open in the main thread; the signal that came in one


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised in the main thread like Ctrl-C's KeyboardInterrupt (``signum`` says which)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = int(signum)

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name


def _interrupt(signum: int) -> KeyboardInterrupt:
    return KeyboardInterrupt() if signum == signal.SIGINT else Terminated(signum)


#: how long a signal that arrived where its exception would be dropped waits before it is delivered again (s)
REDELIVER_S = 0.01


def _dropped_here(frame) -> bool:
    """Whether an exception raised at ``frame`` would be printed and dropped instead of propagated.

    Python calls weakref callbacks from C, and an exception raised inside one is reported as
    "Exception ignored in ..." and dropped. importlib's module locks have one (``_get_module_lock``'s
    ``cb``), so a Ctrl-C that lands in it while a module is imported printed a traceback, and the
    command went on as if nothing had happened.
    """
    while frame is not None:
        code = frame.f_code
        if code.co_name == "cb" and code.co_filename.startswith("<frozen importlib"):
            return True
        frame = frame.f_back
    return False


def _raise_terminated(signum: int, frame) -> None:
    if _HOLD["depth"]:  # inside held(): raised when the block ends
        _HOLD["pending"] = int(signum)
        return
    if _dropped_here(frame):  # delivered again a moment later, once out of the callback
        threading.Timer(REDELIVER_S, _thread.interrupt_main, args=(int(signum),)).start()
        return
    raise _interrupt(signum)


@contextmanager
def held() -> Iterator[None]:
    """A signal that would interrupt the block (Ctrl-C's SIGINT; SIGTERM / SIGHUP inside
    :func:`interruptible`) is raised when the block ends instead, as ``KeyboardInterrupt`` /
    :class:`Terminated`.

    For a few statements that must not be cut in two, such as starting the threads that write into
    a staging folder (so that every one of them is joined before the folder is removed). Only in the
    main thread (signals are handled there); a program's own SIGINT handler is kept. Re-entrant.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    saved = signal.signal(signal.SIGINT, _raise_terminated) \
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler else None
    _HOLD["depth"] += 1
    try:
        yield
    finally:
        _HOLD["depth"] -= 1
        if saved is not None:
            signal.signal(signal.SIGINT, saved)
        if not _HOLD["depth"] and _HOLD["pending"] is not None:
            pending, _HOLD["pending"] = _HOLD["pending"], None
            raise _interrupt(pending)


@contextmanager
def interruptible() -> Iterator[None]:
    """SIGTERM and SIGHUP raise :class:`Terminated` (a KeyboardInterrupt) inside the block, so that what
    cleans up after Ctrl-C (the staging folder, the lock) cleans up after them too.

    Ctrl-C still raises KeyboardInterrupt, but never where Python would drop it (inside importlib's
    module-lock callback, see :func:`_dropped_here`): there it is raised again 10 ms later.
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
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # Ctrl-C: KeyboardInterrupt, never dropped
        saved[signal.SIGINT] = signal.signal(signal.SIGINT, _raise_terminated)
    try:
        yield
    finally:
        for sig, old in saved.items():
            signal.signal(sig, old)
