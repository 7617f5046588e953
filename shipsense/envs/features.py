"""What the Passage environment computes from its observer's output, compiled for their per-environment
kernels (inlined): the track's observation features and its position error and NEES against the truth."""

from __future__ import annotations

import math

from numba import njit

from shipsense import numba_cache


@njit(cache=True, error_model="numpy", inline="always")
def at_least(a, b):
    """``np.maximum(a, b)`` of numbers (NaN if ``a`` is)."""
    return a if not a <= b else b


@njit(cache=True, error_model="numpy", inline="always")
def track_features(est, cov, centre, position_scale, row):
    """The observation's first six entries from one estimate ``est`` (n,) and covariance ``cov`` (n, n) into
    ``row``: position relative to ``centre`` / ``position_scale``, velocity / 10 m/s, and ``log10(std) / 3``
    of x and y (variances floored at 1e-12)."""
    row[0] = (est[0] - centre[0]) / position_scale
    row[1] = (est[1] - centre[1]) / position_scale
    row[2] = est[2] * 0.1
    row[3] = est[3] * 0.1
    row[4] = math.log10(at_least(cov[0, 0], 1e-12)) / 6.0
    row[5] = math.log10(at_least(cov[1, 1], 1e-12)) / 6.0


@njit(cache=True, error_model="numpy", inline="always")
def error_and_nees(d0, d1, a, b, c):
    """Position error ``|d|`` and NEES ``d^T C^-1 d`` of an error ``d = (d0, d1)`` with covariance ``C = [[a,
    b], [b, c]]`` (its inverse in closed form; not finite where ``C`` is singular)."""
    return math.hypot(d0, d1), (c * (d0 * d0) - 2 * b * d0 * d1 + a * (d1 * d1)) / (a * c - b * b)


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
