r"""The interacting multiple model (IMM) filter over any filter unit: motion modes as one more batch axis.

A belief of the IMM (:class:`ModeBelief`) is one Gaussian per motion mode (:mod:`shipsense.models.motion_modes`)
and the modes' probabilities, for every batch element: means (..., M, n), factors (..., M, n, n),
probabilities (..., M).  One cycle (Blom & Bar-Shalom 1988; Bar-Shalom, Li & Kirubarajan 2001, section 11.6.6):

1. **mixing**: with the switching matrix :math:`\Pi_{ij}` over the step, the predicted mode probabilities
   :math:`\bar c_j = \sum_i \Pi_{ij}\mu_i`, the mixing weights :math:`\mu_{i|j} = \Pi_{ij}\mu_i/\bar c_j`, and
   each mode's start :math:`x^0_j = \sum_i \mu_{i|j} x_i`,
   :math:`P^0_j = \sum_i \mu_{i|j}\,[P_i + (x_i - x^0_j)(x_i - x^0_j)^T]`;
2. **mode-matched filtering**: every mode's time update from its start (its own transition and process
   noise), then the filter unit's measurement update, all modes of all elements in one batched call of the
   unit's compiled steps (:class:`~shipsense.trackers.filters.FilterUnit`);
3. **mode probabilities** from the innovation likelihoods :math:`\Lambda_j`:
   :math:`\mu_j = \bar c_j\Lambda_j / \sum_l \bar c_l\Lambda_l`, and the sample's log-likelihood
   :math:`\ln\sum_j \bar c_j\Lambda_j`;
4. **combination** for output (:func:`combine`): :math:`x = \sum_j \mu_j x_j`,
   :math:`P = \sum_j \mu_j [P_j + (x_j - x)(x_j - x)^T]`.

With a single mode this is the unit's own filter.  The innovation an IMM step reports (for consistency tests)
is the moment-matched mixture of the modes' innovations under the predicted probabilities :math:`\bar c`.

The mixing and combination are vectorised numpy over the batch; the mode-matched steps are the units'
compiled kernels.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from shipsense.models.field_model import Transitioned
from shipsense.trackers.filters.core import Belief, BeliefWithCov, Innovation, safe_cholesky


class ModeBelief(NamedTuple):
    """Mode-conditioned Gaussians and mode probabilities: ``mean`` (..., M, n), ``chol`` (..., M, n, n), ``ok``
    (..., M) health flags and ``prob`` (..., M)."""

    mean: np.ndarray
    chol: np.ndarray
    ok: np.ndarray
    prob: np.ndarray

    @property
    def cov(self):
        """The modes' covariances (..., M, n, n)."""
        return self.chol @ np.swapaxes(self.chol, -1, -2)

    @classmethod
    def start(cls, belief: Belief, prob):
        """Every mode at ``belief`` (mean (..., n)) with probabilities ``prob`` (M,) or (..., M)."""
        prob = np.asarray(prob, dtype=float)
        M = prob.shape[-1]
        mean = np.asarray(belief.mean, dtype=float)
        batch = mean.shape[:-1]
        n = mean.shape[-1]
        return cls(np.broadcast_to(mean[..., None, :], batch + (M, n)).copy(),
                   np.broadcast_to(np.asarray(belief.chol)[..., None, :, :], batch + (M, n, n)).copy(),
                   np.broadcast_to(np.asarray(belief.ok)[..., None], batch + (M,)).copy(),
                   np.broadcast_to(prob, batch + (M,)).copy())


def combine(belief: ModeBelief):
    """The moment-matched Gaussian of a :class:`ModeBelief`: mean (..., n), covariance (..., n, n)."""
    mu = belief.prob
    x = np.einsum("...j,...jn->...n", mu, belief.mean)
    d = belief.mean - x[..., None, :]
    P = np.einsum("...j,...jnm->...nm", mu, belief.cov + d[..., :, None] * d[..., None, :])
    return x, P


def mix(belief: ModeBelief, switching):
    """Step 1 of the cycle: the modes' starts (mean (..., M, n), covariance (..., M, n, n)) and the predicted
    mode probabilities (..., M), from ``switching`` (M, M) or (..., M, M)."""
    mu = belief.prob
    c = np.einsum("...i,...ij->...j", mu, switching)
    w = mu[..., :, None] * switching / np.where(c > 0, c, 1.0)[..., None, :]        # (..., i, j)
    x0 = np.einsum("...ij,...in->...jn", w, belief.mean)
    d = belief.mean[..., :, None, :] - x0[..., None, :, :]                             # (..., i, j, n)
    P0 = (np.einsum("...ij,...inm->...jnm", w, belief.cov)
          + np.einsum("...ij,...ijn,...ijm->...jnm", w, d, d))
    return x0, P0, c


def _logsumexp(a, axis=-1):
    top = np.max(a, axis=axis, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    return np.squeeze(top, axis) + np.log(np.sum(np.exp(a - top), axis=axis))


class IMM:
    """An interacting multiple model filter: a filter ``unit`` run on every motion mode of ``modes``
    (:class:`~shipsense.models.motion_modes.MotionModes`), batched over leading axes (see the module).

    ``start`` makes the first belief from a Gaussian; ``step`` runs one cycle (mixing, the modes' time and
    measurement updates, the mode probabilities) and returns the new :class:`ModeBelief` and the step's
    :class:`~shipsense.trackers.filters.core.Innovation` (the mixture's; ``loglik`` the IMM's log-likelihood
    of the sample).
    """

    def __init__(self, unit, modes):
        self.unit, self.modes = unit, modes

    def start(self, belief: Belief) -> ModeBelief:
        return ModeBelief.start(belief, self.modes.prior)

    def predict(self, belief: ModeBelief, model, tau=None):
        """Steps 1-2a: mixing and every mode's time update over steps ``tau`` (...) s (default: the model's
        period); returns the predicted mode-conditioned :class:`~shipsense.trackers.filters.core.Belief`
        (..., M) and the predicted mode probabilities (..., M)."""
        tau = np.asarray(self.modes.period if tau is None else tau, dtype=float)
        x0, P0, c = mix(belief, self.modes.switching(tau))
        A, Q = self.modes.transitions(x0, tau)
        if self.unit.name == "srcdkf":          # (its time update propagates the factor)
            L0, ok = safe_cholesky(P0)
            start = Belief(x0, L0, ok & belief.ok)
        else:                                   # (the covariance form starts from the covariance)
            start = BeliefWithCov.with_cov(x0, np.zeros_like(P0), belief.ok.copy(), P0)
        return self.unit.predict(start, Transitioned(model, A, Q)), c

    def update(self, predicted: Belief, c, y, model, mask=None):
        """Steps 2b-3: every mode's measurement update with sample ``y`` (..., m) and the mode probabilities;
        returns ``(ModeBelief, Innovation)``."""
        y = np.asarray(y, dtype=float)[..., None, :]
        mask = None if mask is None else np.asarray(mask, dtype=bool)[..., None, :]
        post, inn = self.unit.update(predicted, y, model, mask)
        ll = np.where(np.isnan(inn.loglik), -np.inf, inn.loglik)
        a = np.log(np.where(c > 0, c, 1e-300)) + ll
        total = _logsumexp(a)
        prob = np.exp(a - total[..., None])
        bad = ~np.isfinite(total)
        if bad.any():                         # (no mode explains the sample: keep the predicted probabilities)
            prob = np.where(bad[..., None], c, prob)
        eps = np.einsum("...j,...jm->...m", c, inn.eps)
        d = inn.eps - eps[..., None, :]
        S = np.einsum("...j,...jkl->...kl", c, inn.S + d[..., :, None] * d[..., None, :])
        nis = np.einsum("...k,...k->...", eps, np.linalg.solve(S, eps[..., None])[..., 0])
        return (ModeBelief(post.mean, post.chol, post.ok, prob),
                Innovation(eps, S, total, nis, inn.m[..., 0]))

    def step(self, belief: ModeBelief, y, model, mask=None, tau=None):
        """One IMM cycle: :meth:`predict` then :meth:`update`."""
        predicted, c = self.predict(belief, model, tau)
        return self.update(predicted, c, y, model, mask)
