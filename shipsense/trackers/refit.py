"""Batch refits of tracked passages, and a tracker that restarts its bank from them.

The passages the trackers are built for are straight, constant-velocity
tracks with a constant source: everything up to sample ``k`` is one initial
state ``theta`` (at the window start ``k0`` of the global initialiser), and a
Levenberg–Marquardt fit of it to every sample so far is the maximum-
likelihood (with a prior, MAP) estimate of those data.  A recursive filter
instead linearises each sample once, at the estimate of its time; where the
field is most nonlinear -- the closest approach -- it can keep a track
metres off with a covariance of centimetres.  :func:`track_with_restarts`
therefore runs the bank and restarts it from a refit when

* the signal has fallen to ``through_peak`` of its peak (once, after the
  closest approach: :func:`~shipsense.trackers.init.refit_after_peak`), or
* the selected hypothesis's innovations say it has diverged: its normalised
  innovation squared per measurement component, averaged over
  ``nis_window`` samples, exceeds ``nis_limit`` (trackers.md §3's
  divergence flag, acted on).

Every refit uses only the samples before the restart (causal), and all
passages that restart together are one batch.
"""

from __future__ import annotations

import numpy as np

from shipsense.trackers.batchfit import fit_passages, powers


def refit_at(model, measurements, gi, estimates, at, *, prior=None, inflate=1.0, gof=0.01, multistart=None):
    """One hypothesis per passage, re-fitted to its samples ``gi.k0`` .. ``at - 1``, for a bank from ``at``.

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
        As for :func:`~shipsense.trackers.batchfit.fit_passages`.
    inflate : float
        Factor on the inverse Gauss–Newton information.
    gof : float or None
        Level of the chi-square test that gives ``fit_ok``
        (:func:`~shipsense.trackers.init.global_init`).
    multistart : ndarray of bool, shape (R,), optional
        Passages whose fit also starts from each of the initialiser's window
        fits; the lowest chi-square wins (for a track that has diverged, its
        own estimate may sit in the wrong basin).

    Returns
    -------
    GlobalInit
        One hypothesis per passage, starting at ``at``.
    """
    from shipsense.trackers.init import GlobalInit, _chi2_limit

    y = np.asarray(measurements, dtype=float) / model.y_scale
    R, K, _ = y.shape
    at = np.asarray(at, dtype=int)
    k0 = np.asarray(gi.k0, dtype=int)
    if np.any(at <= k0) or np.any(at >= K):
        raise ValueError(f"refit samples must lie after the window start and before the end ({K} samples)")
    Wf = int((at - k0).max())
    xs = model.x_scale
    rows = np.arange(R)
    last = np.asarray(estimates)[rows, at - 1] / xs                                 # (R, n) at at - 1
    back = powers(np.linalg.inv(model.A), Wf)[at - 1 - k0]                          # A^-(at-1-k0)
    theta = np.einsum("rij,rj->ri", back, last)
    ks = k0[:, None] + np.arange(Wf)[None, :]
    yfit = np.where((ks < at[:, None])[..., None], y[rows[:, None], np.minimum(ks, K - 1)], np.nan)
    theta, chi2, info = fit_passages(model, yfit, theta, Wf, return_information=True, prior=prior)
    chi2 = np.where(np.isfinite(chi2), chi2, np.inf)
    many = np.flatnonzero(multistart) if multistart is not None else np.zeros(0, dtype=int)
    if many.size:   # the initialiser's window fits as further starts
        M = gi.window.shape[1]
        t2, c2, i2 = fit_passages(model, np.repeat(yfit[many], M, axis=0),
                                  (gi.window[many, :, 0] / xs).reshape(many.size * M, -1), Wf,
                                  return_information=True, prior=prior)
        c2 = np.where(np.isfinite(c2), c2, np.inf).reshape(many.size, M)
        b = np.argmin(c2, axis=1)
        better = c2[np.arange(many.size), b] < chi2[many]
        pick = many[better]
        flat = np.arange(many.size)[better] * M + b[better]
        theta[pick], chi2[pick], info[pick] = t2[flat], c2.reshape(-1)[flat], i2[flat]
    cov = np.linalg.pinv(info, hermitian=True) * inflate
    Ak = powers(model.A, Wf + 1)
    Ae = Ak[at - k0]                                                                   # (R, n, n)
    seeds = np.einsum("rij,rj->ri", Ae, theta)
    P0 = Ae @ cov @ np.swapaxes(Ae, -1, -2)
    traj = np.einsum("kij,rj->rki", Ak[:Wf], theta)
    return GlobalInit(start=at, seeds=(seeds * xs)[:, None], P0=(P0 * np.outer(xs, xs))[:, None],
                      loglik=-0.5 * chi2[:, None], window=(traj * xs)[:, None], k0=k0,
                      fit_ok=chi2 <= _chi2_limit(model, yfit, prior, gof))


def peak_refit_sample(model, measurements, k0, start, through_peak=0.5):
    """Sample (R,) of the refit after the closest approach: the first after the bank's ``start`` at which
    the strongest channel has fallen below ``through_peak`` of its peak since ``k0``
    (:func:`~shipsense.trackers.init.fit_end`); the last sample where it never does."""
    from shipsense.trackers.init import fit_end

    K = np.shape(measurements)[1]
    start = np.asarray(start, dtype=int)
    end = np.minimum(fit_end(model, measurements, k0, start - np.asarray(k0), through_peak), K - 1)
    return np.where(end > start, end, K - 1)


def selected_nis(bank):
    """NIS per measurement component of each passage's selected hypothesis (R, J) (NaN without a measurement)."""
    idx = bank.selected[:, None, :]
    nis = np.take_along_axis(bank.nis, idx, axis=1)[:, 0]
    m = np.take_along_axis(bank.m, idx, axis=1)[:, 0]
    return np.where(m > 0, nis / np.maximum(m, 1), np.nan)


def divergence_alarm(nis, start, window, limit):
    """First sample (R,) after which a bank started at ``start`` restarts: the sample after the first
    ``window`` samples whose mean ``nis`` (per component, (R, K)) exceeds ``limit`` (at least half of
    them measured); ``K`` when there is none (an alarm on the last sample has nothing to restart)."""
    R, K = nis.shape
    v = np.where(np.arange(K)[None, :] >= np.asarray(start)[:, None], nis, np.nan)
    present = np.isfinite(v)
    zero = np.zeros((R, 1))
    s = np.concatenate([zero, np.cumsum(np.where(present, v, 0.0), axis=1)], axis=1)
    n = np.concatenate([zero, np.cumsum(present, axis=1)], axis=1)
    s_w, n_w = s[:, window:] - s[:, :-window], n[:, window:] - n[:, :-window]      # windows ending at window-1..K-1
    alarm = (n_w >= max(1, window // 2)) & (s_w > limit * np.maximum(n_w, 1))
    alarm[:, -1] = False
    return np.where(alarm.any(axis=1), np.argmax(alarm, axis=1) + window, K)


def track_with_restarts(unit, model, measurements, gi, *, prior=None, through_peak=0.5, nis_window=10,
                        nis_limit=3.0, max_restarts=4, inflate=1.0, gof=0.01):
    """Track passages from the global initialiser, restarting the bank from batch refits (see module).

    ``model`` is used for every bank; for the constant-velocity passages the
    project's tracker passes ``model.without_process_noise()`` (and builds
    ``gi`` with it).  A passage restarts at most ``max_restarts`` times on
    divergence alarms, plus once after its closest approach (``through_peak``;
    None: never); an alarm refit also starts from the initialiser's window
    fits (:func:`refit_at`'s ``multistart``).

    A bank started from a fit that fails the chi-square test (``gi.fit_ok``,
    or a refit's) makes no claim on its accuracy: its position covariance
    is reported as NaN, and the passage is re-fitted (multistart, counted as
    an alarm) every ``nis_window`` samples until a fit passes.  (On 500
    two-magnetometer passages two started from such fits: one ran 136 m off
    with a covariance of millimetres before its alarm, EXPERIMENTS.md.)

    Returns
    -------
    estimates : ndarray, shape (R, K, n)
        SI; before ``gi.start`` the best window fit's trajectory.
    pos_cov : ndarray, shape (R, K, 2, 2)
        Position covariances (SI, m²); NaN before ``gi.start`` and while the
        bank runs from a fit that failed the test.
    restarts : ndarray of int, shape (R,)
        Refits per passage.
    """
    from shipsense.trackers.init import track_with_global_init, unalign

    y = np.asarray(measurements, dtype=float)
    R, K, _ = y.shape
    est, bank = track_with_global_init(unit, model, y, gi)
    start = np.asarray(gi.start, dtype=int).copy()
    cov = unalign(bank.selected_pos_cov, start, K)
    nis = unalign(selected_nis(bank), start, K)
    peak = np.full(R, K) if through_peak is None else peak_refit_sample(model, y, gi.k0, start, through_peak)
    restarts = np.zeros(R, dtype=int)
    alarms = np.zeros(R, dtype=int)
    k = np.arange(K)[None, :]
    trusted = np.ones(R, dtype=bool) if gi.fit_ok is None else np.asarray(gi.fit_ok, dtype=bool).copy()
    cov[~trusted] = np.nan
    while True:
        alarm = divergence_alarm(nis, start, nis_window, nis_limit)
        alarm = np.where(trusted, alarm, np.minimum(alarm, start + nis_window))    # retry a failed fit
        alarm = np.where(alarms < max_restarts, alarm, K)
        at = np.minimum(alarm, np.where(peak > start, peak, K))   # the refit after the peak is due once
        sel = np.flatnonzero(at < K)
        if sel.size == 0:
            return est, cov, restarts
        on_alarm = alarm[sel] <= at[sel]
        sub = _passages(gi, sel)
        again = refit_at(model, y[sel], sub, est[sel], at[sel], prior=prior, inflate=inflate, gof=gof,
                         multistart=on_alarm)
        est[sel], c2, b2 = continue_from(unit, model, y[sel], again, est[sel], cov[sel])
        after = k >= at[sel][:, None]
        trusted[sel] = again.fit_ok
        cov[sel] = np.where(after[..., None, None] & ~again.fit_ok[:, None, None, None], np.nan, c2)
        nis[sel] = np.where(after, unalign(selected_nis(b2), at[sel], K), nis[sel])
        start[sel] = at[sel]
        restarts[sel] += 1
        alarms[sel] += on_alarm


def continue_from(unit, model, measurements, gi, estimates, pos_cov):
    """Run a bank from ``gi`` (e.g. a refit) and splice it into ``estimates`` (R, K, n) and ``pos_cov``
    (R, K, 2, 2) from each passage's ``gi.start`` on; returns the spliced copies and the ``BankRun``."""
    from shipsense.trackers.init import track_with_global_init, unalign

    K = np.shape(measurements)[1]
    e2, bank = track_with_global_init(unit, model, measurements, gi)
    after = np.arange(K)[None, :] >= np.asarray(gi.start)[:, None]
    return (np.where(after[..., None], e2, estimates),
            np.where(after[..., None, None], unalign(bank.selected_pos_cov, gi.start, K), pos_cov), bank)


def _passages(gi, sel):
    """The :class:`~shipsense.trackers.init.GlobalInit` of passages ``sel``."""
    from dataclasses import fields, replace

    return replace(gi, **{f.name: getattr(gi, f.name)[sel] for f in fields(gi) if getattr(gi, f.name) is not None})
