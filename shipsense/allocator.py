"""Process allocator tuning for large batched steps (opt-in, glibc only).

A batched filter step over thousands of hypotheses makes a few dozen numpy
temporaries of 0.1-3 MB each.  glibc serves allocations above its mmap
threshold (128 KiB at start, adapted upwards as chunks are freed) with fresh
``mmap`` pages and returns free heap above its trim threshold to the kernel,
so each step pays page faults on memory it just gave back.
:func:`tune_allocator` raises both thresholds so that freed blocks are reused
instead.  ``python benchmarks/envs.py --observer bank --allocator
tuned|default`` measures the difference on the bank-observed vector
environment (docs: Results).

This changes a process-wide setting, so the library never calls it on
import.  The ``shipsense`` command and the benchmarks call it; call it
yourself at the start of a script or training run if you want the same
speed.  The cost is that the process keeps up to ``trim_threshold`` bytes
of freed heap instead of returning them to the system.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_MAX = 32 * 2**20
"""glibc's largest accepted mmap threshold on 64-bit systems (``HEAP_MAX_SIZE / 2``)."""

_state = {"tuned": False}


def tune_allocator(mmap_threshold: int = MMAP_THRESHOLD_MAX, trim_threshold: int = 256 * 2**20) -> bool:
    """Raise glibc's mmap and trim thresholds (``mallopt``); returns whether it took effect.

    Returns False, doing nothing, on other platforms or C libraries.
    Idempotent.
    """
    if not 0 < mmap_threshold <= MMAP_THRESHOLD_MAX:
        raise ValueError(f"mmap_threshold must be in (0, {MMAP_THRESHOLD_MAX}] bytes, got {mmap_threshold}")
    if trim_threshold <= 0:
        raise ValueError(f"trim_threshold must be positive, got {trim_threshold}")
    libc = _glibc()
    if libc is None:
        return False
    mallopt = libc.mallopt
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    ok = mallopt(M_MMAP_THRESHOLD, int(mmap_threshold)) == 1 and mallopt(M_TRIM_THRESHOLD, int(trim_threshold)) == 1
    _state["tuned"] = _state["tuned"] or ok
    return ok


def release_free_memory() -> bool:
    """Give the heap's free pages back to the system (glibc's ``malloc_trim(0)``); returns whether it could.

    For a long computation followed by lighter work in the same process (a study's figures after its
    runs): the freed temporaries of its batched steps stay resident otherwise, under the tuned trim
    threshold or below glibc's own, and the later work's memory comes on top of them.  Returns False, doing
    nothing, on other platforms or C libraries."""
    libc = _glibc()
    if libc is None:
        return False
    libc.malloc_trim.argtypes = (ctypes.c_size_t,)
    libc.malloc_trim.restype = ctypes.c_int
    libc.malloc_trim(0)
    return True


def _glibc():
    """glibc as a ctypes library, or None (another platform or C library: musl's ``mallopt`` is a stub)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.gnu_get_libc_version   # noqa: B018 (glibc only)
        return libc
    except (OSError, AttributeError):
        return None


def allocator_tuned() -> bool:
    """Whether :func:`tune_allocator` has taken effect in this process."""
    return _state["tuned"]
