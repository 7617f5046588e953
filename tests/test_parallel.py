"""shipsense.parallel: chunks cover the range in order, the thread count setting, a forked child's pool."""

import os
import signal
import sys
import time

import numpy as np
import pytest

from shipsense import parallel
from shipsense.errors import ShipsenseError


@pytest.mark.parametrize(("n", "threads", "parts"), [(10, "4", 1), (parallel.SPLIT_MIN, "4", 2),
                                                      (5 * parallel.SPLIT_MIN + 3, "4", 4), (5000, "1", 1)])
def test_chunks_cover_the_range_in_order(n, threads, parts, monkeypatch):
    monkeypatch.setenv("SHIPSENSE_THREADS", threads)
    out = parallel.in_chunks(lambda lo, hi: np.arange(lo, hi), n)
    assert len(out) == parts
    np.testing.assert_array_equal(np.concatenate(out), np.arange(n))


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_a_forked_child_gets_its_own_pool(monkeypatch):
    """The parent's pool threads do not exist in a forked child: it must not wait on them."""
    monkeypatch.setenv("SHIPSENSE_THREADS", "2")
    n = 2 * parallel.SPLIT_MIN
    parallel.in_chunks(lambda lo, hi: hi - lo, n)          # the parent's pool exists now
    pid = os.fork()
    if pid == 0:     # the child: exit 0 if the split works, never return into pytest
        try:
            ok = sum(parallel.in_chunks(lambda lo, hi: hi - lo, n)) == n
        finally:
            os._exit(0 if ok else 1)
    deadline = time.monotonic() + 60
    while True:      # a child waiting on threads it does not have would hang: give up after a minute
        done, status = os.waitpid(pid, os.WNOHANG)
        if done or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    if not done:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        pytest.fail("the forked child hung on its parent's thread pool")
    assert os.waitstatus_to_exitcode(status) == 0


def test_the_thread_count_setting_is_checked(monkeypatch):
    """A bad value is input the user can fix (the command line: one line, exit 2)."""
    monkeypatch.setenv("SHIPSENSE_THREADS", "two")
    with pytest.raises(ShipsenseError, match="SHIPSENSE_THREADS"):
        parallel.threads()
    monkeypatch.setenv("SHIPSENSE_THREADS", "0")
    with pytest.raises(ShipsenseError, match="SHIPSENSE_THREADS"):
        parallel.threads()
    monkeypatch.setenv("SHIPSENSE_THREADS", "2")
    assert parallel.threads() == 2


def test_turns_hand_each_item_to_the_thread_that_is_free(monkeypatch):
    """Every item runs once; while one thread is held by a slow item (the first taken, by whichever thread),
    the other takes all the rest (contiguous halves would leave the held thread's half waiting).  Event.wait
    and time.sleep release the GIL, as the compiled kernels do."""
    import threading

    monkeypatch.setenv("SHIPSENSE_THREADS", "2")
    n, ran, lock, rest_done, held = 9, [], threading.Lock(), threading.Event(), []

    def fn(lo, hi):
        assert hi == lo + 1
        with lock:
            slow = not held
            if slow:
                held.append(threading.get_ident())
        if slow:
            rest_done.wait(30)                 # (a hang would fail below, not block the suite)
        else:
            time.sleep(0.005)
        with lock:
            ran.append((lo, threading.get_ident(), slow))
            if sum(not s for _, _, s in ran) == n - 1:
                rest_done.set()

    parallel.in_turns(fn, n)
    assert sorted(i for i, _, _ in ran) == list(range(n))
    assert all(t != held[0] for _, t, slow in ran if not slow)


def test_turns_in_one_thread_and_their_errors(monkeypatch):
    """One thread (or one item): the whole range in one call here.  An item's error reaches the caller, after
    every item taken has finished."""
    monkeypatch.setenv("SHIPSENSE_THREADS", "1")
    calls = []
    parallel.in_turns(lambda lo, hi: calls.append((lo, hi)), 5)
    monkeypatch.setenv("SHIPSENSE_THREADS", "2")
    parallel.in_turns(lambda lo, hi: calls.append((lo, hi)), 1)
    assert calls == [(0, 5), (0, 1)]
    finished = []

    def fn(lo, hi):
        time.sleep(0.01)
        if lo == 3:
            raise ValueError("item 3")
        finished.append(lo)

    with pytest.raises(ValueError, match="item 3"):
        parallel.in_turns(fn, 8)
    count = len(finished)
    time.sleep(0.1)
    assert len(finished) == count              # nothing of the call runs after it returned


def test_an_error_on_the_calling_thread_stops_the_helpers(monkeypatch):
    """An item that fails on the calling thread (or Ctrl-C between items) ends the call: the helper finishes
    the item it holds and takes no other (without the stop it would go on through all 50)."""
    import threading

    monkeypatch.setenv("SHIPSENSE_THREADS", "2")
    caller, done, holding = threading.get_ident(), [], threading.Event()

    def fn(lo, hi):
        if threading.get_ident() == caller:
            holding.wait(30)                   # until the helper holds an item
            raise KeyboardInterrupt
        holding.set()
        time.sleep(0.2)
        done.append(lo)

    with pytest.raises(KeyboardInterrupt):
        parallel.in_turns(fn, 50)
    assert 1 <= len(done) <= 2


def test_serial_keeps_a_threads_splits_on_it_and_ends_with_the_block(monkeypatch):
    monkeypatch.setenv("SHIPSENSE_THREADS", "4")
    n = 5 * parallel.SPLIT_MIN
    with parallel.serial():
        assert parallel.threads() == 1 and len(parallel.in_chunks(lambda lo, hi: hi - lo, n)) == 1
        with parallel.serial():
            pass
        assert parallel.threads() == 1               # (nested: still serial until the outer block ends)
    assert parallel.threads() == 4 and len(parallel.in_chunks(lambda lo, hi: hi - lo, n)) == 4


def test_the_background_thread_runs_work_in_turn_and_hands_back_results_and_errors():
    import threading

    order, gate = [], threading.Event()
    first = parallel.background().submit(lambda: (gate.wait(10), order.append(1), threading.current_thread().name))
    second = parallel.background().submit(lambda: order.append(2))
    third = parallel.background().submit(lambda: order.append(3))
    assert third.cancel()                              # not started: cancelled, never run
    gate.set()

    def boom():
        raise ValueError("from the background")

    failed = parallel.background().submit(boom)
    assert first.result(10)[2] == "shipsense-background" and second.result(10) is None
    with pytest.raises(ValueError, match="from the background"):
        failed.result(10)
    assert order == [1, 2]


def test_the_background_thread_holds_one_cpu_while_it_works(monkeypatch):
    """While the background thread has work the other threads split over one CPU fewer (at least one); it may
    take work only when more than one thread is configured, and not from inside ``serial``."""
    import threading

    monkeypatch.setenv("SHIPSENSE_THREADS", "3")
    gate = threading.Event()
    job = parallel.background().submit(lambda: gate.wait(10))
    queued = parallel.background().submit(lambda: None)
    try:
        assert parallel.threads() == 2 and parallel.configured_threads() == 3
        monkeypatch.setenv("SHIPSENSE_THREADS", "1")
        assert parallel.threads() == 1 and not parallel.background_allowed()
    finally:
        assert queued.cancel()
        gate.set()
        job.result(10)
    monkeypatch.setenv("SHIPSENSE_THREADS", "3")
    deadline = time.monotonic() + 10
    while parallel.threads() != 3 and time.monotonic() < deadline:   # (its done-callback runs as it finishes)
        time.sleep(0.01)
    assert parallel.threads() == 3 and parallel.background_allowed()
    with parallel.serial():
        assert not parallel.background_allowed()


class _Given:
    """A stand-in for the caller's own client: it must be handed back and left open."""

    closed = False

    def close(self):
        self.closed = True


def test_the_dask_client_is_the_callers_or_none_without_a_cluster():
    given = _Given()
    with parallel.dask_client(2, None, given) as client:
        assert client is given
    assert not given.closed
    with parallel.dask_client(0, None) as client:                        # serial: no cluster
        assert client is None
    with parallel.dask_client(2, "tcp://nowhere:1", needed=False) as client:   # nothing to run: no cluster
        assert client is None


def test_a_dask_client_made_here_is_closed_with_its_cluster_however_the_block_ends(monkeypatch):
    distributed = pytest.importorskip("distributed")
    closed, close = [], distributed.Client.close

    def recorded(self, *args, **kwargs):
        closed.append(self)
        return close(self, *args, **kwargs)

    monkeypatch.setattr(distributed.Client, "close", recorded)
    lines = []
    with pytest.raises(KeyError), parallel.dask_client(1, None, log=lines.append) as client:
        assert len(client.scheduler_info()["workers"]) == 1
        cluster = client.cluster
        raise KeyError("the block fails")
    assert client in closed and cluster.status.name == "closed"
    assert lines and lines[0].startswith("dask: 1 workers")


def test_a_scheduler_that_does_not_answer_or_no_dask_is_one_message(monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr(parallel, "SCHEDULER_TIMEOUT_S", 0.5)
    with pytest.raises(ShipsenseError, match=r"--scheduler tcp://127.0.0.1:9: no Dask scheduler answered within "
                       r"0.5 s"), parallel.dask_client(None, "tcp://127.0.0.1:9"):
        pass
    monkeypatch.setitem(sys.modules, "distributed", None)      # (import distributed fails)
    with pytest.raises(ShipsenseError, match="running on Dask needs the sweep extra"), parallel.dask_client(2, None):
        pass
