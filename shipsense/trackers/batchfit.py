"""Batch least-squares fits of whole passages (constant velocity), batched over candidates.

Used by the global initialiser (:mod:`shipsense.trackers.init`) and by the
ambiguity search of the design tools.  A passage is its initial state
``theta`` (internal units); its samples are ``h(A^k theta)``.
"""

from __future__ import annotations

import numpy as np


def powers(A, K):
    """A^k for k = 0..K-1, shape (K, n, n)."""
    out = np.empty((K,) + A.shape)
    out[0] = np.eye(A.shape[0])
    for k in range(1, K):
        out[k] = A @ out[k - 1]
    return out


def fit_passages(model, y, theta_init, steps, stride=1, iterations=40, return_information=False):
    """Batched Levenberg–Marquardt fit of passages to measurements (internal units).

    ``y`` (B or 1, K', m) are the measurements at steps ``0, stride, 2 stride, ...``;
    ``theta_init`` (B, n); NaN samples are ignored.  Returns the fitted
    initial states (B, n), kept within the model's ``state_bounds`` (projected
    steps), and their chi-square over the fitted samples (and,
    with ``return_information``, the Gauss–Newton information ``J^T J`` (B, n, n)
    at the solution: the inverse of the batch-fit covariance).
    """
    Ak = powers(model.A, steps)[::stride]
    w = 1.0 / np.sqrt(model.R)
    lo, hi = getattr(model, "state_bounds", (None, None))
    theta = np.array(theta_init, dtype=float)
    if lo is not None:
        theta = np.clip(theta, lo, hi)
    B, n = theta.shape

    present = np.isfinite(y)
    y = np.where(present, y, 0.0)

    def residual(th):
        X = np.einsum("kij,bj->bki", Ak, th)
        return (model.residual(model.h(X), y) * w * present).reshape(B, -1), X

    r, X = residual(theta)
    cost = np.sum(r * r, axis=-1)
    lam = np.full(B, 1e-2)
    for _ in range(iterations):
        Jac = (model.H(X) @ Ak * (w * present)[..., None]).reshape(B, -1, n)
        JtJ = np.swapaxes(Jac, -1, -2) @ Jac
        g = np.einsum("bmn,bm->bn", Jac, r)
        D = np.diagonal(JtJ, axis1=-2, axis2=-1)
        A = JtJ + lam[:, None, None] * (np.eye(n) * (D + 1e-12)[:, None, :])
        step = -np.linalg.solve(A, g[..., None])[..., 0]
        trial = theta + step
        if lo is not None:   # projected steps: the fit stays physical (e.g. the source in the water)
            trial = np.clip(trial, lo, hi)
        r_t, X_t = residual(trial)
        cost_t = np.sum(r_t * r_t, axis=-1)
        better = np.isfinite(cost_t) & (cost_t < cost)
        theta = np.where(better[:, None], trial, theta)
        r = np.where(better[:, None], r_t, r)
        X = np.where(better[:, None, None], X_t, X)
        cost = np.where(better, cost_t, cost)
        lam = np.clip(np.where(better, lam / 3.0, lam * 5.0), 1e-9, 1e9)
    if return_information:
        Jac = (model.H(X) @ Ak * (w * present)[..., None]).reshape(B, -1, n)
        return theta, cost, np.swapaxes(Jac, -1, -2) @ Jac
    return theta, cost
