r"""Square-root central-difference Kalman filter update.

van der Merwe, *Sigma-Point Kalman Filters for Probabilistic Inference in
Dynamic State-Space Models*, PhD thesis, OGI 2004, ch. 3 (SR-CDKF).  The
Cholesky factors are propagated by QR (:func:`tria`) and never re-factored
from a covariance:

.. math::
    S_y = \mathrm{tria}([Y^{(1)T}, Y^{(2)T}, R^{1/2}]), \quad
    K = P_{xy} S_y^{-T} S_y^{-1},

    S_x^+ = \mathrm{tria}([S_x - K Y^{(1)T}, K Y^{(2)T}, K R^{1/2}]),

the square-root form of ``P+ = P - K Pyy K^T`` (expand the product: the
cross terms are ``-Pxy K^T - K Pxy^T``).  Its covariance equals the CDKF's.
"""

from __future__ import annotations

import numpy as np

from shipsense.trackers.filters.cdkf import H_STIRLING, difference_terms
from shipsense.trackers.filters.core import Belief, innovation, prepare, solve_lower, solve_upper_t, tria


def update(belief: Belief, y, model, mask=None, h=H_STIRLING):
    """SR-CDKF measurement update; returns ``(belief, innovation)``."""
    y, present, R = prepare(y, model, mask)
    eps, Pxy, Y1, Y2 = difference_terms(belief, y, model, present, h)
    T = np.swapaxes
    n, m = Y1.shape[-2:]
    batch = np.broadcast_shapes(Y1.shape[:-2], R.shape[:-1])
    sqrtR = np.sqrt(R)
    # [Y1^T, Y2^T, R^(1/2)] written in place (R is diagonal)
    My = np.zeros(batch + (m, 2 * n + m))
    My[..., :n] = T(Y1, -1, -2)
    My[..., n:2 * n] = T(Y2, -1, -2)
    diag = np.arange(m)
    My[..., diag, 2 * n + diag] = sqrtR
    Sy = tria(My)
    Kt = solve_upper_t(Sy, solve_lower(Sy, T(Pxy, -1, -2)))   # K^T (..., m, n)
    K = T(Kt, -1, -2)
    mean = belief.mean + np.einsum("...nm,...m->...n", K, eps)
    # [S_x - K Y1^T, K Y2^T, K R^(1/2)] written in place
    Mx = np.empty(batch + (n, 2 * n + m))
    np.matmul(K, My[..., :n], out=Mx[..., :n])
    np.subtract(belief.chol, Mx[..., :n], out=Mx[..., :n])
    np.matmul(K, My[..., n:2 * n], out=Mx[..., n:2 * n])
    np.multiply(K, sqrtR[..., None, :], out=Mx[..., 2 * n:])
    Sx = tria(Mx)
    d = np.diagonal(Sx, axis1=-2, axis2=-1)
    ok = np.isfinite(Sx).all(axis=(-1, -2)) & np.isfinite(mean).all(axis=-1) & (d > 0).all(axis=-1)
    if not ok.all():
        # a failed element keeps its prior mean; a non-finite factor is replaced by the identity
        fallback = np.where(np.isfinite(belief.chol).all(axis=(-1, -2))[..., None, None], belief.chol,
                            np.eye(n))
        mean = np.where(ok[..., None] & np.isfinite(mean), mean, np.nan_to_num(belief.mean))
        Sx = np.where(ok[..., None, None], Sx, fallback)
    S = Sy @ T(Sy, -1, -2)
    return Belief(mean, Sx, belief.ok & ok), innovation(eps, S, Sy, present)
