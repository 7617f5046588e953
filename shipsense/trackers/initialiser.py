"""The global initialiser: where is the passage, with no prior on its position (beyond the source studies).

The fields are linear in the moment (and in ``p``), so for every candidate
trajectory of a grid (start range and bearing from the array centroid,
course, speed) the best moment is a closed-form least-squares solve
(:func:`linear_basis`); the best distinct grid minima are refined by batched
Levenberg-Marquardt fits (:func:`~shipsense.trackers.batchfit.fit_passages`)
over a window that starts at the detection (:func:`detection_start`), and
checked by a chi-square goodness-of-fit test (:func:`chi2_limit`).
:func:`global_init` returns the fits as the hypotheses of a bank
(:class:`GlobalInit`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shipsense.trackers.batchfit import fit_passages, powers


@dataclass(frozen=True)
class GlobalInit:
    """Hypotheses from :func:`global_init` for R passages (SI units).

    Attributes
    ----------
    start : ndarray of int, shape (R,)
        First sample the bank processes (after the fitted window).
    seeds : ndarray, shape (R, M, n)
        Means at ``start`` (the batch fits propagated to it).
    P0 : ndarray, shape (R, M, n, n)
        Their covariances (batch-fit covariance propagated, plus the process noise).
    loglik : ndarray, shape (R, M)
        ``-chi2 / 2`` of each batch fit: the bank's prior log-likelihoods.
    window : ndarray, shape (R, M, W, n)
        The fitted trajectories over the window (estimates before ``start``).
    k0 : ndarray of int, shape (R,)
        First sample of the window (the detection).
    fit_ok : ndarray of bool, shape (R,), optional
        Whether the passage's best fit passes the chi-square goodness-of-fit
        test (:func:`global_init`'s ``gof``); a failed passage is still seeded
        from its best fit.
    """

    start: np.ndarray
    seeds: np.ndarray
    P0: np.ndarray
    loglik: np.ndarray
    window: np.ndarray
    k0: np.ndarray
    fit_ok: np.ndarray | None = None


def _parameter_slots(model):
    labels = model.labels
    slots = [labels.index(c) for c in ("mx", "my", "mz", "p") if c in labels]
    if any(k == "magnitude" for k in model.array.kinds):
        raise ValueError("the global initialiser needs measurements linear in the moment (not 'magnitude')")
    return slots


def candidate_grid(model, ranges, bearings_deg, courses_deg, speeds, source_z=None):
    """Candidate initial states (C, n) (internal units, parameters zero) around the array centroid."""
    centre = model.array.positions[:, :2].mean(axis=0)
    R_, B_, C_, V_ = np.meshgrid(np.asarray(ranges, float), np.deg2rad(bearings_deg), np.deg2rad(courses_deg),
                                 np.asarray(speeds, float), indexing="ij")
    R_, B_, C_, V_ = (a.ravel() for a in (R_, B_, C_, V_))
    theta = np.zeros((R_.size, model.n))
    theta[:, 0] = centre[0] + R_ * np.cos(B_)
    theta[:, 1] = centre[1] + R_ * np.sin(B_)
    theta[:, 2] = V_ * np.cos(C_)
    theta[:, 3] = V_ * np.sin(C_)
    if "z" in model.labels:
        theta[:, model.labels.index("z")] = model.source_z if source_z is None else source_z
    return theta


_BASIS_CACHE: dict = {}


_BASIS_CACHE_SIZE = 4


def linear_basis(model, theta, steps, stride=1):
    """Offset (C, W, m) and unit-parameter basis (C, W, m, P) of candidate passages (internal units).

    The measurements are linear in the moment (and ``p``) for vector, tmi and
    envelope (``p >= 0``) channels: ``h = offset + basis @ params``; bearing
    channels are in the offset.  The last few results are kept (the grid and
    window are the same for every batch of passages a study initialises);
    treat them as read-only.
    """
    theta = np.ascontiguousarray(theta, dtype=float)
    key = (id(model), theta.shape, hash(theta.tobytes()), steps, stride)
    hit = _BASIS_CACHE.get(key)
    if hit is not None and hit[0] is model:
        return hit[1], hit[2]
    offset, basis = _linear_basis(model, theta, steps, stride)
    offset.flags.writeable = False
    basis.flags.writeable = False
    if len(_BASIS_CACHE) >= _BASIS_CACHE_SIZE:
        _BASIS_CACHE.pop(next(iter(_BASIS_CACHE)))
    _BASIS_CACHE[key] = (model, offset, basis)
    return offset, basis


def _linear_basis(model, theta, steps, stride):

    slots = _parameter_slots(model)
    Ak = powers(model.A, steps)[::stride]
    X = np.einsum("kij,cj->cki", Ak, theta)
    X[..., slots] = 0.0
    offset = model.h(X)
    basis = np.empty(offset.shape + (len(slots),))
    for j, s in enumerate(slots):
        Xj = X.copy()
        Xj[..., s] = 1.0
        basis[..., j] = model.h(Xj) - offset
    return offset, basis


def window_samples(model, K, window_s=15.0):
    """Samples W of the fitted window: ``window_s`` seconds, at least 4, less than the K samples."""
    return int(np.clip(round(window_s / model.period), 4, K - 1))


def strongest_snr(model, y):
    """The strongest field channel's SNR per sample (R, K) of measurements in internal units (R, K, m)."""
    return np.where(~model.axial, np.abs(np.nan_to_num(y)) / np.sqrt(model.R), 0.0).max(axis=-1)


def detection_start(model, measurements, snr_start=5.0, window=0):
    """First sample (R,) at which some field channel exceeds ``snr_start`` noise standard deviations.

    The adaptive start of :func:`global_init`'s window (0 if never; at most
    ``K - window - 1`` so that the window fits).  ``measurements`` (R, K, m) SI.
    """
    y = np.asarray(measurements, dtype=float) / model.y_scale
    K = y.shape[1]
    snr = strongest_snr(model, y)
    above = snr > snr_start
    k0 = np.where(above.any(axis=1), np.argmax(above, axis=1), 0)
    return np.minimum(k0, K - window - 1).clip(0)


def fit_end(model, measurements, k0, window, through_peak=None):
    """End (exclusive, (R,)) of the refinement window that starts at ``k0``: ``k0 + window``, or with
    ``through_peak`` (a fraction) the first later sample at which the strongest channel's SNR has
    fallen below that fraction of its maximum since ``k0`` -- the fit then spans the closest
    approach -- if the passage gets there (else ``k0 + window``); at most ``K - 1``."""
    y = np.asarray(measurements, dtype=float) / model.y_scale
    R, K = y.shape[:2]
    k0 = np.asarray(k0, dtype=int)
    end = np.minimum(k0 + window, K - 1)
    if through_peak is None:
        return end
    snr = strongest_snr(model, y)
    k = np.arange(K)[None, :]
    since = np.where(k >= k0[:, None], snr, 0.0)
    peak = np.maximum.accumulate(since, axis=1)
    past = (k >= end[:, None]) & (since < through_peak * peak) & (k < K - 1)
    return np.where(past.any(axis=1), np.argmax(past, axis=1), end)


def _grid_fit_masked(model, yw_all, offset, G, std, max_bytes, clamp):
    """Moment-eliminated chi-square (R, C) and moments (R, C, P) of every candidate, general case.

    Handles bearing channels (non-zero offsets) and missing samples (each
    passage its own masked design); passages in chunks so that the
    (chunk, C, W', m, P) arrays stay near ``max_bytes``.
    """
    R, Wn, m = yw_all.shape
    C, P = G.shape[0], G.shape[-1]
    chi2 = np.empty((R, C))
    params = np.empty((R, C, P))
    chunk = max(1, int(max_bytes // (8 * C * Wn * m * max(P, 1) * 3)))
    for lo in range(0, R, chunk):
        yw = yw_all[lo:lo + chunk]
        present = np.isfinite(yw)
        d = model.residual(np.where(present, yw, 0.0)[:, None], offset[None]) / std      # (r, C, W', m)
        d = np.where(present[:, None], d, 0.0)
        Gm = G[None] * present[:, None, ..., None]                                        # (r, C, W', m, P)
        A = np.einsum("rcwmp,rcwmq->rcpq", Gm, Gm) + 1e-9 * np.eye(P)
        b = np.einsum("rcwmp,rcwm->rcp", Gm, d)
        par = np.linalg.solve(A, b[..., None])[..., 0]
        if clamp:
            par[..., -1] = np.maximum(par[..., -1], 0.0)
        fit = d - np.einsum("rcwmp,rcp->rcwm", Gm, par)
        chi2[lo:lo + chunk] = np.sum(fit * fit, axis=(-1, -2))
        params[lo:lo + chunk] = par
    return chi2, params


def depth_prior(model, z_std, source_z=None):
    """Gaussian prior ``(mean, information)`` (internal units) on the source depth around ``source_z``
    (default the model's) with standard deviation ``z_std`` (m), for :func:`fit_passages`; None when
    ``z_std`` is None or the model has no depth."""
    if z_std is None or "z" not in model.labels:
        return None
    iz = model.labels.index("z")
    mean, weight = np.zeros(model.n), np.zeros(model.n)
    mean[iz] = (model.source_z if source_z is None else source_z) / model.x_scale[iz]
    weight[iz] = (model.x_scale[iz] / z_std) ** 2
    return mean, weight


def _refine_stages(refine, keep):
    """Cumulative numbers of grid minima refined per stage (each at least ``keep``, increasing)."""
    if refine is None:
        return [keep]
    stages = [int(refine)] if np.isscalar(refine) else [int(r) for r in refine]
    if any(r < 1 for r in stages) or any(b <= a for a, b in zip(stages, stages[1:])):
        raise ValueError(f"refine must be a positive count or increasing counts, got {refine!r}")
    return [max(keep, r) for r in stages]


def _dof(model, yfit, prior):
    """Degrees of freedom (R,) of passage fits to ``yfit`` (R, W, m): samples present, plus the prior's
    rows, minus the states."""
    rows = 0 if prior is None else int(np.count_nonzero(prior[1]))
    return np.maximum(np.isfinite(yfit).sum(axis=(1, 2)) + rows - model.n, 1)


def chi2_limit(model, yfit, prior, gof):
    """Chi-square (R,) above which a fit to ``yfit`` fails the goodness-of-fit test at level ``gof``."""
    from scipy import stats

    if gof is None:
        return np.full(yfit.shape[0], np.inf)
    return stats.chi2.isf(gof, _dof(model, yfit, prior))


def _distinct(chi2, positions, M, distinct_m):
    """Indices of the ``M`` lowest ``chi2`` whose ``positions`` (N, 2) are more than ``distinct_m`` apart.

    Greedy over the finite ``chi2`` (each pick the best candidate not within ``distinct_m`` of an earlier
    pick); when fewer than ``M`` are distinct the best one fills the rest.
    """
    alive = np.isfinite(chi2)          # not fitted (staged refinement) or failed: never picked
    chosen = []
    while len(chosen) < M and alive.any():
        c = int(np.argmin(np.where(alive, chi2, np.inf)))
        chosen.append(c)
        d = positions - positions[c]
        alive &= np.einsum("ij,ij->i", d, d) > distinct_m * distinct_m
    return chosen + [chosen[0]] * (M - len(chosen))


def distinct_rows(chi2, positions, M, distinct_m):
    """:func:`_distinct` for every row at once: indices (R, M) of each row's ``M`` lowest finite ``chi2``
    (R, C) whose ``positions`` (R, C, 2) are more than ``distinct_m`` apart, and whether each is a pick
    (R, M) (False: fewer were distinct, the index repeats the row's best)."""
    chi2 = np.where(np.isfinite(chi2), chi2, np.inf)
    R = chi2.shape[0]
    rows = np.arange(R)
    alive = np.isfinite(chi2)
    idx = np.zeros((R, M), dtype=int)
    found = np.zeros((R, M), dtype=bool)
    for j in range(M):   # M greedy picks, each over all rows
        c = np.argmin(np.where(alive, chi2, np.inf), axis=1)
        found[:, j] = alive[rows, c]
        idx[:, j] = np.where(found[:, j], c, idx[:, 0])
        d = positions - positions[rows, c][:, None]
        alive &= ~found[:, j:j + 1] | (np.einsum("rci,rci->rc", d, d) > distinct_m * distinct_m)
    return idx, found


def distinct_loglik(chi2, found):
    """Log-likelihoods ``-chi2 / 2`` (R, M) of fits picked by :func:`distinct_rows`, ``-inf`` for the repeats
    that fill a row (no weight in a mixture); a row's first is always finite (its best, or a failed fit's
    very low value) so that every bank has a hypothesis to select."""
    first = np.arange(np.shape(chi2)[1]) == 0
    return np.where(found | first, -0.5 * np.minimum(chi2, 1e300), -np.inf)


def global_init(model, measurements, *, ranges, speeds, bearing_step_deg=15.0, course_step_deg=30.0,
                window_s=15.0, grid_samples=16, keep=5, distinct_m=15.0, snr_start=5.0, inflate=2.0,
                source_z=None, common_start=False, max_bytes=512e6, through_peak=None, z_std=None, refine=None,
                gof=0.01, explore_samples=None):
    """Global initialisation of passages from a grid search with the moment eliminated in closed form.

    Parameters
    ----------
    model : FieldModel
    measurements : ndarray, shape (R, K, m)
        SI units, NaN = missing.
    ranges, speeds : sequence of float
        Grid of start ranges from the array centroid (m) and speeds (m/s).
    bearing_step_deg, course_step_deg : float
        Grid steps of the start bearing and the course.
    window_s : float
        Duration (s) fitted from the detection on (W samples); the grid search
        uses about ``grid_samples`` of them, the refinement all.
    keep : int
        Distinct minima kept per passage (M): the best ones more than ``distinct_m`` apart (5: on the
        wide study, 4 lost two-magnetometer passages and 6 cost more than the bank, EXPERIMENTS.md).
    refine : int or sequence of int, optional
        Distinct grid minima refined by the batch fit (default ``keep``); the
        best ``keep`` distinct refined fits seed the bank.  At high SNR the
        global minimum's basin can be narrower than the grid spacing, so it
        may not be among the ``keep`` best grid points (EXPERIMENTS.md).
        Increasing counts, e.g. ``(5, 20, 60)``, refine in stages: the first
        count for every passage, each further one only for the passages whose
        best fit so far fails the chi-square test (``gof``), so that the cost
        goes to the passages that need it.
    gof : float or None
        Level of the chi-square goodness-of-fit test of the fits (default
        1 %): a fit whose chi-square exceeds the ``1 - gof`` quantile for
        its degrees of freedom has not explained the data to the noise
        level (a local minimum, or a source the model does not describe).
        At 0.1 % a single-magnetometer fit 21 m off passed (EXPERIMENTS.md).
        It drives the staged ``refine`` and gives ``GlobalInit.fit_ok``.
        (Scaling a failed fit's covariance by its reduced chi-square, the
        Birge ratio, was tried and dropped: on 500 two-magnetometer passages
        the first bank from the larger covariances went from 3.8x to 5.2x
        the constant-velocity bound, EXPERIMENTS.md.)
    explore_samples : int, optional
        The refinement's fits of the grid minima use about this many samples
        of the window, evenly spaced (and the staged test those samples); the
        ``keep`` fits kept are then polished on every sample.  Exploring many
        minima then costs that much less: on S0 (150-sample windows), 60
        minima explored on 15 samples missed the global minimum of none of
        100 passages, where 5, 20 and 60 in stages on every sample missed 16
        (EXPERIMENTS.md).  None: every sample.
    snr_start : float
        The window starts at the first sample with some channel above this SNR (adaptive start).
    inflate : float
        Factor on the batch-fit covariance (linearisation of a nonlinear fit).
    z_std : float, optional
        Standard deviation (m) of a Gaussian prior on the source depth around
        ``source_z`` (models with electrodes): the batch fits are then MAP fits
        and their covariances include it.  The envelope fits otherwise often
        settle on a wrong depth, the depth and ``p`` trading off in the far
        field (EXPERIMENTS.md); the studies' bank starts with the same prior
        (``BankConfig.z_std``).
    common_start : bool
        Start every passage's window at the latest detection of the batch, so
        that one bank runs them all (:func:`track_with_global_init`).
    max_bytes : float
        Memory for the grid stage; passages are processed in chunks within it.
    through_peak : float, optional
        Extend the refinement (not the grid search) past the window until the
        strongest channel has fallen below this fraction of its peak
        (:func:`fit_end`): the batch fit then spans the closest approach, and
        the bank starts after it.

    Returns
    -------
    GlobalInit
    """

    y_si = np.asarray(measurements, dtype=float)
    R, K, m = y_si.shape
    window = window_samples(model, K, window_s)
    stride = max(1, window // grid_samples)
    y = y_si / model.y_scale
    std = np.sqrt(model.R)
    k0 = detection_start(model, y_si, snr_start, window)
    if common_start:   # one bank start for the whole batch: every window starts at the latest detection
        k0 = np.full(R, k0.max())
    grid = candidate_grid(model, ranges, np.arange(0.0, 360.0, bearing_step_deg),
                          np.arange(0.0, 360.0, course_step_deg), speeds, source_z)
    offset, basis = linear_basis(model, grid, window, stride)                            # (C, W', m[, P])
    Wn = offset.shape[1]
    idx = k0[:, None] + stride * np.arange(Wn)[None, :]                                   # (R, W')
    yw_all = y[np.arange(R)[:, None], idx]                                                # (R, W', m)
    G = basis / std[:, None]                                                              # (C, W', m, P)
    P = G.shape[-1]
    C = G.shape[0]
    Gf = G.reshape(C, Wn * m, P)                                                          # (C, W'm, P)
    A_all = np.swapaxes(Gf, -1, -2) @ Gf + 1e-9 * np.eye(P)                               # shared by passages
    clamp = "p" in model.labels                                   # the envelope needs p >= 0
    if not np.any(offset) and np.isfinite(yw_all).all():
        # no offset (no bearing channels) and nothing missing: the whitened data d are the same for every
        # candidate, so b = G^T d is one matmul and chi2 = |d|^2 - 2 par.b + par^T A par (no fit formed)
        d = (yw_all / std).reshape(R, Wn * m)
        b = np.matmul(np.swapaxes(Gf, -1, -2), d.T)                                       # (C, P, R)
        par = np.linalg.inv(A_all) @ b
        if clamp:
            par[:, -1] = np.maximum(par[:, -1], 0.0)
        chi2 = (np.sum(d * d, axis=-1)[None] - 2.0 * np.sum(par * b, axis=1)
                + np.sum(par * (A_all @ par), axis=1)).T                                  # (R, C)
        params = np.moveaxis(par, -1, 0)                                                  # (R, C, P)
    else:
        chi2, params = _grid_fit_masked(model, yw_all, offset, G, std, max_bytes, clamp)
    slots = _parameter_slots(model)
    Ak = powers(model.A, window)
    mid = Ak[window // 2][:2]
    mid_grid = grid @ mid.T                                                              # (C, 2)
    stages = _refine_stages(refine, keep)
    M = stages[-1]

    def grid_starts(rows, count):   # the ``count`` best distinct grid minima of passages ``rows``, their moments
        out = np.zeros((len(rows), count, model.n))
        for i, r in enumerate(rows):
            chosen = _distinct(chi2[r], mid_grid, count, distinct_m)
            out[i] = grid[chosen]
            out[i][:, slots] = params[r, chosen]
        return out

    prior = depth_prior(model, z_std, source_z)
    # refine grid minima by batch Levenberg-Marquardt fits over the whole window, stage by stage: a
    # passage whose best fit so far fails the chi-square test gets the next stage's minima
    yfit = y[np.arange(R)[:, None], k0[:, None] + np.arange(window)[None, :]]           # (R, W, m)
    if explore_samples is not None and explore_samples < 2:
        raise ValueError(f"explore_samples must be at least 2, got {explore_samples!r}")
    explore_stride = 1 if explore_samples is None else max(1, window // int(explore_samples))
    ysub = yfit[:, ::explore_stride]
    limit = chi2_limit(model, ysub, prior, gof)
    theta = np.zeros((R, M, model.n))
    chi2_fit = np.full((R, M), np.inf)
    info = np.zeros((R, M, model.n, model.n))
    todo, lo = np.arange(R), 0
    for hi in stages:
        starts = grid_starts(todo, hi)[:, lo:]
        t, c, j = fit_passages(model, np.repeat(ysub[todo], hi - lo, axis=0), starts.reshape(-1, model.n),
                               window, stride=explore_stride, return_information=True, prior=prior)
        theta[todo, lo:hi] = t.reshape(todo.size, hi - lo, -1)
        chi2_fit[todo, lo:hi] = np.where(np.isfinite(c), c, np.inf).reshape(todo.size, hi - lo)
        info[todo, lo:hi] = j.reshape(todo.size, hi - lo, model.n, model.n)
        todo, lo = np.flatnonzero(chi2_fit.min(axis=1) > limit), hi
        if todo.size == 0:
            break
    # the best ``keep`` distinct refined fits seed the bank (fits that converged to the same minimum count
    # once: a repeat of the best fills a passage's bank at log-likelihood -inf, no weight)
    sel, found = distinct_rows(chi2_fit, theta @ mid.T, keep, distinct_m)
    pick = (np.arange(R)[:, None], sel)
    theta, chi2_fit, info = (a[pick] for a in (theta, chi2_fit, info))
    M = keep
    theta, chi2_fit, info = (a.reshape((R * M,) + a.shape[2:]) for a in (theta, chi2_fit, info))
    if explore_stride > 1:   # polish the kept fits on every sample of the window
        theta, chi2_fit, info = fit_passages(model, np.repeat(yfit, M, axis=0), theta, window,
                                             return_information=True, prior=prior)
        limit = chi2_limit(model, yfit, prior, gof)
    end = fit_end(model, y_si, k0, window, through_peak)
    if common_start:
        end = np.full(R, end.max())
    Wf = int((end - k0).max())
    if Wf > window:   # continue every fit through the closest approach, from the window's solution
        ks = k0[:, None] + np.arange(Wf)[None, :]
        yfit = y[np.arange(R)[:, None], np.minimum(ks, K - 1)]                           # (R, Wf, m)
        yfit = np.where((ks < end[:, None])[..., None], yfit, np.nan)                   # each passage to its end
        theta, chi2_fit, info = fit_passages(model, np.repeat(yfit, M, axis=0), theta, Wf, return_information=True,
                                             prior=prior)
        limit = chi2_limit(model, yfit, prior, gof)
    theta, chi2_fit = theta.reshape(R, M, -1), chi2_fit.reshape(R, M)
    cov = np.linalg.pinv(info, hermitian=True).reshape(R, M, model.n, model.n) * inflate
    # propagate to the first sample after the fitted stretch
    Ak = powers(model.A, Wf + 1)
    Aw = Ak[np.minimum(end - k0, Wf)]                                                   # (R, n, n)
    seeds = np.einsum("rij,rmj->rmi", Aw, theta)
    P0 = Aw[:, None] @ cov @ np.swapaxes(Aw, -1, -2)[:, None] + (end - k0)[:, None, None, None] * model.Q
    traj = np.einsum("kij,rmj->rmki", Ak[:Wf], theta)
    xs = model.x_scale
    return GlobalInit(start=end, seeds=seeds * xs, P0=P0 * np.outer(xs, xs), loglik=distinct_loglik(chi2_fit, found),
                      window=traj * xs, k0=k0, fit_ok=chi2_fit.min(axis=1) <= limit)


def unalign(values, start, K, fill=np.nan):
    """Values on a bank's aligned axis (R, J, ...) (:func:`track_with_global_init`) back on the samples (R, K, ...)."""
    values = np.asarray(values)
    R, J = values.shape[:2]
    out = np.full((R, K) + values.shape[2:], fill, dtype=np.result_type(values, np.asarray(fill)))
    src = np.asarray(start, dtype=int)[:, None] + np.arange(J)[None, :]
    inside = src < K
    rows = np.broadcast_to(np.arange(R)[:, None], src.shape)
    out[rows[inside], src[inside]] = values[inside]
    return out
