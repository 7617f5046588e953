"""The compiled Levenberg-Marquardt loop of :func:`~shipsense.trackers.fit.least_squares.fit_passages`, one fit
at a time.

Which form is which.  For a model with a compiled measurement kernel (:func:`~shipsense.models.measurement.kernel_of`)
this loop is the implementation of :func:`~shipsense.trackers.fit.least_squares.fit_passages`' fits: every fit
is independent, so each runs its damped Gauss-Newton iterations to the end inside one compiled loop.  The
batched numpy loop of :mod:`~shipsense.trackers.fit.least_squares` is the generic path, for a model without a
kernel (the series HED path, a user's own ``h``), and the tests' reference for this one.  The iteration is the
numpy loop's, step for step: the normal equations ``J^T W J`` and gradient ``J^T W r`` (``W`` the Huber weights
``min(1, gamma / |r|)``, 1 without Huber) accumulated sample by sample from the measurement kernel's readings
and Jacobian (no Jacobian is stored), the damping ``lam diag(J^T W J + 1e-12)`` solved by Gaussian elimination
with partial pivoting, the projection on the state bounds, the same acceptance, damping schedule and stall
rule.  The two agree to rounding (tests/trackers/fit/test_lm.py).

The kernel takes its arrays in bundles named by meaning (:class:`FitProblem`, :class:`FitPrior`,
:class:`FitOptions`, :class:`Fits`), passed as plain tuples of their fields and named inside (numba's
dispatcher types a plain tuple in its compiled fast path, a named one in Python).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from shipsense import numba_cache
from shipsense.models.measurement import loop_jit, measure_jacobian, wrap_angle
from shipsense.parallel import in_turns
from shipsense.trackers.linalg import solve_in_place


def lm_fits(spec, theta, Ak, y, w, mu, root, gamma, bounds, iterations, tol, information=None):
    """Fit every row of ``theta`` (B, n) (modified in place; returned with the costs (B,)).

    ``Ak`` (B or 1, K, n, n) transitions to the fitted samples, ``y`` (B or 1, K, m) internal units (NaN =
    missing), ``w`` (m,) whitening, ``mu`` (B or 1, n) and ``root`` (n,) the prior's mean and square-root
    information (``root`` empty: no prior), ``gamma`` the Huber threshold (``inf``: least squares),
    ``bounds`` ``(lo, hi)`` (n,) or None.  Also returns each fit's number of cost evaluations (B,) (its start
    and one per step tried).  ``information`` (B, n, n), optional, receives each fit's normal matrix ``J^T W J``
    at its solution (with the prior's ``root^2``; ``W`` the Huber weights): the Gauss-Newton information of a
    least-squares fit.
    """
    B, n = theta.shape
    present = np.isfinite(y)
    y0 = np.where(present, y, 0.0)
    lo, hi = (np.empty(0), np.empty(0)) if bounds is None else (np.asarray(b, dtype=float) for b in bounds)
    cost = np.empty(B)
    evaluations = np.zeros(B, dtype=np.int64)
    Ak = np.ascontiguousarray(Ak, dtype=float)
    if not Ak.flags.writeable:                   # (shared powers: one compiled signature, a writeable array)
        Ak = Ak.copy()
    # the kernel's bundles (FitProblem, FitPrior, FitOptions, Fits) as plain tuples: numba's dispatch types a
    # plain tuple in its compiled fast path
    problem = (spec, Ak, y0, present, np.ascontiguousarray(w, dtype=float), _constant_velocity(Ak))
    prior = (np.ascontiguousarray(mu, dtype=float), np.ascontiguousarray(root, dtype=float))
    options = (float(gamma), lo, hi, int(iterations), float(tol))
    fits = (theta, cost, evaluations, np.empty((0, n, n)) if information is None else information)
    in_turns(lambda b_lo, b_hi: lm_kernel(problem, prior, options, fits, b_lo, b_hi), B)
    return theta, cost, evaluations


class FitProblem(NamedTuple):
    """The fits' data: the model's compiled measurement description ``measurement``
    (:func:`~shipsense.models.measurement.kernel_of`), the transitions ``Ak`` (B or 1, K, n, n) from the fitted
    state to the samples ``y`` (B or 1, K, m) (internal units, 0 where missing) and which are ``present``, the
    whitening ``w`` (m,) and whether every transition is a constant-velocity one (``cv``,
    :func:`_constant_velocity`)."""

    measurement: tuple
    Ak: np.ndarray
    y: np.ndarray
    present: np.ndarray
    w: np.ndarray
    cv: bool


class FitPrior(NamedTuple):
    """A Gaussian prior on the fitted state: its mean ``mu`` (B or 1, n) and square-root information ``root``
    (n,) (empty: no prior)."""

    mu: np.ndarray
    root: np.ndarray


class FitOptions(NamedTuple):
    """The Huber threshold ``gamma`` (``inf``: least squares), the state bounds ``lo``, ``hi`` (n,) (empty:
    none), the most ``iterations`` and the relative ``tol`` of the stall rule."""

    gamma: float
    lo: np.ndarray
    hi: np.ndarray
    iterations: int
    tol: float


class Fits(NamedTuple):
    """The fits, a row each: the states ``theta`` (B, n) (starts in, solutions out), their ``cost`` (B,),
    ``evaluations`` (B,) int64 and normal matrices ``info`` (B, n, n) (written; (0, n, n): not wanted)."""

    theta: np.ndarray
    cost: np.ndarray
    evaluations: np.ndarray
    info: np.ndarray


@njit(cache=True, error_model="numpy", nogil=True)
def lm_kernel(problem, prior, options, fits, b_lo, b_hi):
    """:func:`lm_fits` of rows ``b_lo:b_hi``: the bundles :class:`FitProblem`, :class:`FitPrior`,
    :class:`FitOptions` and :class:`Fits`, each a plain tuple of its fields (named here).  Allocates the
    scratch; the loop is :func:`lm_loop`."""
    problem, prior, options, fits = FitProblem(*problem), FitPrior(*prior), FitOptions(*options), Fits(*fits)
    n, m = fits.theta.shape[1], problem.y.shape[2]
    lm_loop(problem, prior, options, fits, b_lo, b_hi, np.empty((6, n)), np.empty((4, n, n)), np.empty(m),
            np.empty((m, n)), np.empty(3), np.empty(3), np.empty(3), np.empty((3, 3)), np.empty((3, 3)))
    return True


@loop_jit
def lm_loop(problem, prior, options, fits, b_lo, b_hi, vec, mat, yhat, H, r3, m3, Bf, dBq, dBm):
    """:func:`lm_kernel`'s loop over its fits, on its scratch."""
    theta, lo, hi = fits.theta, options.lo, options.hi
    iterations, tol = options.iterations, options.tol
    n = theta.shape[1]
    th, tt, g, gt, x, row = vec[0], vec[1], vec[2], vec[3], vec[4], vec[5]
    N, Nt, M = mat[0], mat[1], mat[2]
    for b in range(b_lo, b_hi):
        for a in range(n):
            th[a] = theta[b, a]
            tt[a] = th[a]
        c = 0.0
        lam = 1e-2
        pred = 0.0
        projected = False
        stall = 0
        for it in range(iterations + 1):           # 0: the start's cost and normal equations; then the steps
            if it > 0:
                if stall >= 3:
                    break
                for p in range(n):                   # (J^T W J + lam diag(D + 1e-12)) step = -g
                    for q in range(n):
                        M[p, q] = N[p, q]
                    M[p, p] += lam * (N[p, p] + 1e-12)
                    tt[p] = -g[p]
                solve_in_place(M, tt, n)
                projected = False
                for a in range(n):
                    tt[a] += th[a]
                    if lo.size > 0:
                        free = tt[a]
                        tt[a] = min(max(tt[a], lo[a]), hi[a])
                        projected = projected or tt[a] != free
                pred = 0.0                           # the linearised model's gain -(2 g.d + d^T N d), d = tt - th
                for p in range(n):
                    dp = tt[p] - th[p]
                    acc = 2.0 * g[p]
                    for q in range(n):
                        acc += N[p, q] * (tt[q] - th[q])
                    pred -= dp * acc
            # (one call site; normal_equations is compiled on its own, not inlined here: numba copies an inlined
            # function's IR, and copying this one, with the measurement kernel inlined in it, was a large share of
            # the loop's first compilation; called once a step, it costs nothing at run time)
            ct = normal_equations(problem, prior, options.gamma, tt, b, Nt, gt, x, row, yhat, H, r3, m3, Bf, dBq, dBm)
            fits.evaluations[b] += 1
            if it == 0:
                c = ct
                for p in range(n):
                    g[p] = gt[p]
                    for q in range(n):
                        N[p, q] = Nt[p, q]
                continue
            better = math.isfinite(ct) and ct < c
            gain = (c - ct) / max(c, 1e-300) if better else 0.0
            if better:
                c = ct
                for p in range(n):
                    th[p] = tt[p]
                    g[p] = gt[p]
                    for q in range(n):
                        N[p, q] = Nt[p, q]
            lam = min(max(lam / 3.0 if better else lam * 5.0, 1e-9), 1e9)
            # (a step the bounds moved is no longer the model's minimiser: its predicted gain says nothing)
            stalled = gain < tol if better else (lam >= 1e6 or (not projected and pred <= tol * max(c, 1e-300)))
            stall = stall + 1 if stalled else 0
        for a in range(n):
            theta[b, a] = th[a]
            if fits.info.shape[0] > 0:
                for q in range(n):
                    fits.info[b, a, q] = N[a, q]
        fits.cost[b] = c


@loop_jit
def normal_equations(problem, prior, gamma, th, b, N, g, x, row, yhat, H, r3, m3, Bf, dBq, dBm):
    """Cost (chi-square, or Huber's) of fit ``b`` at state ``th`` and its normal matrix ``N = J^T W J`` and
    gradient ``g = J^T W r`` (``W`` the Huber weights).

    With ``cv`` (:func:`_constant_velocity`: every transition is the identity but ``t`` at (0, 2) and (1, 3)),
    the state ``A_k th`` and the Jacobian rows ``H_i A_k`` take only their nonzero terms: the same numbers
    (a dense product adds exact zeros to them), in less time a sample."""
    spec, Ak, y, present, w, cv = problem
    mu, root = prior
    n = th.shape[0]
    K, m = y.shape[1], y.shape[2]
    ia = b if Ak.shape[0] > 1 else 0
    iy = b if y.shape[0] > 1 else 0
    axial = spec[9]
    for p in range(n):
        g[p] = 0.0
        for q in range(n):
            N[p, q] = 0.0
    c = 0.0
    tk = 0.0
    for k in range(K):
        if cv:                                       # the state at sample k
            tk = Ak[ia, k, 0, 2]
            x[0] = th[0] + tk * th[2]
            x[1] = th[1] + tk * th[3]
            for i in range(2, n):
                x[i] = th[i]
        else:
            for i in range(n):
                acc = 0.0
                for j in range(n):
                    acc += Ak[ia, k, i, j] * th[j]
                x[i] = acc
        measure_jacobian(x, spec, yhat, H, r3, m3, Bf, dBq, dBm)
        for i in range(m):
            if not present[iy, k, i]:
                continue
            e = yhat[i] - y[iy, k, i]
            if axial[i]:
                e = wrap_angle(e)
            e *= w[i]
            if cv:                                   # the Jacobian's row: w_i H_i A_k
                row[0] = w[i] * H[i, 0]
                row[1] = w[i] * H[i, 1]
                row[2] = w[i] * (H[i, 0] * tk + H[i, 2])
                row[3] = w[i] * (H[i, 1] * tk + H[i, 3])
                for a in range(4, n):
                    row[a] = w[i] * H[i, a]
            else:
                for a in range(n):
                    acc = 0.0
                    for j in range(n):
                        acc += H[i, j] * Ak[ia, k, j, a]
                    row[a] = w[i] * acc
            c += _accumulate(e, gamma, row, N, g, n)
    if root.size > 0:                                # the prior's rows root_a (th_a - mu_a)
        im = b if mu.shape[0] > 1 else 0
        for a in range(n):
            if root[a] == 0.0:
                continue
            for j in range(n):
                row[j] = 0.0
            row[a] = root[a]
            c += _accumulate(root[a] * (th[a] - mu[im, a]), gamma, row, N, g, n)
    for p in range(n):
        for q in range(p):
            N[q, p] = N[p, q]
    return c


@njit(cache=True, nogil=True)
def _constant_velocity(Ak):
    """Whether every transition ``Ak`` (B, K, n, n) is a constant-velocity one: the identity but one time ``t``
    at (0, 2) and (1, 3) (n >= 4)."""
    n = Ak.shape[-1]
    if n < 4:
        return False
    for b in range(Ak.shape[0]):
        for k in range(Ak.shape[1]):
            t = Ak[b, k, 0, 2]
            for i in range(n):
                for j in range(n):
                    want = t if (i == 0 and j == 2) or (i == 1 and j == 3) else (1.0 if i == j else 0.0)
                    if Ak[b, k, i, j] != want:
                        return False
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _accumulate(e, gamma, row, N, g, n):
    """Add residual ``e`` with Jacobian row ``row`` to ``N`` (lower triangle) and ``g``; its cost."""
    a = abs(e)
    if a <= gamma:
        wt, cost = 1.0, e * e
    else:
        wt, cost = gamma / max(a, 1e-300), 2.0 * gamma * a - gamma * gamma
    for p in range(n):
        rp = wt * row[p]
        g[p] += rp * e
        for q in range(p + 1):
            N[p, q] += rp * row[q]
    return cost


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
