r"""Unscented Kalman filter update (scaled sigma points).

Julier & Uhlmann 1997; Wan & van der Merwe 2000.  With
:math:`\lambda = \alpha^2 (n + \kappa) - n` the ``2n + 1`` points are
:math:`x` and :math:`x \pm \sqrt{n + \lambda}\, L_i` (columns of the Cholesky
factor), with weights :math:`W^m_0 = \lambda/(n+\lambda)`,
:math:`W^c_0 = W^m_0 + 1 - \alpha^2 + \beta`,
:math:`W_i = 1 / (2(n+\lambda))`.  The points are drawn from the predicted
belief (as FilterPy does after its predict), so with a linear model the
update is the Kalman filter's.
"""

from __future__ import annotations

import numpy as np

from shipsense.trackers.filters._core import Belief, gain_update, prepare


def merwe_weights(n, alpha=1.0, beta=2.0, kappa=0.0):
    """Spread ``sqrt(n + lambda)`` and weights ``(Wm, Wc)`` of the scaled unscented transform."""
    lam = alpha**2 * (n + kappa) - n
    if n + lam <= 0:
        raise ValueError(f"alpha^2 (n + kappa) must be > 0, got alpha={alpha}, kappa={kappa}, n={n}")
    Wm = np.full(2 * n + 1, 0.5 / (n + lam))
    Wm[0] = lam / (n + lam)
    Wc = Wm.copy()
    Wc[0] += 1.0 - alpha**2 + beta
    return np.sqrt(n + lam), Wm, Wc


def symmetric_points(dX, center=True):
    """Offsets ``[0,] +dX_i, -dX_i`` (..., 2n[+1], n) from rows ``dX_i`` (..., n, n), preallocated."""
    n = dX.shape[-1]
    c = int(center)
    out = np.empty(dX.shape[:-2] + (2 * n + c, n))
    if center:
        out[..., 0, :] = 0.0
    out[..., c:c + n, :] = dX
    np.negative(dX, out=out[..., c + n:, :])
    return out


def sigma_statistics(belief: Belief, y, model, present, spread, Wm, Wc, center=True):
    """Innovation ``eps``, cross-covariance ``Pxy`` and ``Pyy`` (without R) of a symmetric point set.

    Points: the mean (if ``center``) then ``x + spread L_i`` and ``x - spread L_i``.
    Angular (axial) channels are averaged as residuals about the first point's
    prediction.  Rows of masked components are zeroed.
    """
    x = belief.mean
    dXs = symmetric_points(spread * np.swapaxes(belief.chol, -1, -2), center)   # (..., N, n) offsets
    Y = model.h(x[..., None, :] + dXs)                     # (..., N, m)
    if model.axial.any():  # average angles as residuals about the first point's prediction
        ref = Y[..., :1, :]
        yhat = ref[..., 0, :] + (Wm @ model.residual(Y, ref))
        dY = model.residual(Y, yhat[..., None, :])
    else:
        yhat = Wm @ Y
        dY = Y - yhat[..., None, :]
    if not present.all():
        dY = dY * present[..., None, :]
    WdY = dY * Wc[:, None]
    Pyy = np.swapaxes(dY, -1, -2) @ WdY
    Pxy = np.swapaxes(dXs, -1, -2) @ WdY
    eps = np.where(present, model.residual(y, yhat), 0.0)
    return eps, Pxy, Pyy


def update(belief: Belief, y, model, mask=None, alpha=1.0, beta=2.0, kappa=0.0):
    """UKF measurement update; returns ``(belief, innovation)``."""
    y, present, R = prepare(y, model, mask)
    spread, Wm, Wc = merwe_weights(belief.mean.shape[-1], alpha, beta, kappa)
    eps, Pxy, Pyy = sigma_statistics(belief, y, model, present, spread, Wm, Wc)
    return gain_update(belief, eps, Pxy, Pyy + R[..., :, None] * np.eye(R.shape[-1]), present)
