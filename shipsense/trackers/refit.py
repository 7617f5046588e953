"""Causal tracking by batch refits: every hypothesis's whole passage re-fitted to the samples seen so far.

A passage of the simulated families is a straight, constant-velocity track
with a constant source: its state at sample ``k`` is ``A^(k - k0) theta``,
``theta`` the state at the window's first sample ``k0``.  With no process
noise a recursive filter linearises each sample once, at the estimate of
its time, and keeps that linearisation for good; at the very high SNR of a
close pass its covariance then shrinks faster than its error (EXPERIMENTS.md,
consistency).  Here every hypothesis of the global initialiser instead
re-fits ``theta`` by Levenberg–Marquardt (:func:`fit_passages`, warm-started
from its last solution) to all its samples up to ``k``, every ``every``
samples: the estimate is the maximum-likelihood (or, with a prior, MAP)
estimate of the data so far, its covariance the inverse Gauss–Newton
information, and the hypothesis with the lowest chi-square is selected.
Between refits the last fit is propagated (causal: the estimate at ``k``
uses samples up to ``k`` only).  All passages and hypotheses are one batch.
"""

from __future__ import annotations

import numpy as np

from shipsense.trackers.batchfit import fit_passages, powers


def track_by_refits(model, measurements, gi, *, every=1, iterations=8, prior=None, scale_by_fit=False,
                    progress=False):
    """Track passages from a :class:`~shipsense.trackers.init.GlobalInit` by growing-window batch refits.

    Parameters
    ----------
    model : FieldModel
    measurements : ndarray, shape (R, K, m)
        SI units, NaN = missing.
    gi : GlobalInit
        Its window trajectories give every hypothesis's ``theta`` at ``gi.k0``;
        the tracker starts at ``gi.start``.
    every : int
        Samples between refits (the last fit is propagated in between).
    iterations : int
        Levenberg–Marquardt iterations per refit (warm start: a few suffice).
    prior : tuple, optional
        ``(mean (n,), information (n,))`` in internal units, as for :func:`fit_passages`.
    scale_by_fit : bool
        Scale the covariance by the reduced chi-square of the selected fit when
        it exceeds 1 (a fit that does not explain its data: a local minimum).

    Returns
    -------
    estimates : ndarray, shape (R, K, n)
        SI; before ``gi.start`` the best window fit's trajectory.
    pos_cov : ndarray, shape (R, K, 2, 2)
        Position covariance (SI, m²); NaN before ``gi.start``.
    chi2 : ndarray, shape (R, M)
        Final chi-square of every hypothesis.
    """
    y = np.asarray(measurements, dtype=float) / model.y_scale
    R, K, m = y.shape
    M, n = gi.seeds.shape[1], model.n
    k0 = np.asarray(gi.k0, dtype=int)
    first = np.asarray(gi.start, dtype=int) - k0              # aligned index of each passage's first tracked sample
    J = K - int(k0.min())
    src = k0[:, None] + np.arange(J)[None, :]
    yk = np.where((src < K)[..., None], y[np.arange(R)[:, None], np.minimum(src, K - 1)], np.nan)   # (R, J, m)
    theta = (gi.window[:, :, 0] / model.x_scale).reshape(R * M, n)
    Ak = powers(model.A, J)
    xs = model.x_scale
    est = np.full((R, J, n), np.nan)
    cov = np.full((R, J, 2, 2), np.nan)
    chi2 = np.full((R, M), np.nan)
    steps = list(range(int(first.min()), J, every))
    if progress:
        from tqdm import tqdm

        steps = tqdm(steps, desc="refits", unit="refit", leave=False)
    rows = np.arange(R)
    for j in steps:
        data = np.repeat(yk[:, : j + 1], M, axis=0)                                    # samples k0..k0+j
        theta, c, info = fit_passages(model, data, theta, j + 1, iterations=iterations, return_information=True,
                                      prior=prior)
        chi2 = c.reshape(R, M)
        best = np.argmin(np.where(np.isfinite(chi2), chi2, np.inf), axis=1)
        th = theta.reshape(R, M, n)[rows, best]                                           # (R, n) at k0
        C = np.linalg.pinv(info.reshape(R, M, n, n)[rows, best], hermitian=True)
        if scale_by_fit:
            dof = np.maximum(np.isfinite(yk[:, : j + 1]).sum(axis=(1, 2)) - n, 1)
            C = C * np.maximum(1.0, chi2[rows, best] / dof)[:, None, None]
        upto = min(j + every, J)
        A = Ak[j:upto]                                                                    # (e, n, n)
        est[:, j:upto] = np.einsum("eij,rj->rei", A, th) * xs
        P = A[None] @ C[:, None] @ np.swapaxes(A, -1, -2)[None]                          # (R, e, n, n)
        cov[:, j:upto] = P[..., :2, :2] * np.outer(xs[:2], xs[:2])
    mine = np.arange(J)[None, :] >= first[:, None]                                        # each passage's tracked part
    est_k = np.full((R, K, n), np.nan)
    cov_k = np.full((R, K, 2, 2), np.nan)
    inside = mine & (src < K)
    r_idx = np.broadcast_to(rows[:, None], src.shape)
    est_k[r_idx[inside], src[inside]] = est[inside]
    cov_k[r_idx[inside], src[inside]] = cov[inside]
    # before the tracker starts: the best window fit's constant-velocity trajectory (backwards before k0)
    b0 = np.argmax(gi.loglik, axis=1)
    theta0 = gi.window[rows, b0, 0] / xs
    ks = np.arange(K)[None, :] - k0[:, None]
    traj = np.repeat(theta0[:, None, :], K, axis=1)
    traj[..., 0:2] += ks[..., None] * model.period * theta0[:, None, 2:4]
    before = np.arange(K)[None, :] < np.asarray(gi.start)[:, None]
    est_k[before] = (traj * xs)[before]
    return est_k, cov_k, chi2
