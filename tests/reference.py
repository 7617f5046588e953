"""Independent references for the tests (on the path through ``pythonpath = ["tests"]``)."""

import numpy as np


def kalman_reference(A, Q, C, R, y, x0, P0):
    """Textbook Kalman filter with explicit inverses, one batch element at a time: the independent reference
    the filters (numpy and compiled) are checked against."""
    x, P = x0.copy(), P0.copy()
    xs, Ps, ll = [], [], []
    for k in range(y.shape[0]):
        if k:
            x, P = A @ x, A @ P @ A.T + Q
        S = C @ P @ C.T + R
        K = P @ C.T @ np.linalg.inv(S)
        e = y[k] - C @ x
        ll.append(-0.5 * (len(e) * np.log(2 * np.pi) + np.log(np.linalg.det(S)) + e @ np.linalg.inv(S) @ e))
        x, P = x + K @ e, (np.eye(len(x)) - K @ C) @ P
        xs.append(x)
        Ps.append(P)
    return np.array(xs), np.array(Ps), np.array(ll)


def odd_observer_outputs(last, rng):
    """Fill an environment's record of its observer's output (``last.estimate`` (E, n), ``last.cov`` (E, n, n),
    E >= 7) with covariances over 22 decades and, in rows 0-6, what a broken track can report: a NaN or an
    infinite variance, a zero position block, a negative variance, an infinite covariance, a NaN position,
    an infinite velocity."""
    E, n = last.estimate.shape
    last.estimate[:] = rng.normal(0, 300, (E, n))
    L = rng.normal(0, 5, (E, n, n))
    last.cov[:] = L @ np.swapaxes(L, -1, -2) * 10.0 ** rng.integers(-16, 6, (E, 1, 1))
    last.cov[0, 0, 0] = np.nan
    last.cov[1, 1, 1] = np.inf
    last.cov[2, :2, :2] = 0.0
    last.cov[3, 0, 0] = -1.0
    last.cov[4, 0, 1] = last.cov[4, 1, 0] = np.inf
    last.estimate[5, 0] = np.nan
    last.estimate[6, 2] = -np.inf


def gram_reference(G, C, P):
    """The grid's Gram matrices ``A[c] = sum_k G[k, c P:(c + 1) P]^T G[k, c P:(c + 1) P]`` (C, P, P) of a
    whitened basis ``G`` (K, C*P), in numpy: each row's outer products added in row order from zeros (the
    sums the compiled ``initialiser._gram_on`` makes, to the bit)."""
    A = np.zeros((C, P, P))
    for g in np.asarray(G).reshape(len(G), C, P):
        A += g[:, :, None] * g[:, None, :]
    return A


def linear_gaussian(rng):
    """A constant-velocity linear-Gaussian model (n = 4, m = 3, C drawn from ``rng``): ``(A, Q, C, R)`` and the
    :class:`~shipsense.models.field_model.LinearModel` of them, on which every Gaussian filter and bound is the
    Kalman filter's."""
    from shipsense.models.field_model import LinearModel

    A = np.eye(4)
    A[0, 2] = A[1, 3] = 0.5
    Q = 0.05 * np.eye(4)
    C = rng.standard_normal((3, 4))
    R = np.array([0.5, 1.0, 2.0])
    return (A, Q, C, R), LinearModel(A, Q, C, R)


def terms(eps, state_var, noise_var, present, gamma=np.inf, outliers=0.0, scale=1.0):
    """The windowed innovation consistency test's terms of one sample, in numpy (the definition the tracker's
    compiled pass, ``shipsense.trackers.tracker.consistency.window_test``, is tested against): its
    contributions (..., 2, m) to the window sums, ``psi(z)`` and its variance ``v`` under the declared noise,
    per channel (zero where a component is missing)."""
    from shipsense.trackers.tracker.consistency import psi_variance

    z = eps / np.sqrt(state_var + noise_var)
    psi = np.clip(z, -gamma, gamma) if np.isfinite(gamma) else z
    v = psi_variance(state_var, noise_var, gamma, outliers, scale)
    return np.where(present[..., None, :], np.stack([psi, v], axis=-2), 0.0)


def statistic(sums):
    """The consistency test's statistic ``T`` and its degrees of freedom (the channels with data) from window
    sums (..., 2, m) (:func:`terms` summed over the window), in numpy."""
    s, v = sums[..., 0, :], sums[..., 1, :]
    has = v > 0.0
    return np.sum(np.where(has, s * s / np.where(has, v, 1.0), 0.0), axis=-1), has.sum(axis=-1)
