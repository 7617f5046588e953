r"""Motion models: constant velocity with constant parameters.

State layout used throughout the project: the kinematic block
``(x, y, v_x, v_y)`` followed by ``n_params`` constant parameters (the
magnetic moment ``(m_x, m_y, m_z)``; or the electric source height and scalar
moment ``(z, p)``).  Note the electric source study orders its state
``(x, y, z, v_x, v_y, p)``; the project keeps the kinematic block first for
every model.

.. math::  x_k = A x_{k-1} + w_k, \quad
           A = \mathrm{blockdiag}\!\left(\begin{bmatrix} I_2 & T I_2\\ 0 & I_2\end{bmatrix}, I_{n_p}\right)

Process noise: (a) ``Q = sigma_q I`` (the magnetic source study, sigma_q =
0.1); (b) discrete white-noise acceleration ``Gamma Sigma Gamma^T`` with
``Gamma = [T^2/2 I2; T I2]`` plus a random walk of variance ``param_var`` per
step on each parameter (the default for new scenarios).  Reference:
Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and
Navigation*, §6.3.2.

The truth of manoeuvring passages (coordinated turns, along-track speed changes) and the transitions of
their steps: :mod:`shipsense.physics.manoeuvre`.
"""

from __future__ import annotations

import numpy as np


def cv_transition(period, n_params):
    """Transition matrix ``A`` of shape (4 + n_params, 4 + n_params)."""
    A = np.eye(4 + n_params)
    A[0, 2] = A[1, 3] = period
    return A


def q_identity(n_params, sigma_q):
    """Process noise option (a): ``sigma_q * I`` on every state (sigma_q is a variance)."""
    return float(sigma_q) * np.eye(4 + n_params)


def q_dwna(period, sigma_a, param_var):
    """Process noise option (b): DWNA on (x, y, v) plus a random walk on the parameters.

    Parameters
    ----------
    period : float
        Sampling period T, s.
    sigma_a : (float, float)
        Standard deviations of the white acceleration along x and y, m/s².
    param_var : sequence of float
        Per-step random-walk variance of each parameter (0 for a constant).
    """
    T = float(period)
    sax, say = sigma_a
    param_var = np.asarray(param_var, dtype=float).reshape(-1)
    Q = np.zeros((4 + param_var.size,) * 2)
    for axis, s in ((0, sax), (1, say)):
        g = np.array([T * T / 2.0, T])
        idx = [axis, axis + 2]
        Q[np.ix_(idx, idx)] = s * s * np.outer(g, g)
    Q[4:, 4:] = np.diag(param_var)
    return Q


def cv_positions(start, velocity, times):
    """Positions of constant-velocity tracks, ``start + t * velocity``.

    start, velocity : (..., d); times : (k,) -> (..., k, d).
    """
    start = np.asarray(start, dtype=float)
    velocity = np.asarray(velocity, dtype=float)
    return start[..., None, :] + np.asarray(times, dtype=float)[:, None] * velocity[..., None, :]
