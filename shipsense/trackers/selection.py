"""Choosing among hypotheses (trackers.md §3): the mixture of a bank's hypotheses and its mean-square error."""

from __future__ import annotations

import numpy as np


def mixture_mse(weights, means, covs, about):
    """Mean-square-error matrix about ``about`` of a Gaussian mixture, summed over its axis 1:
    ``sum_j w_j (P_j + e_j e_j^T)``, ``e_j = means_j - about`` (components of zero weight ignored, even
    with NaN means)."""
    w = np.asarray(weights)[..., None, None]
    e = means - about
    return np.sum(np.where(w > 0, w * (covs + e[..., :, None] * e[..., None, :]), 0.0), axis=1)
