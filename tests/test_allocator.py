"""Allocator tuning: takes effect on glibc Linux, rejects bad values, never breaks computation."""

import sys

import numpy as np
import pytest

from shipsense.allocator import MMAP_THRESHOLD_MAX, allocator_tuned, tune_allocator


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
