"""Batch least-squares fits of whole passages (constant velocity), batched over candidates.

Used by the global initialiser (:mod:`shipsense.trackers.init`), the
tracker's refits and the ambiguity search of the design tools.  A passage is
its initial state ``theta`` (internal units); its samples are ``h(A^k theta)``.
"""

from __future__ import annotations

import numpy as np

from shipsense.models.measurement import FIELD, kernel_of
from shipsense.models.transitions import shared_powers, transitions
from shipsense.trackers.fit.robust import Huber, huber_cost, leverage_information

FIT_CHUNK_BYTES = 4 * 2**20
"""Largest Jacobian (fits x samples x m x n doubles) :func:`fit_passages` forms at once; more fits run in chunks."""


def fit_passages(model, y, theta_init, steps, stride=1, iterations=40, return_information=False, tol=1e-9,
                 prior=None, taus=None, huber=None):
    """Batched Levenberg–Marquardt fit of passages to measurements (internal units).

    ``y`` (B or 1, K', m) are the measurements at steps ``0, stride, 2 stride, ...``
    -- or, with ``taus`` (B or 1, K'), at those times (s) after the fitted
    state's (irregular sampling); ``theta_init`` (B, n); NaN samples are
    ignored.  ``prior``, optional, is a
    Gaussian prior ``(mean (n,) or (B, n), information (n,))`` on the initial
    state with a diagonal information (zero where a component has none): the
    fit is then the MAP estimate, and its chi-square and information include
    the prior's term.  With ``huber`` (a threshold gamma on the whitened
    residuals, e.g. 1.345) the fit is a Huber M-estimate (iteratively
    reweighted: residuals beyond gamma count linearly), robust to outliers;
    its "chi-square" is then :func:`huber_cost` and its information the
    Gauss-Newton information ``J^T J`` unweighted, corrected for leverage
    (:func:`leverage_information`; scale the covariance by
    :attr:`Huber.variance_factor`).  Returns the fitted
    initial states (B, n), kept within the model's ``state_bounds`` (projected
    steps), and their chi-square over the fitted samples (and,
    with ``return_information``, the Gauss–Newton information ``J^T J`` (B, n, n)
    at the solution: the inverse of the batch-fit covariance).  Stops after
    ``iterations``; a fit stops earlier once it stalled three times in a row
    (an accepted step gaining less than the relative ``tol``, or a rejected
    step at a damping of 1e6 or more or, unless the bounds moved it, whose
    linearised model predicted a gain below ``tol``).  A model with a compiled measurement
    kernel (every field model but the series HED path) runs each fit's
    iterations in one compiled loop (:mod:`~shipsense.trackers.fit.lm`, the implementation for those
    models), the others the batched numpy loop of this module (the generic path; the compiled loop's
    reference in the tests): the same iteration, equal to rounding (tested).
    """
    B = len(theta_init)
    if B == 0:   # no fits (a refit whose every start is NaN): empty results, as a batch of them would give
        empty = (np.zeros((0, model.n)), np.zeros(0))
        return empty + (np.zeros((0, model.n, model.n)),) if return_information else empty
    spec = kernel_of(model)
    compiled = spec is not None and spec[0] == FIELD
    rows = max(1, FIT_CHUNK_BYTES // (8 * model.n * model.m * max(1, np.shape(y)[-2])))
    if B > rows and not compiled:   # every fit is independent: chunks of rows bound the Jacobians' memory
        parts = []
        for lo in range(0, B, rows):
            part = slice(lo, lo + rows)
            chunk_prior = None if prior is None else (_fit_rows(prior[0], part, 2), prior[1])
            parts.append(fit_passages(model, _fit_rows(y, part), theta_init[part], steps, stride, iterations,
                                      return_information, tol, chunk_prior, _fit_rows(taus, part), huber))
        return tuple(np.concatenate(a) for a in zip(*parts))
    noise = None
    if huber is not None:
        noise = huber if isinstance(huber, Huber) else Huber(gamma=float(huber))
    if taus is None:
        Ak = shared_powers(model.A, steps)[::stride][None]              # (1, K', n, n)
    else:
        Ak = transitions(model, taus)                                    # (B or 1, K', n, n)
    y = np.asarray(y, dtype=float)
    theta = np.array(theta_init, dtype=float)
    _check_shapes(model, y, theta, Ak, prior, steps, stride, taus)
    lo, hi = getattr(model, "state_bounds", None) or (None, None)
    if lo is not None:
        theta = np.clip(theta, lo, hi)
    gamma = None if noise is None else noise.gamma
    if compiled:   # the compiled loop, one fit at a time (lm_kernel.py), on every fit at once
        from shipsense.trackers.fit.lm import lm_fits

        mu, root = (np.zeros((1, model.n)), np.empty(0)) if prior is None else (
            np.atleast_2d(np.asarray(prior[0], dtype=float)), np.sqrt(np.asarray(prior[1], dtype=float)))
        # a least-squares fit's information is the loop's last normal matrix (a Huber fit's wants the Jacobian)
        info = np.empty((B, model.n, model.n)) if return_information and gamma is None else None
        theta, cost, _ = lm_fits(spec, theta, Ak, y, 1.0 / np.sqrt(model.R), mu, root,
                                 np.inf if gamma is None else gamma, None if lo is None else (lo, hi), iterations,
                                 tol, info)
        if not return_information:
            return theta, cost
        if info is not None:
            return theta, cost, info
        info = []
        for start in range(0, B, rows):   # the information's Jacobians in chunks of rows
            part = slice(start, start + rows)
            chunk_prior = None if prior is None else (_fit_rows(prior[0], part, 2), prior[1])
            problem = _Passages(model, _fit_rows(y, part), _fit_rows(Ak, part), chunk_prior, gamma,
                                len(theta[part]))
            info.append(_information(problem, theta[part], noise, prior is not None))
        return theta, cost, np.concatenate(info)
    problem = _Passages(model, y, Ak, prior, gamma, len(theta))
    theta, cost, r, X, Hs = _levenberg_marquardt(problem, theta, iterations, tol, lo, hi)
    if not return_information:
        return theta, cost
    return theta, cost, _information(problem, theta, noise, prior is not None, (r, X, Hs))


def _check_shapes(model, y, theta, Ak, prior, steps, stride, taus):
    """A clear error for arguments of :func:`fit_passages` whose shapes do not match (the compiled loop would
    read past them)."""
    B, n = np.shape(theta) if np.ndim(theta) == 2 else (None, None)
    if n != model.n:
        raise ValueError(f"theta_init must be (fits, {model.n}), got {np.shape(theta)}")
    if y.ndim != 3 or y.shape[2] != model.m or y.shape[0] not in (1, B):
        raise ValueError(f"y must be (1 or {B} fits, samples, {model.m}), got {y.shape}")
    if Ak.shape[0] not in (1, B):
        raise ValueError(f"taus must be (1 or {B} fits, samples), got {np.shape(taus)}")
    if y.shape[1] != Ak.shape[1]:
        given = f"taus give {Ak.shape[1]}" if taus is not None else (
            f"steps={steps} with stride={stride} give {Ak.shape[1]}")
        raise ValueError(f"y has {y.shape[1]} samples per fit but {given}")
    if prior is not None:
        mean = np.asarray(prior[0])
        if mean.shape[-1] != model.n or (mean.ndim == 2 and mean.shape[0] not in (1, B)) or mean.ndim > 2 or (
                np.shape(prior[1]) != (model.n,)):
            raise ValueError(f"prior must be (mean ({model.n},) or (1 or {B}, {model.n}), information "
                             f"({model.n},)), got {mean.shape} and {np.shape(prior[1])}")


def _information(problem, theta, noise, has_prior, at=None):
    """The Gauss-Newton information (len(theta), n, n) of the fits ``theta`` of ``problem`` (the Jacobian
    unweighted; a Huber fit's corrected for leverage); ``at`` the residuals, propagated states and Jacobians at
    ``theta`` when already formed."""
    r, X, Hs = problem.residual(theta, np.arange(len(theta))) if at is None else at
    Jac = problem.jacobian(X, np.arange(len(theta)), r, Hs, weighted=False)   # the sandwich's bread, unweighted
    JtJ = np.swapaxes(Jac, -1, -2) @ Jac
    if noise is not None:
        JtJ = leverage_information(Jac, JtJ, noise, Jac.shape[1] - (problem.n if has_prior else 0))
    return JtJ


def _fit_rows(a, part, ndim=1):
    """Rows ``part`` of a per-fit argument of :func:`fit_passages` (None, or shared: a leading axis of 1, or fewer
    than ``ndim`` axes, stays whole)."""
    if a is None or np.ndim(a) < ndim or np.shape(a)[0] == 1:
        return a
    return a[part]


class _Passages:
    """The whitened residuals and Jacobians of :func:`fit_passages`' least-squares problem.

    Rows ``idx`` of the batch: states ``theta`` (len(idx), n) are propagated by ``Ak`` to every fitted
    sample; masked samples give zero rows; a prior appends its rows ``root (theta - mu)``.  With ``huber``
    the Jacobian rows are scaled by the square root of the Huber weight ``min(1, gamma / |r|)`` (IRLS).
    """

    def __init__(self, model, y, Ak, prior, huber, B):
        self.model, self.Ak, self.huber = model, Ak, huber
        self.n = model.A.shape[0]
        self.w = 1.0 / np.sqrt(model.R)
        self.present = np.isfinite(y)
        self.y = np.where(self.present, y, 0.0)
        self.prior = prior
        if prior is not None:
            self.mu = np.broadcast_to(np.asarray(prior[0], dtype=float), (B, self.n))
            self.root = np.sqrt(np.asarray(prior[1], dtype=float))            # (n,): the prior's rows
        # a model that gives h and H in one pass (FieldModel.h_and_H): every trial state's Jacobian is formed
        # with its residual and kept, so an accepted step's next iteration needs no kernel pass of its own
        self.fused = getattr(model, "h_and_H", None)

    def rows(self, a, idx):
        """Rows ``idx`` (sorted distinct indices, or a slice) of a per-fit array; a shared one (a leading axis of
        1) or every row whole (no copy).  The gathered rows of the last ``idx`` object are kept: the fitting
        loop passes the same one while its set of running fits does not change."""
        if a.shape[0] == 1 or isinstance(idx, slice) or len(idx) == a.shape[0]:
            return a
        cache = self.__dict__.setdefault("_gathered", {})
        if cache.get("idx") is not idx:
            cache.clear()
            cache["idx"] = idx
        hit = cache.get(id(a))
        if hit is None:
            hit = cache[id(a)] = a[idx]
        return hit

    def residual(self, th, idx):
        """Whitened residuals (len(idx), rows), the propagated states and (a fused model) their Jacobians."""
        X = np.einsum("bkij,bj->bki", self.rows(self.Ak, idx), th)
        if self.fused is not None:
            hx, Hx = self.fused(X)
        else:
            hx, Hx = self.model.h(X), None
        r = (self.model.residual(hx, self.rows(self.y, idx)) * self.w * self.rows(self.present, idx)).reshape(
            len(th), -1)
        if self.prior is not None:
            r = np.concatenate([r, self.root * (th - self.rows(self.mu, idx))], axis=-1)
        return r, X, Hx

    def cost(self, r):
        return np.sum(r * r, axis=-1) if self.huber is None else huber_cost(r, self.huber)

    def _weights(self, r):
        return np.sqrt(np.minimum(1.0, self.huber / np.maximum(np.abs(r), 1e-300)))

    def jacobian(self, X, idx, r, Hx=None, weighted=True):
        """Jacobian of the residuals (len(idx), rows, n); IRLS-weighted for a Huber fit unless not ``weighted``."""
        Hx = self.model.H(X) if Hx is None else Hx
        J = (Hx @ self.rows(self.Ak, idx) * (self.w * self.rows(self.present, idx))[..., None]).reshape(
            len(X), -1, self.n)
        if self.prior is not None:
            J = np.concatenate([J, np.broadcast_to(np.diag(self.root), (len(X), self.n, self.n))], axis=1)
        if self.huber is not None and weighted:
            J = J * self._weights(r)[..., None]
        return J

    def weighted(self, r):
        return r if self.huber is None else r * self._weights(r)


def _levenberg_marquardt(problem, theta, iterations, tol, lo, hi):
    """Damped Gauss-Newton steps of every fit of ``problem`` from ``theta`` (B, n), projected on ``[lo, hi]``.

    A fit that stalled three times in a row (an accepted step gaining less than ``tol`` relative, or a
    rejected one at a damping of 1e6 or more, or one the bounds did not move whose linearised model promised
    less than ``tol`` relative: MINPACK's ``ftol`` test, a fit at its minimum to rounding, where a step is as
    often rejected as accepted; a projected step is not the model's minimiser, and its prediction can be
    anything)
    is done: only the others are stepped, so the late iterations of a few slow fits do not cost a full
    batch.  Returns the states, costs, residuals, propagated states and
    (a fused model) Jacobians at the solution.
    """
    B, n = theta.shape
    r, X, Hs = problem.residual(theta, np.arange(B))
    cost = problem.cost(r)
    lam = np.full(B, 1e-2)
    stall = np.zeros(B, dtype=int)
    every, idx = slice(None), None
    for _ in range(iterations):
        a = np.flatnonzero(stall < 3)
        if a.size == 0:
            break
        if idx is not None and np.array_equal(a, idx):
            a = idx              # the same running fits: the problem reuses their gathered rows
        idx = a
        if a.size == B:          # every fit still running: views, not gathered copies
            a = every
        Jac = problem.jacobian(X[a], a, r[a], None if Hs is None else Hs[a])
        JtJ = np.swapaxes(Jac, -1, -2) @ Jac
        g = np.einsum("bmn,bm->bn", Jac, problem.weighted(r[a]))
        D = np.diagonal(JtJ, axis1=-2, axis2=-1)
        A = JtJ + lam[a, None, None] * (np.eye(n) * (D + 1e-12)[:, None, :])
        step = -np.linalg.solve(A, g[..., None])[..., 0]
        trial = theta[a] + step
        projected = np.zeros(len(trial), dtype=bool)
        if lo is not None:   # projected steps: the fit stays physical (e.g. the source in the water)
            free = trial
            trial = np.clip(trial, lo, hi)
            projected = (trial != free).any(axis=-1)
        d = trial - theta[a]                                # the linearised model's gain -(2 g.d + d^T N d)
        pred = -np.einsum("bp,bp->b", d, 2.0 * g + np.einsum("bpq,bq->bp", JtJ, d))
        r_t, X_t, H_t = problem.residual(trial, a)
        cost_t = problem.cost(r_t)
        better = np.isfinite(cost_t) & (cost_t < cost[a])
        gain = np.where(better, (cost[a] - cost_t) / np.maximum(cost[a], 1e-300), 0.0)
        ok = idx[better]
        theta[ok] = trial[better]
        r[ok] = r_t[better]
        X[ok] = X_t[better]
        if Hs is not None:
            Hs[ok] = H_t[better]
        cost[ok] = cost_t[better]
        lam[a] = np.clip(np.where(better, lam[a] / 3.0, lam[a] * 5.0), 1e-9, 1e9)
        # (a step the bounds moved is no longer the model's minimiser: its predicted gain says nothing)
        stalled = np.where(better, gain < tol,
                           (lam[a] >= 1e6) | (~projected & (pred <= tol * np.maximum(cost[a], 1e-300))))
        stall[a] = np.where(stalled, stall[a] + 1, 0)
    return theta, cost, r, X, Hs
