"""Choosing among hypotheses: the mixture of a bank's hypotheses and its mean-square error, and
the tracker's report of every passage's selection (:func:`report`, compiled)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from shipsense import numba_cache


def mixture_mse(weights, means, covs, about):
    """Mean-square-error matrix about ``about`` of a Gaussian mixture, summed over its axis 1:
    ``sum_j w_j (P_j + e_j e_j^T)``, ``e_j = means_j - about`` (components of zero weight ignored, even
    with NaN means)."""
    w = np.asarray(weights)[..., None, None]
    e = means - about
    return np.sum(np.where(w > 0, w * (covs + e[..., :, None] * e[..., None, :]), 0.0), axis=1)


@njit(cache=True, error_model="numpy", inline="always")
def first_max(row):
    """``np.argmax`` of a row: the index of its first maximum, or of its first NaN."""
    sel = 0
    top = row[0]
    for h in range(1, row.shape[0]):
        if math.isnan(top):
            break
        c = row[h]
        if math.isnan(c) or c > top:
            sel, top = h, c
    return sel


@njit(cache=True, error_model="numpy", nogil=True)
def report(mean, chol, runs, H, xs, cum, mixture, report_nats, far_m, excess, estimate, cov, own, gap, ambiguous,
           hypotheses, selected):
    """The selection figures of the passages ``runs``, written at their indices (one compiled pass: the numpy
    form of the same was ~30 small array operations a sample).

    ``mean`` (P*H, n) and ``chol`` (P*H, n, n) are the bank's hypotheses (internal units: ``xs`` scales them
    to SI), ``cum`` (len(runs), H) their cumulative log-likelihoods.  Per passage: the selected hypothesis
    (the first maximum of ``cum``, the first NaN if any, as ``np.argmax``) and its mean (``estimate``); with
    ``mixture`` the mixture mean-square error about it (:func:`mixture_mse`, weights ``exp(cum - max)``
    normalised), else the selected hypothesis's covariance, symmetrised and times the passage's ``excess``
    (``cov``); the trace of the selected
    hypothesis's own position covariance (``own``); the log-likelihood gap between the two best finite
    hypotheses (``gap``, inf with one hypothesis); whether two hypotheses within ``report_nats`` of the best
    are more than ``far_m`` apart (``ambiguous``); the number of finite hypotheses (``hypotheses``).
    """
    n = mean.shape[1]
    means = np.empty((H, n))
    covs = np.empty((H, n, n))
    w = np.empty(H)
    live = np.empty(H, np.bool_)
    acc = np.empty((n, n))
    for p in range(runs.shape[0]):
        r = runs[p]
        for h in range(H):                        # SI means and covariances L L^T
            row = r * H + h
            for a in range(n):
                means[h, a] = mean[row, a] * xs[a]
            for a in range(n):
                for b in range(n):
                    t = 0.0
                    for k in range(n):
                        t += chol[row, a, k] * chol[row, b, k]
                    covs[h, a, b] = t * (xs[a] * xs[b])
        sel = first_max(cum[p])
        top = cum[p, sel]
        for a in range(n):
            estimate[r, a] = means[sel, a]
        if mixture:
            total = 0.0
            for h in range(H):
                w[h] = math.exp(cum[p, h] - top)
                total += w[h]
            for a in range(n):
                for b in range(n):
                    acc[a, b] = 0.0
            for h in range(H):
                wh = w[h] / total
                if not wh > 0.0:                  # zero weight (or NaN): ignored, even with NaN means
                    continue
                for a in range(n):
                    ea = means[h, a] - means[sel, a]
                    for b in range(n):
                        acc[a, b] += wh * (covs[h, a, b] + ea * (means[h, b] - means[sel, b]))
        else:
            for a in range(n):
                for b in range(n):
                    acc[a, b] = covs[sel, a, b]
        for a in range(n):
            for b in range(n):
                cov[r, a, b] = 0.5 * (acc[a, b] + acc[b, a]) * excess[r]
        own[r] = covs[sel, 0, 0] + covs[sel, 1, 1]
        best = -math.inf                          # (np.max: NaN if any is NaN; then no hypothesis is live)
        for h in range(H):
            c = cum[p, h]
            if math.isnan(c) or math.isnan(best):
                best = math.nan
            elif c > best:
                best = c
        first, second = -math.inf, -math.inf      # the two best finite log-likelihoods
        count = 0
        for h in range(H):
            c = cum[p, h]
            live[h] = c > best - report_nats
            if math.isfinite(c):
                count += 1
                if c > first:
                    first, second = c, first
                elif c > second:
                    second = c
        gap[r] = first - second if H > 1 else math.inf
        hypotheses[r] = count
        selected[r] = sel
        amb = False
        for i in range(H):
            if not live[i]:
                continue
            for j in range(H):
                if live[j]:
                    dx, dy = means[i, 0] - means[j, 0], means[i, 1] - means[j, 1]
                    if dx * dx + dy * dy > far_m * far_m:
                        amb = True
        ambiguous[r] = amb


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
