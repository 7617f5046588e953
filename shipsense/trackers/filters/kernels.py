"""The compiled filter kernels: each filter's measurement update and the shared prediction, one numba loop over
the batch each (:mod:`~shipsense.trackers.filters.fused` calls them); the shared time update is
:func:`~shipsense.trackers.filters.time_update.predict_kernel`.

One step per batch element, with no Python objects, no temporaries and no reference counting in the loop:
the per-step cost is one call's overhead plus the arithmetic.  Each filter has its own update kernel
(:func:`_update_kernel_for`: one source, the filter a constant of each), so a first call compiles that
filter's statistics and gain only, not all six filters'; the kernels are cached on disk
(:mod:`shipsense.numba_cache`).  For a model with a compiled measurement kernel these are the filters'
implementation; the numpy updates of the filter modules are the generic path of the other models
(:mod:`~shipsense.trackers.filters.fused` says which runs where).

An update kernel takes its arrays in four bundles named by meaning -- :class:`Prior`, :class:`Readings`,
:class:`UpdateSpec`, :class:`Posterior`.  Python calls its entry (:data:`UPDATE_KERNELS`) with the bundles'
fields flat, which bundles them for the kernel: numba's dispatcher types a flat argument in its compiled fast
path and a tuple's fields one by one, which at a batch of one costs a share of a filter step.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from shipsense import numba_cache
from shipsense.models.measurement import loop_jit, measure, measure_jacobian, wrap_angle
from shipsense.trackers.filters.core import LOG_2PI
from shipsense.trackers.linalg import (
    backward_into,
    cho_solve_into,
    cholesky_into,
    forward_into,
    matmul_into,
    tria_into,
    whitened,
)

# -- small dense linear algebra, one element at a time ----------------------------------------------------------

@njit(cache=True, error_model="numpy", inline="always")
def _residual(a, b, axial):
    """``a - b``, wrapped modulo pi on an axial channel."""
    return wrap_angle(a - b) if axial else a - b


@njit(cache=True, error_model="numpy", inline="always")
def _gain(x, P, eps, Pxy, S, n, m, Ls, W, w, mean, Pout):
    """Kalman update ``x+ = x + Pxy S^-1 eps``, ``P+ = P - Pxy S^-1 Pxy^T`` into ``mean``, ``Pout``.

    Returns ``(ok, nis, log det S)``; with ``S = Ls Ls^T`` and ``[W | w] = Ls^-1 [Pxy^T | eps]``.
    """
    if not cholesky_into(S, Ls):
        return False, 0.0, 0.0
    for i in range(m):
        for a in range(n):
            t = Pxy[a, i]
            for k in range(i):
                t -= Ls[i, k] * W[k, a]
            W[i, a] = t / Ls[i, i]
    nis, logdet = whitened(Ls, eps, w)
    for a in range(n):
        t = x[a]
        for i in range(m):
            t += W[i, a] * w[i]
        mean[a] = t
        for b in range(a + 1):
            t = 0.0
            for i in range(m):
                t += W[i, a] * W[i, b]
            Pout[a, b] = P[a, b] - t
            Pout[b, a] = P[b, a] - t
    ok = True
    for a in range(n):
        if not math.isfinite(mean[a]):
            ok = False
    return ok, nis, logdet


# -- the filters' statistics ----------------------------------------------------------------------------------

@njit(cache=True, error_model="numpy", inline="always")
def _sigma_stats(x, L, present, spec, spread, Wm, Wc, center, pt, Y, yhat, dY, Pxy, Pyy, B):
    """Unscented/cubature ``yhat``, ``Pxy``, ``Pyy`` (no R) of the points ``[x,] x +- spread L_i``."""
    n = x.shape[0]
    m = yhat.shape[0]
    N = 2 * n + center
    for p in range(N):
        if center and p == 0:
            for a in range(n):
                pt[a] = x[a]
        else:
            i = (p - center) % n
            sg = 1.0 if p - center < n else -1.0
            for a in range(n):
                pt[a] = x[a] + sg * spread * L[a, i]
        measure(pt, spec, Y[p], B)
    axial = spec[9]
    for j in range(m):
        t = 0.0
        if axial[j]:    # angles averaged as residuals about the first point's prediction
            for p in range(N):
                t += Wm[p] * wrap_angle(Y[p, j] - Y[0, j])
            yhat[j] = Y[0, j] + t
        else:
            for p in range(N):
                t += Wm[p] * Y[p, j]
            yhat[j] = t
    for p in range(N):
        for j in range(m):
            d = Y[p, j] - yhat[j]
            dY[p, j] = (wrap_angle(d) if axial[j] else d) if present[j] else 0.0
    for i in range(m):
        for j in range(i + 1):
            t = 0.0
            for p in range(N):
                t += Wc[p] * dY[p, i] * dY[p, j]
            Pyy[i, j] = t
            Pyy[j, i] = t
    for a in range(n):
        for j in range(m):
            t = 0.0
            for i in range(n):
                t += L[a, i] * Wc[center + i] * (dY[center + i, j] - dY[center + n + i, j])
            Pxy[a, j] = spread * t


@njit(cache=True, error_model="numpy", inline="always")
def _difference_stats(x, L, present, spec, h, pt, Y, yhat, Y1, Y2, Pxy, B):
    """Central-difference ``yhat``, first and second-order rows ``Y1``, ``Y2`` (n, m) and ``Pxy = L Y1``."""
    n = x.shape[0]
    m = yhat.shape[0]
    for p in range(2 * n + 1):
        if p == 0:
            for a in range(n):
                pt[a] = x[a]
        else:
            i = (p - 1) % n
            sg = 1.0 if p - 1 < n else -1.0
            for a in range(n):
                pt[a] = x[a] + sg * h * L[a, i]
        measure(pt, spec, Y[p], B)
    c1 = 1.0 / (2.0 * h)
    c2 = math.sqrt(h * h - 1.0) / (2.0 * h * h)
    axial = spec[9]
    for j in range(m):
        t = 0.0
        for i in range(n):
            dp = Y[1 + i, j] - Y[0, j]
            dm = Y[1 + n + i, j] - Y[0, j]
            if axial[j]:
                dp = wrap_angle(dp)
                dm = wrap_angle(dm)
            t += dp + dm
            keep = 1.0 if present[j] else 0.0
            Y1[i, j] = (dp - dm) * c1 * keep
            Y2[i, j] = c2 * (dp + dm) * keep
        yhat[j] = Y[0, j] + t / (2.0 * h * h)
    matmul_into(L, Y1, Pxy, n, n, m)


UKF, CDKF, HUBER, EKF, PUEKF, SRCDKF = range(6)


@njit(cache=True, error_model="numpy", inline="always")
def _huber_reweight(L, present, R, eps, Pxy, Pyy, S, gamma, iterations, Ls, w, Ht, Reff, new, dx):
    """The Huber update's reweighting: ``S = Pyy + diag(R_eff)`` with the noise of every component whose
    posterior residual exceeds ``gamma`` standard deviations inflated by ``|e| / gamma``, iterated until the
    weights settle (at most ``iterations``).  ``L`` is the prior's factor.  False if ``S`` is not positive
    definite."""
    n, m = L.shape[0], eps.shape[0]
    cho_solve_into(L, Pxy, Ht)   # H^T = P^-1 Pxy through the prior's factor
    for j in range(m):
        Reff[j] = R[j]
    for _ in range(iterations):
        if not cholesky_into(S, Ls):
            return False
        forward_into(Ls, eps, w)    # dx = K eps = Pxy S^-1 eps
        backward_into(Ls, w)
        for a in range(n):
            t = 0.0
            for j in range(m):
                t += Pxy[a, j] * w[j]
            dx[a] = t
        same = True
        for j in range(m):
            t = eps[j]
            for a in range(n):
                t -= Ht[a, j] * dx[a]
            e = abs(t) / math.sqrt(R[j])
            new[j] = R[j] * (e / gamma if present[j] and e > gamma else 1.0)
            if not abs(new[j] - Reff[j]) <= 1e-9 * abs(Reff[j]):
                same = False
        if same:
            break
        for j in range(m):
            Reff[j] = new[j]
            S[j, j] = Pyy[j, j] + Reff[j]
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _difference_cov(Y1, Y2, R, S):
    """The CDKF's innovation covariance ``S = Y1^T Y1 + Y2^T Y2 + diag(R)``."""
    n, m = Y1.shape
    for i in range(m):
        for j in range(i + 1):
            t = 0.0
            for a in range(n):
                t += Y1[a, i] * Y1[a, j] + Y2[a, i] * Y2[a, j]
            S[i, j] = t
            S[j, i] = t
        S[i, i] += R[i]


@njit(cache=True, error_model="numpy", inline="always")
def _srcdkf_gain(x, L, eps, Y1, Y2, Pxy, R, My, Ls, Asc, vsc, nzs, W, w, Mx, S, mean, Pout):
    """The SR-CDKF update: ``Sy = tria([Y1^T, Y2^T, R^(1/2)])``, ``K = Pxy Sy^-T Sy^-1``, ``Sx = tria([L - K Y1^T,
    K Y2^T, K R^(1/2)])`` into ``mean``, ``Pout`` (the factor) and ``S = Sy Sy^T``.  Returns
    ``(ok, nis, log det S)``."""
    n, m = x.shape[0], eps.shape[0]
    for i in range(m):
        for a in range(n):
            My[i, a] = Y1[a, i]
            My[i, n + a] = Y2[a, i]
        My[i, 2 * n + i] = math.sqrt(R[i])
    ok = tria_into(My, Ls, Asc, vsc, nzs)
    for i in range(m):
        if not Ls[i, i] > 0.0:
            ok = False
    if not ok:
        return False, 0.0, 0.0
    cho_solve_into(Ls, Pxy.T, W)   # K^T = Sy^-T Sy^-1 Pxy^T
    for a in range(n):
        t = x[a]
        for i in range(m):
            t += W[i, a] * eps[i]
        mean[a] = t
        if not math.isfinite(t):
            ok = False
        for c in range(n):
            t1 = 0.0
            t2 = 0.0
            for i in range(m):
                t1 += W[i, a] * Y1[c, i]
                t2 += W[i, a] * Y2[c, i]
            Mx[a, c] = L[a, c] - t1
            Mx[a, n + c] = t2
        for i in range(m):
            Mx[a, 2 * n + i] = W[i, a] * My[i, 2 * n + i]
    ok = ok and tria_into(Mx, Pout, Asc, vsc, nzs)
    for a in range(n):
        if not Pout[a, a] > 0.0:
            ok = False
    nis, logdet = whitened(Ls, eps, w)
    for i in range(m):
        for j in range(i + 1):
            t = 0.0
            for q in range(j + 1):
                t += Ls[i, q] * Ls[j, q]
            S[i, j] = t
            S[j, i] = t
    return ok, nis, logdet


@njit(cache=True, error_model="numpy", inline="always")
def _ekf_gain(subs, x, P0, present, y, R, spec, sc, mean, Pout, eps_out, S_out):
    """EKF (``subs = 1``) or PUEKF update: ``subs`` sub-updates with noise ``R subs``, each re-linearised at the
    current estimate, into ``mean`` and ``Pout``; ``eps_out``, ``S_out`` get the first one's innovation and its
    covariance, from which the returned ``(ok, nis, log det S)`` are computed.  ``sc``: scratch."""
    xc, P, Pn, H, yhat, eps, Pxy, Pyy, S, Ls, W, w, r3, m3, B, dBq, dBm = sc
    n, m = x.shape[0], y.shape[0]
    axial = spec[9]
    for a in range(n):
        xc[a] = x[a]
        for c in range(n):
            P[a, c] = P0[a, c]
    ok, nis, logdet = True, 0.0, 0.0
    for sub in range(subs):
        measure_jacobian(xc, spec, yhat, H, r3, m3, B, dBq, dBm)
        for j in range(m):
            eps[j] = _residual(y[j], yhat[j], axial[j]) if present[j] else 0.0
            if not present[j]:
                H[j, :] = 0.0
        for a in range(n):          # Pxy = P H^T
            for j in range(m):
                t = 0.0
                for c in range(n):
                    t += P[a, c] * H[j, c]
                Pxy[a, j] = t
        for i in range(m):          # H P H^T
            for j in range(m):
                t = 0.0
                for c in range(n):
                    t += H[i, c] * Pxy[c, j]
                Pyy[i, j] = t
        for i in range(m):
            if sub == 0:
                for j in range(m):
                    S_out[i, j] = Pyy[i, j]
                S_out[i, i] += R[i]
                eps_out[i] = eps[i]
            for j in range(m):
                S[i, j] = Pyy[i, j]
            S[i, i] += R[i] * subs if present[i] else 1.0
        ok, nis, logdet = _gain(xc, P, eps, Pxy, S, n, m, Ls, W, w, mean, Pn)
        if not ok:
            return ok, nis, logdet
        for a in range(n):
            xc[a] = mean[a]
            for c in range(n):
                P[a, c] = Pn[a, c]
                Pout[a, c] = Pn[a, c]
    if subs > 1:   # the statistics of the first innovation
        ok = cholesky_into(S_out, Ls)
        if ok:
            nis, logdet = whitened(Ls, eps_out, w)
    return ok, nis, logdet


class Prior(NamedTuple):
    """The beliefs an update starts from, a row per batch element: means (B, n), their lower Cholesky factors
    (B, n, n) and covariances (B, n, n) (the SR-CDKF reads no covariance: (1, 1, 1); the linearised filters
    read no factor: their covariances again)."""

    mean: np.ndarray
    chol: np.ndarray
    cov: np.ndarray


class Readings(NamedTuple):
    """What an update reads: the measurements ``y`` (B, m) in the model's internal units (NaN = missing) and
    the channels to read, ``mask`` (B or 1, m) bool."""

    y: np.ndarray
    mask: np.ndarray


class UpdateSpec(NamedTuple):
    """A filter on its model, the same for every call: the measurement noise variances ``R`` (m,), the
    model's compiled measurement description ``measurement``
    (:func:`~shipsense.models.measurement.kernel_of`), and the filter's constants
    (:func:`~shipsense.trackers.filters.fused.filter_constants`): the sigma points' ``spread`` and whether
    they have a ``center`` point, their weights ``Wm``, ``Wc``, the difference step ``h``, the Huber
    threshold ``gamma`` and its reweighting's ``iterations``, the PUEKF's sub-updates ``n_pu``."""

    R: np.ndarray
    measurement: tuple
    spread: float
    center: int
    Wm: np.ndarray
    Wc: np.ndarray
    h: float
    gamma: float
    iterations: int
    n_pu: int


class Posterior(NamedTuple):
    """An update's results, a row per batch element (written by the kernel): the means (B, n), covariances
    (B, n, n) (the SR-CDKF's factors) and their factors (B, n, n) (the SR-CDKF: (1, 1, 1), unused), the
    innovations ``eps`` (B, m), their covariances ``S`` (B, m, m), log-likelihoods ``loglik`` (B,),
    normalised squares ``nis`` (B,), channels read ``m`` (B,) int64, and ``ok`` (B,) bool."""

    mean: np.ndarray
    cov: np.ndarray
    chol: np.ndarray
    eps: np.ndarray
    S: np.ndarray
    loglik: np.ndarray
    nis: np.ndarray
    m: np.ndarray
    ok: np.ndarray


def _update_kernel_for(code):
    """The compiled measurement update of filter ``code`` (UKF/CKF, CDKF, HUBER, EKF, PUEKF, SRCDKF): a kernel
    and its loop over the batch, with ``filt`` a constant of each, so that numba prunes the other filters'
    branches before it compiles (a filter's first call compiles its own statistics and gain only, not all
    six; one source for the six)."""
    filt_code = code

    def loop(prior, readings, spec, post, work, ekf):
        """The kernel's loop over the batch, on its scratch ``work`` and ``ekf``; the bundles as
        :func:`_update_kernel_for`'s kernel takes them, named."""
        filt = filt_code
        (present, y, R, yhat, eps, w, Y, dY, Pxy, Pyy, S, Ls, W, Y1, Y2, Ht, pt, dx, Reff, new, My, Mx, Asc, vsc,
         nzs, B) = work
        nb, n = prior.mean.shape
        Yobs, mask = readings.y, readings.mask
        m = Yobs.shape[1]
        meas = spec.measurement
        axial = meas[9]
        for b in range(nb):
            x = prior.mean[b]
            L = prior.chol[b]
            cnt = 0
            for j in range(m):
                present[j] = math.isfinite(Yobs[b, j]) and mask[b if mask.shape[0] > 1 else 0, j]
                y[j] = Yobs[b, j] if present[j] else 0.0
                R[j] = spec.R[j] if present[j] else 1.0
                cnt += present[j]
            post.m[b] = cnt
            ok, nis, logdet = True, 0.0, 0.0
            if filt == UKF or filt == HUBER:
                _sigma_stats(x, L, present, meas, spec.spread, spec.Wm, spec.Wc, spec.center, pt, Y, yhat, dY, Pxy,
                             Pyy, B)
                for i in range(m):
                    eps[i] = _residual(y[i], yhat[i], axial[i]) if present[i] else 0.0
                    for j in range(m):
                        S[i, j] = Pyy[i, j]
                    S[i, i] += R[i]
                if filt == HUBER:
                    ok = _huber_reweight(L, present, R, eps, Pxy, Pyy, S, spec.gamma, spec.iterations, Ls, w, Ht, Reff,
                                         new, dx)
                if ok:
                    ok, nis, logdet = _gain(x, prior.cov[b], eps, Pxy, S, n, m, Ls, W, w, post.mean[b], post.cov[b])
            elif filt == CDKF or filt == SRCDKF:
                _difference_stats(x, L, present, meas, spec.h, pt, Y, yhat, Y1, Y2, Pxy, B)
                for j in range(m):
                    eps[j] = _residual(y[j], yhat[j], axial[j]) if present[j] else 0.0
                if filt == CDKF:
                    _difference_cov(Y1, Y2, R, S)
                    ok, nis, logdet = _gain(x, prior.cov[b], eps, Pxy, S, n, m, Ls, W, w, post.mean[b], post.cov[b])
                else:
                    ok, nis, logdet = _srcdkf_gain(x, L, eps, Y1, Y2, Pxy, R, My, Ls, Asc, vsc, nzs, W, w, Mx, S,
                                                   post.mean[b], post.cov[b])
            else:   # EKF, PUEKF: n_pu sub-updates with R n_pu, re-linearised; the innovation is the first one's
                ok, nis, logdet = _ekf_gain(1 if filt == EKF else spec.n_pu, x, prior.cov[b], present, y, R, meas, ekf,
                                            post.mean[b], post.cov[b], post.eps[b], post.S[b])
            if filt != EKF and filt != PUEKF:
                for i in range(m):
                    post.eps[b, i] = eps[i]
                    for j in range(m):
                        post.S[b, i, j] = S[i, j]
            post.nis[b] = nis
            post.loglik[b] = -0.5 * (cnt * LOG_2PI + logdet + nis)
            if ok and filt != SRCDKF:
                ok = cholesky_into(post.cov[b], post.chol[b])
            post.ok[b] = ok

    def kernel(prior, readings, spec, post):
        """One measurement update of every batch element: the bundles :class:`Prior`, :class:`Readings`,
        :class:`UpdateSpec` and :class:`Posterior` (written), named tuples or plain tuples of their fields.

        The covariance-form filters also write the posterior's factor into ``post.chol`` (the SR-CDKF's factor
        is ``post.cov``); ``post.ok`` is False where a factorisation failed or a result is not finite; returns
        whether every element is ok.  Allocates the scratch; the loop over the batch is ``_LOOP``, its filter's.
        """
        prior, readings, spec, post = Prior(*prior), Readings(*readings), UpdateSpec(*spec), Posterior(*post)
        n = prior.mean.shape[1]
        m = readings.y.shape[1]
        k = 2 * n + m
        present, y, R, yhat, eps, w = (np.empty(m, np.bool_), np.empty(m), np.empty(m), np.empty(m), np.empty(m),
                                       np.empty(m))
        Y, dY = np.empty((2 * n + 1, m)), np.empty((2 * n + 1, m))
        Pxy, Pyy, S, Ls = np.empty((n, m)), np.empty((m, m)), np.empty((m, m)), np.zeros((m, m))
        W, Y1, Y2, Ht = np.empty((m, n)), np.empty((n, m)), np.empty((n, m)), np.empty((n, m))
        pt, dx, Reff, new = np.empty(n), np.empty(n), np.empty(m), np.empty(m)
        My, Mx, Asc, vsc = np.zeros((m, k)), np.empty((n, k)), np.empty((max(n, m), k)), np.empty(k)
        nzs = np.empty(k, np.int64)
        B = np.empty(3)
        ekf = (np.empty(n), np.empty((n, n)), np.empty((n, n)), np.empty((m, n)), yhat, eps, Pxy, Pyy, S, Ls, W, w,
               np.empty(3), np.empty(3), B, np.empty((3, 3)), np.empty((3, 3)))
        work = (present, y, R, yhat, eps, w, Y, dY, Pxy, Pyy, S, Ls, W, Y1, Y2, Ht, pt, dx, Reff, new, My, Mx, Asc, vsc,
                nzs, B)
        _LOOP(prior, readings, spec, post, work, ekf)  # noqa: F821 - the copy's global
        return post.ok.all()

    def entry(mean, chol, cov, y, mask, R, measurement, spread, center, Wm, Wc, h, gamma, iterations, n_pu,
              post_mean, post_cov, post_chol, eps, S, loglik, nis, m, ok):
        """The update's entry: the bundles' fields in their order, flat (numba's dispatcher types a flat
        argument in its compiled fast path, a tuple's fields one by one: at a batch of one, a share of the
        step), bundled for the kernel ``_KERNEL`` (inlined)."""
        return _KERNEL(Prior(mean, chol, cov), Readings(y, mask),  # noqa: F821 - the copy's global
                       UpdateSpec(R, measurement, spread, center, Wm, Wc, h, gamma, iterations, n_pu),
                       Posterior(post_mean, post_cov, post_chol, eps, S, loglik, nis, m, ok))

    # each filter's entry, kernel and loop are named for it, each finding the next as a global of its own copy
    # (numba_cache.specialised says why)
    loop.__qualname__ = f"_update_loop_{code}"
    loop = loop_jit(loop)
    bundled = numba_cache.specialised(kernel, f"_update_kernel_{code}",
                                      njit(cache=True, error_model="numpy", inline="always"), _LOOP=loop)
    return numba_cache.specialised(entry, f"_update_entry_{code}", njit(cache=True, error_model="numpy", nogil=True),
                                   _KERNEL=bundled), bundled, loop


_UPDATE_PAIRS = {code: _update_kernel_for(code) for code in (UKF, CDKF, HUBER, EKF, PUEKF, SRCDKF)}
UPDATE_KERNELS = {code: entry for code, (entry, _, _) in _UPDATE_PAIRS.items()}
UPDATE_BUNDLED = {code: bundled for code, (_, bundled, _) in _UPDATE_PAIRS.items()}
UPDATE_LOOPS = {code: loop for code, (_, _, loop) in _UPDATE_PAIRS.items()}
"""Each filter's compiled update (:func:`_update_kernel_for`), by the filter's code: its entry on the bundles'
fields (what Python calls), the kernel on the bundles (what the tracker's compiled step calls) and its loop
(the last two here so that :func:`shipsense.numba_cache.key_on_sources` stamps them too)."""


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
