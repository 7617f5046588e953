"""shipsense.parallel: chunks cover the range in order, the thread count setting, a forked child's pool."""

import os
import signal
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
