"""Robust (Huber) fits: the cost, its expected value under the noise's outlier model, and
the leverage-corrected information of a robust fit.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache, partial

import numpy as np

from shipsense.defaults import HUBER_GAMMA


@dataclass(frozen=True)
class Huber:
    """Robust (Huber) fits, and what their cost should be under the noise's outlier model.

    The noise of a whitened residual is taken as ``(1 - eps) N(0, 1) + eps N(0, scale^2)`` (the contaminated
    Gaussian of :mod:`shipsense.physics.noise`; ``eps = 0``: Gaussian).  Fits minimise :func:`huber_cost`
    with threshold ``gamma``; the goodness-of-fit test compares that cost with its distribution under the
    noise model: mean ``dof mu`` and variance ``dof sigma^2`` per residual (:attr:`moments`, by
    Gauss-Hermite quadrature), a normal approximation.
    """

    gamma: float = HUBER_GAMMA
    eps: float = 0.0
    scale: float = 10.0

    def expect(self, f):
        """``E[f(e)]`` for one residual ``e`` of the noise model (adaptive quadrature, split at +-gamma)."""
        from scipy import integrate

        total = 0.0
        for share, sd in ((1.0 - self.eps, 1.0), (self.eps, self.scale)):
            if share == 0.0:
                continue
            pdf = partial(_normal_pdf, sd=sd)
            for lo, hi in ((-np.inf, -self.gamma), (-self.gamma, self.gamma), (self.gamma, np.inf)):
                total += share * integrate.quad(lambda e, pdf=pdf: f(e) * pdf(e), lo, hi, epsabs=1e-12)[0]
        return total

    @property
    def moments(self):
        """Mean and variance of ``2 rho(e)`` (:func:`huber_cost`) for one residual ``e`` of the noise model."""
        return _huber_figures(self.gamma, self.eps, self.scale)[:2]

    @property
    def variance_factor(self):
        """``kappa = E[psi^2] / E[psi']^2``: the Huber M-estimate's variance over the nominal (Gaussian) one
        under the noise model (Huber 1964): for Gaussian noise the reciprocal of the estimate's efficiency
        (95 % at gamma = 1.345), larger with outliers.  A robust fit's covariance is ``kappa (J^T J)^-1``."""
        return _huber_figures(self.gamma, self.eps, self.scale)[2]

    def variance_factor_at(self, threshold):
        """``kappa`` of a Huber clip at ``threshold`` (array) on a residual of the noise model, in closed form:
        ``E[min(e^2, c^2)] / P(|e| <= c)^2`` (``threshold = gamma``: :attr:`variance_factor`; infinite: the
        noise's variance ``1 - eps + eps scale^2``)."""
        from scipy.special import ndtr

        c = np.asarray(threshold, dtype=float)
        finite = np.isfinite(c)
        psi2, slope = np.zeros_like(c), np.zeros_like(c)
        for share, sd in ((1.0 - self.eps, 1.0), (self.eps, self.scale)):
            if share == 0.0:
                continue
            a = np.where(finite, c, 0.0) / sd
            inside = np.where(finite, 2.0 * ndtr(a) - 1.0, 1.0)
            tail_a = np.where(finite, a * np.exp(-0.5 * a * a) / np.sqrt(2.0 * np.pi), 0.0)
            tail_c = np.where(finite, a * a * 2.0 * ndtr(-a), 0.0) * sd * sd
            psi2 += share * (sd * sd * (inside - 2.0 * tail_a) + tail_c)
            slope += share * inside
        return psi2 / slope**2

    def _figures(self):
        def cost(e):
            return huber_cost(np.atleast_1d(e)[:, None], self.gamma)[0]

        mean = self.expect(cost)
        psi2 = self.expect(lambda e: min(e * e, self.gamma**2))
        slope = self.expect(lambda e: float(abs(e) <= self.gamma))
        return mean, self.expect(lambda e: cost(e) ** 2) - mean * mean, psi2 / slope**2

    def limit(self, dof, gof):
        """Cost (like ``dof``) above which a fit with ``dof`` degrees of freedom fails at level ``gof``."""
        from scipy.special import ndtri  # -ndtri(q) = scipy.stats.norm.isf(q), without importing scipy.stats

        mu, var = self.moments
        return np.asarray(dof) * mu - ndtri(gof) * np.sqrt(np.asarray(dof) * var)


@lru_cache(maxsize=32)
def _huber_figures(gamma, eps, scale):
    return Huber(gamma, eps, scale)._figures()


def _normal_pdf(e, sd):
    """The N(0, sd^2) density (scipy.stats.norm(scale=sd).pdf, without importing scipy.stats, a large module)."""
    u = e / sd
    return np.exp(-u**2 / 2.0) / np.sqrt(2.0 * np.pi) / sd


def huber_cost(r, gamma):
    """Huber's ``2 rho(r)`` summed over the last axis: ``r^2`` where ``|r| <= gamma``, ``2 gamma |r| - gamma^2``
    beyond (equal to the chi-square of Gaussian residuals that are not outliers)."""
    a = np.abs(r)
    return np.sum(np.where(a <= gamma, r * r, 2.0 * gamma * a - gamma * gamma), axis=-1)


def leverage_information(J, JtJ, huber, rows):
    """The information ``I`` of a Huber fit whose covariance ``variance_factor * I^-1`` accounts for leverage.

    The asymptotic ``kappa (J^T J)^-1`` holds when every residual has a small leverage ``h_i`` (the diagonal
    of ``J (J^T J)^-1 J^T``).  A residual of leverage ``h`` is fitted to ``(1 - h)`` of its noise, so Huber's
    clip at ``gamma`` on the residual is a clip at ``gamma / (1 - h)`` on the noise: an outlier on a sample
    that dominates the information (an inverse-cube field at the closest approach) is masked and enters
    with nearly its full variance.  The covariance is then the sandwich
    ``(J^T J)^-1 J^T diag(kappa(gamma / (1 - h_i))) J (J^T J)^-1``
    (:meth:`Huber.variance_factor_at`); returned as ``I`` with ``kappa I^-1`` equal to it, so that callers
    scaling ``I^-1`` by :attr:`Huber.variance_factor` get it (``I = J^T J`` when every leverage is small).
    Rows of ``J`` (B, M, n) past ``rows`` are a prior's (exact, weight 1 relative to the noise's kappa).
    """
    with np.errstate(all="ignore"):
        inv = np.linalg.pinv(JtJ, hermitian=True)
        h = np.clip(np.einsum("bmi,bij,bmj->bm", J, inv, J), 0.0, 1.0 - 1e-12)
        rel = huber.variance_factor_at(huber.gamma / (1.0 - h)) / huber.variance_factor
    rel[:, rows:] = 1.0
    rel = np.where(np.isfinite(rel), rel, 1.0)
    meat = np.swapaxes(J, -1, -2) @ (J * rel[..., None])
    try:
        info = JtJ @ np.linalg.solve(meat + 1e-300 * np.eye(JtJ.shape[-1]), JtJ)
    except np.linalg.LinAlgError:   # a fit some state component does not reach (a singular J^T J): its pseudo-inverse
        with np.errstate(all="ignore"):
            info = JtJ @ np.linalg.pinv(meat, hermitian=True) @ JtJ
    ok = np.isfinite(info).all(axis=(-1, -2))
    return np.where(ok[:, None, None], 0.5 * (info + np.swapaxes(info, -1, -2)), JtJ)
