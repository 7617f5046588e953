"""The global initialiser: where is the passage, with no prior on its position.

:func:`global_init` finds the detection (:mod:`~shipsense.trackers.init.detection`),
fits the window that starts there (:mod:`~shipsense.trackers.init.window_fits`)
and returns the fits as the hypotheses of a bank (:class:`GlobalInit`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shipsense.models.transitions import powers
from shipsense.trackers.fit.least_squares import fit_passages
from shipsense.trackers.init.detection import detection_start, fit_end, window_samples
from shipsense.trackers.init.distinct import distinct_loglik
from shipsense.trackers.init.window_fits import chi2_limit, depth_prior, window_fits


@dataclass(frozen=True)
class GlobalInit:
    """Hypotheses from :func:`global_init` for R passages (SI units).

    Attributes
    ----------
    start : ndarray of int, shape (R,)
        First sample the bank processes (after the fitted window).
    seeds : ndarray, shape (R, M, n)
        Means at ``start`` (the batch fits propagated to it).
    P0 : ndarray, shape (R, M, n, n)
        Their covariances (batch-fit covariance propagated, plus the process noise).
    loglik : ndarray, shape (R, M)
        ``-chi2 / 2`` of each batch fit: the bank's prior log-likelihoods.
    window : ndarray, shape (R, M, W, n)
        The fitted trajectories over the window (estimates before ``start``).
    k0 : ndarray of int, shape (R,)
        First sample of the window (the detection).
    fit_ok : ndarray of bool, shape (R,), optional
        Whether the passage's best fit passes the chi-square goodness-of-fit
        test (:func:`global_init`'s ``gof``); a failed passage is still seeded
        from its best fit.
    """

    start: np.ndarray
    seeds: np.ndarray
    P0: np.ndarray
    loglik: np.ndarray
    window: np.ndarray
    k0: np.ndarray
    fit_ok: np.ndarray | None = None


def global_init(model, measurements, *, ranges, speeds, bearing_step_deg=15.0, course_step_deg=30.0,
                window_s=15.0, grid_samples=16, keep=5, distinct_m=15.0, snr_start=5.0, inflate=2.0,
                source_z=None, common_start=False, through_peak=None, z_std=None, refine=None, gof=0.01,
                explore_samples=None, huber=None):
    """Global initialisation of passages from a grid search with the moment eliminated in closed form.

    Parameters
    ----------
    model : FieldModel
    measurements : ndarray, shape (R, K, m)
        SI units, NaN = missing.
    ranges, speeds : sequence of float
        Grid of start ranges from the array centroid (m) and speeds (m/s).
    bearing_step_deg, course_step_deg : float
        Grid steps of the start bearing and the course.
    window_s : float
        Duration (s) fitted from the detection on (W samples); the grid search
        uses about ``grid_samples`` of them, the refinement all.
    keep : int
        Distinct minima kept per passage (M): the best ones more than ``distinct_m`` apart (the default was
        chosen on the wide-prior study's two-magnetometer passages: fewer minima lost passages, more cost
        time and converged no more often; docs: Results).
    refine : int or sequence of int, optional
        Distinct grid minima refined by the batch fit (default ``keep``); the
        best ``keep`` distinct refined fits seed the bank.  At high SNR the
        global minimum's basin can be narrower than the grid spacing, so it
        may not be among the ``keep`` best grid points (docs: Results).
        Increasing counts, e.g. ``(5, 20, 60)``, refine in stages: the first
        count for every passage, each further one only for the passages whose
        best fit so far fails the chi-square test (``gof``), so that the cost
        goes to the passages that need it.
    gof : float or None
        Level of the chi-square goodness-of-fit test of the fits (default
        1 %): a fit whose chi-square exceeds the ``1 - gof`` quantile for
        its degrees of freedom has not explained the data to the noise
        level (a local minimum, or a source the model does not describe).
        At 0.1 % a single-magnetometer fit far off the truth passed (docs:
        Results).  It drives the staged ``refine`` and gives
        ``GlobalInit.fit_ok``.  (Scaling a failed fit's covariance by its
        reduced chi-square, the Birge ratio, was tried and dropped: it took
        the first bank of two-magnetometer passages further from the
        constant-velocity bound; ``experiments/refit_after_peak.py``.)
    explore_samples : int, optional
        The refinement's fits of the grid minima use about this many samples
        of the window, evenly spaced (and the staged test those samples); the
        ``keep`` fits kept are then polished on every sample.  Exploring many
        minima then costs that much less, and on S0 exploring them on a few
        samples missed the window's global minimum less often than refining
        them in stages on every sample (``experiments/staged_refinement.py``,
        docs: Results).  None: every sample.
    snr_start : float
        The window starts at the first sample with some channel above this SNR (adaptive start).
    inflate : float
        Factor on the batch-fit covariance (linearisation of a nonlinear fit).
    z_std : float, optional
        Standard deviation (m) of a Gaussian prior on the source depth around
        ``source_z`` (models with electrodes): the batch fits are then MAP fits
        and their covariances include it.  The envelope fits otherwise often
        settle on a wrong depth, the depth and ``p`` trading off in the far
        field (docs: Results); the studies' bank starts with the same prior
        (``BankConfig.z_std``).
    common_start : bool
        Start every passage's window at the latest detection of the batch, so
        that one bank runs them all (:func:`track_with_global_init`).
    through_peak : float, optional
        Extend the refinement (not the grid search) past the window until the
        strongest channel has fallen below this fraction of its peak
        (:func:`fit_end`): the batch fit then spans the closest approach, and
        the bank starts after it.

    huber : Huber, optional
        Robust (Huber) fits and their test under the noise's outlier model
        (:class:`~shipsense.trackers.fit.robust.Huber`).

    Returns
    -------
    GlobalInit
    """
    y_si = np.asarray(measurements, dtype=float)
    R, K, m = y_si.shape
    window = window_samples(model, K, window_s)
    y = y_si / model.y_scale
    k0 = detection_start(model, y_si, snr_start, window)
    if common_start:   # one bank start for the whole batch: every window starts at the latest detection
        k0 = np.full(R, k0.max())
    yfit = y[np.arange(R)[:, None], k0[:, None] + np.arange(window)[None, :]]           # (R, W, m)
    fits = window_fits(model, yfit, ranges=ranges, speeds=speeds, bearing_step_deg=bearing_step_deg,
                       course_step_deg=course_step_deg, grid_samples=grid_samples, keep=keep, distinct_m=distinct_m,
                       source_z=source_z, z_std=z_std, refine=refine, gof=gof,
                       explore_samples=explore_samples, huber=huber)
    prior = depth_prior(model, z_std, source_z)
    theta, chi2, info, limit = fits.theta.reshape(R * keep, -1), fits.chi2.reshape(-1), fits.info, fits.limit
    end = fit_end(model, y_si, k0, window, through_peak)
    if common_start:
        end = np.full(R, end.max())
    Wf = int((end - k0).max())
    if Wf > window:   # continue every fit through the closest approach, from the window's solution
        ks = k0[:, None] + np.arange(Wf)[None, :]
        yfit = y[np.arange(R)[:, None], np.minimum(ks, K - 1)]                           # (R, Wf, m)
        yfit = np.where((ks < end[:, None])[..., None], yfit, np.nan)                   # each passage to its end
        theta, chi2, info = fit_passages(model, np.repeat(yfit, keep, axis=0), theta, Wf, return_information=True,
                                         prior=prior, huber=huber)
        limit = chi2_limit(model, yfit, prior, gof, huber)
    theta, chi2 = theta.reshape(R, keep, -1), chi2.reshape(R, keep)
    cov = np.linalg.pinv(info, hermitian=True).reshape(R, keep, model.n, model.n) * inflate
    # propagate to the first sample after the fitted stretch
    Ak = powers(model.A, Wf + 1)
    Aw = Ak[np.minimum(end - k0, Wf)]                                                   # (R, n, n)
    seeds = np.einsum("rij,rmj->rmi", Aw, theta)
    P0 = Aw[:, None] @ cov @ np.swapaxes(Aw, -1, -2)[:, None] + (end - k0)[:, None, None, None] * model.Q
    traj = np.einsum("kij,rmj->rmki", Ak[:Wf], theta)
    xs = model.x_scale
    return GlobalInit(start=end, seeds=seeds * xs, P0=P0 * np.outer(xs, xs),
                      loglik=distinct_loglik(chi2, fits.found), window=traj * xs, k0=k0,
                      fit_ok=chi2.min(axis=1) <= limit)


def unalign(values, start, K, fill=np.nan):
    """Values on a bank's aligned axis (R, J, ...) (:func:`track_with_global_init`) back on the samples (R, K, ...)."""
    values = np.asarray(values)
    R, J = values.shape[:2]
    out = np.full((R, K) + values.shape[2:], fill, dtype=np.result_type(values, np.asarray(fill)))
    src = np.asarray(start, dtype=int)[:, None] + np.arange(J)[None, :]
    inside = src < K
    rows = np.broadcast_to(np.arange(R)[:, None], src.shape)
    out[rows[inside], src[inside]] = values[inside]
    return out
