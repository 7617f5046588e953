"""Batch least-squares fits of whole passages (constant velocity), batched over candidates.

Used by the global initialiser (:mod:`shipsense.trackers.initialiser`) and by the
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


def fit_passages(model, y, theta_init, steps, stride=1, iterations=40, return_information=False, tol=1e-9,
                 prior=None):
    """Batched Levenberg–Marquardt fit of passages to measurements (internal units).

    ``y`` (B or 1, K', m) are the measurements at steps ``0, stride, 2 stride, ...``;
    ``theta_init`` (B, n); NaN samples are ignored.  ``prior``, optional, is a
    Gaussian prior ``(mean (n,) or (B, n), information (n,))`` on the initial
    state with a diagonal information (zero where a component has none): the
    fit is then the MAP estimate, and its chi-square and information include
    the prior's term.  Returns the fitted
    initial states (B, n), kept within the model's ``state_bounds`` (projected
    steps), and their chi-square over the fitted samples (and,
    with ``return_information``, the Gauss–Newton information ``J^T J`` (B, n, n)
    at the solution: the inverse of the batch-fit covariance).  Stops after
    ``iterations``; a fit stops earlier once it stalled three times in a row
    (an accepted step gaining less than the relative ``tol``, or a rejected
    step at a damping of 1e6 or more).
    """
    Ak = powers(model.A, steps)[::stride]
    w = 1.0 / np.sqrt(model.R)
    lo, hi = getattr(model, "state_bounds", None) or (None, None)
    theta = np.array(theta_init, dtype=float)
    if lo is not None:
        theta = np.clip(theta, lo, hi)
    B, n = theta.shape

    present = np.isfinite(y)
    y = np.where(present, y, 0.0)
    shared = y.shape[0] == 1          # one measurement set for every fit

    def rows(a, idx):
        return a if shared else a[idx]

    if prior is not None:
        mu = np.broadcast_to(np.asarray(prior[0], dtype=float), (B, n))
        root = np.sqrt(np.asarray(prior[1], dtype=float))                 # (n,): the prior's rows

    def residual(th, idx):
        X = np.einsum("kij,bj->bki", Ak, th)
        r = (model.residual(model.h(X), rows(y, idx)) * w * rows(present, idx)).reshape(len(th), -1)
        if prior is not None:
            r = np.concatenate([r, root * (th - mu[idx])], axis=-1)
        return r, X

    def jacobian(X, idx):
        J = (model.H(X) @ Ak * (w * rows(present, idx))[..., None]).reshape(len(X), -1, n)
        if prior is not None:
            J = np.concatenate([J, np.broadcast_to(np.diag(root), (len(X), n, n))], axis=1)
        return J

    everyone = np.arange(B)
    r, X = residual(theta, everyone)
    cost = np.sum(r * r, axis=-1)
    lam = np.full(B, 1e-2)
    stall = np.zeros(B, dtype=int)
    for _ in range(iterations):
        # fits that stalled in 3 successive iterations are done: only the
        # others are stepped (the late iterations of a few slow fits no longer cost a full batch)
        a = np.flatnonzero(stall < 3)
        if a.size == 0:
            break
        Jac = jacobian(X[a], a)
        JtJ = np.swapaxes(Jac, -1, -2) @ Jac
        g = np.einsum("bmn,bm->bn", Jac, r[a])
        D = np.diagonal(JtJ, axis1=-2, axis2=-1)
        A = JtJ + lam[a, None, None] * (np.eye(n) * (D + 1e-12)[:, None, :])
        step = -np.linalg.solve(A, g[..., None])[..., 0]
        trial = theta[a] + step
        if lo is not None:   # projected steps: the fit stays physical (e.g. the source in the water)
            trial = np.clip(trial, lo, hi)
        r_t, X_t = residual(trial, a)
        cost_t = np.sum(r_t * r_t, axis=-1)
        better = np.isfinite(cost_t) & (cost_t < cost[a])
        gain = np.where(better, (cost[a] - cost_t) / np.maximum(cost[a], 1e-300), 0.0)
        ok = a[better]
        theta[ok] = trial[better]
        r[ok] = r_t[better]
        X[ok] = X_t[better]
        cost[ok] = cost_t[better]
        lam[a] = np.clip(np.where(better, lam[a] / 3.0, lam[a] * 5.0), 1e-9, 1e9)
        # a stall: an accepted step that gained less than tol, or a rejected one at a large damping
        stalled = np.where(better, gain < tol, lam[a] >= 1e6)
        stall[a] = np.where(stalled, stall[a] + 1, 0)
    if return_information:
        Jac = jacobian(X, everyone)
        return theta, cost, np.swapaxes(Jac, -1, -2) @ Jac
    return theta, cost
