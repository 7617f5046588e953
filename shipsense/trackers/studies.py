"""Study variants of the project's tracker, kept to reproduce the studies: the bank started from the global
initialiser (``global_init`` in the wide-prior study), one refit after the closest approach
(``global_init_refit``), and a bank spliced in from a refit.  Users get :class:`~shipsense.trackers.tracker.Tracker`.
"""

from __future__ import annotations

import numpy as np

from shipsense.trackers.initialiser import GlobalInit, unalign
from shipsense.trackers.restarts import (
    _fit_at_last,
    collapse_alarm,
    divergence_alarm,
    passages_of,
    peak_refit_sample,
    refit_at,
    selected_nis,
    trace2,
)


def track_with_global_init(unit, model, measurements, gi: GlobalInit):
    """Run the bank from the global initialiser's hypotheses; returns ``(estimates (R, K, n) SI, BankRun)``.

    Every passage's bank starts at its own ``gi.start``: the measurements are
    aligned on it (bank step j processes sample ``start + j`` of each
    passage; passages that end earlier are padded with missing samples), so
    all passages are one batch whatever their starts.  The returned
    ``BankRun`` is on that aligned axis (step j of passage r is its sample
    ``gi.start[r] + j``).  Before the bank starts, the estimate is the best
    batch fit's trajectory (constant velocity, propagated backwards before
    the detection).
    """
    from shipsense.trackers.bank import run_bank

    y = np.asarray(measurements, dtype=float)
    R, K, _ = y.shape
    start = np.asarray(gi.start, dtype=int)
    if np.any(start >= K):
        raise ValueError(f"a passage ({K} samples) ends inside its fitted window (bank start {int(start.max())})")
    J = K - int(start.min())                                                  # aligned bank steps
    j = np.arange(J)[None, :]
    src = start[:, None] + j                                                  # (R, J): sample of step j
    inside = src < K
    aligned = np.where(inside[..., None], y[np.arange(R)[:, None], np.minimum(src, K - 1)], np.nan)
    bank = run_bank(unit, model, aligned, gi.seeds, gi.P0, initial_loglik=gi.loglik)
    est = unalign(bank.selected_means, start, K)
    best = np.argmax(gi.loglik, axis=1)
    theta0 = gi.window[np.arange(R), best, 0] / model.x_scale                 # internal, at k0
    ks = np.arange(K)[None, :] - gi.k0[:, None]                               # steps relative to k0
    # constant velocity forwards and backwards: x_k = x_0 + k T v for the kinematic block
    traj = np.repeat(theta0[:, None, :], K, axis=1)
    traj[..., 0:2] += ks[..., None] * model.period * theta0[:, None, 2:4]
    before = np.arange(K)[None, :] < start[:, None]
    est[before] = (traj * model.x_scale)[before]
    return est, bank


def refit_after_peak(model, measurements, gi: GlobalInit, estimates, through_peak=0.5, prior=None, inflate=1.0,
                     gof=0.01):
    """One hypothesis per passage for a second bank after the closest approach (causal).

    At each passage's sample ``e`` where the strongest channel has fallen
    below ``through_peak`` of its peak since the window start (:func:`fit_end`;
    passages that never get there are refitted at their last sample), the
    first bank's estimate at ``e - 1`` is moved back to the window start
    ``gi.k0`` along its constant-velocity track and re-fitted by
    Levenberg–Marquardt to every sample from ``gi.k0`` to ``e - 1``: a batch
    fit across the closest approach, warm-started from a track that has
    followed it (a fit of that stretch from the window's solution falls into
    local minima more often, EXPERIMENTS.md).  Returns a :class:`GlobalInit`
    starting at ``e`` (:func:`~shipsense.trackers.restarts.refit_at`: the fit,
    ``inflate`` times its inverse Gauss–Newton information, and ``fit_ok``
    from the chi-square test at level ``gof``); ``prior`` as for
    :func:`fit_passages`.
    """

    end = peak_refit_sample(model, measurements, gi.k0, gi.start, through_peak)
    return refit_at(model, measurements, gi, estimates, end, prior=prior, inflate=inflate, gof=gof)


def continue_from(unit, model, measurements, gi, estimates, pos_cov, mixture=False):
    """Run a bank from ``gi`` (e.g. a refit) and splice it into ``estimates`` (R, K, n) and ``pos_cov``
    (R, K, 2, 2) from each passage's ``gi.start`` on (with ``mixture`` the selected estimate's
    mean-square-error matrix under the bank's mixture, else the selected hypothesis's covariance);
    returns the spliced copies and the ``BankRun``."""

    K = np.shape(measurements)[1]
    e2, bank = track_with_global_init(unit, model, measurements, gi)
    after = np.arange(K)[None, :] >= np.asarray(gi.start)[:, None]
    c2 = bank.selected_pos_mse if mixture else bank.selected_pos_cov
    return (np.where(after[..., None], e2, estimates),
            np.where(after[..., None, None], unalign(c2, gi.start, K), pos_cov), bank)


def _store(hyps, bank, start, K, nats):
    """Write a bank's hypotheses within ``nats`` of its best (NaN otherwise) into ``hyps`` (R, K, H, n) from
    each passage's ``start`` on."""

    H = bank.means.shape[1]
    live = bank.normalised_loglik > -nats                                          # (R, H, J)
    means = np.where(live[..., None], bank.means, np.nan)
    vals = unalign(np.moveaxis(means, 2, 1), start, K)                             # (R, K, H, n)
    after = np.arange(K)[None, :] >= np.asarray(start)[:, None]
    hyps[..., :H, :] = np.where(after[..., None, None], vals, hyps[..., :H, :])
    hyps[..., H:, :] = np.where(after[..., None, None], np.nan, hyps[..., H:, :])


def track_with_restarts(unit, model, measurements, gi, *, prior=None, through_peak=0.5, nis_window=10,
                        nis_limit=3.0, max_restarts=4, inflate=1.0, gof=0.01, refit_every=20, keep=3,
                        ambiguity_nats=10.0, mixture=True, collapse=0.25):
    """Track passages from the global initialiser, restarting the bank from batch refits (see module).

    ``model`` is used for every bank; for the constant-velocity passages the
    project's tracker passes ``model.without_process_noise()`` (and builds
    ``gi`` with it).  A passage restarts at most ``max_restarts`` times on
    divergence alarms, plus once after its closest approach (``through_peak``;
    None: never), plus -- with ``refit_every`` -- every that many samples
    until then; an alarm refit also starts from the initialiser's window
    fits (:func:`refit_at`'s ``multistart``).

    Every refit also starts from the bank's hypotheses within
    ``ambiguity_nats`` of the selected one's log-likelihood, and the new bank
    holds the ``keep`` best distinct fits weighted by their likelihoods, so
    that a second passage that explains the data almost as well survives
    the refit.  With ``mixture`` the reported covariance is the selected
    estimate's mean-square-error matrix under the bank's mixture
    (:attr:`~shipsense.trackers.bank.BankRun.selected_pos_mse`), else the
    selected hypothesis's own.

    With ``collapse`` (a fraction), a bank whose selected position covariance
    (trace) falls below ``collapse`` times its refit's within ``nis_window``
    samples is re-fitted at once.  One sample cannot carry that much
    information; what shrinks it is the filter combining the fit's
    information with a Jacobian taken metres away, where a curved
    (banana-shaped) likelihood turns the other way.  The batch fit
    re-linearises every sample at one point (on S0 passage 85, from a fit
    with a position standard deviation of 6.1 m, the UKF reported 0.75 m
    after one more sample and the EKF 0.90 m after two, where the fits of
    the same samples gave 5.97 and 5.79 m: ``experiments/filter_collapse.py``).
    At every refit, the last fitted sample's estimate and covariance are the
    fit's.

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

    y = np.asarray(measurements, dtype=float)
    R, K, _ = y.shape
    est, bank = track_with_global_init(unit, model, y, gi)
    start = np.asarray(gi.start, dtype=int).copy()
    cov = unalign(bank.selected_pos_mse if mixture else bank.selected_pos_cov, start, K)
    nis = unalign(selected_nis(bank), start, K)
    hyps = None                                           # every bank's hypotheses that carry weight, per sample
    if keep > 1:
        hyps = np.full((R, K, max(bank.means.shape[1], keep), model.n), np.nan)
        _store(hyps, bank, start, K, ambiguity_nats)
    peak = np.full(R, K) if through_peak is None else peak_refit_sample(model, y, gi.k0, start, through_peak)
    restarts = np.zeros(R, dtype=int)
    alarms = np.zeros(R, dtype=int)
    k = np.arange(K)[None, :]
    trusted = np.ones(R, dtype=bool) if gi.fit_ok is None else np.asarray(gi.fit_ok, dtype=bool).copy()
    cov[~trusted] = np.nan
    spread = unalign(trace2(bank.selected_pos_cov), start, K)                     # for the collapse alarm
    ref = trace2(gi.P0[np.arange(R), np.argmax(gi.loglik, axis=1)])                # the fit's, at the start
    inv_A = np.linalg.inv(model.A)
    while True:
        alarm = divergence_alarm(nis, start, nis_window, nis_limit)
        alarm = np.where(trusted, alarm, np.minimum(alarm, start + nis_window))    # retry a failed fit
        alarm = np.where(alarms < max_restarts, alarm, K)
        due = np.where(peak > start, peak, K)                     # the refit after the peak is due once
        if refit_every is not None:                               # and until then, every refit_every samples
            due = np.minimum(due, np.where(peak > start, start + refit_every, K))
        at = np.minimum(alarm, due)
        if collapse is not None:
            at = np.minimum(at, collapse_alarm(spread, start, ref, collapse, nis_window))
        sel = np.flatnonzero(at < K)
        if sel.size == 0:
            return est, cov, restarts
        on_alarm = alarm[sel] <= at[sel]
        sub = passages_of(gi, sel)
        others = hyps[sel, at[sel] - 1] if keep > 1 else None
        again = refit_at(model, y[sel], sub, est[sel], at[sel], prior=prior, inflate=inflate, gof=gof,
                         multistart=on_alarm, hypotheses=others, keep=keep)
        est[sel], c2, b2 = continue_from(unit, model, y[sel], again, est[sel], cov[sel], mixture=mixture)
        last, c_last = _fit_at_last(model, again, inv_A, mixture)                  # the fit at at - 1
        est[sel, at[sel] - 1], c2[np.arange(sel.size), at[sel] - 1] = last, c_last
        after = k >= at[sel][:, None] - 1
        trusted[sel] = again.fit_ok
        cov[sel] = np.where(after[..., None, None] & ~again.fit_ok[:, None, None, None], np.nan, c2)
        spread[sel] = np.where(k > at[sel][:, None] - 1, unalign(trace2(b2.selected_pos_cov), at[sel], K),
                               spread[sel])
        ref[sel] = trace2(again.P0[:, 0])
        nis[sel] = np.where(after, unalign(selected_nis(b2), at[sel], K), nis[sel])
        if keep > 1:
            sub_h = hyps[sel]
            _store(sub_h, b2, at[sel], K, ambiguity_nats)
            hyps[sel] = sub_h
        start[sel] = at[sel]
        restarts[sel] += 1
        alarms[sel] += on_alarm
