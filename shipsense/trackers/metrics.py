"""Tracking metrics (shared/spec/trackers.md §4).

Conventions: estimates and truth are (runs, steps, >= 2) with (x, y) first;
"error" is the horizontal position error.
"""

from __future__ import annotations

import numpy as np

CONVERGENCE_THRESHOLD_M = 10.0
"""Default convergence threshold on the final position error (m)."""


def position_error(means, truth):
    """Horizontal position error (..., steps) of estimates and truth (x, y first)."""
    d = np.asarray(means)[..., :2] - np.asarray(truth)[..., :2]
    return np.sqrt(np.sum(d * d, axis=-1))


def rmse_k(means, truth, run_axis=0):
    """``RMSE_k``: root mean over runs of the squared position error at each step."""
    return np.sqrt(np.mean(position_error(means, truth) ** 2, axis=run_axis))


def trmse(means, truth):
    """``TRMSE`` per run: time average of the position error (..., ) -- the studies' 'total RMSE'.

    Average it over runs for the scenario's figure.
    """
    return position_error(means, truth).mean(axis=-1)


def mrmse(means, truth, run_axis=0):
    """``MRMSE_x``, ``MRMSE_y``, ``MRMSE_r``: time averages of the per-step RMSE over runs."""
    d = np.asarray(means)[..., :2] - np.asarray(truth)[..., :2]
    rx = np.sqrt(np.mean(d[..., 0] ** 2, axis=run_axis)).mean(axis=-1)
    ry = np.sqrt(np.mean(d[..., 1] ** 2, axis=run_axis)).mean(axis=-1)
    rr = rmse_k(means, truth, run_axis).mean(axis=-1)
    return {"x": float(rx), "y": float(ry), "r": float(rr)} if np.ndim(rr) == 0 else {"x": rx, "y": ry, "r": rr}


def converged(means, truth, threshold=CONVERGENCE_THRESHOLD_M, hold=0.1):
    """Per run: the final error is below ``threshold`` and stays there for the last ``hold`` of the steps."""
    e = position_error(means, truth)
    n_hold = max(1, int(round(hold * e.shape[-1])))
    return np.all(e[..., -n_hold:] < threshold, axis=-1)


def convergence_rate(means, truth, threshold=CONVERGENCE_THRESHOLD_M, hold=0.1):
    """Fraction of runs that converged (see :func:`converged`)."""
    return float(np.mean(converged(means, truth, threshold, hold)))


def nees(means, covs, truth, components=(0, 1)):
    """Normalised estimation error squared over ``components`` (default position), shape (..., steps).

    Its mean over runs of a consistent filter is ``len(components)``.
    """
    idx = list(components)
    e = np.asarray(means)[..., idx] - np.asarray(truth)[..., idx]
    P = np.asarray(covs)[..., idx, :][..., :, idx]
    return np.einsum("...i,...i->...", e, np.linalg.solve(P, e[..., None])[..., 0])


def selection_accuracy(selected, hypothesis_trmse):
    """Fraction of runs whose selected hypothesis (R,) has the lowest TRMSE (R, H)."""
    return float(np.mean(np.asarray(selected) == np.argmin(hypothesis_trmse, axis=-1)))
