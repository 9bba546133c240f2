"""xatlas in child processes (issue 21): the packing beside the caller, and a page packed beside the first call.

xatlas holds the interpreter for its whole call, so a thread cannot run next to it; a child process
can. :func:`pack_charts_beside` runs :func:`~o3d_seqcc.texturing.packing.pack_charts` in one while
the bake solves the seam leveling (neither needs the other); inside it, :func:`speculative_page`
packs in a second child the page that a sure second xatlas call will want, beside the first. Both
give the packing :func:`~o3d_seqcc.texturing.packing.pack_charts` gives, byte for byte.
"""

from __future__ import annotations

import logging
import os

import numpy as np

from ..errors import InputError, warn
from .packing import Packing, _pack_charts, _Packer, _sizes, pack_charts
from .settings import TextureSettings

__all__ = ["BESIDE_MIN_FACES", "pack_charts_beside", "pack_speculating", "speculative_page"]

logger = logging.getLogger("o3d_seqcc.texturing.packing")  # the packing's records, wherever they are made


#: charts' faces from which :func:`pack_charts_beside` packs in a child process (below, xatlas takes less time than
#: starting one: about 0.15 s of interpreter and imports)
BESIDE_MIN_FACES = 60_000


class _Packed:
    """A packing under way: :meth:`result` gives the :class:`Packing` (re-raising the packer's error, re-emitting its
    warnings and log records here)."""

    def __init__(self, run, cancel=None) -> None:
        self._run, self._cancel = run, cancel
        self._value = None

    def result(self) -> Packing:
        if self._value is None:
            self._value = self._run()
        return self._value

    def cancel(self) -> None:
        """Stop the child if it still runs (its result is not wanted)."""
        if self._cancel is not None and self._value is None:
            try:
                self._cancel()
            except OSError:
                pass


def pack_charts_beside(uv: np.ndarray, faces: np.ndarray, chart: np.ndarray, *, beside: bool = True,
                       **options) -> _Packed:
    """:func:`pack_charts`, started now and run in a child process while the caller goes on.

    The same packing, byte for byte (the child runs :func:`pack_charts` on the same arrays). Inline (at
    :meth:`result`) when ``beside`` is false (one thread asked for), for fewer than :data:`BESIDE_MIN_FACES`
    faces, or when no child process can be started. The child dies with its parent (``PR_SET_PDEATHSIG``)
    and is killed when the caller stops waiting for it (an error, Ctrl-C).

    Returns
    -------
    an object with ``result() -> Packing``
    """
    def inline() -> Packing:
        return pack_charts(uv, faces, chart, **options)

    if not beside or len(faces) < BESIDE_MIN_FACES or set(options) - set(_OPTIONS):
        return _Packed(inline)  # (an unknown option raises there, as pack_charts does)
    # the child has a core of its own while the caller levels seams, and a second one once it waits: it may pack the
    # page a second xatlas call will want beside the first (speculative_page)
    opts = {k: options.get(k, getattr(TextureSettings, k)) for k in _OPTIONS}
    return _beside("pack_speculating", (uv, faces, chart), opts, inline)


def pack_speculating(uv: np.ndarray, faces: np.ndarray, chart: np.ndarray, **options) -> Packing:
    """:func:`~o3d_seqcc.texturing.packing.pack_charts` with a core to spare: the page a sure second xatlas call
    will want is packed beside the first (:func:`speculative_page`); the same packing."""
    import functools

    from .blocks import pack_with_block

    small = {k: int(options.pop(k, getattr(TextureSettings, k))) for k in ("small_charts", "small_padding")}
    return pack_with_block(uv, faces, chart, functools.partial(_pack_charts, speculate=speculative_page), **small,
                           **options)


#: the options of :func:`pack_charts` (their defaults: :class:`TextureSettings`')
_OPTIONS = ("atlas_size", "texels_per_pixel", "overflow", "padding", "power_of_two", "shrink_to_fit", "small_charts",
            "small_padding", "pack_effort")


def _beside(function: str, args: tuple, kwargs: dict, inline, *, sent: bool = False) -> _Packed:
    """This module's ``function(*args, **kwargs)`` in a child process, started now: ``result()`` gives its value
    (re-raising its :class:`InputError`, re-emitting its warnings and log records here), or ``inline()``'s when the
    child cannot start or fails; ``cancel()`` kills it. ``sent``: return once the child has read the call (the
    arguments go through a pipe from a thread of this process, which cannot send while this one holds the
    interpreter, e.g. in xatlas)."""
    import pickle
    import subprocess
    import sys
    import threading

    payload = [pickle.dumps((function, tuple(np.asarray(a) if isinstance(a, np.ndarray) else a for a in args),
                             kwargs), protocol=5)]
    # the child imports what this process imports (its sys.path, not the working folder's modules that ``-c`` would
    # put first), and reads its call before its imports: the pipe is emptied as soon as the interpreter runs
    code = (f"import sys; sys.path[:] = {list(sys.path)!r}; call = sys.stdin.buffer.read(); "
            f"from {__name__} import _child; _child(call)")
    try:
        proc = subprocess.Popen([sys.executable, "-c", code, str(os.getpid())], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    except OSError as exc:
        logger.debug("packing inline: no child process (%s)", exc)
        return _Packed(inline)
    out: dict = {}
    done_sending = threading.Event()

    def talk() -> None:
        try:
            try:
                proc.stdin.write(payload.pop())  # the bytes dropped once sent
                proc.stdin.close()
            finally:
                done_sending.set()
            proc.stdin = None  # closed: communicate() reads the child's output only
            out["stdout"], out["stderr"] = proc.communicate()
        except BaseException as exc:  # noqa: BLE001 - reported by result()
            out["exc"] = exc

    talker = threading.Thread(target=talk, name="o3d_seqcc-pack", daemon=True)
    talker.start()
    if sent:
        done_sending.wait()

    def result():
        try:
            talker.join()
        except BaseException:
            proc.kill()
            raise
        if "exc" in out or proc.returncode != 0 or not out.get("stdout"):
            err = out.get("stderr", b"").decode("utf-8", "replace").strip().splitlines()
            logger.debug("packing child failed (exit %s: %s): packing inline", proc.returncode, err[-1:] or out.get("exc"))
            return inline()
        status, value, notes, records = pickle.loads(out.pop("stdout"))
        for rec in records:
            if logger.isEnabledFor(rec.levelno):  # the level check logging makes before a record exists
                logger.handle(rec)
        for msg in notes:
            warn(msg)
        if status == "error":
            raise value
        return value

    return _Packed(result, cancel=proc.kill)


def _child(call: bytes) -> None:
    """The child of :func:`_beside`: the pickled call (read from stdin), ``(status, value, warnings, log records)``
    pickled on stdout."""
    import logging
    import pickle
    import sys
    import warnings

    _die_with_parent(int(sys.argv[1]))
    function, args, kwargs = pickle.loads(call)
    del call
    records: list = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            record.msg, record.args = record.getMessage(), None
            records.append(record)

    logger.addHandler(Keep())
    logger.setLevel(logging.DEBUG)
    logger.propagate = False
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            res = ("ok", globals()[function](*args, **kwargs))
        except InputError as exc:
            res = ("error", exc)
    notes = [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
    sys.stdout.buffer.write(pickle.dumps((*res, notes, records), protocol=5))
    sys.stdout.buffer.flush()


# --------------------------------------------------------------------------------------------
# a second xatlas call made beside the first: when the unlimited placement cannot be read off the page the charts
# need (a chart as large as the page's slack, e.g. 10 photos of 6 MP: 7469 x 8178 texels and a chart of 4565 on an
# 8192 page), pack_charts packs twice, on an unlimited page and then on the page; which page is known from the first
# call's extents, but those are predictable from the charts' padded boxes: xatlas's extents are 0.87 - 0.95 x the
# square root of their total area (Fountain 16k / 300k, the 6 MP room)

#: xatlas's extents (the square root of width x height) over the square root of the charts' padded boxes' area: the
#: smallest seen, with a margin (a second call is sure when the largest chart does not fit the slack from there), and
#: the guess (the page packed beside is the one it calls for)
_EXTENT_RATIO_LOW, _EXTENT_RATIO_GUESS = 0.8, 0.92


class _Snapshot:
    """What :func:`_result` and :meth:`_Packer.shrunk` read of an ``xatlas.Atlas`` (which does not pickle)."""

    def __init__(self, a) -> None:
        self.width, self.height, self.atlas_count = int(a.width), int(a.height), int(a.atlas_count)
        self._mesh = tuple(np.asarray(x) for x in a[0])
        self._assignment = tuple(np.asarray(x) for x in a.get_mesh_vertex_assignment(0))
        self._utilization = [a.get_utilization(i) for i in range(a.atlas_count)]

    def __getitem__(self, i: int):
        return self._mesh

    def get_mesh_vertex_assignment(self, i: int):
        return self._assignment

    def get_utilization(self, i: int):
        return self._utilization[i]


def _page_snapshot(uv: np.ndarray, faces: np.ndarray, chart: np.ndarray, padding: int, t: float,
                   size: int, effort: str = "fast") -> _Snapshot:
    """``_Packer(uv, faces, chart, padding, effort=effort).pack(t, size)`` (the child of :func:`_speculative_page`)."""
    return _Snapshot(_Packer(uv, faces, chart, padding, effort=effort).pack(t, size))


class _Speculation:
    """A page packed beside: ``size``, ``result()`` (the packing), ``cancel()``."""

    def __init__(self, size: int, packed: _Packed) -> None:
        self.size, self._packed = int(size), packed

    def result(self):
        return self._packed.result()

    def cancel(self) -> None:
        self._packed.cancel()


def speculative_page(pk: _Packer, t: float, N: int, power_of_two: bool) -> _Speculation | None:
    """The page of side S that :func:`pack_charts` will likely pack at density ``t`` after the unlimited placement,
    packed in a child process from now; None unless that second call is sure (the largest chart does not fit the
    slack between the smallest likely extent and S; powers of two only). S is the page the likely extents call for
    (:data:`_EXTENT_RATIO_GUESS`). A wrong guess costs the spare core's time only: the page used is always the one the
    actual extents call for, packed again when it is not S."""
    if not power_of_two or pk.n_charts == 0:
        return None
    boxes = pk.boxes_side(t)
    S = next((s for s in _sizes(N, True, 0.0) if s * 0.98 >= _EXTENT_RATIO_GUESS * boxes), None)
    if S is None or _EXTENT_RATIO_LOW * boxes + 1 + pk.largest_chart(t) <= S:
        return None  # several pages, or the unlimited placement may be read off that page: no second call
    logger.debug("packing: a %dx%d page packed beside the unlimited one", S, S)
    effort = "best" if pk.brute_force else "fast"
    return _Speculation(S, _beside("_page_snapshot", (pk.uv, pk.faces, pk.chart.reshape(-1), pk.padding, t, S, effort), {},
                                   lambda: pk.pack(t, S), sent=True))


def _die_with_parent(parent: int) -> None:
    """Linux: this process gets SIGKILL when its parent ends (``prctl(PR_SET_PDEATHSIG)``); it exits now when the
    parent has already gone."""
    import ctypes
    import ctypes.util
    import signal

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent:
        os._exit(1)
