"""Batch least-squares fits of whole passages (constant velocity), batched over candidates.

Used by the global initialiser (:mod:`shipsense.trackers.initialiser`) and by the
ambiguity search of the design tools.  A passage is its initial state
``theta`` (internal units); its samples are ``h(A^k theta)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache, partial

import numpy as np

from shipsense.trackers.measurement import FIELD, kernel_of


def powers(A, K):
    """A^k for k = 0..K-1, shape (K, n, n)."""
    out = np.empty((K,) + A.shape)
    out[0] = np.eye(A.shape[0])
    for k in range(1, K):
        out[k] = A @ out[k - 1]
    return out


def shared_powers(A, K):
    """:func:`powers`, read-only and kept for the last few ``(A, K)`` (the window fits ask for the same ones at
    every window: K matrix products each time)."""
    A = np.ascontiguousarray(A, dtype=float)
    return _shared_powers(A.tobytes(), A.shape, int(K))


@lru_cache(maxsize=32)
def _shared_powers(data, shape, K):
    out = powers(np.frombuffer(data, dtype=float).reshape(shape), K)
    out.flags.writeable = False
    return out


def transitions(model, taus):
    """Constant-velocity transitions ``A(tau)`` (..., n, n) over ``taus`` (...) seconds (negative: backwards).

    ``A(tau) = I + (tau / T)(A - I)``: the model's one-period transition moves positions by ``T v`` and
    leaves the rest, so a time ``tau`` moves them by ``tau v``.
    """
    taus = np.asarray(taus, dtype=float)
    A = np.ascontiguousarray(model.A, dtype=float)
    eye, step = _identity_and_step(A.tobytes(), A.shape)
    return eye + (taus[..., None, None] / model.period) * step


@lru_cache(maxsize=32)
def _identity_and_step(data, shape):
    """``(I, A - I)`` of a transition ``A`` (by its bytes), read-only: kept for :func:`transitions`, which the
    trackers call several times a refit (the same numbers as forming them each time, in half the time)."""
    A = np.frombuffer(data, dtype=float).reshape(shape)
    eye = np.eye(shape[0])
    step = A - eye
    eye.flags.writeable = step.flags.writeable = False
    return eye, step


@dataclass(frozen=True)
class Huber:
    """Robust (Huber) fits, and what their cost should be under the noise's outlier model.

    The noise of a whitened residual is taken as ``(1 - eps) N(0, 1) + eps N(0, scale^2)`` (physics.md §5;
    ``eps = 0``: Gaussian).  Fits minimise :func:`huber_cost` with threshold ``gamma``; the goodness-of-fit
    test compares that cost with its distribution under the noise model: mean ``dof mu`` and variance
    ``dof sigma^2`` per residual (:attr:`moments`, by Gauss-Hermite quadrature), a normal approximation.
    """

    gamma: float = 1.345
    eps: float = 0.0
    scale: float = 10.0

    def expect(self, f):
        """``E[f(e)]`` for one residual ``e`` of the noise model (adaptive quadrature, split at +-gamma)."""
        from scipy import integrate

        total = 0.0
        for share, sd in ((1.0 - self.eps, 1.0), (self.eps, self.scale)):
            if share == 0.0:
                continue
            pdf = partial(_normal_pdf, sd=sd)
            for lo, hi in ((-np.inf, -self.gamma), (-self.gamma, self.gamma), (self.gamma, np.inf)):
                total += share * integrate.quad(lambda e, pdf=pdf: f(e) * pdf(e), lo, hi, epsabs=1e-12)[0]
        return total

    @property
    def moments(self):
        """Mean and variance of ``2 rho(e)`` (:func:`huber_cost`) for one residual ``e`` of the noise model."""
        return _huber_figures(self.gamma, self.eps, self.scale)[:2]

    @property
    def variance_factor(self):
        """``kappa = E[psi^2] / E[psi']^2``: the Huber M-estimate's variance over the nominal (Gaussian) one
        under the noise model (Huber 1964); 1.05 for Gaussian noise at gamma = 1.345, about 2 with 20 %
        outliers of ten times the standard deviation.  A robust fit's covariance is ``kappa (J^T J)^-1``."""
        return _huber_figures(self.gamma, self.eps, self.scale)[2]

    def variance_factor_at(self, threshold):
        """``kappa`` of a Huber clip at ``threshold`` (array) on a residual of the noise model, in closed form:
        ``E[min(e^2, c^2)] / P(|e| <= c)^2`` (``threshold = gamma``: :attr:`variance_factor`; infinite: the
        noise's variance ``1 - eps + eps scale^2``)."""
        from scipy.special import ndtr

        c = np.asarray(threshold, dtype=float)
        finite = np.isfinite(c)
        psi2, slope = np.zeros_like(c), np.zeros_like(c)
        for share, sd in ((1.0 - self.eps, 1.0), (self.eps, self.scale)):
            if share == 0.0:
                continue
            a = np.where(finite, c, 0.0) / sd
            inside = np.where(finite, 2.0 * ndtr(a) - 1.0, 1.0)
            tail_a = np.where(finite, a * np.exp(-0.5 * a * a) / np.sqrt(2.0 * np.pi), 0.0)
            tail_c = np.where(finite, a * a * 2.0 * ndtr(-a), 0.0) * sd * sd
            psi2 += share * (sd * sd * (inside - 2.0 * tail_a) + tail_c)
            slope += share * inside
        return psi2 / slope**2

    def _figures(self):
        def cost(e):
            return huber_cost(np.atleast_1d(e)[:, None], self.gamma)[0]

        mean = self.expect(cost)
        psi2 = self.expect(lambda e: min(e * e, self.gamma**2))
        slope = self.expect(lambda e: float(abs(e) <= self.gamma))
        return mean, self.expect(lambda e: cost(e) ** 2) - mean * mean, psi2 / slope**2

    def limit(self, dof, gof):
        """Cost (like ``dof``) above which a fit with ``dof`` degrees of freedom fails at level ``gof``."""
        from scipy.special import ndtri  # -ndtri(q) = scipy.stats.norm.isf(q), without scipy.stats' 40 MB

        mu, var = self.moments
        return np.asarray(dof) * mu - ndtri(gof) * np.sqrt(np.asarray(dof) * var)


@lru_cache(maxsize=32)
def _huber_figures(gamma, eps, scale):
    return Huber(gamma, eps, scale)._figures()


def _normal_pdf(e, sd):
    """The N(0, sd^2) density (scipy.stats.norm(scale=sd).pdf, without scipy.stats' 40 MB import)."""
    u = e / sd
    return np.exp(-u**2 / 2.0) / np.sqrt(2.0 * np.pi) / sd


def huber_cost(r, gamma):
    """Huber's ``2 rho(r)`` summed over the last axis: ``r^2`` where ``|r| <= gamma``, ``2 gamma |r| - gamma^2``
    beyond (equal to the chi-square of Gaussian residuals that are not outliers)."""
    a = np.abs(r)
    return np.sum(np.where(a <= gamma, r * r, 2.0 * gamma * a - gamma * gamma), axis=-1)


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
    iterations in one compiled loop (:mod:`~shipsense.trackers.lm_kernel`),
    the others the batched numpy loop (:func:`_levenberg_marquardt`): the same
    iteration, equal to rounding (tested).
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
        from shipsense.trackers.lm_kernel import lm_fits

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


def leverage_information(J, JtJ, huber, rows):
    """The information ``I`` of a Huber fit whose covariance ``variance_factor * I^-1`` accounts for leverage.

    The asymptotic ``kappa (J^T J)^-1`` holds when every residual has a small leverage ``h_i`` (the diagonal
    of ``J (J^T J)^-1 J^T``).  A residual of leverage ``h`` is fitted to ``(1 - h)`` of its noise, so Huber's
    clip at ``gamma`` on the residual is a clip at ``gamma / (1 - h)`` on the noise: an outlier on a sample
    that dominates the information (an inverse-cube field at the closest approach) is masked and enters
    with nearly its full variance.  The covariance is then the sandwich
    ``(J^T J)^-1 J^T diag(kappa(gamma / (1 - h_i))) J (J^T J)^-1``
    (:meth:`Huber.variance_factor_at`); returned as ``I`` with ``kappa I^-1`` equal to it, so that callers
    scaling ``I^-1`` by :attr:`Huber.variance_factor` get it (``I = J^T J`` when every leverage is small).
    Rows of ``J`` (B, M, n) past ``rows`` are a prior's (exact, weight 1 relative to the noise's kappa).
    """
    with np.errstate(all="ignore"):
        inv = np.linalg.pinv(JtJ, hermitian=True)
        h = np.clip(np.einsum("bmi,bij,bmj->bm", J, inv, J), 0.0, 1.0 - 1e-12)
        rel = huber.variance_factor_at(huber.gamma / (1.0 - h)) / huber.variance_factor
    rel[:, rows:] = 1.0
    rel = np.where(np.isfinite(rel), rel, 1.0)
    meat = np.swapaxes(J, -1, -2) @ (J * rel[..., None])
    try:
        info = JtJ @ np.linalg.solve(meat + 1e-300 * np.eye(JtJ.shape[-1]), JtJ)
    except np.linalg.LinAlgError:   # a fit some state component does not reach (a singular J^T J): its pseudo-inverse
        with np.errstate(all="ignore"):
            info = JtJ @ np.linalg.pinv(meat, hermitian=True) @ JtJ
    ok = np.isfinite(info).all(axis=(-1, -2))
    return np.where(ok[:, None, None], 0.5 * (info + np.swapaxes(info, -1, -2)), JtJ)
