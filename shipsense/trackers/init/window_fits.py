"""Window fits: the global fits of a window of samples, refined and tested.

The best distinct grid minima (:func:`~shipsense.trackers.init.grid.grid_minima`)
are refined by batched Levenberg-Marquardt fits
(:func:`~shipsense.trackers.fit.least_squares.fit_passages`) in stages and
checked by a chi-square goodness-of-fit test (:func:`chi2_limit`);
:func:`window_fits` returns them as :class:`WindowFits`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from shipsense.models.transitions import shared_powers
from shipsense.trackers.fit.least_squares import fit_passages
from shipsense.trackers.init.distinct import distinct_loglik, distinct_rows
from shipsense.trackers.init.grid import candidate_grid, grid_minima


def depth_prior(model, z_std, source_z=None):
    """Gaussian prior ``(mean, information)`` (internal units) on the source depth around ``source_z``
    (default the model's) with standard deviation ``z_std`` (m), for :func:`fit_passages`; None when
    ``z_std`` is None or the model has no depth."""
    if z_std is None or "z" not in model.labels:
        return None
    iz = model.labels.index("z")
    mean, weight = np.zeros(model.n), np.zeros(model.n)
    mean[iz] = (model.source_z if source_z is None else source_z) / model.x_scale[iz]
    weight[iz] = (model.x_scale[iz] / z_std) ** 2
    return mean, weight


def _refine_stages(refine, keep):
    """Cumulative numbers of grid minima refined per stage (each at least ``keep``, increasing)."""
    if refine is None:
        return [keep]
    stages = [int(refine)] if np.isscalar(refine) else [int(r) for r in refine]
    if any(r < 1 for r in stages) or any(b <= a for a, b in zip(stages, stages[1:])):
        raise ValueError(f"refine must be a positive count or increasing counts, got {refine!r}")
    return [max(keep, r) for r in stages]


def _dof(model, yfit, prior):
    """Degrees of freedom (R,) of passage fits to ``yfit`` (R, W, m): samples present, plus the prior's
    rows, minus the states."""
    rows = 0 if prior is None else int(np.count_nonzero(prior[1]))
    return np.maximum(np.isfinite(yfit).sum(axis=(1, 2)) + rows - model.n, 1)


def chi2_expected(model, yfit, prior, huber=None):
    """Mean (R,) of the chi-square (Huber cost) of fits to ``yfit`` at the noise level."""
    dof = _dof(model, yfit, prior).astype(float)
    return dof if huber is None else dof * huber.moments[0]


def chi2_limit(model, yfit, prior, gof, huber=None):
    """Chi-square (R,) above which a fit to ``yfit`` fails the goodness-of-fit test at level ``gof``.

    With ``huber`` (robust fits) the statistic is the Huber cost, and its limit the normal approximation of
    its distribution under the noise's outlier model (:meth:`~shipsense.trackers.fit.robust.Huber.limit`).
    """
    from scipy import special  # chdtri(dof, q) = scipy.stats.chi2.isf(q, dof), without importing scipy.stats

    if gof is None:
        return np.full(yfit.shape[0], np.inf)
    dof = _dof(model, yfit, prior)
    return special.chdtri(dof, gof) if huber is None else huber.limit(dof, gof)


@dataclass(frozen=True)
class WindowFits:
    """The distinct fits of passages' windows, at each window's first sample (internal units).

    Attributes
    ----------
    theta : ndarray, shape (R, M, n)
        Fitted initial states, best first.
    chi2 : ndarray, shape (R, M)
        Their chi-square (Huber cost for robust fits).
    info : ndarray, shape (R, M, n, n)
        Gauss-Newton information at the fits.
    found : ndarray of bool, shape (R, M)
        False where a passage had fewer distinct fits (the entry repeats its best).
    limit : ndarray, shape (R,)
        The goodness-of-fit test's limit on the chi-square.
    expected : ndarray, shape (R,)
        The chi-square's mean for a fit at the noise level (its degrees of freedom; for Huber fits, times
        the cost's mean per residual).
    """

    theta: np.ndarray
    chi2: np.ndarray
    info: np.ndarray
    found: np.ndarray
    limit: np.ndarray
    expected: np.ndarray

    def take(self, rows):
        """The fits of passages ``rows`` (indices or a boolean mask over the R passages)."""
        return WindowFits(*(getattr(self, f.name)[rows] for f in fields(self)))

    @property
    def fit_ok(self):
        """Whether each passage's best fit passes the goodness-of-fit test (R,)."""
        return self.chi2[:, 0] <= self.limit

    @property
    def loglik(self):
        """The fits' log-likelihoods ``-chi2 / 2`` (R, M), ``-inf`` for repeats (:func:`distinct_loglik`)."""
        return distinct_loglik(self.chi2, self.found)


def _window_middle(model, W):
    """The position at the middle of a ``W``-sample window as a linear map of its first state (2, n): where
    the distinct minima are told apart."""
    return shared_powers(model.A, W)[W // 2][:2]


def refine_minima(model, yfit, starts, *, stages, keep, distinct_m, prior, gof, explore_samples, taus=None,
                  huber=None):
    """The ``keep`` best distinct Levenberg-Marquardt fits of each passage's window ``yfit`` (R, W, m),
    started from its best distinct grid minima ``starts`` (R, stages[-1], n) (:func:`grid_minima`), refined
    in ``stages`` (a passage whose best fit so far fails the chi-square test gets the next stage's minima);
    :class:`WindowFits`."""
    R, W, _ = yfit.shape
    mid = _window_middle(model, W)
    M = stages[-1]
    if explore_samples is not None and explore_samples < 2:
        raise ValueError(f"explore_samples must be at least 2, got {explore_samples!r}")
    explore = 1 if explore_samples is None else max(1, W // int(explore_samples))
    ysub = yfit[:, ::explore]
    tsub = None if taus is None else taus[:, ::explore]
    limit = chi2_limit(model, ysub, prior, gof, huber)
    theta = np.zeros((R, M, model.n))
    chi2 = np.full((R, M), np.inf)
    info = np.zeros((R, M, model.n, model.n))
    todo, lo = np.arange(R), 0
    for hi in stages:
        first = starts[todo, lo:hi].reshape(-1, model.n)
        t, c, j = fit_passages(model, np.repeat(ysub[todo], hi - lo, axis=0), first, W, stride=explore,
                               return_information=True, prior=prior, huber=huber,
                               taus=None if tsub is None else np.repeat(tsub[todo], hi - lo, axis=0))
        theta[todo, lo:hi] = t.reshape(todo.size, hi - lo, -1)
        chi2[todo, lo:hi] = np.where(np.isfinite(c), c, np.inf).reshape(todo.size, hi - lo)
        info[todo, lo:hi] = j.reshape(todo.size, hi - lo, model.n, model.n)
        todo, lo = np.flatnonzero(chi2.min(axis=1) > limit), hi
        if todo.size == 0:
            break
    # the best ``keep`` distinct refined fits (fits that converged to the same minimum count once: a repeat of
    # the best fills a passage's row at log-likelihood -inf, no weight)
    sel, found = distinct_rows(chi2, theta @ mid.T, keep, distinct_m)
    pick = (np.arange(R)[:, None], sel)
    theta, chi2, info = (a[pick] for a in (theta, chi2, info))
    if explore > 1:   # polish the kept fits on every sample of the window
        t, c, j = fit_passages(model, np.repeat(yfit, keep, axis=0), theta.reshape(R * keep, -1), W,
                               return_information=True, prior=prior, huber=huber,
                               taus=None if taus is None else np.repeat(taus, keep, axis=0))
        theta, chi2, info = t.reshape(R, keep, -1), c.reshape(R, keep), j.reshape(R, keep, model.n, model.n)
        limit = chi2_limit(model, yfit, prior, gof, huber)
    return WindowFits(theta, np.where(np.isfinite(chi2), chi2, np.inf), info, found, limit,
                      chi2_expected(model, yfit, prior, huber))


def window_fits(model, yfit, *, ranges, speeds, taus=None, bearing_step_deg=15.0, course_step_deg=30.0,
                grid_samples=16, keep=5, distinct_m=15.0, source_z=None, z_std=None, refine=None, gof=0.01,
                explore_samples=None, huber=None, grid_reserve=0):
    """Global fits of given windows ``yfit`` (R, W, m) (internal units, NaN = missing): the grid search on
    every ``W // grid_samples``-th sample (at least ``grid_samples`` of them and fewer than twice as many, or
    all of a window shorter than that;
    ``grid_reserve``: :func:`grid_terms`' ``reserve``), then :func:`refine_minima`.  ``taus`` (R, W),
    optional: the samples' times (s) after each window's first (irregular sampling; the grid search then uses
    the nominal steps, the fits the times).  Options as for :func:`global_init`; returns :class:`WindowFits`."""
    R, W, _ = yfit.shape
    stride = max(1, W // int(grid_samples))
    grid = candidate_grid(model, ranges, np.arange(0.0, 360.0, bearing_step_deg),
                          np.arange(0.0, 360.0, course_step_deg), speeds, source_z)
    stages = _refine_stages(refine, keep)
    starts = grid_minima(model, yfit[:, ::stride], grid, W, stride, stages[-1], distinct_m,
                         _window_middle(model, W), grid_reserve)
    return refine_minima(model, yfit, starts, stages=stages, keep=keep,
                         distinct_m=distinct_m, prior=depth_prior(model, z_std, source_z), gof=gof,
                         explore_samples=explore_samples, taus=taus, huber=huber)
