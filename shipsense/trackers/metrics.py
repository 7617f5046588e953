"""Tracking metrics: position error, RMSE, convergence (and the rule that judges it over the passages whose data
allow it), NEES and 95 % ellipse coverage, and the position bound the errors are compared with; for several ships
at once, GOSPA (:func:`gospa`), the share of samples with the right number of ships (:func:`cardinality_rate`),
and each ship's RMSE and coverage by its labelled track (:func:`label_assignment`, :func:`ship_rmse`,
:func:`ship_coverage`).

Conventions: estimates and truth are (runs, steps, >= 2) with (x, y) first, in metres;
"error" is the horizontal position error.
"""

from __future__ import annotations

from dataclasses import dataclass

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


# -- several ships ------------------------------------------------------------------------------------------------

GOSPA_CUTOFF_M = 20.0
"""Default cut-off ``c`` of :func:`gospa`, m: a position error beyond it counts as a missed and a false ship."""


@dataclass(frozen=True)
class Gospa:
    """The GOSPA metric of estimated against true ship sets (:func:`gospa`), each array of the batch shape.

    Attributes
    ----------
    total : ndarray
        :math:`d_p^{(c, 2)}`, m.
    localisation, missed, false : ndarray
        Its parts, m²: the summed squared position errors of the assigned pairs, and :math:`c^2 / 2` for each
        missed or false ship; they add up to ``total**2``.
    assignment : ndarray of int, shape (..., J)
        The estimate assigned to each true ship (-1: missed).
    """

    total: np.ndarray
    localisation: np.ndarray
    missed: np.ndarray
    false: np.ndarray
    assignment: np.ndarray


def present(states):
    """Which rows of ``states`` (..., n, >= 2; x, y first) hold a ship: finite x and y; shape (..., n)."""
    s = np.asarray(states, dtype=float)
    return np.isfinite(s[..., 0]) & np.isfinite(s[..., 1])


def gospa(estimates, truth, c=GOSPA_CUTOFF_M):
    r"""Generalised optimal sub-pattern assignment metric (GOSPA) of estimated against true ships, at every
    sample of a batch, with :math:`p = 2` and :math:`\alpha = 2`.

    For the estimated positions :math:`X = \{x_1 .. x_{|X|}\}` and the true ones :math:`Y`,

    .. math::  d_p^{(c, 2)}(X, Y) = \Big[\min_{\gamma} \sum_{(i, j) \in \gamma} d(x_i, y_j)^2
               + \frac{c^2}{2} \big(|X| + |Y| - 2 |\gamma|\big)\Big]^{1/2},

    the minimum over assignments :math:`\gamma` of estimates to ships with :math:`d(x_i, y_j) < c`
    (horizontal distance, m): the localisation error of the assigned pairs plus :math:`c^2/2` for every missed
    ship (true, unassigned) and every false one (estimated, unassigned), so an error in the number of ships
    counts.  The optimal assignment is found by ``scipy.optimize.linear_sum_assignment`` on the square
    cost matrix of :math:`\min(d, c)^2` between ships and estimates padded with :math:`c^2/2` (a ship or an
    estimate left over) and 0; a pair at :math:`d \ge c` is a missed and a false ship.

    Parameters
    ----------
    estimates : array_like, shape (..., I, >= 2)
        Estimated ships, x and y first (m); a row with a NaN x or y is no ship (fewer estimates at a sample).
    truth : array_like, shape (..., J, >= 2)
        True ships, likewise (:attr:`shipsense.simulator.Simulation.ships` with the ships axis last but one).
    c : float
        Cut-off, m (default :data:`GOSPA_CUTOFF_M`, 20 m).

    Returns
    -------
    Gospa
        The metric and its parts per sample of the batch shape ``...``, and the assignment.

    References
    ----------
    A. S. Rahmathullah, Á. F. García-Fernández and L. Svensson, "Generalized optimal sub-pattern assignment
    metric", 20th International Conference on Information Fusion (FUSION), 2017.
    """
    from scipy.optimize import linear_sum_assignment

    est, tru = np.asarray(estimates, dtype=float), np.asarray(truth, dtype=float)
    batch = np.broadcast_shapes(est.shape[:-2], tru.shape[:-2])
    I, J = est.shape[-2], tru.shape[-2]
    est = np.broadcast_to(est[..., :2], batch + (I, 2)).reshape(-1, I, 2)
    tru = np.broadcast_to(tru[..., :2], batch + (J, 2)).reshape(-1, J, 2)
    has_e, has_t = present(est), present(tru)
    d2 = np.sum((tru[:, :, None, :] - est[:, None, :, :]) ** 2, axis=-1)               # (B, J, I)
    near = has_t[:, :, None] & has_e[:, None, :] & (d2 < c * c)
    n = max(I, J)
    half = 0.5 * c * c
    # square costs: ships (rows) against estimates (columns), a real pair min(d, c)^2, a real row or column
    # against padding c^2/2, padding against padding 0
    cost = np.zeros((d2.shape[0], n, n))
    row = np.zeros((d2.shape[0], n), dtype=bool)
    col = np.zeros((d2.shape[0], n), dtype=bool)
    row[:, :J], col[:, :I] = has_t, has_e
    cost[:, :J, :I] = np.where(near, d2, c * c)
    cost = np.where(row[:, :, None] & col[:, None, :], cost, half * (row[:, :, None] ^ col[:, None, :]))
    assignment = np.full((d2.shape[0], J), -1)
    both = np.flatnonzero(has_t.any(axis=1) & has_e.any(axis=1))
    for b in both:                                        # the few ships per sample: one small problem each
        rows, cols = linear_sum_assignment(cost[b])
        keep = (rows < J) & (cols < I)
        assignment[b, rows[keep]] = cols[keep]
    gathered = np.take_along_axis(near, np.maximum(assignment, 0)[:, :, None], axis=2)[..., 0] & (assignment >= 0)
    assignment = np.where(gathered, assignment, -1)
    loc = np.sum(np.where(gathered, np.take_along_axis(d2, np.maximum(assignment, 0)[:, :, None], axis=2)[..., 0],
                          0.0), axis=1)
    pairs = gathered.sum(axis=1)
    missed = half * (has_t.sum(axis=1) - pairs)
    false = half * (has_e.sum(axis=1) - pairs)
    return Gospa(np.sqrt(loc + missed + false).reshape(batch), loc.reshape(batch), missed.reshape(batch),
                 false.reshape(batch), assignment.reshape(batch + (J,)))


def cardinality_rate(estimates, truth, where=None):
    """The share (0 to 1) of the samples ``where`` (a mask of the batch shape; None: all) at which the number
    of estimated ships (rows of ``estimates`` (..., I, >= 2) with finite x, y: :func:`present`) equals the
    number of true ones (``truth`` (..., J, >= 2)); NaN if ``where`` selects none."""
    right = present(estimates).sum(axis=-1) == present(truth).sum(axis=-1)
    where = np.ones_like(right) if where is None else np.broadcast_to(where, right.shape)
    return float(np.sum(right & where) / np.sum(where)) if np.any(where) else float("nan")


def label_assignment(estimates, truth, c=GOSPA_CUTOFF_M):
    r"""Which labelled track follows which ship over a passage: the track :math:`i` assigned to each ship
    :math:`j` by the optimal assignment (``scipy.optimize.linear_sum_assignment``) of the costs

    .. math::  C_{ji} = \sum_k \min(d_{jik}, c)^2 + \frac{c^2}{2}\, n_{jik},

    summed over the samples :math:`k` at which both exist (the truncated squared distance, m²) and those at
    which only one does (:math:`n_{jik}`: a missed or false ship there).

    Parameters
    ----------
    estimates : array_like, shape (..., K, I, >= 2)
        Track ``i``'s estimate at sample ``k`` (x, y first, m; NaN where the track does not exist).
    truth : array_like, shape (..., K, J, >= 2)
        Ship ``j``'s true state (NaN where it does not sail).
    c : float
        Cut-off, m.

    Returns
    -------
    ndarray of int, shape (..., J)
        The track of each ship (-1: more ships than tracks).
    """
    from scipy.optimize import linear_sum_assignment

    est, tru = np.asarray(estimates, dtype=float), np.asarray(truth, dtype=float)
    batch = np.broadcast_shapes(est.shape[:-3], tru.shape[:-3])
    K, I, J = tru.shape[-3], est.shape[-2], tru.shape[-2]
    est = np.broadcast_to(est[..., :2], batch + (K, I, 2)).reshape(-1, K, I, 2)
    tru = np.broadcast_to(tru[..., :2], batch + (K, J, 2)).reshape(-1, K, J, 2)
    has_e, has_t = present(est)[:, :, None, :], present(tru)[:, :, :, None]         # (B, K, 1, I), (B, K, J, 1)
    d2 = np.sum((tru[:, :, :, None, :] - est[:, :, None, :, :]) ** 2, axis=-1)       # (B, K, J, I)
    cost = np.where(has_t & has_e, np.minimum(np.nan_to_num(d2, nan=c * c), c * c), 0.5 * c * c * (has_t ^ has_e))
    cost = cost.sum(axis=1)
    out = np.full((cost.shape[0], J), -1)
    for b in range(cost.shape[0]):
        rows, cols = linear_sum_assignment(cost[b])
        out[b, rows] = cols
    return out.reshape(batch + (J,))


def _assigned(values, assignment):
    """The assigned track's rows of ``values`` (..., K, I, ...) for each ship: (..., K, J, ...), NaN where a
    ship has no track (``assignment`` (..., J), -1)."""
    v = np.asarray(values, dtype=float)
    a = np.asarray(assignment)
    extra = v.ndim - a.ndim - 1                               # trailing axes after I
    idx = np.maximum(a, 0)[..., None, :].reshape(a.shape[:-1] + (1, a.shape[-1]) + (1,) * extra)
    out = np.take_along_axis(v, idx, axis=a.ndim)
    return np.where((a >= 0).reshape(a.shape[:-1] + (1, a.shape[-1]) + (1,) * extra), out, np.nan)


def ship_rmse(estimates, truth, assignment, where=None):
    """Each ship's root mean square horizontal position error (m) against its track (``assignment`` (..., J),
    :func:`label_assignment`) over the samples at which both exist (and ``where``, a mask (..., K, J) or
    broadcastable; None: all); ``estimates`` (..., K, I, >= 2), ``truth`` (..., K, J, >= 2).  Shape (..., J);
    NaN for a ship with no such sample.  Compare it with the square root of the position trace of the
    ship's block of the joint-state PCRLB (:func:`position_crlb_trace`)."""
    est = _assigned(estimates, assignment)
    err2 = position_error(est, truth) ** 2
    ok = np.isfinite(err2) if where is None else np.isfinite(err2) & np.asarray(where, dtype=bool)
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.sum(np.where(ok, err2, 0.0), axis=-2) / np.sum(ok, axis=-2))


def ship_coverage(estimates, covariances, truth, assignment, where=None, limit=CHI2_2DOF_95):
    """Each ship's 95 % ellipse coverage (0 to 1; :func:`coverage` of :func:`position_nees`) by its track
    (``assignment`` (..., J)) over the samples at which the ship sails (and ``where``, a mask (..., K, J);
    None: all); a sample at which its track does not exist counts as not covered.  ``estimates`` (..., K, I,
    >= 2), ``covariances`` (..., K, I, >= 2, >= 2) (m², x, y first), ``truth`` (..., K, J, >= 2).  Shape (...,
    J); NaN for a ship with no such sample."""
    q = position_nees(_assigned(estimates, assignment), _assigned(covariances, assignment), truth)
    sails = present(truth) if where is None else present(truth) & np.asarray(where, dtype=bool)
    with np.errstate(invalid="ignore"):
        return coverage(q, sails, axis=-2)
