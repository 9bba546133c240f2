"""Where the per-view and per-edge work runs: local threads, or a Dask cluster.

The pipeline's heavy work is a graph of independent tasks: visibility per view, pairwise
mappings + joint image histogram + colour mapping function fit per graph edge, image encoding
per view. An *executor* runs a list of such tasks and returns their results **in the order of
the inputs** (never in completion order), so a run is deterministic whatever runs it:

- :class:`LocalExecutor` (the default): joblib threads in this process (``n_jobs``, joblib
  semantics: None = the active ``joblib.parallel_config`` or 1, -1 = all cores);
- :class:`DaskExecutor`: the tasks of a ``dask.distributed.Client``'s cluster. Shared inputs
  (the mesh geometry, the visibility records, a correction method's closure) are scattered to
  every worker once (:meth:`DaskExecutor.share`); each task then carries a view or an edge
  index. Workers read the scene's files themselves, so the scene's paths must resolve on every
  worker (a shared NFS folder or an object store mounted at the same path). A task that raises
  is retried ``retries`` times (transient file-system errors); a worker that dies has its tasks
  rescheduled on the others by the scheduler (``distributed.scheduler.allowed-failures``).

The library functions pick up the active executor (:func:`current`); enter one with
:func:`use`::

    from dask.distributed import Client, LocalCluster
    import o3d_seqcc as sc

    with LocalCluster(n_workers=2, threads_per_worker=1) as cluster, Client(cluster) as client:
        res = sc.pipeline.run("scene.json", client=client)   # or: with sc.parallel.use(client): ...
"""

from __future__ import annotations

import contextvars
import logging
import threading
import uuid
from contextlib import contextmanager
from typing import Any, Callable, Iterable, Iterator, Sequence

from ..errors import InputError, require
from .progress import track

__all__ = ["DaskExecutor", "LocalExecutor", "SCHEDULER_ENV", "carried", "connect", "current", "thread_map", "use"]

logger = logging.getLogger(__name__)

#: environment variable with the Dask scheduler address used when ``--scheduler`` is not given
SCHEDULER_ENV = "O3D_SEQCC_SCHEDULER"

_CURRENT: contextvars.ContextVar[Any] = contextvars.ContextVar("o3d_seqcc_executor", default=None)


class LocalExecutor:
    """Tasks in joblib threads of this process.

    Parameters
    ----------
    n_jobs : int, optional
        joblib semantics: None = the active ``joblib.parallel_config`` (the command line's
        ``-j``) or 1; -1 = all cores.
    """

    kind = "local"

    def __init__(self, n_jobs: int | None = None) -> None:
        self.n_jobs = n_jobs

    def share(self, obj: Any) -> Any:
        """The object itself (threads share memory)."""
        return obj

    def threads(self) -> int:
        """The number of threads ``n_jobs`` stands for (the active ``joblib.parallel_config`` when None)."""
        from joblib import cpu_count
        from joblib.parallel import get_active_backend

        n = self.n_jobs if self.n_jobs is not None else get_active_backend()[1]
        n = 1 if n is None else int(n)
        return max(1, cpu_count() + 1 + n if n < 0 else n)

    def imap(self, fn: Callable, items: Sequence, *args: Any, desc: str = "tasks", unit: str = "task") -> Iterator:
        """``fn(item, *args)`` for every item, yielded in the order of ``items``."""
        from joblib import Parallel, delayed

        items = list(items)
        if not items:
            return iter(())
        n = self.threads()
        if n == 1:
            return iter(track((fn(item, *args) for item in items), desc=desc, total=len(items), unit=unit))
        guard = _InFlight()
        # n_jobs resolved here: joblib's Parallel(n_jobs=None, prefer="threads") ignores parallel_config's n_jobs
        gen = Parallel(n_jobs=n, prefer="threads", return_as="generator")(
            delayed(guard.run)(fn, item, *args) for item in items)
        return guard.drain(track(gen, desc=desc, total=len(items), unit=unit))

    def map(self, fn: Callable, items: Sequence, *args: Any, desc: str = "tasks", unit: str = "task") -> list:
        """``[fn(item, *args) for item in items]``, computed in parallel."""
        return list(self.imap(fn, items, *args, desc=desc, unit=unit))

    def __repr__(self) -> str:
        return f"LocalExecutor(n_jobs={self.n_jobs})"


class _InFlight:
    """Tasks of one :meth:`LocalExecutor.imap`, so that none is still running when it raises.

    joblib stops dispatching after a task raises (or the consumer stops), but the tasks already
    running in its threads go on; if the exception then ends the program, the interpreter shuts
    down under native code still running in them (Open3D, OpenCV), which aborts with
    "terminate called without an active exception". Here the tasks not yet started return at
    once and the error waits for the running ones to finish.
    """

    def __init__(self) -> None:
        self._cv = threading.Condition()
        self._running = 0
        self._stopped = False

    def run(self, fn: Callable, *args: Any) -> Any:
        with self._cv:
            if self._stopped:
                return None
            self._running += 1
        try:
            return fn(*args)
        finally:
            with self._cv:
                self._running -= 1
                self._cv.notify_all()

    def drain(self, results: Iterator) -> Iterator:
        try:
            yield from results
        except BaseException:
            self.stop()
            raise
        finally:
            self.stop()

    def stop(self) -> None:
        with self._cv:
            self._stopped = True
            while self._running:
                self._cv.wait(0.1)


class DaskExecutor:
    """Tasks on the workers of a ``dask.distributed.Client``.

    Parameters
    ----------
    client : dask.distributed.Client
    retries : int, default 2
        Extra attempts of a task that raises (a worker that dies is handled by the scheduler,
        not by this count).
    """

    kind = "dask"

    def __init__(self, client: Any, *, retries: int = 2) -> None:
        self.client = client
        self.retries = int(retries)

    def share(self, obj: Any) -> Any:
        """Scatter ``obj`` to every worker once; pass the returned future as a task argument."""
        return self.client.scatter(obj, broadcast=True, hash=False)

    def imap(self, fn: Callable, items: Sequence, *args: Any, desc: str = "tasks", unit: str = "task") -> Iterator:
        """``fn(item, *args)`` for every item on the cluster, yielded in the order of ``items``.

        Results stream back as tasks finish; a result is released by the client as soon as it
        has been yielded.
        """
        from distributed import as_completed

        items = list(items)
        if not items:
            return
        tag = f"o3d_seqcc-{desc.replace(' ', '_')}-{uuid.uuid4().hex[:8]}"
        futures = [self.client.submit(fn, item, *args, key=f"{tag}-{i}", pure=False, retries=self.retries)
                   for i, item in enumerate(items)]
        index = {f.key: i for i, f in enumerate(futures)}
        done: dict[int, Any] = {}
        nxt = 0
        try:
            done_order = as_completed(futures, loop=self.client.loop)
            for fut in track(done_order, desc=desc, total=len(futures), unit=unit):
                done[index[fut.key]] = fut.result()
                futures[index[fut.key]] = None
                while nxt in done:
                    yield done.pop(nxt)
                    nxt += 1
        finally:
            for f in futures:
                if f is not None:
                    f.cancel()

    def map(self, fn: Callable, items: Sequence, *args: Any, desc: str = "tasks", unit: str = "task") -> list:
        """``[fn(item, *args) for item in items]`` on the cluster, in the order of ``items``."""
        return list(self.imap(fn, items, *args, desc=desc, unit=unit))

    def __repr__(self) -> str:
        return f"DaskExecutor({self.client!r})"


def carried(fn: Callable, timed: str | None = None) -> Callable:
    """``fn`` to run on another thread as if here: the active executor (:func:`use`), the progress
    settings and joblib's ``n_jobs`` (``parallel_config``, which joblib keeps per thread) go with it.

    Wrap at submission, once per task (``pool.submit(carried(fn), ...)``): each call copies this
    thread's context. ``timed``: a name under which the call's seconds are logged at DEBUG.
    """
    import contextvars
    import time

    from joblib import parallel_config
    from joblib.parallel import get_active_backend

    ctx, n_jobs = contextvars.copy_context(), get_active_backend()[1]

    def run(*args: Any, **kwargs: Any) -> Any:
        t = time.perf_counter()
        try:
            with parallel_config(n_jobs=n_jobs):
                return ctx.run(fn, *args, **kwargs)
        finally:
            if timed is not None:
                logger.debug("%s: %.3f s", timed, time.perf_counter() - t)

    return run


def thread_map(fn: Callable, items: Iterable, threads: int, *, name: str = "o3d_seqcc-threads") -> list:
    """``[fn(item) for item in items]`` on up to ``threads`` threads of this process, in the order of ``items``.

    For array work in bands or chunks that releases the interpreter (numpy, OpenCV); each task runs
    with this thread's context (:func:`carried`). With one thread or one item, here and in order.
    """
    items = list(items)
    if threads <= 1 or len(items) <= 1:
        return [fn(it) for it in items]
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=int(threads), thread_name_prefix=name) as pool:
        futures = [pool.submit(carried(fn), it) for it in items]  # one carried context per task
        return [f.result() for f in futures]


def current(n_jobs: int | None = None) -> LocalExecutor | DaskExecutor:
    """The executor entered with :func:`use`, else local threads with ``n_jobs``."""
    ex = _CURRENT.get()
    return ex if ex is not None else LocalExecutor(n_jobs)


def _as_executor(target: Any) -> LocalExecutor | DaskExecutor | None:
    if target is None or isinstance(target, (LocalExecutor, DaskExecutor)):
        return target
    if hasattr(target, "scatter") and hasattr(target, "submit"):  # a dask.distributed.Client
        return DaskExecutor(target)
    raise InputError(f"client must be a dask.distributed.Client, an executor or None, got {target!r:.60} "
                     f"({type(target).__name__})")


@contextmanager
def use(target: Any) -> Iterator[LocalExecutor | DaskExecutor | None]:
    """Run the library's per-view and per-edge tasks on ``target`` inside the ``with`` block.

    Parameters
    ----------
    target : dask.distributed.Client, LocalExecutor, DaskExecutor or None
        None keeps the current choice (local threads unless an outer block chose otherwise).
    """
    ex = _as_executor(target)
    if ex is None:
        yield _CURRENT.get()
        return
    token = _CURRENT.set(ex)
    try:
        yield ex
    finally:
        _CURRENT.reset(token)


def connect(address: str, *, timeout: float = 10.0, option: str = "--scheduler") -> Any:
    """A ``dask.distributed.Client`` connected to the scheduler at ``address``.

    Parameters
    ----------
    address : str
        ``tcp://HOST:8786`` (``dask scheduler`` prints it).
    timeout : float, default 10.0
        Seconds to wait for the scheduler.
    option : str
        How the caller named the address (in the error message).

    Raises
    ------
    InputError
        ``dask.distributed`` is not installed, or no scheduler answers at ``address``.
    """
    import socket

    Client = require("distributed", extra="dask", what=f"{option} (a Dask cluster)").Client
    from distributed.comm.addressing import parse_address, parse_host_port

    address = str(address).strip()
    hint = (f"start one with `dask scheduler` and workers with `dask worker {address}`, or drop {option} "
            f"(and unset {SCHEDULER_ENV}) to run on this machine")
    try:
        scheme, loc = parse_address(address if "://" in address else f"tcp://{address}")
        host, port = parse_host_port(loc)
        if port is None:
            raise ValueError(f"no port in {address!r}")
    except (ValueError, TypeError) as e:
        raise InputError(f"{option} {address!r}: not a scheduler address ({e}); give tcp://HOST:8786") from None
    if scheme in ("tcp", "tls"):  # fail fast, before Dask's own retries, when nothing listens there
        try:
            socket.create_connection((host, int(port)), timeout=timeout).close()
        except OSError as e:
            raise InputError(f"{option} {address}: cannot reach a Dask scheduler ({e}); {hint}") from None
    try:
        client = Client(address, timeout=timeout, set_as_default=False)
    except Exception as e:  # whatever answered is not a working scheduler
        raise InputError(f"{option} {address}: no Dask scheduler answered within {timeout:g} s "
                         f"({type(e).__name__}: {e}); {hint}") from None
    n = len(client.scheduler_info().get("workers", {}))
    logger.info("connected to the Dask scheduler at %s (%d workers)", address, n)
    if n == 0:
        logger.warning("the Dask scheduler at %s has no workers yet: tasks wait until one joins", address)
    return client

