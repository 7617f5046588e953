"""The Passage environment's compiled per-environment kernels: the sensors an action reads, what it computes
from its observer's output (the observation's features, the position error and NEES against the truth) and the
episode's sums (:class:`~shipsense.envs.passage_core.PassageV1Core` calls them on all its environments at once).

They keep the GIL (no ``nogil``): each runs for microseconds, and a thread that gives the GIL up for so little
waits to get it back whenever the process's background thread (the run-ins done ahead,
:mod:`~shipsense.envs.prefetch`) runs Python -- up to the interpreter's switch interval (5 ms) a call."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from shipsense import numba_cache
from shipsense.trackers.linalg import matmul_into


@njit(cache=True, error_model="numpy", inline="always")
def at_least(a, b):
    """``np.maximum(a, b)`` of numbers (NaN if ``a`` is)."""
    return a if not a <= b else b


@njit(cache=True, error_model="numpy", inline="always")
def track_features(est, cov, centre, position_scale, row):
    """The observation's first six entries from one estimate ``est`` (n,) and covariance ``cov`` (n, n) into
    ``row``: position relative to ``centre`` / ``position_scale``, velocity / 10 m/s, and ``log10(std) / 3``
    of x and y (variances floored at 1e-12)."""
    row[0] = (est[0] - centre[0]) / position_scale
    row[1] = (est[1] - centre[1]) / position_scale
    row[2] = est[2] * 0.1
    row[3] = est[3] * 0.1
    row[4] = math.log10(at_least(cov[0, 0], 1e-12)) / 6.0
    row[5] = math.log10(at_least(cov[1, 1], 1e-12)) / 6.0


@njit(cache=True, error_model="numpy", inline="always")
def error_and_nees(d0, d1, a, b, c):
    """Position error ``|d|`` and NEES ``d^T C^-1 d`` of an error ``d = (d0, d1)`` with covariance ``C = [[a,
    b], [b, c]]`` (its inverse in closed form; not finite where ``C`` is singular)."""
    return math.hypot(d0, d1), (c * (d0 * d0) - 2 * b * d0 * d1 + a * (d1 * d1)) / (a * c - b * b)


@njit(cache=True, error_model="numpy")
def write_observations(est, cov, status, k, since, gains, centre, position_scale, steps, obs):
    """:meth:`~shipsense.envs.passage_core.PassageV1Core.observe` into ``obs`` (E, 9 + 2 S) float32: the table's
    entries in float64 (NaN -> 0, +-inf -> +-1), clipped to [-1, 1]."""
    S = since.shape[1]
    row = np.empty(obs.shape[1])
    for e in range(est.shape[0]):
        track_features(est[e], cov[e], centre, position_scale, row)
        row[6] = cov[e, 0, 1] / math.sqrt(at_least(cov[e, 0, 0] * cov[e, 1, 1], 1e-300))
        row[7] = status[e] / 4.0
        row[8] = k[e] / steps
        for s in range(S):
            row[9 + s] = since[e, s] / steps
            g = at_least(gains[e, 1 + s], 0.0)             # the single-sensor actions
            row[9 + S + s] = g / (1.0 + g)
        for i in range(row.size):
            v = row[i]
            v = 0.0 if v != v else v
            obs[e, i] = min(max(v, -1.0), 1.0)


@njit(cache=True, error_model="numpy")
def read_sensors(actions, who, subsets, sensor_of, y_all, k, since, last_read, y, reads):
    """The reads of :meth:`~shipsense.envs.passage_core.PassageV1Core.step`: every environment's reads
    (``reads``, float) under its action (a row of ``subsets``); for environments ``who``, the next sample
    (``k``), its channels of the sensors read (``y``, the others NaN), the read mask (``last_read``) and the
    steps since each sensor was read (``since``: 0 read, else one more).  Returns -1, or the first environment
    whose action is not a row of ``subsets`` (then nothing is written)."""
    S = subsets.shape[1]
    for e in range(actions.size):
        if actions[e] < 0 or actions[e] >= subsets.shape[0]:
            return e                                    # (nothing written)
    for e in range(actions.size):
        count = 0
        for s in range(S):
            count += subsets[actions[e], s]
        reads[e] = count
    for i in range(who.size):
        e = who[i]
        row = subsets[actions[e]]
        k[e] += 1
        for j in range(y.shape[1]):
            y[i, j] = y_all[e, k[e], j] if row[sensor_of[j]] else np.nan
        for s in range(S):
            last_read[e, s] = row[s]
            since[e, s] = 0.0 if row[s] else since[e, s] + 1.0
    return -1


@njit(cache=True, error_model="numpy")
def accumulate_steps(who, rewards, reads, returns, total_reads):
    """The episode's sums of environments ``who``: their rewards and reads."""
    for i in range(who.size):
        e = who[i]
        returns[e] += rewards[e]
        total_reads[e] += reads[e]


@njit(cache=True, error_model="numpy")
def measure_errors(envs, k, est, cov, truth, limit, est_hist, errors, inside, error, nees):
    """The measurement step of :class:`~shipsense.envs.passage_core.PassageV1Core` on environments ``envs``: the
    position error (into ``error``) and NEES (``nees``; inf where not finite) at each one's current sample,
    stored in the histories."""
    for r in range(envs.size):
        e = envs[r]
        ke = k[e]
        error[r], q = error_and_nees(est[e, 0] - truth[e, ke, 0], est[e, 1] - truth[e, ke, 1], cov[e, 0, 0],
                                     cov[e, 0, 1], cov[e, 1, 1])
        nees[r] = q if math.isfinite(q) else np.inf
        est_hist[e, ke, 0], est_hist[e, ke, 1] = est[e, 0], est[e, 1]
        errors[e, ke] = error[r]
        inside[e, ke] = nees[r] <= limit


@njit(cache=True, error_model="numpy")
def predicted_beliefs(envs, est, cov, x_scale, A, X, P):
    """The observers' beliefs of environments ``envs`` predicted one step, in the model's internal units (the
    linearisation point of the predicted gains of
    :class:`~shipsense.envs.passage_core.PassageV1Core`): ``X[r] = A
    (est[e] / s)`` (r, n) and ``P[r] = A (cov[e] / (s s^T)) A^T`` (r, n, n), ``s`` the model's ``x_scale``
    (SI per internal unit) -- numpy's ``to_internal(est) @ A.T`` and ``A @ cov_to_internal(cov) @ A.T``
    without their temporaries.  Not the trackers' time update
    (:func:`~shipsense.trackers.filters.time_update.predict_kernel`, the same products): that one mirrors its
    lower triangle into the upper, this one sums both, so their upper entries differ at rounding and the
    environment's episodes would change."""
    n = x_scale.size
    xi, Pi, tmp = np.empty(n), np.empty((n, n)), np.empty((n, n))
    for r in range(envs.size):
        e = envs[r]
        for a in range(n):
            xi[a] = est[e, a] / x_scale[a]
            for b in range(n):
                Pi[a, b] = cov[e, a, b] / (x_scale[a] * x_scale[b])
        for a in range(n):
            acc = 0.0
            for b in range(n):
                acc += xi[b] * A[a, b]
            X[r, a] = acc
        matmul_into(A, Pi, tmp, n, n, n)
        matmul_into(tmp, A.T, P[r], n, n, n)


@njit(cache=True, error_model="numpy")
def apply_budget(actions, subsets, budget, reads, last_read, wakes):
    """Passage-v2's read budget before a step (:meth:`~shipsense.envs.passage_v2.PassageV2Core.step`), for every
    environment ``e``: an action (a row of ``subsets``) reading more sensors than the budget has left, ``budget -
    reads[e]``, is replaced by action 0 (read nothing), in place in ``actions``; ``wakes[e]``: the sensors the
    action then reads that were not read at the previous step (``last_read``).  An action outside ``subsets`` is
    left for :func:`read_sensors` to refuse (no wakes)."""
    S = subsets.shape[1]
    for e in range(actions.size):
        a = actions[e]
        inside = a >= 0 and a < subsets.shape[0]
        count, woken = 0, 0
        if inside:
            for s in range(S):
                if subsets[a, s]:
                    count += 1
                    if not last_read[e, s]:
                        woken += 1
        if inside and count > budget - reads[e]:
            actions[e] = 0
            woken = 0
        wakes[e] = woken


@njit(cache=True, error_model="numpy")
def accumulate_costs(who, step_wakes, energy_term, wakes, energy):
    """Passage-v2's episode sums of environments ``who``: their wake-ups and the energy their steps cost (the
    negative ``energy_term``)."""
    for i in range(who.size):
        e = who[i]
        wakes[e] += step_wakes[e]
        energy[e] -= energy_term[e]


@njit(cache=True, error_model="numpy")
def write_budget_features(budget, reads, next_mark, k, steps, obs, col):
    """Passage-v2's two observation entries into columns ``col`` and ``col + 1`` of ``obs`` (E, obs_dim) float32:
    the share of the read budget left, ``(budget - reads) / max(budget, 1)`` (1 without a budget), and the samples
    to the next checkpoint (``next_mark[k] - k``) / ``steps``, both clipped to [0, 1]."""
    K = next_mark.size
    for e in range(k.size):
        left = 1.0 if math.isinf(budget) else (budget - reads[e]) / max(budget, 1.0)
        obs[e, col] = min(max(left, 0.0), 1.0)
        ke = k[e]
        ahead = (next_mark[min(ke, K - 1)] - ke) / steps
        obs[e, col + 1] = min(max(ahead, 0.0), 1.0)


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
