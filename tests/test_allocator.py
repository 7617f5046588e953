"""Allocator tuning: takes effect on glibc Linux, rejects bad values, never breaks computation."""

import sys

import numpy as np
import pytest

from shipsense.allocator import MMAP_THRESHOLD_MAX, allocator_tuned, release_free_memory, tune_allocator


def test_bad_thresholds_are_rejected():
    with pytest.raises(ValueError, match="mmap_threshold"):
        tune_allocator(mmap_threshold=2 * MMAP_THRESHOLD_MAX)
    with pytest.raises(ValueError, match="trim_threshold"):
        tune_allocator(trim_threshold=0)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc mallopt")
def test_tuning_takes_effect_on_linux_and_numpy_still_works():
    import platform

    if platform.libc_ver()[0] != "glibc":
        pytest.skip("not glibc")
    assert tune_allocator() is True
    assert allocator_tuned()
    a = np.arange(10**6, dtype=float)
    assert float((a * 2.0).sum()) == 2.0 * float(a.sum())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc malloc_trim")
def test_releasing_free_memory_gives_freed_heap_back():
    import platform
    import threading

    if platform.libc_ver()[0] != "glibc":
        pytest.skip("not glibc")
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("the main arena (another thread's arena gives freed pages back by itself)")

    def anon_mib():
        with open("/proc/self/status") as fh:
            return next(int(line.split()[1]) for line in fh if line.startswith("RssAnon:")) / 1024

    assert tune_allocator() is True       # (freed heap is then kept: a 256 MiB trim threshold)
    blocks = [np.ones(2**17) for _ in range(96)]          # 96 MiB of 1 MiB heap blocks, touched
    held = anon_mib()
    del blocks
    kept = anon_mib()
    assert release_free_memory() is True
    assert kept > held - 16               # kept by the allocator after the free...
    assert anon_mib() < kept - 64         # ...and given back
