r"""Seismic (seabed vibration) bearing from a three-axis accelerometer.

The node sees the ship's vibration :math:`s(n)` projected on the unit vector
towards the source plus sensor noise,

.. math::  L(n) = u\,s(n) + \text{noise}, \quad
           u = (\cos\phi,\ \sin\phi\cos\theta,\ \sin\phi\sin\theta)

in (Z, X, Y) order, with :math:`\phi` the angle from vertical and
:math:`\theta` the azimuth.  The principal eigenvector of the windowed sample
covariance estimates :math:`u` up to sign, so the bearing is *axial*:
:math:`\hat\theta = \operatorname{atan2}(u_Y, u_X)` modulo :math:`\pi`.
"""

from __future__ import annotations

import numpy as np


def wrap_axial(angle):
    """Wrap an axial angle (defined modulo pi) into [-pi/2, pi/2)."""
    a = np.asarray(angle)
    return a - np.pi * np.floor((a + 0.5 * np.pi) / np.pi)


def bearing(sensors, sources):
    """Axial bearing from sensor to source, ``atan2(y - y_j, x - x_j)`` wrapped modulo pi (..., 3) -> (...)."""
    d = np.asarray(sources, dtype=float) - np.asarray(sensors, dtype=float)
    return wrap_axial(np.arctan2(d[..., 1], d[..., 0]))


def direction_zxy(sensors, sources):
    """Unit vector from sensor to source in (Z, X, Y) order, shape (..., 3)."""
    d = np.asarray(sources, dtype=float) - np.asarray(sensors, dtype=float)
    u = np.stack([d[..., 2], d[..., 0], d[..., 1]], axis=-1)
    return u / np.linalg.norm(u, axis=-1, keepdims=True)


def simulate_vibration(rng, sensors, sources, n_samples, *, amplitude=1.0, range_ref=100.0,
                       range_exponent=1.0, noise_std=0.05, multipath_gain=0.0,
                       multipath_bias_deg=0.0, noise_dof=None, tail_rng=None):
    """Simulate windows of triaxial vibration at nodes, (Z, X, Y) order.

    Parameters
    ----------
    rng : numpy.random.Generator
        All Gaussian draws come from one call on this generator, with the
        broadcast batch axes first (so a prefix of the batch is reproducible).
    sensors, sources : array_like, shape (..., 3)
        Node and source positions, m (one window per broadcast element).
    n_samples : int
        Samples per window.
    amplitude : float
        RMS vibration amplitude at ``range_ref`` metres.
    range_ref, range_exponent : float
        Amplitude falls as ``(range_ref / r) ** range_exponent``.
    noise_std : float
        Sensor noise per axis (same units as ``amplitude``).
    multipath_gain, multipath_bias_deg : float
        A second, independent arrival of relative amplitude ``multipath_gain``
        from an azimuth rotated by ``multipath_bias_deg``: a multipath-like
        bias of the eigen-bearing.
    noise_dof : float, optional
        Student-t degrees of freedom (> 2) for heavy-tailed sensor noise,
        scaled to unit variance (Gaussian if None).
    tail_rng : numpy.random.Generator, optional
        Source of the chi-square draws of the Student-t noise (default ``rng``).

    Returns
    -------
    L : ndarray, shape (..., n_samples, 3)
    """
    sensors = np.asarray(sensors, dtype=float)
    sources = np.asarray(sources, dtype=float)
    u = direction_zxy(sensors, sources)
    r = np.linalg.norm(sources - sensors, axis=-1)
    a = amplitude * (range_ref / r) ** range_exponent
    shape = u.shape[:-1] + (n_samples,)
    z = rng.standard_normal(shape + (5,))
    L = (a[..., None] * z[..., 0])[..., None] * u[..., None, :]
    if multipath_gain:
        bias = np.deg2rad(multipath_bias_deg)
        c, s = np.cos(bias), np.sin(bias)
        u2 = np.stack([u[..., 0], c * u[..., 1] - s * u[..., 2], s * u[..., 1] + c * u[..., 2]], axis=-1)
        L = L + (multipath_gain * a[..., None] * z[..., 1])[..., None] * u2[..., None, :]
    noise = z[..., 2:]
    if noise_dof is not None:
        chi2 = (tail_rng or rng).chisquare(noise_dof, noise.shape)
        noise = noise / np.sqrt(chi2 / noise_dof) * np.sqrt((noise_dof - 2.0) / noise_dof)
    return L + noise_std * noise


def eigen_bearing(L):
    """Axial bearing from windows of triaxial samples (..., n, 3) in (Z, X, Y) order.

    Returns ``atan2(u_Y, u_X)`` of the principal eigenvector of the sample
    covariance ``(1/n) sum L L^T``, wrapped into [-pi/2, pi/2).
    """
    L = np.asarray(L, dtype=float)
    C = np.einsum("...ni,...nj->...ij", L, L) / L.shape[-2]
    _, vecs = np.linalg.eigh(C)
    u = vecs[..., :, -1]
    return wrap_axial(np.arctan2(u[..., 2], u[..., 1]))


def bearing_jacobian(sensors, sources):
    """Derivative of the bearing with respect to the source position, shape (..., 3) (rad/m).

    ``d atan2(dy, dx) = (-dy, dx, 0) / (dx^2 + dy^2)``; the wrap modulo pi does
    not change it.
    """
    d = np.asarray(sources, dtype=float) - np.asarray(sensors, dtype=float)
    r2 = d[..., 0] ** 2 + d[..., 1] ** 2
    return np.stack([-d[..., 1] / r2, d[..., 0] / r2, np.zeros_like(r2)], axis=-1)
