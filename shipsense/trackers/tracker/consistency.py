r"""The tracker's windowed innovation consistency test: is the filter as sure of its state as its innovations allow?

A Kalman filter whose covariance is honest has white innovations: the
component ``i`` of the innovation at sample ``k``, normalised by its own
predicted standard deviation,

.. math:: z_{ki} = \epsilon_{ki} / \sqrt{P_{yy,ki} + R_i}

(``P_yy`` the state's share of the innovation covariance, ``R`` the declared
noise variance, not the filter's kappa-inflated one), is a zero-mean draw of
the declared noise model, independent from sample to sample.  A filter that
is too sure of a wrong state instead sees innovations with a persistent mean
``H (x - x_hat)``: the error it does not believe in.  The test sums each
channel's normalised innovations over the last ``consistency_window``
samples and compares

.. math:: T = \sum_i \frac{(\sum_k \psi(z_{ki}))^2}{\sum_k v_{ki}}

with the chi-square quantile of its degrees of freedom (the channels with
data in the window).  ``psi`` is Huber's clip at ``gamma`` when the tracker is
robust, so an outlier moves a channel's sum by no more than ``gamma``
(identity otherwise), and ``v`` is the variance of ``psi(z)`` under the declared noise
(a share ``eps`` of outliers ``scale`` times the standard deviation; closed
form).  With Gaussian noise, a linear model, an honest filter and
uncorrelated channels (the state's share of the innovations small against
the noise) ``T`` is exactly chi-square, so the false-alarm rate per test is
the test's level (``consistency_level``); with Huber's clip it is a normal
approximation (both checked in tests/trackers/tracker/test_consistency.py, against the test's definition in numpy:
``terms`` and ``statistic`` of tests/reference.py).

When the test fails, the tracker refits the passage
(:class:`~shipsense.trackers.Tracker`'s restarts): a batch fit of every
sample so far replaces the filter's state and covariance, and the sample is
reported ``inconsistent``.  On faulty one-magnetometer passages (outliers
and dropouts), where the filter runs alone for most of the passage after its
closest approach, the refit raises the post-convergence coverage of the 95 %
ellipse (``experiments/tracker_consistency.py``; docs: Results).  Inflating
the filter's covariance instead, by the factor the same statistic estimates
(method of moments, ``1 + (T - dof) / sum_i (sum_k a_ki)^2 / sum_k v_ki``
with ``a = g sqrt(P_yy / (P_yy + R))``, ``g`` the mean slope of ``psi``),
raised it less: the position error of an optimistic filter shows in its
innovations less than in its position (the moment and the velocity take up
part of it), and a refit replaces the biased state as well.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit, vectorize
from scipy import special

from shipsense import numba_cache


@njit(cache=True, error_model="numpy", inline="always")
def _clipped_variance(sd, c):
    """``E[psi(e)^2]`` for ``e ~ N(0, sd^2)`` and Huber's clip ``psi`` at ``c``."""
    if not math.isfinite(c):
        return sd * sd
    a = c / sd
    inside = math.erf(a / math.sqrt(2.0))                                     # P(|u| < a)
    pdf = math.exp(-0.5 * a * a) / math.sqrt(2.0 * math.pi)
    return sd * sd * (inside - 2.0 * a * pdf) + c * c * (1.0 - inside)


@njit(cache=True, error_model="numpy", inline="always")
def _psi_variance(state_var, noise_var, gamma, eps, scale):
    """:func:`psi_variance` of one component (the formula the tracker's compiled pass uses too)."""
    v = _clipped_variance(1.0, gamma)
    if eps > 0.0:
        total = state_var + noise_var
        v = (1.0 - eps) * v + eps * _clipped_variance(math.sqrt((state_var + scale * scale * noise_var) / total),
                                                       gamma)
    return v


def _psi_variance_scalar(state_var, noise_var, gamma, eps, scale):
    return _psi_variance(state_var, noise_var, gamma, eps, scale)


@lru_cache(maxsize=1)
def _psi_variance_ufunc():
    """:func:`psi_variance`'s compiled ufunc, made (loaded from numba's cache, or compiled) at its first use, not
    when this module is imported: an eager ufunc costs every process that imports the tracker its load."""
    return vectorize(["float64(float64, float64, float64, float64, float64)"], cache=True)(_psi_variance_scalar)


def psi_variance(state_var, noise_var, gamma=np.inf, eps=0.0, scale=1.0):
    """Variance ``v`` of ``psi(z)`` for the normalised innovations ``z`` of an honest filter.

    ``z = eps / sqrt(state_var + noise_var)``: a share ``1 - eps`` of components has variance 1, a share
    ``eps`` (outliers of ``scale`` times the noise's standard deviation) ``(state_var + scale^2 noise_var) /
    (state_var + noise_var)``.  Arrays broadcast.
    """
    with np.errstate(all="ignore"):   # (the compiled loop may evaluate an unused branch: inf * 0 for no clip)
        return _psi_variance_ufunc()(state_var, noise_var, gamma, eps, scale)


def threshold(dof, level):
    """The chi-square quantile ``1 - level`` of ``dof`` degrees of freedom (inf at 0)."""
    dof = np.asarray(dof, dtype=int)
    table = _quantiles(float(level), max(int(dof.max(initial=0)), 1))
    return table[dof]


def quantile_table(level, top):
    """:func:`threshold`'s table: ``table[k]`` the chi-square quantile ``1 - level`` of ``k`` degrees of freedom
    for k = 0..top at least (inf at 0; cached)."""
    return _quantiles(float(level), max(int(top), 1))


@lru_cache(maxsize=32)
def _quantiles(level, top):
    """``chi2.isf(level, k)`` for k = 0..top (inf at 0), rounded up to a power of two of entries: the tracker
    asks every sample for a handful of small degrees of freedom (a table lookup, not a scipy call each time)."""
    size = 1 << int(top).bit_length()
    k = np.arange(size)
    return np.where(k > 0, special.chdtri(np.maximum(k, 1), level), np.inf)     # scipy.stats.chi2.isf


@njit(cache=True, error_model="numpy", nogil=True)
def window_test(runs, sel, H, eps, S, R_used, R_declared, present, gamma, outliers, scale, table, window, count,
                tests, fails, now, failed):
    """The tracker's test of passages ``runs`` at one sample, in one compiled pass (the test's implementation):
    each passage's terms of its selected hypothesis ``sel`` -- ``psi(z)`` and its variance ``v``
    (:func:`psi_variance`) per channel, from the innovations ``eps`` (len(runs)*H, m) and their covariances'
    diagonals from ``S`` (len(runs)*H, m, m), less the noise on them, ``R_used`` (len(runs)*H or 1, m) --
    written into its window ``window`` (P, N, 2, m) at slot ``count % N``; once the window is full (``tests``
    counts it), the statistic ``T`` of its sums against ``table[dof]`` (:func:`quantile_table`).  A passage
    that fails has its window emptied, ``fails`` and ``now`` set; ``failed`` (len(runs),) says which.  (The
    definitions in numpy, ``terms`` and ``statistic`` of tests/reference.py, are the independent reference
    tests/trackers/tracker/test_consistency.py holds this equal to.)"""
    N, m = window.shape[1], window.shape[3]
    for p in range(runs.shape[0]):
        r = runs[p]
        row = p * H + sel[p]
        slot = count[r] % N
        for i in range(m):
            noise = R_used[row if R_used.shape[0] > 1 else 0, i]
            state = S[row, i, i] - noise
            if state < 0.0:                       # (np.maximum and np.clip: NaN stays NaN)
                state = 0.0
            total = state + R_declared[i]
            z = eps[row, i] / math.sqrt(total)
            psi = gamma if z > gamma else (-gamma if z < -gamma else z)
            v = _psi_variance(state, R_declared[i], gamma, outliers, scale)
            window[r, slot, 0, i] = psi if present[p, i] else 0.0
            window[r, slot, 1, i] = v if present[p, i] else 0.0
        count[r] += 1
        failed[p] = False
        if count[r] < N:
            continue
        tests[r] += 1
        T = 0.0
        dof = 0
        for i in range(m):
            s = 0.0
            v = 0.0
            for k in range(N):
                s += window[r, k, 0, i]
                v += window[r, k, 1, i]
            if v > 0.0:
                T += s * s / v
                dof += 1
        if T > table[dof]:
            failed[p] = True
            for k in range(N):
                for c in range(2):
                    for i in range(m):
                        window[r, k, c, i] = 0.0
            count[r] = 0
            fails[r] += 1
            now[r] = True


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
