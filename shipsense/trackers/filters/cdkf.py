r"""Central-difference Kalman filter update (Stirling interpolation, ``h = sqrt(3)``).

Nørgaard, Poulsen & Ravn, Automatica 2000; Ito & Xiong, IEEE TAC 2000.  With
points ``x +- h L_i`` and ``Y_i^+-`` their predictions,

.. math::
    \hat y = \frac{h^2 - n}{h^2} Y_0 + \frac{1}{2h^2} \sum_i (Y_i^+ + Y_i^-), \quad
    Y^{(1)}_i = \frac{Y_i^+ - Y_i^-}{2h}, \quad
    Y^{(2)}_i = \frac{\sqrt{h^2 - 1}}{2h^2} (Y_i^+ + Y_i^- - 2 Y_0),

    P_{yy} = Y^{(1)T} Y^{(1)} + Y^{(2)T} Y^{(2)} + R, \qquad P_{xy} = L\, Y^{(1)}.
"""

from __future__ import annotations

import numpy as np

from shipsense.trackers.filters.core import Belief, add_noise, gain_update, prepare, transposed
from shipsense.trackers.filters.ukf import sigma_points

H_STIRLING = float(np.sqrt(3.0))


def difference_terms(belief: Belief, y, model, present, h=H_STIRLING):
    """``eps``, ``Pxy`` and the first and second-order difference rows ``Y1``, ``Y2`` (..., n, m)."""
    x = belief.mean
    n = x.shape[-1]
    Y = model.h(sigma_points(x, belief.chol, h))
    Y0 = Y[..., :1, :]
    dp = model.residual(Y[..., 1:n + 1, :], Y0)
    dm = model.residual(Y[..., n + 1:, :], Y0)
    yhat = Y0[..., 0, :] + (dp + dm).sum(axis=-2) / (2.0 * h * h)
    keep = present[..., None, :]
    Y1 = (dp - dm) / (2.0 * h) * keep
    Y2 = np.sqrt(h * h - 1.0) / (2.0 * h * h) * (dp + dm) * keep
    eps = np.where(present, model.residual(y, yhat), 0.0)
    return eps, belief.chol @ Y1, Y1, Y2


def update(belief: Belief, y, model, mask=None, h=H_STIRLING):
    """CDKF measurement update; returns ``(belief, innovation)``."""
    y, present, R = prepare(y, model, mask)
    eps, Pxy, Y1, Y2 = difference_terms(belief, y, model, present, h)
    S = add_noise(transposed(Y1) @ Y1 + transposed(Y2) @ Y2, R)
    return gain_update(belief, eps, Pxy, S, present)
