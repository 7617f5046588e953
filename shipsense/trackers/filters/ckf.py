r"""Cubature Kalman filter update: ``2n`` equally weighted points ``x +- sqrt(n) L_i``.

Arasaratnam & Haykin, "Cubature Kalman filters", IEEE TAC 2009 (third-degree
spherical-radial rule).
"""

from __future__ import annotations

import numpy as np

from shipsense.trackers.filters.core import Belief, add_noise, gain_update, prepare
from shipsense.trackers.filters.ukf import sigma_statistics


def update(belief: Belief, y, model, mask=None):
    """CKF measurement update; returns ``(belief, innovation)``."""
    y, present, R = prepare(y, model, mask)
    n = belief.mean.shape[-1]
    W = np.full(2 * n, 0.5 / n)
    eps, Pxy, Pyy = sigma_statistics(belief, y, model, present, np.sqrt(n), W, W, center=False)
    return gain_update(belief, eps, Pxy, add_noise(Pyy, R), present)
