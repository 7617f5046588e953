"""Threads for the compiled kernels, each run by a kernel that releases the GIL (numba ``nogil=True``): a large
batch split into contiguous chunks (:func:`in_chunks`), or a few items of unequal cost handed out one at a
time (:func:`in_turns`); and, across processes, the Dask client a command's tasks run on (:func:`dask_client`).

The filter steps (:mod:`shipsense.trackers.filters.fused`), the tracker's step, the grid search, the
Levenberg-Marquardt fits and the fast HED field (:mod:`shipsense.physics.electric`) treat every element
independently, so a split changes no result; it only spreads the work over the CPUs this process may use
(``SHIPSENSE_THREADS`` overrides; 1 keeps every step on the calling thread).
"""

from __future__ import annotations

import os
import threading
from contextlib import contextmanager

from shipsense.errors import ShipsenseError

SPLIT_MIN = 512
"""Batches of at least this many elements are split (chunks of at least half of it: a chunk is then hundreds
of microseconds of work, and handing one to a thread costs tens of microseconds)."""

_pool = None
_background = None
_local = threading.local()


def threads() -> int:
    """Threads a large batch is split across: 1 inside :func:`serial`; else ``SHIPSENSE_THREADS`` if set, else the
    CPUs this process may use -- one fewer (at least 1) while the :func:`background` thread has work, whose CPU
    that is (a split waiting on a chunk that shares a CPU with it leaves its own CPU idle: Passage-v1's vector
    env, 64 envs, 16.0-16.5k env-steps/s splitting over both CPUs, 17.3-18.2k with the background's spared)."""
    if getattr(_local, "serial", False):
        return 1
    count = configured_threads()
    if _background is not None and _background[0] == os.getpid() and _background[1].busy:
        count = max(1, count - 1)
    return count


def configured_threads() -> int:
    """``SHIPSENSE_THREADS`` if set, else the CPUs this process may use (:func:`threads` before it spares the
    background's CPU)."""
    value = os.environ.get("SHIPSENSE_THREADS", "").strip()
    if value:
        try:
            count = int(value)
        except ValueError:
            count = 0
        if count < 1:
            raise ShipsenseError(f"the environment variable SHIPSENSE_THREADS must be a whole number >= 1, "
                                 f"got {value!r}")
        return count
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:    # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _executor():
    """The process's pool of threads (a forked child has the pool object but not its threads: a new one)."""
    global _pool
    if _pool is None or _pool[0] != os.getpid():
        from concurrent.futures import ThreadPoolExecutor

        _pool = (os.getpid(), ThreadPoolExecutor(thread_name_prefix="shipsense"))
    return _pool[1]


@contextmanager
def serial():
    """Run every split of this thread on this thread (:func:`threads` is 1 here): for work done beside another
    thread's (:func:`background`), where splitting it would only make the two wait on each other's chunks."""
    before = getattr(_local, "serial", False)
    _local.serial = True
    try:
        yield
    finally:
        _local.serial = before


def background_allowed() -> bool:
    """Whether this thread may leave work to :func:`background`: more than one thread configured
    (:func:`configured_threads`; ``SHIPSENSE_THREADS=1`` keeps everything on the calling thread), and not inside
    :func:`serial` (the background's own work does not queue more)."""
    return not getattr(_local, "serial", False) and configured_threads() > 1


def background():
    """The process's one background thread (a forked child gets its own): ``background().submit(fn)`` returns a
    :class:`~concurrent.futures.Future` of ``fn()``, run in turn.  For work a caller will need later, done
    meanwhile under :func:`serial` (e.g. Passage-v1's next run-ins).  A daemon thread: work still queued when
    the interpreter exits is dropped, not waited for."""
    global _background
    if _background is None or _background[0] != os.getpid():
        _background = (os.getpid(), _Background())
    return _background[1]


class _Background:
    def __init__(self):
        import queue

        self._queue = queue.SimpleQueue()
        self._lock = threading.Lock()
        self.busy = 0                      # work submitted and not yet done or cancelled
        threading.Thread(target=self._work, name="shipsense-background", daemon=True).start()

    def submit(self, fn):
        from concurrent.futures import Future

        future = Future()
        with self._lock:
            self.busy += 1
        future.add_done_callback(self._finished)     # (done, failed or cancelled)
        self._queue.put((future, fn))
        return future

    def _finished(self, _):
        with self._lock:
            self.busy -= 1

    def _work(self):
        while True:
            future, fn = self._queue.get()
            if not future.set_running_or_notify_cancel():      # cancelled before it started
                continue
            try:
                future.set_result(fn())
            except BaseException as exc:                       # (the caller gets it from the future)
                future.set_exception(exc)


def in_chunks(fn, n, split_min=SPLIT_MIN):
    """``[fn(lo, hi), ...]`` over contiguous chunks ``[lo, hi)`` covering ``range(n)``, in order: one chunk (the
    whole range, called here) below ``split_min``, else up to :func:`threads` chunks, the first run on the
    calling thread and the others in a shared pool."""
    parts = min(threads(), n // (split_min // 2)) if n >= split_min else 1
    if parts <= 1:
        return [fn(0, n)]
    edges = [n * i // parts for i in range(parts + 1)]
    futures = [_executor().submit(fn, edges[i], edges[i + 1]) for i in range(1, parts)]
    first = fn(edges[0], edges[1])
    return [first] + [f.result() for f in futures]


def in_turns(fn, n):
    """``fn(i, i + 1)`` for every ``i`` in ``range(n)``, each item taken by whichever thread is free next: the
    calling thread and up to :func:`threads` - 1 threads of the shared pool (itself at most ``min(32, CPUs +
    4)`` threads) take the next item as they finish their last.  For a few items of unequal cost
    (Levenberg-Marquardt fits of very different numbers of cost evaluations), where
    :func:`in_chunks`' contiguous halves leave one CPU idle.  A single item, or a single thread, runs here
    (``fn(0, n)``).  ``fn`` must release the GIL (a ``nogil`` kernel) and write only its item's results: the
    order in which the items run then changes nothing.

    An error in an item reaches the caller once the items taken have finished; an error (or Ctrl-C) on the
    calling thread stops the helpers after the item each holds, and the call returns after them -- unless a
    second Ctrl-C interrupts that wait, when a helper may still finish the one item it holds."""
    workers = min(threads(), n) if n >= 2 else 1
    if workers <= 1:
        fn(0, n)
        return
    items = iter(range(n))            # (next() on a range iterator is atomic under the GIL)

    def work():
        for i in items:
            fn(i, i + 1)

    def stop():                       # the helpers take no further item
        for _ in items:
            pass

    futures = []
    try:
        futures += [_executor().submit(work) for _ in range(workers - 1)]
        work()
    except BaseException:
        stop()
        raise
    finally:   # a helper that has not started has nothing left to take: cancelled, not waited for
        try:
            for f in futures:
                if not f.cancel():
                    f.exception()     # (waits for it: no item of this call runs after the call returns)
        except BaseException:
            stop()
            raise
    for f in futures:
        if not f.cancelled() and f.exception() is not None:
            raise f.exception()


SCHEDULER_TIMEOUT_S = 5.0
"""How long to wait for a ``--scheduler`` address to answer."""
ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "SHIPSENSE_THREADS": "1"}
"""A local cluster runs a single-threaded worker per core: BLAS, OpenMP and the compiled filter steps held to one
thread in each."""


@contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None, client=None, *, needed: bool = True,
                log=print):
    """The Dask client a command's tasks run on, for the ``with`` block; a client made here is closed (with
    its local cluster) when the block ends, however it ends.

    * ``client`` given: that one (the caller's: left open);
    * ``workers == 0`` and no ``scheduler``, or nothing to run (``needed`` false): None -- run in this process;
    * else a new client on ``scheduler`` (an address, ``tcp://host:8786``, answering within
      :data:`SCHEDULER_TIMEOUT_S`), or on a new local cluster of ``workers`` single-threaded processes (None:
      one per core) with BLAS held to one thread each (:data:`ONE_THREAD`).

    A scheduler that does not answer, or Dask not installed, is a :class:`~shipsense.errors.ShipsenseError`
    raised before the block runs."""
    if client is not None or not needed or (scheduler is None and workers == 0):
        yield client
        return
    own = _connect(workers, scheduler, log)
    try:
        yield own
    finally:
        cluster = getattr(own, "cluster", None)
        own.close()
        if cluster is not None:
            cluster.close()


def _connect(workers, scheduler, log):
    import logging

    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError:
        raise ShipsenseError("running on Dask needs the sweep extra: pip install 'shipsense[sweep]' "
                             "(or --workers 0 to run serially)") from None
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S}s")
        except (OSError, TimeoutError, ValueError) as err:
            raise ShipsenseError(f"--scheduler {scheduler}: no Dask scheduler answered within "
                                 f"{SCHEDULER_TIMEOUT_S:g} s ({type(err).__name__}: {err})") from None
    else:
        n = workers if workers is not None else (os.cpu_count() or 1)
        with dask.config.set({"distributed.nanny.pre-spawn-environ": ONE_THREAD}):
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, silence_logs=logging.ERROR,
                                   dashboard_address=":0")
        client = Client(cluster)
    log(f"dask: {len(client.scheduler_info().get('workers', {}))} workers, dashboard {client.dashboard_link}")
    return client
