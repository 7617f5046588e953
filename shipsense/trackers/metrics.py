"""Tracking metrics (shared/spec/trackers.md §4)."""

from __future__ import annotations

import numpy as np


def position_error(means, truth):
    """Horizontal position error (..., steps) of estimates and truth (x, y first)."""
    d = np.asarray(means)[..., :2] - np.asarray(truth)[..., :2]
    return np.sqrt(np.sum(d * d, axis=-1))


def rmse_k(means, truth, run_axis=0):
    """``RMSE_k``: root mean over runs of the squared position error at each step."""
    return np.sqrt(np.mean(position_error(means, truth) ** 2, axis=run_axis))


def nees(means, covs, truth, components=(0, 1)):
    """Normalised estimation error squared over ``components`` (default position), shape (..., steps).

    Its mean over runs of a consistent filter is ``len(components)``.
    """
    idx = list(components)
    e = np.asarray(means)[..., idx] - np.asarray(truth)[..., idx]
    P = np.asarray(covs)[..., idx, :][..., :, idx]
    return np.einsum("...i,...i->...", e, np.linalg.solve(P, e[..., None])[..., 0])
