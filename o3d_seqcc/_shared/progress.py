"""Progress reporting: the library marks its long loops, the command line decides whether to show them.

Library code wraps the loops that can take more than a second in :func:`track` (an iterable)
or :func:`steps` (named steps of one stage); nothing is shown unless a caller turned progress
on with :func:`show_progress` (the ``o3d-seqcc`` command does when stderr is a terminal and
``-q`` is not given). Bars are tqdm's, on stderr, and vanish when done.

For programs that run ``o3d-seqcc`` as a child process (the MeshLab plugin), :func:`progress_lines`
writes the same events as machine-readable lines instead (``o3d-seqcc --progress-lines``)::

    o3d-seqcc-progress PERCENT TEXT

``PERCENT`` is an integer 0-100 that never decreases, the share of the command's work done
(its stages weighted by a plan, e.g. :data:`RUN_PLAN`); ``TEXT`` is the stage and, inside a
loop, ``desc i/n`` (``o3d-seqcc-progress 37 correction: fit edges 4/9``). Lines are written at
each stage start and when the integer percent or the step changes (at most 10 a second).
"""

from __future__ import annotations

import contextvars
import shutil
import sys
import threading
import time
from contextlib import contextmanager
from typing import Iterable, Iterator, Sequence, TextIO, TypeVar

__all__ = ["CORRECT_PLAN", "LINE_PREFIX", "PLANS", "RUN_PLAN", "TEXTURE_PLAN", "on_stage", "progress_lines",
           "show_progress", "stage", "steps", "track"]

T = TypeVar("T")

_ENABLED: contextvars.ContextVar[bool] = contextvars.ContextVar("o3d_seqcc_progress", default=False)

#: prefix of the machine-readable progress lines (:func:`progress_lines`)
LINE_PREFIX = "o3d-seqcc-progress"
#: stages of ``run`` and their shares of its time (the 16k-face Fountain run's stage timings; export includes the report)
RUN_PLAN: tuple[tuple[str, float], ...] = (("visibility", 12), ("mappings", 3), ("correction", 22), ("selection", 5),
                                           ("bake", 30), ("seams", 3), ("export", 25))
#: stages of ``texture``
TEXTURE_PLAN: tuple[tuple[str, float], ...] = (("visibility", 15), ("selection", 7), ("bake", 42), ("seams", 4),
                                               ("export", 32))
#: stages of ``correct`` (the mappings stage computes the visibility too; metrics = Table 2 of the report)
CORRECT_PLAN: tuple[tuple[str, float], ...] = (("mappings", 20), ("correction", 40), ("metrics", 15), ("export", 25))
#: command -> plan (``o3d-seqcc COMMAND --progress-lines``)
PLANS = {"run": RUN_PLAN, "texture": TEXTURE_PLAN, "correct": CORRECT_PLAN}


class _LineReporter:
    """Writes :func:`progress_lines`' lines: stage starts and loop steps mapped onto the plan's percent."""

    def __init__(self, stream: TextIO, plan: Sequence[tuple[str, float]]) -> None:
        self.stream = stream
        total = float(sum(w for _, w in plan)) or 1.0
        self.span: dict[str, tuple[float, float]] = {}
        done = 0.0
        for n, w in plan:
            self.span[n] = (100.0 * done / total, 100.0 * w / total)
            done += w
        self.stage = ""
        self.percent = 0
        self.last: tuple[int, str] | None = None
        self.last_time = 0.0
        self.lock = threading.Lock()

    def emit(self, percent: float, text: str, *, force: bool = False) -> None:
        with self.lock:
            self.percent = max(self.percent, min(100, int(percent)))
            now = time.monotonic()
            key = (self.percent, text)
            if key == self.last or (not force and self.last is not None and self.last[0] == self.percent
                                    and now - self.last_time < 0.1):
                return
            self.last, self.last_time = key, now
            self.stream.write(f"{LINE_PREFIX} {self.percent} {text}\n")
            self.stream.flush()

    def start(self, name: str) -> None:
        self.stage = name
        if name in self.span:
            self.emit(self.span[name][0], name, force=True)
        else:  # a stage outside the plan: report it, percent unchanged
            self.emit(self.percent, name, force=True)

    def end(self, name: str) -> None:
        if name in self.span:
            s0, w = self.span[name]
            self.emit(s0 + w, f"{name} done")

    def step(self, desc: str, i: int, total: int | None, name: str = "") -> None:
        s0, w = self.span.get(self.stage, (self.percent, 0.0))
        frac = min(1.0, i / total) if total else 0.0
        what = " ".join(x for x in (desc if desc != self.stage else "", name) if x)
        count = f"{i}/{total}" if total else str(i)
        head = f"{self.stage}:" if self.stage and what else self.stage
        self.emit(s0 + w * frac, " ".join(x for x in (head, what, count) if x))


_LINES: contextvars.ContextVar[_LineReporter | None] = contextvars.ContextVar("o3d_seqcc_progress_lines",
                                                                             default=None)


@contextmanager
def progress_lines(stream: TextIO | None, plan: Sequence[tuple[str, float]] = ()) -> Iterator[None]:
    """Write machine-readable progress lines (module docstring) to ``stream`` inside the block.

    Parameters
    ----------
    stream : text stream or None
        Where to write (the CLI: ``sys.stderr``); None turns nothing on.
    plan : sequence of (str, float)
        The stages the block runs, in order, with their relative weights (:data:`RUN_PLAN`,
        :data:`TEXTURE_PLAN`, :data:`CORRECT_PLAN`); stages outside it are reported without moving
        the percent. The block's end writes ``100 done``.
    """
    if stream is None:
        yield
        return
    rep = _LineReporter(stream, plan)
    token = _LINES.set(rep)
    listener = on_stage(lambda name, event, t: rep.start(name) if event == "start" else rep.end(name))
    try:
        with listener:
            rep.emit(0, "start", force=True)
            yield
        rep.emit(100, "done", force=True)
    finally:
        _LINES.reset(token)


def _reported(iterable: Iterable[T], rep: _LineReporter, desc: str, total: int | None) -> Iterator[T]:
    for i, item in enumerate(iterable):
        yield item
        rep.step(desc, i + 1, total)


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
    """``iterable`` itself, or wrapped in a progress bar when progress is shown (in progress lines when on)."""
    rep = _LINES.get()
    if rep is not None:
        if total is None and hasattr(iterable, "__len__"):
            total = len(iterable)  # type: ignore[arg-type]
        iterable = _reported(iterable, rep, desc, total)
    if not _ENABLED.get():
        return iterable
    from tqdm import tqdm

    return tqdm(iterable, desc=desc, total=total, unit=unit, leave=False, file=sys.stderr, **_size())


class _Steps:
    def __init__(self, bar, desc: str = "", total: int = 0) -> None:
        self._bar = bar
        self._lines = _LINES.get()
        self._desc, self._total, self._done = desc, total, 0

    def __call__(self, name: str) -> None:
        """Start the step ``name`` (the previous one is done)."""
        if self._lines is not None:
            self._lines.step(self._desc, self._done, self._total, name)
            self._done += 1
        if self._bar is not None:
            if self._bar.n or self._bar.postfix:
                self._bar.update(1)
            self._bar.set_postfix_str(name, refresh=True)


@contextmanager
def steps(desc: str, total: int) -> Iterator[_Steps]:
    """A stage of ``total`` named steps; call the yielded object with each step's name as it starts."""
    if not _ENABLED.get():
        yield _Steps(None, desc, total)
        return
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit="step", leave=False, file=sys.stderr, **_size())
    try:
        yield _Steps(bar, desc, total)
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
