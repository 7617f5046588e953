"""The fast HED path's compiled kernel: the electric field of a horizontal dipole in a layered sea, and its
Jacobian, in one pass per point (numba).

Used by :class:`shipsense.physics.electric.FastHED`, which owns the medium's table of the far images and the
physics (see its docstring and :mod:`shipsense.physics.electric`); this module is imported with the first
field it evaluates, so importing the physics does not import numba.  ``cache=True``: compiled once per
environment, then loaded from ``__pycache__``.
"""

from __future__ import annotations

import numba
import numpy as np

from shipsense import numba_cache


@numba.njit(cache=True, inline="always")
def _exact(rho, dz, coef):
    """One image at vertical offset dz: coef * (1/R^3, 1/R^5, dz/R^5), then their d/drho and d/dw (9 values)."""
    inv2 = 1.0 / (rho * rho + dz * dz)
    inv3 = coef * inv2 * np.sqrt(inv2)   # no pow: 1/R^3, 1/R^5, 1/R^7 from one square root
    inv5 = inv3 * inv2
    inv7 = inv5 * inv2
    return (inv3, inv5, dz * inv5,
            -3.0 * rho * inv5, -5.0 * rho * inv7, -5.0 * dz * rho * inv7,
            -3.0 * dz * inv5, -5.0 * dz * inv7, inv5 - 5.0 * dz * dz * inv7)


@numba.njit(cache=True, inline="always")
def _remainder(rho, w, table, nx, nw, a, x0, hx, w0, hw, rho_max):
    """The tabulated remainder (|n| >= 2 shells) at (rho, w) by tensor cubic Lagrange, then its d/drho and
    d/dw (9 values).  The table holds the remainder scaled by powers of s^2 = rho^2 + a^2; beyond ``rho_max``
    the scaled remainder is held at its last value (its rho^-3 / rho^-5 asymptote), so dT/dgx = 0 there.  The
    cell is clipped to the table: a point beyond it is extrapolated from the edge cell."""
    gx = (np.arcsinh(min(rho, rho_max) / a) - x0) / hx
    gw = (w - w0) / hw
    i = min(max(int(np.floor(gx)), 1), nx - 3)
    j = min(max(int(np.floor(gw)), 1), nw - 3)
    lx = _lagrange4(gx - i)
    lw = _lagrange4(gw - j)
    dlx = _lagrange4_derivative(gx - i)
    dlw = _lagrange4_derivative(gw - j)
    s2 = rho * rho + a * a
    root = np.sqrt(s2)
    u1 = 1.0 / (s2 * root)
    u2 = u1 / s2
    dgx = 0.0 if rho > rho_max else 1.0 / (hx * root)
    r = (i - 1) * nw + (j - 1)   # the stencil's first row; rows k * nw apart
    v1, x1, w1 = _contract(table, r, nw, 0, lx, lw, dlx, dlw)
    v2, x2, w2 = _contract(table, r, nw, 1, lx, lw, dlx, dlw)
    v3, x3, w3 = _contract(table, r, nw, 2, lx, lw, dlx, dlw)
    K1 = v1 * u1
    K2 = v2 * u2
    K3 = v3 * a * u2
    # d/drho of T s^-k: dT/dgx dgx/drho s^-k - k T rho s^-(k+2)
    q = rho / s2
    return (K1, K2, K3,
            x1 * dgx * u1 - 3.0 * K1 * q, x2 * dgx * u2 - 5.0 * K2 * q, x3 * dgx * a * u2 - 5.0 * K3 * q,
            w1 * u1 / hw, w2 * u2 / hw, w3 * a * u2 / hw)


@numba.njit(cache=True, inline="always")
def _contract(table, r, nw, c, lx, lw, dlx, dlw):
    """Column ``c`` of the 4 x 4 stencil from row ``r``, contracted: sum_k lx_k sum_b lw_b t_kb, and the same
    with dlx (d/dgx) and with dlw (d/dgw)."""
    v = vx = vw = 0.0
    for k in range(4):
        t0, t1, t2, t3 = table[r, c], table[r + 1, c], table[r + 2, c], table[r + 3, c]
        sb = lw[0] * t0 + lw[1] * t1 + lw[2] * t2 + lw[3] * t3
        v += lx[k] * sb
        vx += dlx[k] * sb
        vw += lx[k] * (dlw[0] * t0 + dlw[1] * t1 + dlw[2] * t2 + dlw[3] * t3)
        r += nw
    return v, vx, vw


@numba.njit(cache=True, nogil=True)
def hed_points(rx, ry, zs, zt, px, py, table, nx, nw, a, x0, hx, w0, hw, rho_max, D, eta, c, derivatives):
    """The HED field (and its derivatives) at N points: :func:`hed_field_point` or :func:`hed_point` each.

    Returns E (N, 3), dE/dq (N, 3, 3) and G = dE/dp (N, 3, 2) (the last two empty without ``derivatives``).
    """
    n = rx.size
    E = np.empty((n, 3))
    nd = n if derivatives else 0
    dE = np.empty((nd, 3, 3))
    G = np.empty((nd, 3, 2))
    e, de, g = np.empty(3), np.empty((3, 3)), np.empty((3, 2))
    for p in range(n):
        if not derivatives:
            E[p, 0], E[p, 1], E[p, 2] = hed_field_point(rx[p], ry[p], zs[p], zt[p], px[p], py[p], table, nx, nw,
                                                        a, x0, hx, w0, hw, rho_max, D, eta, c)
            continue
        hed_point(rx[p], ry[p], zs[p], zt[p], px[p], py[p], table, nx, nw, a, x0, hx, w0, hw, rho_max, D, eta, c,
                  e, de, g)
        for i in range(3):
            E[p, i] = e[i]
            for j in range(3):
                dE[p, i, j] = de[i, j]
            for j in range(2):
                G[p, i, j] = g[i, j]
    return E, dE, G


@numba.njit(cache=True, inline="always")
def _sums(rho, zs, zt, table, nx, nw, a, x0, hx, w0, hw, rho_max, D, eta):
    """Per family ``w`` (u = zs - zt, v = zs + zt): the source and the nearest images exactly (n = 0, and
    |n| = 1 when eta != 0) plus the tabulated remainder.  Returns K1, K2, K3 summed over both families, their
    d/drho, and their d/dz_t = -d/du + d/dv."""
    K1 = K2 = K3 = R1 = R2 = R3 = Z1 = Z2 = Z3 = 0.0
    for f in range(2):
        w = zs - zt if f == 0 else zs + zt
        sign = -1.0 if f == 0 else 1.0
        for m in range(4 if eta != 0.0 else 1):
            if m == 0:
                e = _exact(rho, w, 1.0)
            elif m == 1:
                e = _exact(rho, w + 2.0 * D, eta)
            elif m == 2:
                e = _exact(rho, w - 2.0 * D, eta)
            else:
                e = _remainder(rho, w, table, nx, nw, a, x0, hx, w0, hw, rho_max)
            K1 += e[0]
            K2 += e[1]
            K3 += e[2]
            R1 += e[3]
            R2 += e[4]
            R3 += e[5]
            Z1 += sign * e[6]
            Z2 += sign * e[7]
            Z3 += sign * e[8]
    return K1, K2, K3, R1, R2, R3, Z1, Z2, Z3


# hed_field_point and hed_point are called, not inlined, by the compiled filter steps: inlined at each of the
# steps' call sites they made the steps' first compilation much longer (benchmarks/filters.py's first-call
# probe) and ran no faster (benchmarks/physics.py prints the measurement models' cost per state).
@numba.njit(cache=True, nogil=True)
def hed_field_point(x, y, zs, zt, mx, my, table, nx, nw, a, x0, hx, w0, hw, rho_max, D, eta, c):
    """The HED field ``(E_x, E_y, E_z)`` at one point: ``E_h = c (3 (p.rho) rho K2 - p K1)``,
    ``E_z = 3 c (p.rho) K3``.

    ``(x, y)`` is the horizontal offset sensor - source, ``zs``, ``zt`` the sensor's and the source's heights,
    ``(mx, my)`` the moment, ``c`` = 1 / (4 pi sigma1) times the unit of the result; the rest is the medium's
    table (:class:`~shipsense.physics.electric.FastHED`).  With :func:`hed_point`, the one implementation of the
    fast HED field: :func:`hed_points` (the numpy-facing batch) and the compiled measurement functions of
    :mod:`shipsense.models.measurement` call them.
    """
    K1, K2, K3 = _sums(np.hypot(x, y), zs, zt, table, nx, nw, a, x0, hx, w0, hw, rho_max, D, eta)[:3]
    g01 = 3.0 * x * y * K2      # E = c g p, as :func:`hed_point` forms it (the same rounding)
    return (c * ((3.0 * x * x * K2 - K1) * mx + g01 * my), c * (g01 * mx + (3.0 * y * y * K2 - K1) * my),
            c * (3.0 * x * K3 * mx + 3.0 * y * K3 * my))


@numba.njit(cache=True, nogil=True)
def hed_point(x, y, zs, zt, mx, my, table, nx, nw, a, x0, hx, w0, hw, rho_max, D, eta, c, E, dE, G):
    """:func:`hed_field_point` into ``E`` (3,), with dE/dq (source position) into ``dE`` (3, 3) and dE/dp into
    the first two columns of ``G`` (3, >= 2)."""
    rho = np.hypot(x, y)
    K1, K2, K3, R1, R2, R3, Z1, Z2, Z3 = _sums(rho, zs, zt, table, nx, nw, a, x0, hx, w0, hw, rho_max, D, eta)
    g00 = 3.0 * x * x * K2 - K1
    g01 = 3.0 * x * y * K2
    g11 = 3.0 * y * y * K2 - K1
    g20 = 3.0 * x * K3
    g21 = 3.0 * y * K3
    E[0] = c * (g00 * mx + g01 * my)
    E[1] = c * (g01 * mx + g11 * my)
    E[2] = c * (g20 * mx + g21 * my)
    G[0, 0] = c * g00
    G[0, 1] = c * g01
    G[1, 0] = c * g01
    G[1, 1] = c * g11
    G[2, 0] = c * g20
    G[2, 1] = c * g21
    ux = x / rho if rho > 0 else 0.0
    uy = y / rho if rho > 0 else 0.0
    pr = mx * x + my * y
    for j in range(2):   # d/drho_j, then d/dq_j = -d/drho_j
        pj = mx if j == 0 else my
        uj = ux if j == 0 else uy
        e0 = 1.0 if j == 0 else 0.0
        dK1 = R1 * uj
        dK2 = R2 * uj
        dK3 = R3 * uj
        dE[0, j] = -c * (3 * pj * x * K2 + 3 * pr * e0 * K2 + 3 * pr * x * dK2 - mx * dK1)
        dE[1, j] = -c * (3 * pj * y * K2 + 3 * pr * (1.0 - e0) * K2 + 3 * pr * y * dK2 - my * dK1)
        dE[2, j] = -c * (3 * pj * K3 + 3 * pr * dK3)
    dE[0, 2] = c * (3 * pr * x * Z2 - mx * Z1)
    dE[1, 2] = c * (3 * pr * y * Z2 - my * Z1)
    dE[2, 2] = c * 3 * pr * Z3


@numba.njit(cache=True, inline="always")
def _lagrange4(t):
    """Cubic Lagrange weights on nodes -1, 0, 1, 2 at offset t in [0, 1)."""
    return (-t * (t - 1.0) * (t - 2.0) / 6.0, (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0,
            -(t + 1.0) * t * (t - 2.0) / 2.0, (t + 1.0) * t * (t - 1.0) / 6.0)


@numba.njit(cache=True, inline="always")
def _lagrange4_derivative(t):
    """Their derivatives in t."""
    return (-(3 * t * t - 6 * t + 2) / 6.0, (3 * t * t - 4 * t - 1) / 2.0,
            -(3 * t * t - 2 * t - 2) / 2.0, (3 * t * t - 1) / 6.0)


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
