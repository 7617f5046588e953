"""Tracking metrics: position error, RMSE, convergence (and the rule that judges it over the passages whose data
allow it), NEES and 95 % ellipse coverage, and the position bound the errors are compared with.

Conventions: estimates and truth are (runs, steps, >= 2) with (x, y) first, in metres;
"error" is the horizontal position error.
"""

from __future__ import annotations

import numpy as np

CONVERGENCE_THRESHOLD_M = 10.0
"""Default convergence threshold on the final position error (m)."""
CHI2_2DOF_95 = 5.991464547107979
"""The 95 % quantile of chi-square with 2 degrees of freedom, ``-2 ln 0.05``: a position whose NEES is at most
this lies inside the reported 95 % ellipse."""
CRLB_SD_LIMIT_M = CONVERGENCE_THRESHOLD_M / np.sqrt(CHI2_2DOF_95)
r"""The position CRLB's standard deviation (m) up to which a passage's data allow convergence
(:func:`convergence_allowed`): 10 / sqrt(2 ln 20) = 4.08 m.

An efficient estimate's horizontal error is Gaussian with the bound's covariance; with an equal standard
deviation :math:`s` on each axis its length is Rayleigh distributed, so

.. math::  P(|e| \le r) = 1 - \exp\!\Big(-\frac{r^2}{2 s^2}\Big) = 0.95
           \iff s = \frac{r}{\sqrt{2 \ln 20}} = \frac{r}{\sqrt{\chi^2_{2, 0.95}}},

with :math:`r` = :data:`CONVERGENCE_THRESHOLD_M` (10 m) and :math:`2 \ln 20 = -2 \ln 0.05` =
:data:`CHI2_2DOF_95`.  A bound of unequal axes is judged by its larger one (:func:`crlb_sd`): its covariance
lies below :math:`s^2 I` for that :math:`s`, so the probability of the disc is at least the equal-axes one
(Anderson's theorem: T. W. Anderson, "The integral of a symmetric unimodal function over a symmetric convex
set", Proc. AMS 6, 1955).  At a larger bound even an efficient estimate misses the threshold in more than
5 % of the passages: a miss there is the data's, not the tracker's."""


def position_error(means, truth):
    """Horizontal position error (..., steps) of estimates and truth (x, y first).

    Formed in place (``sqrt(dx^2 + dy^2)``, the same numbers as summing ``d * d`` over x and y): a study's
    bank of hypotheses over runs and steps needs two arrays of its size, not five."""
    err, dy = squared_axis_errors(means, truth)
    err += dy
    del dy
    return np.sqrt(err, out=err)[()]          # (one state: a scalar)


def squared_axis_errors(means, truth):
    """Squared x and y errors (..., steps) each of estimates and truth (x, y first), formed in place (new
    arrays, floating and as wide as the inputs): what :func:`position_error` sums."""
    means, truth = np.asarray(means), np.asarray(truth)
    dtype = np.result_type(means, truth, 1.0)
    out = []
    for i in (0, 1):
        e = np.asarray(np.subtract(means[..., i], truth[..., i], dtype=dtype))
        out.append(np.square(e, out=e))
    return out


def rmse_k(means, truth, run_axis=0):
    """``RMSE_k``: root mean over runs of the squared position error at each step."""
    return np.sqrt(np.mean(position_error(means, truth) ** 2, axis=run_axis))


def trmse(means, truth):
    """``TRMSE`` per run: time average of the position error (..., ) -- the studies' 'total RMSE'.

    Average it over runs for the scenario's figure.
    """
    return position_error(means, truth).mean(axis=-1)


def mrmse(means, truth, run_axis=0):
    """``MRMSE_x``, ``MRMSE_y``, ``MRMSE_r``: time averages of the per-step RMSE over runs."""
    d = np.asarray(means)[..., :2] - np.asarray(truth)[..., :2]
    rx = np.sqrt(np.mean(d[..., 0] ** 2, axis=run_axis)).mean(axis=-1)
    ry = np.sqrt(np.mean(d[..., 1] ** 2, axis=run_axis)).mean(axis=-1)
    rr = rmse_k(means, truth, run_axis).mean(axis=-1)
    return {"x": float(rx), "y": float(ry), "r": float(rr)} if np.ndim(rr) == 0 else {"x": rx, "y": ry, "r": rr}


def converged(means, truth, threshold=CONVERGENCE_THRESHOLD_M, hold=0.1):
    """Per run: the final error is below ``threshold`` and stays there for the last ``hold`` of the steps."""
    e = position_error(means, truth)
    n_hold = max(1, int(round(hold * e.shape[-1])))
    return np.all(e[..., -n_hold:] < threshold, axis=-1)


def convergence_rate(means, truth, threshold=CONVERGENCE_THRESHOLD_M, hold=0.1):
    """Fraction of runs that converged (see :func:`converged`)."""
    return float(np.mean(converged(means, truth, threshold, hold)))


def passage_ends(truth, centre, period):
    """Last sample (R,) of each passage (truth (R, K, >= 4)) as far past its closest approach to ``centre`` as
    its start was before it (a symmetric passage; at most the last sample)."""
    p0, v = truth[:, 0, :2] - np.asarray(centre), truth[:, 0, 2:4]
    speed2 = np.sum(v * v, axis=-1)
    t_cpa = -np.sum(p0 * v, axis=-1) / speed2
    return np.minimum(np.round(2 * t_cpa / period).astype(int), truth.shape[1] - 1)


def converged_until(means, truth, ends, threshold=CONVERGENCE_THRESHOLD_M, hold=0.1):
    """:func:`converged` over each passage's own samples ``0 .. ends`` (R,).

    Returns ``(converged (R,), errors (R, K) NaN after each end, valid (R, K))``: the error is below
    ``threshold`` over the last ``hold`` of the passage's samples.
    """
    k = np.arange(truth.shape[1])[None, :]
    valid = k <= np.asarray(ends)[:, None]
    err = np.where(valid, position_error(means, truth), np.nan)
    tail = valid & (k >= judged_sample(ends, hold)[:, None])
    return np.all(np.where(tail, err < threshold, True), axis=1), err, valid


def judged_sample(ends, hold=0.1):
    """The first sample (R,) of the last ``hold`` of each passage's samples ``0 .. ends`` (R,): where
    :func:`converged_until` starts judging."""
    ends = np.asarray(ends)
    return ends - np.maximum(1, (hold * (ends + 1)).astype(int)) + 1


def crlb_sd(bounds):
    """The position bound's standard deviation along its larger axis (m): the square root of the largest
    eigenvalue of the (x, y) block of ``bounds`` (..., >= 2, >= 2; SI, m²: a CRLB's position block or its
    whole state); shape (...)."""
    b = np.asarray(bounds, dtype=float)
    a, c, off = b[..., 0, 0], b[..., 1, 1], 0.5 * (b[..., 0, 1] + b[..., 1, 0])
    return np.sqrt(0.5 * (a + c) + np.hypot(0.5 * (a - c), off))


def convergence_allowed(bounds, limit=CRLB_SD_LIMIT_M):
    """Whether each passage's data allow convergence: the position CRLB ``bounds`` (..., >= 2, >= 2, SI) at its
    judged sample (:func:`judged_sample`) has a standard deviation (:func:`crlb_sd`) of at most ``limit``
    (:data:`CRLB_SD_LIMIT_M`: an efficient estimate is then within the 10 m threshold in at least 95 % of
    cases).  The rule the convergence of a tracker is judged by (:func:`convergence_rates`); shape (...)."""
    return crlb_sd(bounds) <= limit


def convergence_rates(converged, allowed):
    """The convergence rate restricted to the passages whose data allow it, beside the unrestricted one.

    Parameters
    ----------
    converged : array of bool, shape (R,)
        Each passage converged (:func:`converged_until`).
    allowed : array of bool, shape (R,)
        Its data allow convergence (:func:`convergence_allowed`).

    Returns
    -------
    dict
        ``convergence`` (the share of all passages), ``convergence_bounded`` (the share of the allowed ones;
        NaN if none is) and ``bounded`` (how many are allowed).
    """
    converged, allowed = np.asarray(converged, dtype=bool), np.asarray(allowed, dtype=bool)
    return {"convergence": float(converged.mean()),
            "convergence_bounded": float(converged[allowed].mean()) if allowed.any() else float("nan"),
            "bounded": int(allowed.sum())}


def nees(means, covs, truth, components=(0, 1)):
    """Normalised estimation error squared over ``components`` (default position: :func:`position_nees`),
    shape (..., steps).

    Its mean over runs of a consistent filter is ``len(components)``.
    """
    if tuple(components) == (0, 1):
        return position_nees(means, covs, truth)
    idx = list(components)
    e = np.asarray(means)[..., idx] - np.asarray(truth)[..., idx]
    P = np.asarray(covs)[..., idx, :][..., :, idx]
    return np.einsum("...i,...i->...", e, np.linalg.solve(P, e[..., None])[..., 0])


def position_nees(means, covs, truth):
    """Position NEES ``d^T P^-1 d`` (..., steps), dimensionless: ``d`` the horizontal error (m) of estimates
    ``means`` against ``truth`` (..., steps, >= 2), ``P`` the (x, y) block (m²) of ``covs`` (..., steps, >= 2,
    >= 2: position covariances or whole state covariances).  Its mean is 2 for a consistent tracker.

    In closed form, ``(P_yy d_x² - 2 P_xy d_x d_y + P_xx d_y²) / (P_xx P_yy - P_xy²)``; NaN where ``P`` is not a
    finite positive-definite matrix (no covariance reported)."""
    d = np.asarray(means)[..., :2] - np.asarray(truth)[..., :2]
    P = np.asarray(covs, dtype=float)
    a, b, c = P[..., 0, 0], P[..., 0, 1], P[..., 1, 1]
    det = a * c - b * b
    ok = np.isfinite(P[..., :2, :2]).all(axis=(-2, -1)) & (a > 0) & (det > 0)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        q = (c * d[..., 0] ** 2 - 2 * b * d[..., 0] * d[..., 1] + a * d[..., 1] ** 2) / det
    return np.where(ok, q, np.nan)


def coverage(q, where=None, axis=None, limit=CHI2_2DOF_95):
    """95 % ellipse coverage: the share (dimensionless, 0 to 1) of the samples ``where`` (a mask broadcast
    against ``q``; None: all) whose position NEES ``q`` (:func:`position_nees`) is at most ``limit`` -- the
    truth inside the reported ellipse.  A NaN NEES (no covariance) counts as not covered.  Summed over
    ``axis`` (None: all samples): the shape of ``q`` without it (NaN where ``where`` selects no sample)."""
    inside = np.asarray(q) <= limit
    if where is None:
        where = np.ones_like(inside)
    return np.sum(inside & where, axis=axis) / np.sum(where, axis=axis)


def position_crlb_trace(bounds):
    """Trace of the position block of error-covariance bounds ``bounds`` (..., n, n) in SI units (a CRLB or
    PCRLB; a model's ``cov_to_si`` converts one in its internal units): the least mean square horizontal
    position error ``B_xx + B_yy``, m².  Shape (...)."""
    b = np.asarray(bounds)
    return b[..., 0, 0] + b[..., 1, 1]


def selection_accuracy(selected, hypothesis_trmse):
    """Fraction of runs whose selected hypothesis (R,) has the lowest TRMSE (R, H)."""
    return float(np.mean(np.asarray(selected) == np.argmin(hypothesis_trmse, axis=-1)))
