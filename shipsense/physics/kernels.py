r"""Compiled (numba) point kernels of the fields, one source and one sensor per call.

The same physics as :mod:`shipsense.physics.magnetic` (the dipole field and its
derivatives), written on scalars so that compiled filter steps
(:mod:`shipsense.trackers.filters.fused`) can call them inside their loops
with no Python objects and no temporary arrays.  The numpy functions stay the
batched implementation for everything else and the reference in the tests.
"""

from __future__ import annotations

import math

from numba import njit

from shipsense import numba_cache
from shipsense.physics.magnetic import MU0_OVER_4PI


@njit(cache=True, error_model="numpy", inline="always")
def dipole_point(rx, ry, rz, mx, my, mz, out):
    """Flux density of a dipole ``m`` at separation ``r = s - q`` into ``out`` (3,); NaN where ``r = 0``."""
    r2 = rx * rx + ry * ry + rz * rz
    if r2 == 0.0:
        out[0] = out[1] = out[2] = math.nan
        return
    inv_r5 = MU0_OVER_4PI / (r2 * r2 * math.sqrt(r2))
    a = 3.0 * (mx * rx + my * ry + mz * rz) * inv_r5
    b = r2 * inv_r5
    out[0] = a * rx - b * mx
    out[1] = a * ry - b * my
    out[2] = a * rz - b * mz


@njit(cache=True, error_model="numpy", inline="always")
def dipole_point_jacobian(r, m, B, dB_dq, dB_dm):
    """Field ``B`` (3,), ``dB/dq`` (3, 3) (source position) and ``dB/dm`` (3, 3) at separation ``r = s - q``.

    The formulas of :func:`~shipsense.physics.magnetic.dipole_field_jacobian`:
    ``dB/dr = c [3 (r m^T + m r^T) + 3 (m.r) I - 15 (m.r) r r^T / r^2] / r^5``, ``dB/dq = -dB/dr``,
    ``dB/dm = c (3 r r^T - r^2 I) / r^5``.
    """
    r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    mr = m[0] * r[0] + m[1] * r[1] + m[2] * r[2]
    a = MU0_OVER_4PI / (r2 * r2 * math.sqrt(r2))
    a3 = 3.0 * a
    ar2 = a * r2
    a3mr = a3 * mr
    c15 = 5.0 * a3mr / r2
    for i in range(3):
        B[i] = a3mr * r[i] - ar2 * m[i]
        for j in range(i, 3):
            rr = r[i] * r[j]
            vm = a3 * rr
            vr = a3 * (r[i] * m[j] + m[i] * r[j]) - c15 * rr
            if i == j:
                vm -= ar2
                vr += a3mr
            dB_dm[i, j] = vm
            dB_dm[j, i] = vm
            dB_dq[i, j] = -vr
            dB_dq[j, i] = -vr


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
