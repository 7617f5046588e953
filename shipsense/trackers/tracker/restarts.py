"""Batch refits of tracked passages: the restarts of :class:`~shipsense.trackers.Tracker`'s bank.

The passages the trackers are built for are straight, constant-velocity
tracks with a constant source: everything up to sample ``k`` is one initial
state ``theta`` (at the window start ``k0`` of the global initialiser), and a
Levenberg–Marquardt fit of it to every sample so far is the maximum-
likelihood (with a prior, MAP) estimate of those data.  A recursive filter
instead linearises each sample once, at the estimate of its time; where the
field is most nonlinear -- the closest approach -- it can keep a track
metres off with a covariance of centimetres.  The tracker therefore restarts
its bank from :func:`refit_window` (when, see :mod:`shipsense.trackers.tracker`):
a refit keeps up to ``keep`` distinct fits (also started from the bank's
hypotheses that still carry weight) as the next bank's hypotheses, weighted
by their likelihoods.  Every refit uses only the samples before the restart
(causal), and all passages that restart together are one batch.  :func:`due` is the tracker's test of which
passages restart at a sample.

:func:`refit_at` and :func:`peak_refit_sample` are the batch form of one
refit after the closest approach, used by the studies' ``global_init_refit``
method (:mod:`shipsense.reproduce.studies`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from shipsense import numba_cache
from shipsense.models.transitions import powers, transitions
from shipsense.trackers.fit.least_squares import fit_passages
from shipsense.trackers.init.detection import fit_end
from shipsense.trackers.init.distinct import distinct_rows
from shipsense.trackers.init.global_init import GlobalInit
from shipsense.trackers.init.window_fits import WindowFits, chi2_expected, chi2_limit


def refit_window(model, yw, starts, *, taus=None, prior=None, keep=1, distinct_m=15.0, gof=0.01, huber=None):
    """Levenberg-Marquardt fits of passages' windows from several starts; the ``keep`` best distinct ones.

    Parameters
    ----------
    model : FieldModel
    yw : ndarray, shape (R, W, m)
        The windows' samples (internal units, NaN = missing).
    starts : ndarray, shape (R, C, n)
        Initial states at each window's first sample (internal units); rows with a NaN are skipped.
    taus : ndarray, shape (R, W), optional
        The samples' times (s) after the window's first (default ``k T``).
    prior, huber : as for :func:`~shipsense.trackers.fit.least_squares.fit_passages`
    keep, distinct_m : int, float
        The best fits whose positions at the window's last sample are more than ``distinct_m`` (m) apart.
    gof : float or None
        Level of the goodness-of-fit test (:func:`~shipsense.trackers.init.window_fits.chi2_limit`).

    Returns
    -------
    WindowFits
        At each window's first sample, best first.
    """
    R, W, _ = yw.shape
    taus = np.broadcast_to(np.arange(W) * model.period, (R, W)) if taus is None else np.asarray(taus, dtype=float)
    use = np.isfinite(starts).all(axis=-1)
    pr, pc = np.nonzero(use)
    t, c, j = fit_passages(model, yw[pr], starts[pr, pc], W, return_information=True, prior=prior, taus=taus[pr],
                           huber=huber)
    C = starts.shape[1]
    fits = np.zeros((R, C, model.n))
    chi2 = np.full((R, C), np.inf)
    info = np.zeros((R, C, model.n, model.n))
    fits[pr, pc], chi2[pr, pc], info[pr, pc] = t, np.where(np.isfinite(c), c, np.inf), j
    last = np.einsum("rij,rcj->rci", transitions(model, taus[:, -1]), fits)[..., :2] * model.x_scale[:2]
    pick, found = distinct_rows(chi2, last, keep, distinct_m)
    rows = np.arange(R)[:, None]
    return WindowFits(fits[rows, pick], chi2[rows, pick], info[rows, pick], found,
                      chi2_limit(model, yw, prior, gof, huber), chi2_expected(model, yw, prior, huber))


def refit_at(model, measurements, gi, estimates, at, *, prior=None, inflate=1.0, gof=0.01, multistart=None,
             hypotheses=None, keep=1, distinct_m=15.0):
    """Passages re-fitted to their samples ``gi.k0`` .. ``at - 1``: the hypotheses of a bank from ``at``.

    Parameters
    ----------
    model : FieldModel
    measurements : ndarray, shape (R, K, m)
        SI units, NaN = missing.
    gi : GlobalInit
        The passages' initialiser output (its ``k0``, and its window fits for ``multistart``).
    estimates : ndarray, shape (R, K, n)
        The tracker's estimates so far (SI); the one at ``at - 1`` is moved
        back to ``gi.k0`` along its constant-velocity track and starts the fit.
    at : ndarray of int, shape (R,)
        First sample of the new bank (``gi.k0 < at < K``).
    prior : tuple, optional
        As for :func:`~shipsense.trackers.fit.least_squares.fit_passages`.
    inflate : float
        Factor on the inverse Gauss–Newton information.
    gof : float or None
        Level of the chi-square test that gives ``fit_ok``.
    multistart : ndarray of bool, shape (R,), optional
        Passages whose fit also starts from each of the initialiser's window
        fits (for a track that has diverged, its own estimate may sit in the
        wrong basin).
    hypotheses : ndarray, shape (R, H, n), optional
        Further starts at ``at - 1`` (SI; NaN rows are skipped), e.g. a bank's
        hypotheses that still carry weight.
    keep : int
        Hypotheses returned per passage (:func:`refit_window`).

    Returns
    -------
    GlobalInit
        ``keep`` hypotheses per passage, starting at ``at``; ``fit_ok`` is the
        best fit's chi-square test.
    """
    y = np.asarray(measurements, dtype=float) / model.y_scale
    R, K, _ = y.shape
    at = np.asarray(at, dtype=int)
    k0 = np.asarray(gi.k0, dtype=int)
    if np.any(at <= k0) or np.any(at >= K):
        raise ValueError(f"refit samples must lie after the window start and before the end ({K} samples)")
    Wf = int((at - k0).max())
    xs = model.x_scale
    rows = np.arange(R)
    back = powers(np.linalg.inv(model.A), Wf)[at - 1 - k0]                          # A^-(at-1-k0)
    starts = [np.asarray(estimates)[rows, at - 1][:, None]]                          # (R, 1, n) at at - 1
    if hypotheses is not None:   # (the selected hypothesis is the estimate: fitted once)
        h = np.asarray(hypotheses, dtype=float)
        starts.append(np.where(np.all(h == starts[0], axis=-1, keepdims=True), np.nan, h))
    theta = np.einsum("rij,rhj->rhi", back, np.concatenate(starts, axis=1) / xs)      # at k0
    if multistart is not None:   # the initialiser's window fits (at k0) for the passages that ask
        win = np.where(np.asarray(multistart, dtype=bool)[:, None, None], gi.window[:, :, 0] / xs, np.nan)
        theta = np.concatenate([theta, win], axis=1)
    ks = k0[:, None] + np.arange(Wf)[None, :]
    yfit = np.where((ks < at[:, None])[..., None], y[rows[:, None], np.minimum(ks, K - 1)], np.nan)
    fits = refit_window(model, yfit, theta, prior=prior, keep=keep, distinct_m=distinct_m, gof=gof)
    Ak = powers(model.A, Wf + 1)
    Ae = Ak[at - k0]                                                                   # (R, n, n)
    cov = np.linalg.pinv(fits.info, hermitian=True) * inflate
    seeds = np.einsum("rij,rmj->rmi", Ae, fits.theta)
    P0 = Ae[:, None] @ cov @ np.swapaxes(Ae, -1, -2)[:, None]
    traj = np.einsum("kij,rmj->rmki", Ak[:Wf], fits.theta)
    return GlobalInit(start=at, seeds=seeds * xs, P0=P0 * np.outer(xs, xs), loglik=fits.loglik,
                      window=traj * xs, k0=k0, fit_ok=fits.fit_ok)


def peak_refit_sample(model, measurements, k0, start, through_peak=0.5):
    """Sample (R,) of the refit after the closest approach: the first after the bank's ``start`` at which
    the strongest channel has fallen below ``through_peak`` of its peak since ``k0``
    (:func:`~shipsense.trackers.init.detection.fit_end`); the last sample where it never does."""

    K = np.shape(measurements)[1]
    start = np.asarray(start, dtype=int)
    end = np.minimum(fit_end(model, measurements, k0, start - np.asarray(k0), through_peak), K - 1)
    return np.where(end > start, end, K - 1)


@njit(cache=True, error_model="numpy", nogil=True)
def due(runs, n, start, nis, trusted, alarms, peak, peak_done, snr, scan, own, ref, cons_now, robust, nis_window,
        nis_limit, max_restarts, through_peak, refit_every, rescan, collapse, status, cov, inconsistent, flags):
    """Which of the passages ``runs`` restart at this sample (:meth:`~shipsense.trackers.Tracker.update`), in one
    compiled pass over the tracker's per-passage arrays (indexed by passage).

    The options are numbers as given (floats compare as the tracker's options did; NaN for an option that is
    None).  ``flags`` (len(runs), 4) gets, per passage, whether it is due, and why among: an alarm (the mean NIS of
    its window -- the median with ``robust`` -- above ``nis_limit`` on at least half a window, or an untrusted
    fit a window old, with restarts left), the peak passed (the SNR below ``through_peak`` of its peak, once;
    NaN: never), a scheduled refit (every ``refit_every`` samples, NaN: never; with ``rescan`` also a rescan)
    -- or a collapse (the selected hypothesis's position covariance below ``collapse`` (NaN: never) of the
    start's within a window) or a failed consistency test.  ``peak`` is updated with ``snr``; a passage that
    diverged with no restarts left is reported ``inconsistent`` with its covariance scaled by the NIS level.
    """
    N = nis.shape[1]
    vals = np.empty(N)
    zeroed = np.empty(N)
    for p in range(runs.shape[0]):
        r = runs[p]
        since = n[r] - start[r]
        present = 0
        count = 0
        for k in range(N):
            v = nis[r, k]
            if math.isfinite(v):
                present += 1
            zeroed[k] = 0.0 if math.isnan(v) else v
            if not math.isnan(v):                 # (np.nanmean and np.nanmedian count infinities)
                vals[count] = v
                count += 1
        level = 0.0
        if present > 0:
            if robust:
                for i in range(1, count):         # the window's values in order (a window is short)
                    x = vals[i]
                    j = i - 1
                    while j >= 0 and vals[j] > x:
                        vals[j + 1] = vals[j]
                        j -= 1
                    vals[j + 1] = x
                h = count // 2
                level = vals[h] if count % 2 else (vals[h - 1] + vals[h]) / 2.0
            else:                                 # np.nanmean: the sum with NaN as 0, numpy's way
                level = _numpy_sum(zeroed) / count
        diverged = present >= max(1.0, nis_window // 2) and level > nis_limit
        retry = not trusted[r] and since >= nis_window
        alarm = (diverged or retry) and alarms[r] < max_restarts
        if snr[r] > peak[r] or math.isnan(snr[r]):
            peak[r] = snr[r]
        after_peak = (not math.isnan(through_peak)) and not peak_done[r] and since > 0 and (
            snr[r] < through_peak * peak[r])
        scheduled = not peak_done[r] and since >= refit_every          # (NaN: never)
        rescanned = rescan and not peak_done[r] and n[r] - scan[r] >= refit_every
        collapsed = (not math.isnan(collapse)) and since < nis_window and since > 0 and own[r] < collapse * ref[r]
        flags[p, 0] = alarm or after_peak or scheduled or rescanned or collapsed or cons_now[r]
        flags[p, 1] = alarm
        flags[p, 2] = after_peak
        flags[p, 3] = rescanned
        if diverged and not alarm:                # diverged with no restarts left: say so
            status[r] = inconsistent
            f = 1.0 if level <= 1.0 else level    # (np.maximum(1, level))
            for a in range(cov.shape[1]):
                for b in range(cov.shape[2]):
                    cov[r, a, b] *= f


@njit(cache=True, error_model="numpy", inline="always")
def _numpy_sum(a):
    """``np.sum`` of a short contiguous row as numpy adds it (its pairwise sum: in order from 0 below eight
    values; from eight up to 128, eight running sums combined as a tree, then the remainder), so that the
    restart level is ``np.nanmean``'s to the bit (tests/trackers/tracker/test_restarts.py checks this numpy's)."""
    n = a.shape[0]
    if n < 8:
        s = 0.0
        for i in range(n):
            s += a[i]
        return s
    r0, r1, r2, r3, r4, r5, r6, r7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
    i = 8
    while i < n - n % 8:
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    s = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        s += a[i]
        i += 1
    return s


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
