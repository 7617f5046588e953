r"""Progressive-update EKF (the electric source study; cf. Zanetti 2012, recursive update filter).

The measurement update is split into ``N_pu`` sub-updates, each an EKF update
with noise ``R * N_pu`` re-linearised at the current estimate.  With
``N_pu = 1`` it is the EKF.  The innovation reported (and the log-likelihood
used by the bank) is the one of the full measurement at the prior,
``eps = y - h(x^-)``, ``S = H P^- H^T + R``.
"""

from __future__ import annotations

import numpy as np

from shipsense.defaults import N_PU
from shipsense.trackers.filters.core import Belief, gain_update, innovation, prepare, safe_cholesky
from shipsense.trackers.filters.ekf import linearised_terms


def update(belief: Belief, y, model, mask=None, n_pu: int = N_PU):
    """PUEKF measurement update with ``n_pu`` sub-updates; returns ``(belief, innovation)``."""
    if int(n_pu) < 1:
        raise ValueError(f"n_pu must be >= 1, got {n_pu}")
    y, present, R = prepare(y, model, mask)
    eye = np.eye(R.shape[-1])
    R_sub = np.where(present, R * n_pu, 1.0)[..., :, None] * eye
    first = None
    for _ in range(int(n_pu)):
        eps, H, P, Pxy = linearised_terms(belief, y, model, present)
        if first is None:
            first = (eps, H @ Pxy + R[..., :, None] * eye)
        belief, _ = gain_update(belief, eps, Pxy, H @ Pxy + R_sub, present, P)
    eps0, S0 = first
    Ls, ok = safe_cholesky(S0)
    return Belief(belief.mean, belief.chol, belief.ok & ok), innovation(eps0, S0, Ls, present)
