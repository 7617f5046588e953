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

from shipsense.trackers.filters._core import Belief, innovation, prepare, solve_lower, solve_upper_t, tria
from shipsense.trackers.filters.cdkf import H_STIRLING, difference_terms


def update(belief: Belief, y, model, mask=None, h=H_STIRLING):
    """SR-CDKF measurement update; returns ``(belief, innovation)``."""
    y, present, R = prepare(y, model, mask)
    eps, Pxy, Y1, Y2 = difference_terms(belief, y, model, present, h)
    T = np.swapaxes
    sqrtR = np.sqrt(R)[..., :, None] * np.eye(R.shape[-1])
    sqrtR = np.broadcast_to(sqrtR, np.broadcast_shapes(sqrtR.shape[:-2], Y1.shape[:-2]) + sqrtR.shape[-2:])
    Sy = tria(np.concatenate([T(Y1, -1, -2), T(Y2, -1, -2), sqrtR], axis=-1))
    Kt = solve_upper_t(Sy, solve_lower(Sy, T(Pxy, -1, -2)))   # K^T (..., m, n)
    K = T(Kt, -1, -2)
    mean = belief.mean + np.einsum("...nm,...m->...n", K, eps)
    Sx = tria(np.concatenate([belief.chol - K @ T(Y1, -1, -2), K @ T(Y2, -1, -2), K @ sqrtR], axis=-1))
    diag = np.diagonal(Sx, axis1=-2, axis2=-1)
    ok = np.isfinite(Sx).all(axis=(-1, -2)) & np.isfinite(mean).all(axis=-1) & (diag > 0).all(axis=-1)
    # a failed element keeps its prior mean; a non-finite factor is replaced by the identity
    fallback = np.where(np.isfinite(belief.chol).all(axis=(-1, -2))[..., None, None], belief.chol,
                        np.eye(Sx.shape[-1]))
    mean = np.where(ok[..., None] & np.isfinite(mean), mean, np.nan_to_num(belief.mean))
    Sx = np.where(ok[..., None, None], Sx, fallback)
    S = Sy @ T(Sy, -1, -2)
    return Belief(mean, Sx, belief.ok & ok), innovation(eps, S, Sy, present)
