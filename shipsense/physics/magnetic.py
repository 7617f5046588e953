r"""Magnetic dipole field of a ship and the measurement kinds of a magnetometer.

A ship further away than a few hull lengths is a point magnetic dipole with
moment :math:`m` (A·m²).  Its flux density at a sensor :math:`s` is

.. math::

    B(s; q, m) = \frac{\mu_0}{4\pi}\,\frac{3 (m\cdot r) r - |r|^2 m}{|r|^5},
    \qquad r = s - q,

with :math:`\mu_0/4\pi = 10^{-7}` T·m/A.  References: Jackson, *Classical
Electrodynamics*, 3rd ed., eq. 5.56; the magnetic source study (S0).
"""

from __future__ import annotations

import numpy as np

MU0_OVER_4PI = 1e-7
"""mu0 / (4 pi) in T·m/A."""


def dipole_field(sensors, sources, moments):
    """Flux density of point magnetic dipoles at sensor positions.

    Parameters
    ----------
    sensors : array_like, shape (..., 3)
        Sensor positions in metres.
    sources : array_like, shape (..., 3)
        Dipole positions in metres.
    moments : array_like, shape (..., 3)
        Dipole moments in A·m².

    Returns
    -------
    B : ndarray, shape (..., 3)
        Flux density in tesla; the leading axes are the broadcast of the three
        inputs' leading axes.  Where a sensor coincides with a source the field
        is undefined and NaN is returned (explicitly, with no warning).

    Examples
    --------
    On the dipole axis the field is ``2 m / r^3`` (times 1e-7):

    >>> B = dipole_field([0, 0, 10.0], [0, 0, 0], [0, 0, 1e6])
    >>> bool(np.allclose(B, [0, 0, 2e-7 * 1e6 / 10.0**3]))
    True
    """
    s = np.asarray(sensors)
    q = np.asarray(sources)
    m = np.asarray(moments)
    dtype = np.result_type(s, q, m, float)
    # component-wise: every operation runs over the whole batch at unit stride (faster than working
    # on (..., 3) rows, which matters inside sigma-point filters)
    r = [np.subtract(s[..., i], q[..., i], dtype=dtype) for i in range(3)]
    B = np.empty(np.broadcast_shapes(r[0].shape, m.shape[:-1]) + (3,), dtype=dtype)
    _field_into(B, r, m)
    return B


def _field_into(out, r, m):
    """Write the dipole field into ``out`` (X + (3,)) from components ``r`` (3 arrays broadcasting to X)
    and moments ``m`` (..., 3) broadcasting to X; NaN where ``r = 0``."""
    r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    m_dot_r = m[..., 0] * r[0] + m[..., 1] * r[1] + m[..., 2] * r[2]
    singular = r2 == 0.0
    if singular.any():
        r2 = np.where(singular, 1.0, r2)
    inv_r5 = MU0_OVER_4PI / (r2 * r2 * np.sqrt(r2))
    a = 3.0 * m_dot_r * inv_r5
    b = r2 * inv_r5
    for i in range(3):
        np.multiply(a, r[i], out=out[..., i])
        out[..., i] -= b * m[..., i]
    if singular.any():
        out[singular] = np.nan


_ROWS_MAX = 3 * 1024
"""Below this many source-sensor coordinates :func:`dipole_field_at` works on (..., 3) rows (fewer numpy calls);
above it component-wise (unit-stride loops over the batch)."""


def _field_rows(r, m):
    """The dipole field from separation rows ``r`` (..., 3) and moments ``m`` (..., 3); NaN where ``r = 0``."""
    r2 = np.einsum("...i,...i->...", r, r)
    singular = r2 == 0.0
    if singular.any():
        r2 = np.where(singular, 1.0, r2)
    inv_r5 = MU0_OVER_4PI / (r2 * r2 * np.sqrt(r2))
    B = r * (3.0 * np.einsum("...i,...i->...", m, r) * inv_r5)[..., None] - (r2 * inv_r5)[..., None] * m
    if singular.any():
        B[singular] = np.nan
    return B


def dipole_field_at(sensors, sources, moments):
    """Flux density of one dipole per batch element at a set of sensors.

    Same physics as :func:`dipole_field` with the sensor axis placed last in
    the output, computed sensor-major so that every operation loops over the
    batch, not over the (few) sensors.

    Parameters
    ----------
    sensors : array_like, shape (S, 3)
    sources, moments : array_like, shape (..., 3)

    Returns
    -------
    B : ndarray, shape (..., S, 3)
        Tesla; NaN where a sensor coincides with a source.
    """
    s = np.asarray(sensors)
    q = np.asarray(sources)
    m = np.asarray(moments)
    dtype = np.result_type(s, q, m, float)
    batch = np.broadcast_shapes(q.shape[:-1], m.shape[:-1])
    if q.size * s.shape[0] < _ROWS_MAX:   # few evaluations: fewer, row-wise operations cost less
        return _field_rows(s - q[..., None, :].astype(dtype, copy=False), m[..., None, :])
    col = (slice(None),) + (None,) * len(batch)                 # sensor axis first, then the batch
    r = [np.subtract(s[col + (i,)], q[..., i], dtype=dtype) for i in range(3)]   # (S, ...)
    B = np.empty(batch + (s.shape[0], 3), dtype=dtype)
    _field_into(np.moveaxis(B, -2, 0), r, m)                     # written through an (S, ..., 3) view
    return B


def earth_field_direction(inclination_deg, declination_deg):
    """Unit vector of the Earth's main field in the world frame (x east, y north, z up).

    Parameters
    ----------
    inclination_deg : float
        Dip angle below the horizontal, degrees, positive downwards (northern
        hemisphere).
    declination_deg : float
        Angle of the horizontal component east of true north, degrees.

    Returns
    -------
    b : ndarray, shape (3,)
    """
    inc = np.deg2rad(inclination_deg)
    dec = np.deg2rad(declination_deg)
    return np.array([np.cos(inc) * np.sin(dec), np.cos(inc) * np.cos(dec), -np.sin(inc)])


def magnitude_reading(B):
    """Magnitude ``|B|`` of the target field (..., 3) -> (...)."""
    return np.linalg.norm(B, axis=-1)


def tmi_reading(B, earth_direction):
    """Total-field anomaly ``B . b_E`` (..., 3) -> (...): what a scalar magnetometer reports."""
    return np.einsum("...i,...i->...", B, np.broadcast_to(earth_direction, np.shape(B)))


def dipole_field_jacobian(sensors, sources, moments):
    """Flux density and its derivatives with respect to the source position and the moment.

    Returns
    -------
    B : ndarray, shape (..., 3)
        As :func:`dipole_field`, tesla.
    dB_dq : ndarray, shape (..., 3, 3)
        ``dB_i / dq_j`` (source position), T/m.  With ``r = s - q``,
        ``dB/dr = c [(3 r m^T + 3 (m.r) I - 2 m r^T) / r^5 - 5 (3 (m.r) r - r^2 m) r^T / r^7]``
        and ``dB/dq = -dB/dr``.
    dB_dm : ndarray, shape (..., 3, 3)
        ``dB_i / dm_j = c (3 r r^T - r^2 I) / r^5``, T/(A·m²).
    """
    s, q, m = (np.asarray(a, dtype=float) for a in (sensors, sources, moments))
    shape = np.broadcast_shapes(s.shape, q.shape, m.shape)[:-1]
    # component-wise (unit-stride over the batch), and dB/dr is symmetric:
    # c [3 (r m^T + m r^T) + 3 (m.r) I - 15 (m.r) r r^T / r^2] / r^5
    r = [np.subtract(s[..., i], q[..., i]) for i in range(3)]
    mc = [m[..., i] for i in range(3)]
    r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    mr = mc[0] * r[0] + mc[1] * r[1] + mc[2] * r[2]
    a = MU0_OVER_4PI / (r2 * r2 * np.sqrt(r2))
    a3, ar2 = 3.0 * a, a * r2
    a3mr = a3 * mr
    c15 = 5.0 * a3mr / r2
    B = np.empty(shape + (3,))
    dB_dq = np.empty(shape + (3, 3))
    dB_dm = np.empty(shape + (3, 3))
    for i in range(3):
        B[..., i] = a3mr * r[i] - ar2 * mc[i]
        for j in range(i, 3):
            rr = r[i] * r[j]
            vm = a3 * rr
            vr = a3 * (r[i] * mc[j] + mc[i] * r[j]) - c15 * rr
            if i == j:
                vm -= ar2
                vr += a3mr
            dB_dm[..., i, j] = dB_dm[..., j, i] = vm
            dB_dq[..., i, j] = dB_dq[..., j, i] = -vr
    return B, dB_dq, dB_dm
