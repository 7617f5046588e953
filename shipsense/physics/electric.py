r"""Horizontal electric dipole (HED) in a layered sea: the shaft-rate field.

Three layers: insulating air (z > 0), sea water of conductivity
:math:`\sigma_1` and depth :math:`D` (-D < z < 0), and a seabed half-space of
conductivity :math:`\sigma_2` (z < -D).  World coordinates, z up, z = 0 at the
sea surface.

Image theory (quasi-static, DC limit).  With
:math:`\eta = (\sigma_1 - \sigma_2)/(\sigma_1 + \sigma_2)`, the insulating
surface reflects with weight +1 and the seabed with weight :math:`\eta`; a
horizontal dipole is reflected into a horizontal dipole of the same
orientation.  The repeated reflections of a source at height :math:`z_t` are
dipoles at

.. math::

    z = z_t - 2nD \quad\text{and}\quad z = -z_t - 2nD, \qquad n \in \mathbb{Z},

each weighted by :math:`\eta^{|n|}` (``n = 0``: the source and its surface
image).  This is the image series of the electric source study (S1) written
in world coordinates (its sum over ``k >= 1`` is ``n = -k`` here, its sum over
``m >= 0`` is ``n = m``).
Each image contributes the full-space dipole potential
:math:`(p\cdot\rho)/(4\pi\sigma_1 R^3)` and field

.. math::

    E = \frac{3 (p\cdot r) r - R^2 p}{4\pi\sigma_1 R^5}, \qquad r = (\rho, \Delta z).

Validity.  The series gives the field at points *in the sea water*
(-D <= z <= 0).  A sensor on the seabed reads the sea-side limit: horizontal
components are continuous across the seabed, but just inside the seabed
:math:`E_z` is :math:`\sigma_1/\sigma_2` times larger.  Only horizontal moments
are modelled (a vertical moment changes sign in the reflected images); the
z component of ``moments`` is ignored.

Two evaluation paths:

* ``method="series"`` (the reference): shells ``|n| = 0, 1, 2, ...`` are added
  until a proven bound on the remaining tail is below ``rtol`` times the
  direct-field scale :math:`|p|/(4\pi\sigma_1 r_0^3)` (``r_0`` the
  source–sensor distance) at every point.  See :func:`_field_tail_bound`.
* ``method="fast"``: shells ``|n| <= 1`` are summed exactly; the rest, which
  depends on the geometry only through the horizontal offset ``rho`` and one
  vertical coordinate ``w`` (``z_s - z_t`` or ``z_s + z_t``), is read from a
  table built once per medium from the series and interpolated (tensor cubic
  Lagrange on a uniform grid in ``asinh(rho/2D)`` and ``w``).  Its error
  against the series is tested to be below 1e-6 relative for offsets up to
  2 km (``tests/physics/test_electric.py``; ``benchmarks/physics.py`` reports it).
  Beyond the table (20 km) the remainder follows its asymptote.

References: Wait, *Electromagnetic Waves in Stratified Media* (1962); the
electric source study (S1); Jackson, *Classical Electrodynamics*, §4.4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["CONDUCTIVITY_RATIO", "MAX_SHELLS", "Medium", "FastHED", "fast_hed", "hed_field", "hed_potential",
           "envelope_reading", "magnitude_reading", "magnitude_jacobian"]


CONDUCTIVITY_RATIO = (1e-3, 1e3)
r"""The seabed-to-water conductivity ratios :math:`\sigma_2/\sigma_1` a :class:`Medium` may have.

The image series converges like :math:`|\eta|^n` with :math:`|\eta| = |1 - r|/(1 + r)` for the ratio
:math:`r`, so the shells it needs grow like :math:`1/|\ln|\eta|| \approx 1/(2r)` as :math:`r \to 0` (and
:math:`r/2` as :math:`r \to \infty`); at :math:`|\eta| = 1` (an insulating or a perfectly conducting seabed)
the tail falls only like :math:`1/n^2` and no tolerance is reached in a bounded number of shells.  Within
this range :math:`|\eta| \le 0.998` and the stopping rule ends within :data:`MAX_SHELLS` shells at every
tolerance the package uses; the range spans resistive rock under sea water (:math:`r \approx 10^{-3}`) to
conductive sediment.
"""
MAX_SHELLS = 200_000
"""Most image shells a series sums before it gives up with an error (never reached within
:data:`CONDUCTIVITY_RATIO` at the package's tolerances)."""


@dataclass(frozen=True)
class Medium:
    """Sea water over a seabed half-space, under insulating air.

    Parameters
    ----------
    sigma_water : float
        Conductivity of the sea water, S/m (> 0).
    sigma_seabed : float
        Conductivity of the seabed, S/m (> 0).
    water_depth : float
        Depth of the water layer, m (> 0).
    """

    sigma_water: float = 4.0
    sigma_seabed: float = 0.04
    water_depth: float = 15.0

    def __post_init__(self):
        for name in ("sigma_water", "sigma_seabed", "water_depth"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"Medium.{name} must be a finite number > 0, got {value!r}")
        lo, hi = CONDUCTIVITY_RATIO
        if not lo <= self.sigma_seabed / self.sigma_water <= hi:
            raise ValueError(f"Medium.sigma_seabed / sigma_water must be within [{lo:g}, {hi:g}] (CONDUCTIVITY_RATIO), "
                             f"got {self.sigma_seabed!r} / {self.sigma_water!r}")

    @property
    def eta(self) -> float:
        """Seabed reflection coefficient ``(sigma1 - sigma2) / (sigma1 + sigma2)``."""
        return (self.sigma_water - self.sigma_seabed) / (self.sigma_water + self.sigma_seabed)


def _split(sensors, sources, moments):
    s = np.asarray(sensors, dtype=float)
    q = np.asarray(sources, dtype=float)
    p = np.asarray(moments, dtype=float)
    rx = s[..., 0] - q[..., 0]
    ry = s[..., 1] - q[..., 1]
    zs = s[..., 2]
    zt = q[..., 2]
    px = p[..., 0]
    py = p[..., 1]
    rx, ry, zs, zt, px, py = np.broadcast_arrays(rx, ry, zs, zt, px, py)
    return rx, ry, zs, zt, px, py


def _dipole(rx, ry, dz, px, py, out):
    """Add the full-space field ``(3 (p.r) r - R^2 p) / R^5`` (without 1/4 pi sigma) into ``out``."""
    R2 = rx * rx + ry * ry + dz * dz
    inv_R3 = R2**-1.5
    k = 3.0 * (px * rx + py * ry) * inv_R3 / R2
    out[0] += k * rx - px * inv_R3
    out[1] += k * ry - py * inv_R3
    out[2] += k * dz


def _dipole_potential(rx, ry, dz, px, py):
    R2 = rx * rx + ry * ry + dz * dz
    return (px * rx + py * ry) * R2**-1.5


def _integral_tail(eta_abs, N, D, rho, power):
    """Bound on ``sum_{n > N} |eta|^n / (rho^2 + ((2n-2) D)^2)^(power/2)`` for N >= 1.

    The summand is positive and decreasing in n, so the sum is below the
    integral from N to infinity, which is below both
    ``|eta|^N * int_N^inf g`` and ``g(N) * int_N^inf |eta|^t dt``.
    ``power`` is 3 (field) and the integral of ``g`` is then in closed form:
    ``1 / (2 D s (s + u0))`` with ``u0 = (2N - 2) D`` and ``s = hypot(rho, u0)``.
    """
    u0 = (2.0 * N - 2.0) * D
    s = np.hypot(rho, u0)
    with np.errstate(divide="ignore"):
        a = eta_abs**N / (2.0 * D * s * (s + u0))
        if 0.0 < eta_abs < 1.0:
            b = eta_abs**N / s**power / math.log(1.0 / eta_abs)
            a = np.minimum(a, b)
    return a


def _field_tail_bound(eta_abs, N, D, rho):
    """Bound on ``|E_tail| * 4 pi sigma1 / |p|`` after shells ``|n| <= N``.

    Each remaining shell ``|n| = n`` has four images, each at a vertical
    distance of at least ``(2n - 2) D`` from any point in the water, and each
    image's field is at most ``2 |p| / R^3``.  Hence
    ``|E_tail| <= 8 |p| / (4 pi sigma1) * sum_{n > N} |eta|^n / R_n^3``.
    """
    return 8.0 * _integral_tail(eta_abs, N, D, rho, 3)


def _series(rx, ry, zs, zt, px, py, medium, rtol, max_shells, potential):
    D = medium.water_depth
    eta = medium.eta
    u = zs - zt
    v = zs + zt
    rho = np.hypot(np.real(rx), np.real(ry))  # real parts: the sum itself is complex-step safe
    if potential:
        total = _dipole_potential(rx, ry, u, px, py) + _dipole_potential(rx, ry, v, px, py)
    else:
        total = np.zeros((3,) + rx.shape, dtype=np.result_type(rx, zs, px))
        _dipole(rx, ry, u, px, py, total)
        _dipole(rx, ry, v, px, py, total)
    if eta == 0.0:
        return total, 0
    # Stopping rule: tail bound <= rtol * direct-field scale (|p| / r0^3; for the
    # potential |p| rho / r0^3 <= |p| / r0^2 scale is used with an extra rho factor).
    r0 = np.sqrt(rho * rho + np.real(u) ** 2)
    target = rtol / r0**3
    if potential:
        target = rtol / r0**2
    eta_abs = abs(eta)
    for n in range(1, max_shells + 1):
        c = eta**n
        for dz in (u + 2 * n * D, u - 2 * n * D, v + 2 * n * D, v - 2 * n * D):
            if potential:
                total = total + c * _dipole_potential(rx, ry, dz, px, py)
            else:
                shell = np.zeros_like(total)  # complex when the inputs are
                _dipole(rx, ry, dz, px, py, shell)
                total += c * shell
        bound = _field_tail_bound(eta_abs, n, D, rho)
        if potential:
            bound = bound * np.maximum(rho, 1e-300) / 2.0  # |p.rho|/R^3 <= |p| rho / R^3; 4 images not 8
        if np.all(bound <= target):
            return total, n
    raise RuntimeError(
        f"HED image series did not reach rtol={rtol:g} within {max_shells} shells "
        f"(eta={eta:.6f}: the seabed is nearly insulating); raise max_shells or rtol"
    )


def hed_potential(sensors, sources, moments, medium: Medium, *, rtol=1e-10, max_shells=MAX_SHELLS):
    """Electric potential (V) of a horizontal dipole in the layered sea (image series).

    Same arguments as :func:`hed_field`; used to check the field against
    finite differences of the potential.
    """
    rx, ry, zs, zt, px, py = _split(sensors, sources, moments)
    phi, _ = _series(rx, ry, zs, zt, px, py, medium, rtol, max_shells, potential=True)
    return phi / (4.0 * np.pi * medium.sigma_water)


def hed_field(sensors, sources, moments, medium: Medium, *, method="series", rtol=1e-10,
              max_shells=200_000, return_shells=False):
    """Electric field of a horizontal electric dipole in the layered sea.

    Parameters
    ----------
    sensors : array_like, shape (..., 3)
        Field points (sensors) in world coordinates, m; must lie in the water,
        ``-D <= z <= 0``.
    sources : array_like, shape (..., 3)
        Dipole positions in world coordinates, m, ``-D < z < 0``.
    moments : array_like, shape (..., 3) or (..., 2)
        Horizontal dipole moments, A·m; a z component is ignored.
    medium : Medium
    method : {"series", "fast"}
        ``"series"`` sums the image series to ``rtol`` (the reference);
        ``"fast"`` uses the tabulated remainder (:class:`FastHED`).
    rtol : float
        Series only: the tail bound is below ``rtol`` times the direct-field
        scale ``|p| / (4 pi sigma1 r0^3)`` at every point.
    max_shells : int
        Series only: give up (RuntimeError) after this many image shells.
    return_shells : bool
        Series only: also return the number of shells used.

    Returns
    -------
    E : ndarray, shape (..., 3)
        Electric field in V/m (broadcast of the inputs' leading axes).

    Examples
    --------
    >>> m = Medium(sigma_water=4.0, sigma_seabed=0.04, water_depth=15.0)
    >>> E = hed_field([50.0, 0, -15], [0, 0, -6.8], [100.0, 0, 0], m)
    >>> bool(1e-5 < abs(E[0]) < 1e-3)
    True
    """
    if method == "fast":
        return fast_hed(medium)(sensors, sources, moments)
    if method != "series":
        raise ValueError(f"method must be 'series' or 'fast', got {method!r}")
    rx, ry, zs, zt, px, py = _split(sensors, sources, moments)
    total, shells = _series(rx, ry, zs, zt, px, py, medium, rtol, max_shells, potential=False)
    E = np.moveaxis(total, 0, -1) / (4.0 * np.pi * medium.sigma_water)
    return (E, shells) if return_shells else E


def envelope_reading(E):
    """Shaft-rate envelope of each channel, ``(|E_x|, |E_y|, |E_z|)``."""
    return np.abs(E)


def magnitude_reading(E):
    r"""Shaft-rate envelope of the field's magnitude, ``|E| = sqrt(E_x^2 + E_y^2 + E_z^2)``, shape (...,).

    The three channels share the shaft-rate carrier, :math:`E(t) = A \cos(2\pi f_s t + \varphi)`, so
    :math:`|E(t)| = |A| |\cos(\cdot)|` and the envelope of the magnitude is the magnitude of the
    amplitude vector :math:`|A|` -- one channel, independent of the sensor's orientation (the electric
    counterpart of a total-field magnetometer's ``magnitude``).
    """
    E = np.asarray(E)
    return np.sqrt(np.sum(E * E, axis=-1))


def magnitude_jacobian(E, dE):
    r"""``|E|`` and its derivative ``d|E| = \hat E^T dE`` from the field ``E`` (..., 3) and ``dE`` (..., 3, k).

    Returns ``(|E| (...,), d|E| (..., k))``.  At a zero field the magnitude has a cone (its directional
    derivatives are ``|dE u|``, not linear in ``u``); the derivative returned there is zero (the
    minimum-norm subgradient), explicitly, so a sensor at a null of the field gives no NaN.
    """
    norm = magnitude_reading(E)
    unit = np.asarray(E) / np.where(norm > 0, norm, 1.0)[..., None]     # zero vector where |E| = 0
    return norm, np.einsum("...j,...jk->...k", unit, dE)


def _last_shell(eta, D, rho, target):
    """The first shell ``n >= 2`` after which the series' tail is at most ``target`` at every offset ``rho`` (an
    array of the points' ``target`` shape).  Bounded: within :data:`CONDUCTIVITY_RATIO` the tail bound falls
    like ``|eta|^n`` and reaches any positive target within :data:`MAX_SHELLS` shells; beyond them a
    ``RuntimeError`` (not a loop that does not end).  The tail: :func:`_integral_tail` twice (two images
    per shell per family, each term -- and rho^2 K2, rho K3 -- at most 1/R^3).  Bound and target are functions
    of the offset alone, so each distinct offset is tested once."""
    r_abs, first = np.unique(np.abs(rho), return_index=True)
    t = np.broadcast_to(target, np.shape(rho)).reshape(-1)[first]
    for n in range(2, MAX_SHELLS + 1):
        if np.all(2.0 * _integral_tail(abs(eta), n, D, r_abs, 3) <= t):
            return n
    raise RuntimeError(f"HED image series: no stopping shell within {MAX_SHELLS} (eta={eta:.6f}: outside "
                       "CONDUCTIVITY_RATIO)")


def _shell_sums(eta, D, last, rho2, w, out):
    """Shells ``2..last`` of the image sums ``sum c_n (1/R^3, 1/R^5, dz/R^5)`` (both images ``w +- 2 n D`` of
    a shell, in that order) at points ``rho2`` (horizontal offset squared) and ``w`` (N,) into ``out`` (N, 3),
    in place on contiguous scratch."""
    K0, K1, K2 = np.zeros(rho2.shape), np.zeros(rho2.shape), np.zeros(rho2.shape)
    dz, R2, inv_R3, inv_R5, t = (np.empty(rho2.shape) for _ in range(5))
    for n in range(2, last + 1):
        c = eta**n
        for shift in (2 * n * D, -2 * n * D):
            np.add(w, shift, out=dz)
            np.multiply(dz, dz, out=R2)
            np.add(rho2, R2, out=R2)
            np.power(R2, -1.5, out=inv_R3)
            np.divide(inv_R3, R2, out=inv_R5)
            K0 += np.multiply(c, inv_R3, out=t)
            K1 += np.multiply(c, inv_R5, out=t)
            np.multiply(c, dz, out=t)
            K2 += np.multiply(t, inv_R5, out=t)
    out[:, 0], out[:, 1], out[:, 2] = K0, K1, K2


class FastHED:
    """Tabulated HED kernel: exact near shells plus an interpolated far remainder.

    For a medium, the images with ``|n| >= 2`` (all at least ``2D`` away
    vertically from any point in the water) contribute, per family
    ``w in {z_s - z_t, z_s + z_t}``, three smooth radial functions of the
    horizontal offset ``rho`` and of ``w``::

        K1 = sum eta^|n| / R^3,  K2 = sum eta^|n| / R^5,  K3 = sum eta^|n| dz / R^5,
        R^2 = rho^2 + dz^2,  dz = w + 2 n D,

    from which ``E_h = 3 (p.rho) rho K2 - p K1`` and ``E_z = 3 (p.rho) K3``.
    They are tabulated (scaled by powers of ``rho^2 + (2D)^2`` so that they
    are O(1) and slowly varying) on a uniform grid in ``x = asinh(rho / 2D)``
    and ``w``, and read back with tensor cubic Lagrange interpolation.

    Parameters
    ----------
    medium : Medium
    rho_max : float
        Largest tabulated horizontal offset, m.  Beyond it the scaled
        remainder is held at its last value, i.e. extrapolated along its
        ``rho^-3`` / ``rho^-5`` asymptote: finite and smooth, so a diverged
        hypothesis far away never costs a series evaluation, but only right
        in order of magnitude.  The tested error bound covers offsets up to
        2 km.
    hx : float
        Grid step in ``asinh(rho / 2D)``.
    nw_per_depth : int
        Grid points in ``w`` per water depth.
    """

    def __init__(self, medium: Medium, rho_max: float = 20_000.0, hx: float = 0.02,
                 nw_per_depth: int = 20, table_rtol: float = 1e-13):
        self.medium = medium
        self.rho_max = float(rho_max)
        D = medium.water_depth
        self._a = 2.0 * D
        self._hx = hx
        self._x0 = -3 * hx
        nx = int(math.ceil((math.asinh(rho_max / self._a) + 6 * hx) / hx)) + 1
        self._hw = D / nw_per_depth
        self._w0 = -2.0 * D - 3 * self._hw
        nw = int(math.ceil((3.0 * D + 6 * self._hw) / self._hw)) + 1
        x = self._x0 + hx * np.arange(nx)
        w = self._w0 + self._hw * np.arange(nw)
        rho = self._a * np.sinh(x)[:, None] * np.ones((1, nw))
        ww = np.ones((nx, 1)) * w[None, :]
        self._table = self._remainder(rho, ww, table_rtol).reshape(nx * nw, 3)
        self._nx, self._nw = nx, nw

    def _remainder(self, rho, w, rtol):
        """Scaled (K1, K2, K3) remainder sums for |n| >= 2, by the series: shells up to the first whose tail
        bound is within ``rtol`` of the scale at every point (:func:`_last_shell`), each point's sums in shell
        order (:func:`_shell_sums`), the points in chunks on the CPUs (numpy releases the GIL in the
        elementwise loops; a point's sums do not depend on its chunk)."""
        from shipsense.parallel import in_chunks

        K = np.zeros(rho.shape + (3,))
        if self.medium.eta == 0.0:
            return K
        rho2 = rho * rho
        s2 = rho2 + self._a**2
        last = _last_shell(self.medium.eta, self.medium.water_depth, rho, rtol / s2**1.5)
        r2, ww, out = rho2.reshape(-1), np.broadcast_to(w, rho.shape).reshape(-1), K.reshape(-1, 3)
        in_chunks(lambda lo, hi: _shell_sums(self.medium.eta, self.medium.water_depth, last, r2[lo:hi], ww[lo:hi],
                                             out[lo:hi]), r2.size, split_min=8192)
        K[..., 0] *= s2**1.5
        K[..., 1] *= s2**2.5
        K[..., 2] *= s2**2.5 / self._a
        return K

    def _evaluate(self, sensors, sources, moments, derivatives):
        """The fused kernel over the broadcast points: E (..., 3) and, with ``derivatives``, dE/dq (..., 3, 3)
        and G (..., 3, 2), all in V/m units (the 1/(4 pi sigma1) applied)."""
        from shipsense.parallel import in_chunks
        from shipsense.physics.hed_kernel import hed_points  # numba is imported with the first electric field

        rx, ry, zs, zt, px, py = (np.ascontiguousarray(v).ravel() for v in _split(sensors, sources, moments))
        shape = np.broadcast_shapes(*(np.shape(v)[:-1] for v in (sensors, sources, moments)))

        params = self.point_parameters()

        def points(lo, hi):    # the kernel releases the GIL: a large batch runs in chunks on the CPUs
            return hed_points(rx[lo:hi], ry[lo:hi], zs[lo:hi], zt[lo:hi], px[lo:hi], py[lo:hi], *params, derivatives)

        parts = in_chunks(points, rx.size)
        E, dE, G = parts[0] if len(parts) == 1 else (np.concatenate(a) for a in zip(*parts))
        if not derivatives:
            return E.reshape(shape + (3,))
        return E.reshape(shape + (3,)), dE.reshape(shape + (3, 3)), G.reshape(shape + (3, 2))

    def point_parameters(self, unit=1.0):
        """The compiled point functions' description of this medium's field (the arguments after the point of
        :func:`~shipsense.physics.hed_kernel.hed_field_point`): ``(table, nx, nw, a, x0, hx, w0, hw, rho_max, D,
        eta, c)``, with ``c = 1 / (4 pi sigma1 unit)`` (fields in units of ``unit`` V/m)."""
        return (self._table, self._nx, self._nw, self._a, self._x0, self._hx, self._w0, self._hw, self.rho_max,
                self.medium.water_depth, self.medium.eta, 1.0 / (4.0 * np.pi * self.medium.sigma_water * unit))

    def __call__(self, sensors, sources, moments):
        """Electric field (V/m), shape (..., 3); same contract as :func:`hed_field`."""
        return self._evaluate(sensors, sources, moments, False)

    def field_jacobian(self, sensors, sources, moments):
        """Field and its derivatives with respect to the source position and the moment.

        Returns
        -------
        E : ndarray, shape (..., 3)
            V/m, as :meth:`__call__`.
        dE_dq : ndarray, shape (..., 3, 3)
            ``dE_i / dq_j`` with respect to the source position, V/m².
        G : ndarray, shape (..., 3, 2)
            ``dE_i / dp_j`` for the horizontal moment components (E = G p), V/(m·A·m).

        Derivation: per family ``w``, ``E_h = 3 (p.rho) rho K2 - p K1`` and
        ``E_z = 3 (p.rho) K3``; ``d/dq_h = -d/drho`` and
        ``d/dz_t = -d/du + d/dv``.  One compiled pass over the points
        (:func:`shipsense.physics.hed_kernel.hed_points`).
        """
        return self._evaluate(sensors, sources, moments, True)


_FAST_KERNELS: dict[Medium, FastHED] = {}


def fast_hed(medium: Medium) -> FastHED:
    """The :class:`FastHED` kernel for ``medium``, built on first use and kept.

    Building the table sums the series at every grid point, which is costly
    for a resistive seabed (eta close to 1: over a thousand image shells);
    the kernels are kept in a module-level dictionary keyed by the (frozen,
    hashable) medium, so every caller of one medium shares one table.
    """
    kernel = _FAST_KERNELS.get(medium)
    if kernel is None:
        kernel = _FAST_KERNELS[medium] = FastHED(medium)
    return kernel
