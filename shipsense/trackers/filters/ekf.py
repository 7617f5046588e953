r"""Extended Kalman filter update with the model's analytic Jacobian.

.. math::  S = H P H^T + R, \quad K = P H^T S^{-1}, \quad
           x^+ = x + K (y - h(x)), \quad P^+ = P - K S K^T .

Masked components have their rows of ``H`` and their innovation set to zero
and a unit, uncoupled variance, so they contribute exactly nothing.
"""

from __future__ import annotations

import numpy as np

from shipsense.trackers.filters.core import Belief, add_noise, gain_update, prepare, transposed


def linearised_terms(belief: Belief, y, model, present):
    """Innovation, ``H`` (masked), ``P`` and ``P H^T`` at the belief's mean."""
    x = belief.mean
    H = np.where(present[..., :, None], model.H(x), 0.0)
    eps = np.where(present, model.residual(y, model.h(x)), 0.0)
    P = belief.cov
    return eps, H, P, P @ transposed(H)


def update(belief: Belief, y, model, mask=None):
    """EKF measurement update; returns ``(belief, innovation)``."""
    y, present, R = prepare(y, model, mask)
    eps, H, P, Pxy = linearised_terms(belief, y, model, present)
    S = add_noise(H @ Pxy, R)
    return gain_update(belief, eps, Pxy, S, present, P)
