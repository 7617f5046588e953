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

from functools import lru_cache

import numpy as np

from shipsense.physics.seismic import wrap_axial
from shipsense.trackers.filters.core import Belief, add_noise, gain_update, prepare, transposed


@lru_cache(maxsize=32)
def merwe_weights(n, alpha=1.0, beta=2.0, kappa=0.0):
    """Spread ``sqrt(n + lambda)`` and weights ``(Wm, Wc)`` (read-only) of the scaled unscented transform."""
    lam = alpha**2 * (n + kappa) - n
    if n + lam <= 0:
        raise ValueError(f"alpha^2 (n + kappa) must be > 0, got alpha={alpha}, kappa={kappa}, n={n}")
    Wm = np.full(2 * n + 1, 0.5 / (n + lam))
    Wm[0] = lam / (n + lam)
    Wc = Wm.copy()
    Wc[0] += 1.0 - alpha**2 + beta
    Wm.flags.writeable = Wc.flags.writeable = False
    return float(np.sqrt(n + lam)), Wm, Wc


def sigma_points(x, chol, spread, center=True):
    """Points ``[x,] x + spread L_i, x - spread L_i`` (..., 2n[+1], n) of a mean (..., n) and factor (..., n, n).

    ``L_i`` are the columns of the factor.  Written into one preallocated
    array through flat (..., n*n) blocks, so that every operation has a long
    contiguous inner loop (faster than broadcasting rows of length n).
    """
    n = x.shape[-1]
    c = int(center)
    batch = np.broadcast_shapes(x.shape[:-1], chol.shape[:-2])
    S = np.multiply(spread, np.swapaxes(chol, -1, -2), order="C").reshape(chol.shape[:-2] + (n * n,))
    xt = np.tile(x if x.shape[:-1] == batch else np.broadcast_to(x, batch + (n,)), n)   # (..., n*n): x per point
    out = np.empty(batch + ((2 * n + c) * n,))
    if center:
        out[..., :n] = x
    np.add(xt, S, out=out[..., c * n:(c + n) * n])
    np.subtract(xt, S, out=out[..., (c + n) * n:])
    return out.reshape(batch + (2 * n + c, n))


def sigma_statistics(belief: Belief, y, model, present, spread, Wm, Wc, center=True):
    """Innovation ``eps``, cross-covariance ``Pxy`` and ``Pyy`` (without R) of a symmetric point set.

    Points: the mean (if ``center``) then ``x + spread L_i`` and ``x - spread L_i``,
    all off-centre points with the same weight, so that
    ``Pxy = spread W L (dY+ - dY-)`` (the centre's offset is zero).
    Angular (axial) channels are averaged as residuals about the first point's
    prediction.  Rows of masked components are zeroed.
    """
    n = belief.mean.shape[-1]
    c = int(center)
    if Wc[c:].min() != Wc[c:].max():
        raise ValueError("sigma_statistics needs equal weights on the off-centre points")
    Y = model.h(sigma_points(belief.mean, belief.chol, spread, center))     # (..., N, m)
    N, m = Y.shape[-2:]
    yhat = Wm @ Y
    cols = model.axial_cols
    if cols is not None:   # average angles as residuals about the first point's prediction
        Ya = Y[..., cols]
        yhat[..., cols] = Ya[..., 0, :] + Wm @ wrap_axial(Ya - Ya[..., :1, :])
    # flat (..., N*m) rows: contiguous inner loops instead of rows of length m
    dY = (Y.reshape(Y.shape[:-2] + (N * m,)) - np.tile(yhat, N)).reshape(Y.shape)
    if cols is not None:
        dY[..., cols] = wrap_axial(dY[..., cols])
    if not present.all():
        dY = dY * present[..., None, :]
    WdY = (dY.reshape(dY.shape[:-2] + (dY.shape[-2] * dY.shape[-1],)) * np.repeat(Wc, dY.shape[-1])).reshape(dY.shape)
    Pyy = transposed(dY) @ WdY
    Pxy = belief.chol @ (WdY[..., c:c + n, :] - WdY[..., c + n:, :])
    if spread != 1.0:
        Pxy *= spread
    eps = np.where(present, model.residual(y, yhat), 0.0)
    return eps, Pxy, Pyy


def update(belief: Belief, y, model, mask=None, alpha=1.0, beta=2.0, kappa=0.0):
    """UKF measurement update; returns ``(belief, innovation)``."""
    y, present, R = prepare(y, model, mask)
    spread, Wm, Wc = merwe_weights(belief.mean.shape[-1], alpha, beta, kappa)
    eps, Pxy, Pyy = sigma_statistics(belief, y, model, present, spread, Wm, Wc)
    return gain_update(belief, eps, Pxy, add_noise(Pyy, R), present)
