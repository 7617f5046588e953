"""The starts of a tracker's banks: detection and the window fits that start a passage's bank
(:func:`initialise`, :func:`fit_windows`; early, on a growing window, once its fits are :func:`accepted`),
and the refits that restart it when due (:func:`restart`, :func:`refit`), each a batch over the passages concerned.

Functions of a :class:`~shipsense.trackers.tracker.tracker.Tracker` ``trk``: they read its model, settings and
initialiser options, and write its per-passage state (``trk.state``,
:class:`~shipsense.trackers.tracker.passages.PassageArrays`), its bank (``trk.bank``,
:class:`~shipsense.trackers.bank.bank.BankState`) and the sample's output ``out``
(:class:`~shipsense.trackers.tracker.results.Sample`).  When they run: the tracker's module docstring.
"""

from __future__ import annotations

import time

import numpy as np

from shipsense.models.transitions import transitions
from shipsense.trackers.filters.core import symmetrize
from shipsense.trackers.init.window_fits import depth_prior, window_fits
from shipsense.trackers.metrics import crlb_sd
from shipsense.trackers.tracker.passages import PENDING, RUNNING, STARTING
from shipsense.trackers.tracker.restarts import due, refit_window
from shipsense.trackers.tracker.results import INCONSISTENT, INITIALISING, RESTARTED

BANK_INFLATION_MAX = 100.0   # largest chi-square inflation a failed fit's bank starts from (the rest is reported)


def samples_since(state, runs, first):
    """Samples ``first .. k`` (R,) of passages ``runs`` from the history of the per-passage ``state``: y (R, W,
    m) internal and the times after each first sample (R, W); W is the longest, shorter windows padded with
    missing samples."""
    hist = state.y_hist.shape[1]
    cur = state.n[runs]
    W = int((cur - first).max()) + 1
    ks = first[:, None] + np.arange(W)[None, :]
    inside = ks <= cur[:, None]
    slots = np.where(inside, ks, cur[:, None]) % hist
    yw = np.where(inside[..., None], state.y_hist[runs[:, None], slots], np.nan)
    tw = state.t_hist[runs[:, None], slots]
    taus = np.where(inside, tw - tw[:, :1], tw[:, -1:] - tw[:, :1])
    return yw, taus


def robust_snr(state, snr, yi, act):
    """The SNR (P,) of the passages ``act`` with ``robust``: the median of the strongest field channel's SNR
    ``snr`` over their last three samples, kept in the per-passage ``state`` (an outlier alone neither starts
    a window nor moves the peak)."""
    ring = np.roll(state.snr[act], -1, axis=1)
    ring[:, -1] = np.where(np.isfinite(yi[act]).any(axis=1), snr[act], np.nan)
    state.snr[act] = ring
    with np.errstate(all="ignore"):
        med = np.nanmedian(np.where(np.isfinite(ring).sum(axis=1, keepdims=True) >= 2, ring, 0.0), axis=1)
    snr[act] = np.nan_to_num(med)
    return snr


def fit_pending(trk):
    """:meth:`Tracker.fit_pending <shipsense.trackers.tracker.tracker.Tracker.fit_pending>`: the deferred
    window fits of every pending passage in one batch, their banks started as at the sample their windows
    completed; the passages and their Sample at that sample."""
    pend = np.flatnonzero(trk.state.phase == PENDING)
    out = trk.prior_sample()
    if pend.size:
        trk.state.n[pend] -= 1                       # back at the sample the window completed at, for its fits
        try:
            out.status[pend] = INITIALISING
            fit_windows(trk, pend, out)
            trk.widen_inconsistent(pend, out)             # (as update)
        finally:
            trk.state.n[pend] += 1
    return pend, out.take(pend)


def initialise(trk, starting, snr, out, defer=False):
    """Detection and, once a passage's window is complete, its global fits: the bank starts from them
    (with ``defer``, the passage is left pending for :func:`fit_pending`)."""
    if starting.size == 0:
        return
    o = trk.settings
    detect = starting[(trk.state.k0[starting] < 0) & (snr[starting] > o.snr_start)]
    trk.state.k0[detect] = trk.state.n[detect]
    seen = starting[trk.state.k0[starting] >= 0]
    trk.state.peak[seen] = np.maximum(trk.state.peak[seen], snr[seen])
    have = trk.state.n[seen] - trk.state.k0[seen] + 1
    # the window is complete, or the signal has passed its peak: a fit then spans the closest approach
    passed = (o.through_peak is not None) & (snr[seen] < (o.through_peak or 0.0) * trk.state.peak[seen])
    forced = (have >= trk.window) | (passed & (have >= max(4, trk.window // 5)))
    early = ~forced & early_attempt(trk, have)
    ready = seen[forced | early]
    if ready.size == 0:
        return
    trk.state.early[ready] = early[forced | early]
    if defer:
        trk.state.phase[ready] = PENDING
        return
    fit_windows(trk, ready, out)


def early_attempt(trk, have):
    """Whether passages ``have`` (...) samples after their detection, their windows not yet complete, try an
    early start (:func:`fit_windows`, :func:`accepted`): from :data:`EARLY_MIN` samples on, every
    ``window // EARLY_ATTEMPTS`` samples (at least every sample): at most about :data:`EARLY_ATTEMPTS` attempts
    per window, so its cost is bounded.  Never without the setting ``early_starts``."""
    every = max(1, trk.window // EARLY_ATTEMPTS)
    return trk.settings.early_starts & (have >= EARLY_MIN) & (have < trk.window) & ((have - EARLY_MIN) % every == 0)


EARLY_MIN = 4
"""Samples since the detection at a passage's first early start attempt (:func:`early_attempt`)."""
EARLY_ATTEMPTS = 15
"""Early start attempts per initialisation window, at most about (:func:`early_attempt`)."""


def fit_windows(trk, ready, out):
    """The global fits of the windows of passages ``ready`` (complete, or an early attempt, at their current
    sample) and the start of the banks of those whose fits are accepted (:func:`accepted`; the others stay
    initialising), one batch per window length: a passage's fits are those it would have alone (a batch of
    windows of different lengths would pad the shorter ones, and their fits would move at rounding)."""
    o = trk.settings
    have = trk.state.n[ready] - trk.state.k0[ready] + 1
    for length in np.unique(have):
        group = ready[have == length]
        yw, taus = samples_since(trk.state, group, trk.state.k0[group])
        t0 = time.perf_counter()
        early = trk.state.early[group]
        again = early & np.isfinite(trk.state.win[group, 0, 0])         # an earlier attempt's fits to carry on
        if again.all():
            fits = continued_fits(trk, trk.state.win[group], yw, taus)
        else:
            fits = window_fits_of(trk, yw, taus)
        ok = ~early | accepted(trk, fits, yw, taus)
        trk.seconds["initialiser"] += time.perf_counter() - t0
        trk.state.win[group] = fits.theta              # (an early attempt's: the next attempt carries them on)
        trk.state.win_t0[group] = trk.state.t_hist[group, trk.state.k0[group] % trk.state.y_hist.shape[1]]
        trk.state.phase[group[~ok]] = STARTING
        if not ok.any():
            continue
        if not ok.all():
            group, fits, taus = group[ok], fits.take(ok), taus[ok]
        trk.state.scan[group] = trk.state.n[group]
        trk.state.phase[group] = RUNNING
        start_banks(trk, group, fits, taus[:, -1], o.inflate, out)


def continued_fits(trk, theta, yw, taus):
    """An early attempt after the first: the previous attempt's fits ``theta`` (R, keep_init, n, internal, at
    the same window start) and their mirror images (:func:`mirrored`) refitted to the grown windows ``yw`` (R,
    W, m) at times ``taus`` (R, W) (Levenberg-Marquardt only: the grid search ran at the first attempt, and
    runs again at the complete window); the ``keep_init`` best distinct fits, as :class:`WindowFits`."""
    o = trk.settings
    starts = np.concatenate([theta, mirrored(trk, theta)], axis=1)
    return refit_window(trk.model, yw, starts, taus=taus, prior=depth_prior(trk.model, o.z_std), keep=o.keep_init,
                        distinct_m=o.distinct_m, gof=o.gof, huber=trk.huber)


def mirrored(trk, theta):
    r"""States ``theta`` (..., n, internal units) mirrored through the array's centre ``c``: position
    :math:`2c - \mathbf{x}`, velocity :math:`-\mathbf{v}`, the other components as they are."""
    xs = trk.model.x_scale
    centre = trk.model.array.positions[:, :2].mean(axis=0)
    out = np.array(theta, dtype=float)
    out[..., :2] = (2.0 * centre - theta[..., :2] * xs[:2]) / xs[:2]
    out[..., 2:4] = -theta[..., 2:4]
    return out


def accepted(trk, fits, yw, taus):
    r"""Whether the fits ``fits`` of early attempts on windows ``yw`` (R, W, m) at times ``taus`` (R, W) start
    their banks (R,).

    A short window's fits are accepted when they locate the ship and tell it from its mirror image: the best
    fit passes its goodness-of-fit test, the larger axis of its position standard deviation at this sample
    (of the covariance its bank would start from, :func:`start_banks`, at most the passage prior's) is under
    :data:`EARLY_SD_M`, and it explains the window better than the passage mirrored across the array by more
    than ``2 ambiguity_nats`` of chi-square (:func:`mirror_gap`).  A complete window, or one past the peak,
    always starts its bank.

    The last test guards against a short window's other minimum: a few samples far from the array fit the
    mirrored passage (tens to hundreds of metres off) about as well as the true one, and the search may
    find the one alone, with a curvature that would call it metres-accurate.
    """
    o = trk.settings
    A = transitions(trk.model, taus[:, -1])                                        # window start -> now
    cov = np.linalg.inv(fits.info[:, 0] / (o.inflate * trk.kappa) + trk.prior_info)
    pos = trk.model.cov_to_si(A @ cov @ np.swapaxes(A, -1, -2))[:, :2, :2]
    ok = fits.fit_ok & (crlb_sd(pos) < EARLY_SD_M)        # (crlb_sd: the larger axis's standard deviation)
    if ok.any():
        ok[ok] = mirror_gap(trk, fits.take(ok), yw[ok], taus[ok]) > 2.0 * o.ambiguity_nats
    return ok


def mirror_gap(trk, fits, yw, taus):
    r"""The chi-square (Huber cost) (R,) by which the best of ``fits`` explains its window ``yw`` (R, W, m) at
    times ``taus`` (R, W) better than the passage mirrored through the array's centre ``c``: a refit started
    from :math:`(2c - \mathbf{x}, -\mathbf{v})` (the other components as fitted); infinite where that refit
    returns to the best fit (closer than ``distinct_m``).

    A static dipole's field is even in the source-to-sensor vector, so far from a small array a passage and its
    mirror image across it give nearly the same samples (exactly, with one sensor and no depth offset) until
    the closest approach: a short window's search may find the one and not the other.
    """
    o, xs = trk.settings, trk.model.x_scale
    other = refit_window(trk.model, yw, mirrored(trk, fits.theta[:, :1]), taus=taus,
                         prior=depth_prior(trk.model, o.z_std), keep=1, gof=None, huber=trk.huber)
    A = transitions(trk.model, taus[:, -1])
    apart = np.hypot(*((np.einsum("rij,rj->ri", A, other.theta[:, 0] - fits.theta[:, 0])[:, :2]) * xs[:2]).T)
    return np.where(apart < o.distinct_m, np.inf, other.chi2[:, 0] - fits.chi2[:, 0])


EARLY_SD_M = 10.0
"""An early start's largest position standard deviation, m (:func:`accepted`)."""


def window_fits_of(trk, yw, taus):
    """The global initialiser's fits of windows ``yw`` (R, W, m) with times ``taus`` (R, W)."""
    o = trk.settings
    regular = np.allclose(taus, np.arange(taus.shape[1]) * trk.model.period, rtol=0, atol=1e-9)
    return window_fits(trk.model, yw, **trk.grid, taus=None if regular else taus, keep=o.keep_init,
                       grid_samples=o.grid_samples, grid_reserve=trk.window,
                       distinct_m=o.distinct_m, z_std=o.z_std, refine=o.refine, gof=o.gof,
                       explore_samples=o.explore_samples, huber=trk.huber)


def global_starts(trk, yw, taus, which, lengths):
    """Starts (R, keep_init, n) at the windows' first samples: the global fits of the windows ``which``
    (a restart after an alarm need not stay near the track that diverged), NaN for the others; ``lengths``
    (R,): each window's samples (the others padding)."""
    starts = np.full((yw.shape[0], trk.settings.keep_init, trk.model.n), np.nan)
    # (they are only starts, which the refit takes to all the samples: the global fits see at most a
    # window's worth of them, evenly spread from the first to the last, so their cost does not grow; one
    # batch per window length, its own samples: a passage's starts do not depend on the windows beside it)
    for W in np.unique(lengths[which]):
        rows = np.flatnonzero(which & (lengths == W))
        pick = np.unique(np.round(np.linspace(0, W - 1, min(W, trk.window))).astype(int))
        starts[rows] = window_fits_of(trk, yw[rows][:, pick], taus[rows][:, pick]).theta
    return starts


def start_banks(trk, runs, fits, tau, inflate, out):
    """(Re)start the banks of passages ``runs`` at this sample from window fits at times ``tau`` (R,) before
    it; a fit that fails its test has its covariance inflated by its chi-square over the expected."""
    H, xs = trk.H, trk.model.x_scale
    A = transitions(trk.model, tau)                                               # (R, n, n)
    birge = np.where(fits.fit_ok[:, None], 1.0,
                     np.maximum(1.0, fits.chi2[:, :1] / np.maximum(fits.expected[:, None], 1e-300)))
    # the bank starts from at most BANK_INFLATION_MAX times the fit's covariance (a nonlinear filter
    # started from a covariance 1e6 times too wide throws its sigma points far outside the model's
    # domain, and the track is lost); the rest of the inflation is
    # reported on top of the bank's covariance until a fit passes
    bank_birge = np.minimum(birge, BANK_INFLATION_MAX)
    trk.state.excess[runs] = (birge / bank_birge)[:, 0]
    # no start is wider than the passage prior: the fit's information plus the prior's (a weak fit -- the
    # range-moment trade-off of one magnetometer -- otherwise starts a bank kilometres wide)
    scale = (inflate * trk.kappa) * bank_birge[..., None, None]
    cov = symmetrize(np.linalg.inv(fits.info / scale + trk.prior_info))
    seeds = np.einsum("rij,rmj->rmi", A, fits.theta)
    P0 = A[:, None] @ cov @ np.swapaxes(A, -1, -2)[:, None]
    loglik = fits.loglik
    M = seeds.shape[1]
    if M < H:   # fewer fits than hypotheses: the best again, with no weight
        pad = (slice(None), np.zeros(H - M, dtype=int))
        seeds, P0 = np.concatenate([seeds, seeds[pad]], 1), np.concatenate([P0, P0[pad]], 1)
        loglik = np.concatenate([loglik, np.full((len(runs), H - M), -np.inf)], axis=1)
    trk.bank.reset_runs(runs, seeds * xs, P0 * np.outer(xs, xs)[None, None], loglik)
    trk.state.start[runs], trk.state.trusted[runs] = trk.state.n[runs], fits.fit_ok
    trk.state.ref[runs] = np.trace(P0[np.arange(len(runs)), 0, :2, :2] * np.outer(xs[:2], xs[:2]), axis1=-2,
                                    axis2=-1)
    trk.state.nis[runs] = np.nan
    trk.state.cons[runs], trk.state.cons_n[runs], trk.state.cons_now[runs] = 0.0, 0, False
    trk.report_runs(runs, out)


def restart(trk, runs, snr, out):
    """Refit the passages among ``runs`` whose bank is due (alarms, schedule, peak, collapse, a failed
    consistency test: :func:`~shipsense.trackers.tracker.restarts.due`; a selection that has just become
    ambiguous, ``out.ambiguous``); with motion modes, not before a window of samples has come after the last
    manoeuvring one (a refit's line starts after the manoeuvre), or :data:`EARLY_MIN` samples for a passage
    whose bank's fit failed (:func:`settled`)."""
    if trk.modes is not None:
        runs = runs[settled(trk, runs)]
        if runs.size == 0:
            return
    flags, s = np.empty((runs.size, 4), dtype=bool), trk.state
    due(np.asarray(runs, dtype=np.int64), s.n, s.start, s.nis, s.trusted, s.alarms, s.peak, s.peak_done, snr,
        s.scan, s.own, s.ref, s.cons_now, *restart_options(trk.settings), out.status, out.cov, INCONSISTENT,
        flags)
    due_, alarm, after_peak, rescan = flags.T
    tie = newly_tied(trk, runs, out)
    due_ |= tie
    rescan |= tie
    if due_.any():
        sel = runs[due_]
        trk.state.scan[runs[rescan]] = trk.state.n[runs[rescan]]
        trk.state.peak_done[sel] |= after_peak[due_]
        trk.state.alarms[sel] += alarm[due_]
        trk.state.restarts[sel] += 1
        failed_test = trk.state.cons_now[runs]
        refit(trk, sel, alarm[due_], rescan[due_], out)
        # a refit after a failed consistency test: the sample is still the test's (inconsistent), with the
        # refit's covariance -- unless the fit failed its own test (then as any failed fit)
        ok = runs[failed_test & trk.state.trusted[runs]]
        out.status[ok], trk.state.cons_now[ok] = INCONSISTENT, True


def settled(trk, runs):
    """Whether passages ``runs`` (R,) have had enough samples since their last manoeuvring one (state ``since``)
    to refit a line after it: a window's (``window``), or :data:`EARLY_MIN` for a passage whose bank's fit
    failed (``trusted`` false).

    A bank that does not explain its data waits for the least: it is wrong already, and a manoeuvre it reported
    while trusted may have ended long before a window's samples; a passage that is not trusted never moves its
    ``since`` on (:meth:`~shipsense.trackers.tracker.tracker.Tracker.update`: its manoeuvre modes explain the
    misfit of a start across a manoeuvre, not a manoeuvre of their own) and its refits fit the samples since its
    bank's start (:func:`refit`)."""
    since = trk.state.since[runs]
    wait = np.where(trk.state.trusted[runs], trk.window, EARLY_MIN)
    return (since < 0) | (trk.state.n[runs] - since > wait)


def newly_tied(trk, runs, out):
    """Whether the selections of passages ``runs`` (R,) have just become ambiguous (``out.ambiguous``: a near
    tie between hypotheses far apart, :func:`~shipsense.trackers.bank.selection.report`), not at a (re)start.

    Such a passage is refitted (:func:`restart`), with the global initialiser's fits of its samples among the
    starts: the filters' running likelihoods may have drifted (near the closest approach a wrong hypothesis's
    filter can out-predict the true one's for a few samples), or no hypothesis is the passage; the refit
    weighs the hypotheses by their fits to every sample since the window start."""
    s = trk.state
    tie = out.ambiguous[runs] & ~s.tied[runs] & (s.n[runs] > s.start[runs])
    s.tied[runs] = out.ambiguous[runs]
    return tie


def refit(trk, runs, alarm, rescan, out):
    """Batch refits of passages ``runs`` to their samples since the window start (at most ``history``; with
    motion modes, after the last manoeuvring sample, and for a bank whose fit failed since its start),
    started from the selected estimate, the bank's live hypotheses and (``multistart``) the initial
    window fits; the bank restarts from the ``keep`` best distinct fits."""
    o, H, n = trk.settings, trk.H, trk.model.n
    first = np.maximum(np.maximum(trk.state.k0[runs], trk.state.since[runs] + 1),
                       trk.state.n[runs] - trk.state.y_hist.shape[1] + 1)
    if trk.modes is not None:
        # with motion modes, a bank whose fit failed refits the samples since its start: those before it, which
        # its fit did not explain, may hold a manoeuvre (a start across one), which no line explains
        first = np.where(trk.state.trusted[runs], first, np.maximum(first, trk.state.start[runs]))
    lengths = trk.state.n[runs] - first + 1
    if not trk.pads_exactly and np.unique(lengths).size > 1:
        # one batch pads the shorter windows with missing samples: the compiled least-squares fits and their
        # information skip them (a passage's refit is the one it gets alone), numpy's fits (a model without
        # a compiled kernel) and a robust fit's information do not (they move at rounding with the length)
        for w in np.unique(lengths):
            group = lengths == w
            refit(trk, runs[group], alarm[group], rescan[group], out)
        return
    yw, taus = samples_since(trk.state, runs, first)
    back = transitions(trk.model, -taus[:, -1])                                    # now -> window start
    rows = (runs[:, None] * H + np.arange(H)).ravel()
    means = trk.bank.belief.mean[rows].reshape(runs.size, H, n)
    cum = trk.bank.cum[runs]
    sel = np.argmax(cum, axis=1)
    live = cum > cum[np.arange(runs.size), sel][:, None] - o.ambiguity_nats
    live[np.arange(runs.size), sel] = True
    starts = np.where(live[..., None], means, np.nan)
    starts = np.concatenate([starts[np.arange(runs.size), sel][:, None], np.where(
        (np.arange(H) == sel[:, None])[..., None], np.nan, starts)], axis=1)
    theta = np.einsum("rij,rhj->rhi", back, starts)
    t_first = trk.state.t_hist[runs, first % trk.state.y_hist.shape[1]]
    win = np.einsum("rij,rhj->rhi", transitions(trk.model, t_first - trk.state.win_t0[runs]),
                    trk.state.win[runs])
    theta = np.concatenate([theta, np.where(alarm[:, None, None], win, np.nan)], axis=1)
    t0 = time.perf_counter()
    multistart = alarm | rescan
    if multistart.any():   # an alarm: the global initialiser again, on everything since the detection
        theta = np.concatenate([theta, global_starts(trk, yw, taus, multistart, lengths)], axis=1)
    prior = depth_prior(trk.model, o.z_std)
    fits = refit_window(trk.model, yw, theta, taus=taus, prior=prior, keep=o.keep, distinct_m=o.distinct_m,
                        gof=o.gof, huber=trk.huber)
    trk.seconds["refits"] += time.perf_counter() - t0
    start_banks(trk, runs, fits, taus[:, -1], 1.0, out)
    out.status[runs] = np.where(fits.fit_ok, RESTARTED, INCONSISTENT)


def restart_options(o):
    """The options of :func:`~shipsense.trackers.tracker.restarts.due` as it takes them: numbers as given (a fractional,
    infinite or negative value compares as it did in numpy), NaN for None (every comparison with it False)."""
    def number(value):
        return np.nan if value is None else float(value)

    return (bool(o.robust), float(o.nis_window), float(o.nis_limit), float(o.max_restarts), number(o.through_peak),
            number(o.refit_every), bool(o.rescan), number(o.collapse))
