"""Study variants, kept to reproduce the wide-prior study: the bank started from the global initialiser
(``global_init``), one refit after the closest approach (``global_init_refit``), and a bank spliced in from a
refit.  Users get the project's tracker, :class:`~shipsense.trackers.tracker.tracker.Tracker`.
"""

from __future__ import annotations

import numpy as np

from shipsense.trackers.init.global_init import GlobalInit, unalign
from shipsense.trackers.tracker.restarts import peak_refit_sample, refit_at


def track_with_global_init(unit, model, measurements, gi: GlobalInit, store=None):
    """Run the bank from the global initialiser's hypotheses; returns ``(estimates (R, K, n) SI, BankRun)``.

    Every passage's bank starts at its own ``gi.start``: the measurements are
    aligned on it (bank step j processes sample ``start + j`` of each
    passage; passages that end earlier are padded with missing samples), so
    all passages are one batch whatever their starts.  The returned
    ``BankRun`` is on that aligned axis (step j of passage r is its sample
    ``gi.start[r] + j``).  Before the bank starts, the estimate is the best
    batch fit's trajectory (constant velocity, propagated backwards before
    the detection).  ``store``: the bank's records to keep (:func:`~shipsense.trackers.bank.bank.run_bank`; its
    default when None), with the selected track always kept.
    """
    from shipsense.trackers.bank.bank import run_bank

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
    if isinstance(store, str):
        store = (store,)
    kw = {} if store is None else {"store": tuple(dict.fromkeys((*store, "selected")))}
    bank = run_bank(unit, model, aligned, gi.seeds, gi.P0, initial_loglik=gi.loglik, **kw)
    est = unalign(bank.selected_means, start, K)
    best = np.argmax(gi.loglik, axis=1)
    theta0 = model.to_internal(gi.window[np.arange(R), best, 0])                # internal, at k0
    ks = np.arange(K)[None, :] - gi.k0[:, None]                               # steps relative to k0
    # constant velocity forwards and backwards: x_k = x_0 + k T v for the kinematic block
    traj = np.repeat(theta0[:, None, :], K, axis=1)
    traj[..., 0:2] += ks[..., None] * model.period * theta0[:, None, 2:4]
    before = np.arange(K)[None, :] < start[:, None]
    est[before] = model.to_si(traj)[before]
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
    local minima more often; docs: Results).  Returns a :class:`GlobalInit`
    starting at ``e`` (:func:`~shipsense.trackers.tracker.restarts.refit_at`: the fit,
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
