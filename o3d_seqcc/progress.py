"""Progress reporting: the library marks its long loops, the command line decides whether to show them.

Library code wraps the loops that can take more than a second in :func:`track` (an iterable)
or :func:`steps` (named steps of one stage); nothing is shown unless a caller turned progress
on with :func:`show_progress` (the ``o3d-seqcc`` command does when stderr is a terminal and
``-q`` is not given). Bars are tqdm's, on stderr, and vanish when done.
"""

from __future__ import annotations

import contextvars
import shutil
import sys
from contextlib import contextmanager
from typing import Iterable, Iterator, TypeVar

__all__ = ["on_stage", "show_progress", "stage", "steps", "track"]

T = TypeVar("T")

_ENABLED: contextvars.ContextVar[bool] = contextvars.ContextVar("o3d_seqcc_progress", default=False)


@contextmanager
def show_progress(enabled: bool = True) -> Iterator[None]:
    """Show progress bars for the library's long loops inside the ``with`` block."""
    token = _ENABLED.set(bool(enabled))
    try:
        yield
    finally:
        _ENABLED.reset(token)


def _size() -> dict[str, int]:
    """The terminal's size for tqdm (100 x 24 when it reports none, e.g. a fresh pseudo-terminal)."""
    size = shutil.get_terminal_size((100, 24))
    return {"ncols": size.columns, "nrows": size.lines}


def track(iterable: Iterable[T], *, desc: str, total: int | None = None, unit: str = "it") -> Iterable[T]:
    """``iterable`` itself, or wrapped in a progress bar when progress is shown."""
    if not _ENABLED.get():
        return iterable
    from tqdm import tqdm

    return tqdm(iterable, desc=desc, total=total, unit=unit, leave=False, file=sys.stderr, **_size())


class _Steps:
    def __init__(self, bar) -> None:
        self._bar = bar

    def __call__(self, name: str) -> None:
        """Start the step ``name`` (the previous one is done)."""
        if self._bar is not None:
            if self._bar.n or self._bar.postfix:
                self._bar.update(1)
            self._bar.set_postfix_str(name, refresh=True)


@contextmanager
def steps(desc: str, total: int) -> Iterator[_Steps]:
    """A stage of ``total`` named steps; call the yielded object with each step's name as it starts."""
    if not _ENABLED.get():
        yield _Steps(None)
        return
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit="step", leave=False, file=sys.stderr, **_size())
    try:
        yield _Steps(bar)
        bar.update(total - bar.n)
    finally:
        bar.close()


_LISTENERS: contextvars.ContextVar[tuple] = contextvars.ContextVar("o3d_seqcc_stage_listeners", default=())


@contextmanager
def on_stage(callback) -> Iterator[None]:
    """Call ``callback(name, event, time)`` as the pipeline's stages start and end in the block.

    ``event`` is ``"start"`` or ``"end"``; ``time`` is ``time.perf_counter()``. For profilers
    and benchmarks (``benchmarks/scale.py`` samples memory per stage with it).
    """
    token = _LISTENERS.set(_LISTENERS.get() + (callback,))
    try:
        yield
    finally:
        _LISTENERS.reset(token)


@contextmanager
def stage(name: str, timings: dict | None = None) -> Iterator[None]:
    """A pipeline stage: its duration goes to ``timings[name]``; :func:`on_stage` listeners hear of it."""
    import time

    t0 = time.perf_counter()
    for cb in _LISTENERS.get():
        cb(name, "start", t0)
    try:
        yield
    finally:
        t1 = time.perf_counter()
        if timings is not None:
            timings[name] = t1 - t0
        for cb in _LISTENERS.get():
            cb(name, "end", t1)
