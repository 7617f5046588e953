"""The wide-prior study's figures (:mod:`shipsense.reproduce.wide`): a method's per-passage figures, the
position bounds its RMSE is compared with, and the row of figures pooled from them."""

from __future__ import annotations

import numpy as np

from shipsense.trackers.metrics import converged_until, position_crlb_trace, position_nees


def position_bounds(model, truth, P0):
    """Position bounds (trace, m^2) the RMSE is compared with, from the bank's prior ``P0`` (SI).

    ``pcrlb``: each passage's own PCRLB with the tracker's process noise, (R, K);
    ``pcrlb_pooled``: one PCRLB from the information averaged over the passages, (K,) (the
    first version of this study; lower than the mean of the per-passage bounds, so optimistic
    for a population of weak and strong passages); ``crlb_deterministic``: each passage's
    CRLB without process noise, (R, K) (the passages are constant-velocity).
    """
    parts = bound_parts(model, truth, P0)
    return {**parts, "pcrlb_pooled": pooled_bound(model, parts["info_sum"] / len(truth), parts["J0"])}


def bound_parts(model, truth, P0):
    """The per-passage bounds of :func:`position_bounds`, and what its pooled bound needs from these passages:
    the sum of their measurement information (K, n, n) and the prior information ``J0`` (internal units)."""
    from shipsense.design.fisher import measurement_information, pcrlb_from_information

    x = model.to_internal(truth)
    J0 = np.linalg.inv(model.cov_to_internal(P0))
    info = measurement_information(model, x)
    deterministic = pcrlb_from_information(model, info, J0, Q=np.zeros_like(model.Q))
    return {"pcrlb": position_crlb_trace(model.cov_to_si(pcrlb_from_information(model, info, J0))),
            "crlb_deterministic": position_crlb_trace(model.cov_to_si(deterministic)),
            "info_sum": info.sum(axis=0), "J0": J0}


def pooled_bound(model, info_mean, J0):
    from shipsense.design.fisher import pcrlb_from_information

    return position_crlb_trace(model.cov_to_si(pcrlb_from_information(model, info_mean[None], J0)[0]))



def converged(est, truth, ends):
    """The study's rule per passage (:func:`~shipsense.trackers.metrics.converged_until`): error below 10 m over
    the last 10 % of its own samples; also the position errors (NaN after each passage's end) and the mask of
    its samples."""
    return converged_until(est, truth, ends)


def passage_figures(est, covs_pos, truth, ends, status=None):
    """A method's per-passage figures, from which :func:`aggregate` computes its row (so that chunks of
    passages can be pooled): ``conv`` (R,), and (R, K) ``err`` (position error, NaN after each passage's
    end), ``valid`` (its samples), ``q`` (position NEES, :func:`~shipsense.trackers.metrics.position_nees`:
    NaN where no covariance is given) and ``track`` (the method reports a track: for the Tracker, ``status``
    `tracking` or `restarted`; the studies' methods always do)."""
    from shipsense.trackers.tracker.results import RESTARTED, TRACKING

    conv, err, valid = converged(est, truth, ends)
    track = np.ones_like(valid) if status is None else np.isin(status, (TRACKING, RESTARTED))
    return {"conv": conv, "err": err, "valid": valid, "q": position_nees(est, covs_pos, truth), "track": track}


def aggregate(fig, ends, bounds, seconds):
    """A method's row from its per-passage figures (:func:`passage_figures`, pooled over every passage) and
    the position bounds (:func:`position_bounds`; None: no bound ratios)."""
    conv, err, valid, q = fig["conv"], fig["err"], fig["valid"], fig["q"]
    k = np.arange(err.shape[1])[None, :]
    second = valid & (k >= (ends // 2)[:, None])
    rmse = float(np.sqrt(np.nanmean(np.where(second[conv], err[conv], np.nan) ** 2))) if conv.any() else None
    used = second & conv[:, None]   # the (passage, sample) pairs of the RMSE
    ratios = {}
    for key, name in (("pcrlb", "rmse_over_pcrlb"), ("pcrlb_pooled", "rmse_over_pcrlb_pooled"),
                      ("crlb_deterministic", "rmse_over_crlb_deterministic")):
        if bounds is None:
            ratios[name] = None
            continue
        b = bounds[key]
        if b.ndim == 1:   # the pooled bound: one per sample, over every passage's second half (as first reported)
            bound = float(np.sqrt(np.mean(np.broadcast_to(b, second.shape)[second]))) if second.any() else None
        else:
            bound = float(np.sqrt(np.mean(b[used]))) if used.any() else None
        ratios[name] = rmse / bound if rmse is not None and bound else None
    # the same over the samples where the method reports a track (a causal tracker reports the passage prior
    # while its first window fills, and says when its fit fails; the studies' methods always report one)
    ratios["rmse_over_crlb_tracking"] = ratios["untracked_share"] = None
    m = used & fig["track"]
    if bounds is not None and m.any():
        bound = np.mean(bounds["crlb_deterministic"][m])
        ratios["rmse_over_crlb_tracking"] = float(np.sqrt(np.mean(err[m] ** 2) / bound))
        ratios["untracked_share"] = float(1.0 - m.sum() / used.sum())
    ne = ne_run = None
    # the share of the RMSE's (passage, sample) pairs where the method claims a covariance (NEES is over those)
    covered = float(np.mean(np.isfinite(q)[used])) if used.any() else None
    if conv.any():
        qs = np.where(second[conv], q[conv], np.nan)   # NaN also where a method gives no covariance
        n = np.isfinite(qs).sum(axis=1)
        if n.any():
            ne = float(np.nansum(qs) / n.sum())
            ne_run = float(np.median(np.nansum(qs, axis=1)[n > 0] / n[n > 0]))   # the typical run
    # MRMSE_r: the time average of RMSE_k over the samples where passages are still running
    running = valid.any(axis=0)
    rmse_k = np.sqrt(np.nanmean(err[:, running] ** 2, axis=0))
    return {"convergence_rate": float(conv.mean()), "mrmse_r_m": float(np.mean(rmse_k)), **ratios,
            "nees_mean": ne, "nees_median_run": ne_run, "nees_coverage": covered, "seconds_per_passage": seconds}


def method_row(est, covs_pos, truth, bounds, seconds, ends, status=None):
    """A method's row on one batch of passages (:func:`passage_figures`, then :func:`aggregate`)."""
    return aggregate(passage_figures(est, covs_pos, truth, ends, status), ends, bounds, seconds)


__all__ = ["aggregate", "bound_parts", "converged", "method_row", "passage_figures", "pooled_bound",
           "position_bounds"]
