r"""Compiled filter steps: each filter's predict and update fused into one numba loop over the batch.

Who gets which implementation.  :class:`~shipsense.trackers.filters.FilterUnit`
(what :func:`~shipsense.trackers.filters.run.run_filter`, the bank and the tracker
call) runs these compiled steps whenever the model has a compiled measurement
kernel (:func:`shipsense.models.measurement.kernel_of`):

* a :class:`~shipsense.models.field_model.FieldModel` on the fast HED path:
  magnetometers (vector, magnitude or tmi readings; the S0 model), seismic
  bearings (S2) and electrodes (vector, envelope or magnitude readings of the
  HED field; S1, the demo), also with per-element transitions
  (:meth:`~shipsense.models.field_model.FieldModel.stepped`);
* a :class:`~shipsense.models.field_model.LinearModel`.

Every other model (the series HED path; user models with a Python ``h``)
runs the generic numpy steps of the filter modules (``ukf.update`` and so on),
which are also the independent reference the tests compare these steps with.
An element whose step fails numerically here (an innovation or posterior
covariance that is not positive definite, a non-finite result) makes the whole step rerun on the
numpy path, which flags and repairs such elements.

The results equal the numpy steps' to rounding (tests/trackers/filters/test_fused.py), with one difference by
design: the Huber update's reweighting stops for each element when its weights settle, where the numpy
update iterates until the whole batch has settled (an element that settled moves by less than 1e-9 of
its noise variances per further iteration), so a compiled element equals the numpy update of that
element alone.

One step per batch element, with no Python objects, no temporaries and no
reference counting in the loop: the per-step cost is one call's overhead plus
the arithmetic.  A batch of ``shipsense.parallel.SPLIT_MIN`` (512) elements
or more runs as contiguous chunks in threads (:mod:`shipsense.parallel`; the loops
release the GIL).  The first call compiles (``cache=True``: once per machine, the
compiled code is kept next to this file and reused by later processes); each filter has its own update
kernel (:func:`_update_kernel_for`: one source, the filter a constant of each), so a first call compiles
that filter's statistics and gain only, not all six filters'.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit

from shipsense import numba_cache
from shipsense.defaults import HUBER_GAMMA, N_PU
from shipsense.models.measurement import loop_jit, measure, measure_jacobian, wrap_angle
from shipsense.parallel import SPLIT_MIN, in_chunks
from shipsense.trackers.filters.cdkf import H_STIRLING
from shipsense.trackers.filters.core import LOG_2PI, Belief, BeliefWithCov, Innovation, prior_health, sqrt_psd
from shipsense.trackers.filters.ukf import merwe_weights

# -- small dense linear algebra, one element at a time ----------------------------------------------------------

@njit(cache=True, error_model="numpy", inline="always")
def _residual(a, b, axial):
    """``a - b``, wrapped modulo pi on an axial channel."""
    return wrap_angle(a - b) if axial else a - b


@njit(cache=True, error_model="numpy", inline="always")
def _chol(A, L):
    """Lower Cholesky factor of the lower triangle of ``A`` into ``L``; False if ``A`` is not positive definite."""
    n = A.shape[0]
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not (s > 0.0 and s < math.inf):
            return False
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            t = A[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / d
        for i in range(j):
            L[i, j] = 0.0
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _forward(L, b, out):
    """Solve ``L out = b`` (lower triangular) for a vector."""
    for i in range(L.shape[0]):
        t = b[i]
        for k in range(i):
            t -= L[i, k] * out[k]
        out[i] = t / L[i, i]


@njit(cache=True, error_model="numpy", inline="always")
def _tria(M, S, A, v, nz):
    """Lower-triangular ``S`` (n, n) with ``S S^T = M M^T`` for ``M`` (n, k), k >= n, non-negative diagonal.

    Householder triangularisation (an LQ decomposition of ``M``, the QR of ``M^T``) specialised to one small
    matrix (the numpy path calls a batched LAPACK QR), working on rows so that every inner loop is
    contiguous, and only over the reflector's nonzero entries (``[A L, Q^(1/2)]`` is mostly zeros; skipping
    exact zeros leaves every sum the same); ``A`` (at least (n, k)), ``v`` (k,) and the integer ``nz`` (k,) are
    scratch.  False if the result is not finite.
    """
    n, k = M.shape
    for j in range(n):
        for i in range(k):
            A[j, i] = M[j, i]
    for j in range(n):
        norm2 = 0.0
        for i in range(j, k):
            norm2 += A[j, i] * A[j, i]
        if norm2 == 0.0:
            continue
        norm = math.sqrt(norm2)
        alpha = -norm if A[j, j] >= 0 else norm
        vn2 = 0.0
        for i in range(j, k):
            v[i] = A[j, i]
        v[j] -= alpha
        for i in range(j, k):
            vn2 += v[i] * v[i]
        if vn2 == 0.0:
            continue
        A[j, j] = alpha
        for i in range(j + 1, k):
            A[j, i] = 0.0
        q = 0
        for i in range(j, k):
            if v[i] != 0.0:
                nz[q] = i
                q += 1
        for c in range(j + 1, n):
            t = 0.0
            for r in range(q):
                t += v[nz[r]] * A[c, nz[r]]
            t *= 2.0 / vn2
            for r in range(q):
                A[c, nz[r]] -= t * v[nz[r]]
    ok = True
    for j in range(n):
        sgn = -1.0 if A[j, j] < 0 else 1.0
        for i in range(n):
            S[i, j] = sgn * A[i, j] if i >= j else 0.0
            if not math.isfinite(S[i, j]):
                ok = False
    return ok


@njit(cache=True, error_model="numpy", inline="always")
def _cho_solve(L, B, X):
    """Solve ``L L^T X = B`` (``L`` lower triangular (k, k), ``B`` and ``X`` (k, c)) by forward then backward
    substitution, column by column."""
    k = L.shape[0]
    for j in range(B.shape[1]):
        for a in range(k):
            t = B[a, j]
            for q in range(a):
                t -= L[a, q] * X[q, j]
            X[a, j] = t / L[a, a]
        for a in range(k - 1, -1, -1):
            t = X[a, j]
            for q in range(a + 1, k):
                t -= L[q, a] * X[q, j]
            X[a, j] = t / L[a, a]


@njit(cache=True, error_model="numpy", inline="always")
def _whitened(Ls, eps, w):
    """``(eps^T S^-1 eps, log det S)`` from ``S = Ls Ls^T``; ``w`` gets ``Ls^-1 eps``."""
    _forward(Ls, eps, w)
    nis = 0.0
    logdet = 0.0
    for i in range(Ls.shape[0]):
        nis += w[i] * w[i]
        logdet += 2.0 * math.log(Ls[i, i])
    return nis, logdet


@njit(cache=True, error_model="numpy", inline="always")
def _gain(x, P, eps, Pxy, S, n, m, Ls, W, w, mean, Pout):
    """Kalman update ``x+ = x + Pxy S^-1 eps``, ``P+ = P - Pxy S^-1 Pxy^T`` into ``mean``, ``Pout``.

    Returns ``(ok, nis, log det S)``; with ``S = Ls Ls^T`` and ``[W | w] = Ls^-1 [Pxy^T | eps]``.
    """
    if not _chol(S, Ls):
        return False, 0.0, 0.0
    for i in range(m):
        for a in range(n):
            t = Pxy[a, i]
            for k in range(i):
                t -= Ls[i, k] * W[k, a]
            W[i, a] = t / Ls[i, i]
    nis, logdet = _whitened(Ls, eps, w)
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
    for a in range(n):
        for j in range(m):
            t = 0.0
            for i in range(n):
                t += L[a, i] * Y1[i, j]
            Pxy[a, j] = t


UKF, CDKF, HUBER, EKF, PUEKF, SRCDKF = range(6)

@njit(cache=True, error_model="numpy", inline="always")
def _backward(L, w):
    """Solve ``L^T out = w`` in place (``L`` lower triangular)."""
    for i in range(L.shape[0] - 1, -1, -1):
        t = w[i]
        for q in range(i + 1, L.shape[0]):
            t -= L[q, i] * w[q]
        w[i] = t / L[i, i]


@njit(cache=True, error_model="numpy", inline="always")
def _huber_reweight(L, present, R, eps, Pxy, Pyy, S, gamma, iterations, Ls, w, Ht, Reff, new, dx):
    """The Huber update's reweighting: ``S = Pyy + diag(R_eff)`` with the noise of every component whose
    posterior residual exceeds ``gamma`` standard deviations inflated by ``|e| / gamma``, iterated until the
    weights settle (at most ``iterations``).  ``L`` is the prior's factor.  False if ``S`` is not positive
    definite."""
    n, m = L.shape[0], eps.shape[0]
    _cho_solve(L, Pxy, Ht)   # H^T = P^-1 Pxy through the prior's factor
    for j in range(m):
        Reff[j] = R[j]
    for _ in range(iterations):
        if not _chol(S, Ls):
            return False
        _forward(Ls, eps, w)    # dx = K eps = Pxy S^-1 eps
        _backward(Ls, w)
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
    ok = _tria(My, Ls, Asc, vsc, nzs)
    for i in range(m):
        if not Ls[i, i] > 0.0:
            ok = False
    if not ok:
        return False, 0.0, 0.0
    _cho_solve(Ls, Pxy.T, W)   # K^T = Sy^-T Sy^-1 Pxy^T
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
    ok = ok and _tria(Mx, Pout, Asc, vsc, nzs)
    for a in range(n):
        if not Pout[a, a] > 0.0:
            ok = False
    nis, logdet = _whitened(Ls, eps, w)
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
        ok = _chol(S_out, Ls)
        if ok:
            nis, logdet = _whitened(Ls, eps_out, w)
    return ok, nis, logdet


def _update_kernel_for(code):
    """The compiled measurement update of filter ``code`` (UKF/CKF, CDKF, HUBER, EKF, PUEKF, SRCDKF): a kernel
    and its loop over the batch, with ``filt`` a constant of each, so that numba prunes the other filters'
    branches before it compiles (a filter's first call compiles its own statistics and gain only, not all
    six; one source for the six)."""
    filt_code = code

    def loop(X, Ls_in, P_in, Yobs, mask, Rm, spec, spread, center, Wm, Wc, h, gamma, iterations, n_pu, mean_out,
             P_out, L_out, eps_out, S_out, loglik, nis_out, m_out, ok_out, work, ekf):
        """The kernel's loop over the batch, on its scratch ``work`` and ``ekf``."""
        filt = filt_code
        (present, y, R, yhat, eps, w, Y, dY, Pxy, Pyy, S, Ls, W, Y1, Y2, Ht, pt, dx, Reff, new, My, Mx, Asc, vsc,
         nzs, B) = work
        nb, n = X.shape
        m = Yobs.shape[1]
        axial = spec[9]
        for b in range(nb):
            x = X[b]
            L = Ls_in[b]
            cnt = 0
            for j in range(m):
                present[j] = math.isfinite(Yobs[b, j]) and mask[b if mask.shape[0] > 1 else 0, j]
                y[j] = Yobs[b, j] if present[j] else 0.0
                R[j] = Rm[j] if present[j] else 1.0
                cnt += present[j]
            m_out[b] = cnt
            ok, nis, logdet = True, 0.0, 0.0
            if filt == UKF or filt == HUBER:
                _sigma_stats(x, L, present, spec, spread, Wm, Wc, center, pt, Y, yhat, dY, Pxy, Pyy, B)
                for i in range(m):
                    eps[i] = _residual(y[i], yhat[i], axial[i]) if present[i] else 0.0
                    for j in range(m):
                        S[i, j] = Pyy[i, j]
                    S[i, i] += R[i]
                if filt == HUBER:
                    ok = _huber_reweight(L, present, R, eps, Pxy, Pyy, S, gamma, iterations, Ls, w, Ht, Reff, new, dx)
                if ok:
                    ok, nis, logdet = _gain(x, P_in[b], eps, Pxy, S, n, m, Ls, W, w, mean_out[b], P_out[b])
            elif filt == CDKF or filt == SRCDKF:
                _difference_stats(x, L, present, spec, h, pt, Y, yhat, Y1, Y2, Pxy, B)
                for j in range(m):
                    eps[j] = _residual(y[j], yhat[j], axial[j]) if present[j] else 0.0
                if filt == CDKF:
                    _difference_cov(Y1, Y2, R, S)
                    ok, nis, logdet = _gain(x, P_in[b], eps, Pxy, S, n, m, Ls, W, w, mean_out[b], P_out[b])
                else:
                    ok, nis, logdet = _srcdkf_gain(x, L, eps, Y1, Y2, Pxy, R, My, Ls, Asc, vsc, nzs, W, w, Mx, S,
                                                   mean_out[b], P_out[b])
            else:   # EKF, PUEKF: n_pu sub-updates with R n_pu, re-linearised; the innovation is the first one's
                ok, nis, logdet = _ekf_gain(1 if filt == EKF else n_pu, x, P_in[b], present, y, R, spec, ekf,
                                            mean_out[b], P_out[b], eps_out[b], S_out[b])
            if filt != EKF and filt != PUEKF:
                for i in range(m):
                    eps_out[b, i] = eps[i]
                    for j in range(m):
                        S_out[b, i, j] = S[i, j]
            nis_out[b] = nis
            loglik[b] = -0.5 * (cnt * LOG_2PI + logdet + nis)
            if ok and filt != SRCDKF:
                ok = _chol(P_out[b], L_out[b])
            ok_out[b] = ok

    def kernel(X, Ls_in, P_in, Yobs, mask, Rm, spec, spread, center, Wm, Wc, h, gamma, iterations, n_pu, mean_out,
               P_out, L_out, eps_out, S_out, loglik, nis_out, m_out, ok_out):
        """One measurement update of every batch element.

        The covariance-form filters also write the posterior's factor into ``L_out`` (the SR-CDKF's factor is
        ``P_out``); ``ok_out`` is False where a factorisation failed or a result is not finite; returns whether
        every element is ok.  Allocates the scratch; the loop over the batch is ``_LOOP``, its filter's.
        """
        n = X.shape[1]
        m = Yobs.shape[1]
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
        _LOOP(X, Ls_in, P_in, Yobs, mask, Rm, spec, spread, center, Wm, Wc, h, gamma, iterations, n_pu,  # noqa: F821
              mean_out, P_out, L_out, eps_out, S_out, loglik, nis_out, m_out, ok_out, work, ekf)
        return ok_out.all()

    # each filter's kernel and loop are named for it, the kernel finding its loop as the global ``_LOOP`` of its
    # own copy (numba_cache.specialised says why)
    loop.__qualname__ = f"_update_loop_{code}"
    loop = loop_jit(loop)
    return numba_cache.specialised(kernel, f"_update_kernel_{code}", njit(cache=True, error_model="numpy", nogil=True),
                                   _LOOP=loop), loop


_UPDATE_PAIRS = {code: _update_kernel_for(code) for code in (UKF, CDKF, HUBER, EKF, PUEKF, SRCDKF)}
UPDATE_KERNELS = {code: kernel for code, (kernel, _) in _UPDATE_PAIRS.items()}
UPDATE_LOOPS = {code: loop for code, (_, loop) in _UPDATE_PAIRS.items()}
"""Each filter's compiled update and its loop (:func:`_update_kernel_for`), by the filter's code (the loops
are here so that :func:`shipsense.numba_cache.key_on_sources` stamps them too)."""


@njit(cache=True, error_model="numpy", nogil=True)
def predict_kernel(X, P_in, A, Q, sqQ, square_root, mean_out, P_out, L_out, ok_out):
    """``x = A x``; ``P = A P A^T + Q`` and its factor, or (``square_root``) the factor ``tria([A L, Q^(1/2)])``.

    ``A``, ``Q`` and ``sqQ`` have a leading axis of 1 (shared) or of the batch.  ``P_in`` is the covariance, or
    with ``square_root`` the factor.  Returns whether every element is ok.  Allocates the scratch; the loop over
    the batch is :func:`_predict_loop`.
    """
    nb, n = X.shape
    kq = sqQ.shape[2]
    AP = np.empty((n, n))
    M = np.empty((n, n + kq))
    Asc = np.empty((n, n + kq))
    vsc = np.empty(n + kq)
    nzs = np.empty(n + kq, np.int64)
    # each row's nonzero columns of a shared transition (per-element transitions: found element by element)
    nz_count = np.zeros(n, np.int64)
    nz_cols = np.zeros((n, n), np.int64)
    _predict_loop(X, P_in, A, Q, sqQ, square_root, mean_out, P_out, L_out, ok_out, AP, M, Asc, vsc, nzs, nz_count,
                  nz_cols)
    return ok_out.all()


@loop_jit
def _predict_loop(X, P_in, A, Q, sqQ, square_root, mean_out, P_out, L_out, ok_out, AP, M, Asc, vsc, nzs, nz_count,
                  nz_cols):
    """:func:`predict_kernel`'s loop over the batch, on its scratch.  ``A P A^T`` visits only ``A``'s nonzero
    entries (a transition matrix is sparse: n + 2 of n^2 for constant velocity), listed once per transition,
    in the order of a dense sum, so the sums are the same."""
    nb, n = X.shape
    kq = sqQ.shape[2]
    for b in range(nb):
        ia = b if A.shape[0] > 1 else 0
        iq = b if Q.shape[0] > 1 else 0
        Ab = A[ia]
        if b == 0 or A.shape[0] > 1:
            for i in range(n):
                nz_count[i] = 0
                for c in range(n):
                    if Ab[i, c] != 0.0:
                        nz_cols[i, nz_count[i]] = c
                        nz_count[i] += 1
        for i in range(n):      # (dense: a non-finite mean stays non-finite, as numpy's A @ x)
            t = 0.0
            for j in range(n):
                t += Ab[i, j] * X[b, j]
            mean_out[b, i] = t
        Pb = P_in[b]
        for i in range(n):      # A P
            for j in range(n):
                AP[i, j] = 0.0
            for u in range(nz_count[i]):
                c = nz_cols[i, u]
                a = Ab[i, c]
                for j in range(n):
                    AP[i, j] += a * Pb[c, j]
        if square_root:
            for i in range(n):
                for j in range(n):
                    M[i, j] = AP[i, j]
                for j in range(kq):
                    M[i, n + j] = sqQ[b if sqQ.shape[0] > 1 else 0, i, j]
            ok_out[b] = _tria(M, L_out[b], Asc, vsc, nzs)
        else:
            Pout = P_out[b]
            for i in range(n):
                for j in range(i + 1):
                    t = 0.0
                    for u in range(nz_count[j]):
                        c = nz_cols[j, u]
                        t += AP[i, c] * Ab[j, c]
                    Pout[i, j] = t + Q[iq, i, j]
                    Pout[j, i] = t + Q[iq, j, i]
            ok_out[b] = _chol(Pout, L_out[b])


# -- threads --------------------------------------------------------------------------------------------------

_PREDICT_ROWS = frozenset({0, 1, 2, 3, 4, 6, 7, 8, 9})    # the kernels' arguments with a row per batch element
_UPDATE_ROWS = frozenset({0, 1, 2, 3, 4, 15, 16, 17, 18, 19, 20, 21, 22, 23})


def _split(kernel, rows, *args):
    """``kernel(*args)`` (True if every element is ok), over contiguous chunks of the batch in threads when the
    batch is large (:func:`shipsense.parallel.in_chunks`): the arguments at positions ``rows`` that have a row per
    element are sliced."""
    nb = args[0].shape[0]
    if nb < SPLIT_MIN:              # (in_chunks would not split it: called here, without its machinery)
        return bool(kernel(*args))

    def chunk(lo, hi):
        if lo == 0 and hi == nb:
            return kernel(*args)
        return kernel(*(a[lo:hi] if i in rows and a.shape[0] == nb else a for i, a in enumerate(args)))

    return all(in_chunks(chunk, nb))


# -- numpy-facing steps ---------------------------------------------------------------------------------------

def _batch(*shapes):
    """The broadcast of batch shapes (the common case, all equal, without numpy's general machinery)."""
    if len(shapes) == 2 and shapes[0] == shapes[1]:
        return shapes[0]
    shapes = [sh for sh in shapes if sh]      # () broadcasts to anything
    first = shapes[0] if shapes else ()
    for other in shapes[1:]:
        if other != first:
            return np.broadcast_shapes(*shapes)
    return first


def _shaped(a, batch):
    """A kernel's (B, ...) output with its batch axes restored."""
    return a if len(batch) == 1 else a.reshape(batch + a.shape[1:])


def _flag(ok, batch):
    """A copy of the health flag ``ok`` broadcast to ``batch``."""
    ok = np.asarray(ok)
    return ok.copy() if ok.shape == batch else np.broadcast_to(ok, batch).copy()


def _flat(a, batch, tail):
    """``a`` broadcast to ``batch + tail`` as a writable C-contiguous (B, *tail) array (one compiled signature)."""
    a = np.asarray(a)
    full = batch + tail
    if a.shape != full:
        if a.shape[len(a.shape) - len(tail):] == tail and a.size == math.prod(full):   # only axes of length 1 added
            return np.array(a, order="C").reshape((-1,) + tail)
        a = np.broadcast_to(a, full).copy()
    elif not (a.flags.c_contiguous and a.flags.writeable):
        a = a.copy()
    return a if len(batch) == 1 else a.reshape((-1,) + tail)


def per_element(a, batch, n):
    """A transition matrix (n, n) or per-element (..., n, n) as (1 or B, n, n)."""
    a = np.asarray(a, dtype=float)
    if a.ndim == 2:
        return np.ascontiguousarray(a).reshape(1, n, n)
    return _flat(a, batch, (n, n))


def predict(belief: Belief, model, square_root: bool = False):
    """The compiled time update (same result as :func:`~shipsense.trackers.filters.core.predict`); None if an
    element failed (the caller then runs the numpy step)."""
    mean = np.asarray(belief.mean, dtype=float)
    n = mean.shape[-1]
    A = np.asarray(model.A, dtype=float)
    batch = _batch(mean.shape[:-1], A.shape[:-2])
    if square_root:
        src = belief.chol
        Q = np.asarray(model.Q, dtype=float)
        if Q.ndim == 2:
            sqQ = _shared_sqrt(n, np.ascontiguousarray(Q).tobytes())
        else:
            w, V = np.linalg.eigh(np.broadcast_to(Q, batch + (n, n)))
            sqQ = _flat(V * np.sqrt(np.clip(w, 0.0, None))[..., None, :], batch, (n, n))
        Qf = np.zeros((1, 1, 1))
    else:
        cached = getattr(belief, "_cov", None)
        src = cached if cached is not None else belief.chol @ np.swapaxes(belief.chol, -1, -2)
        Qf = per_element(model.Q, batch, n)
        sqQ = no_sqrt(n)
    X = _flat(mean, batch, (n,))
    B = X.shape[0]
    mean_out = np.empty((B, n))
    P_out = np.empty((B, n, n)) if not square_root else np.empty((1, n, n))
    L_out = np.zeros((B, n, n))
    ok = np.empty(B, dtype=bool)
    if not _split(predict_kernel, _PREDICT_ROWS, X, _flat(src, batch, (n, n)), per_element(A, batch, n), Qf, sqQ,
                  square_root, mean_out, P_out, L_out, ok):
        return None
    mean_out, L_out = _shaped(mean_out, batch), _shaped(L_out, batch)
    if square_root:
        return Belief(mean_out, L_out, _flag(belief.ok, batch))
    return BeliefWithCov.with_cov(mean_out, L_out, _flag(prior_health(belief), batch), _shaped(P_out, batch))


_FILTER_CODES = {"ukf": UKF, "ckf": UKF, "huber_ukf": HUBER, "cdkf": CDKF, "srcdkf": SRCDKF, "ekf": EKF,
                 "puekf": PUEKF}


def filter_code(name):
    """The compiled update kernel's code of filter ``name`` (the CKF runs the UKF's with its own points)."""
    try:
        return _FILTER_CODES[name]
    except KeyError:
        raise ValueError(f"no compiled update for filter {name!r}; offered: {', '.join(_FILTER_CODES)}") from None


def update(name, belief: Belief, y, model, spec, mask=None, **options):
    """The compiled measurement update of filter ``name`` (same result as its module's ``update``); None if an
    element failed numerically (the caller then runs the numpy step, which flags and repairs it)."""
    mean = np.asarray(belief.mean, dtype=float)
    y = np.asarray(y, dtype=float)
    n, m = mean.shape[-1], y.shape[-1]
    batch = (_batch(mean.shape[:-1], y.shape[:-1]) if mask is None
             else _batch(mean.shape[:-1], y.shape[:-1], np.shape(mask)[:-1]))
    consts = filter_constants(name, n, options)
    cov_form = consts[0] != SRCDKF
    P = belief.cov if cov_form else _NO_COV
    X = _flat(mean, batch, (n,))
    mask_f = _all_read(m) if mask is None else _flat(np.asarray(mask, dtype=bool), batch, (m,))
    L = belief.chol if consts[0] not in (EKF, PUEKF) else P   # the linearised filters do not read the factor
    out = _run_update(consts, X, _flat(L, batch, (n, n)), _flat(P, batch, (n, n)) if cov_form else _NO_COV,
                      _flat(y, batch, (m,)), mask_f, model, spec)
    if out is None:
        return None
    mean_out, P_out, L_out, inn = out
    inn = Innovation(*inn) if len(batch) == 1 else Innovation(*(_shaped(a, batch) for a in inn))
    mean_out, P_out = _shaped(mean_out, batch), _shaped(P_out, batch)
    if not cov_form:
        return Belief(mean_out, P_out, _flag(belief.ok, batch)), inn
    return BeliefWithCov.with_cov(mean_out, _shaped(L_out, batch), _flag(prior_health(belief), batch), P_out), inn


def _run_update(consts, X, L, P, y, mask, model, spec):
    """The update kernel of ``consts`` (:func:`filter_constants`) on flat (B, ...) arguments: ``(mean, P, L,
    (eps, S, loglik, nis, m))`` (B, ...), or None if an element failed."""
    filt, spread, center, Wm, Wc, h, gamma, iterations, n_pu = consts
    nb, n = X.shape
    m = y.shape[1]
    mean_out = np.empty((nb, n))
    P_out = np.empty((nb, n, n))
    L_out = np.zeros((nb, n, n)) if filt != SRCDKF else _NO_COV
    eps = np.empty((nb, m))
    S = np.empty((nb, m, m))
    loglik = np.empty(nb)
    nis = np.empty(nb)
    cnt = np.empty(nb, dtype=np.int64)
    ok = np.empty(nb, dtype=bool)
    if not _split(UPDATE_KERNELS[filt], _UPDATE_ROWS, X, L, P, y, mask, noise_variances(model), spec, spread, center,
                  Wm, Wc, h, gamma, iterations, n_pu, mean_out, P_out, L_out, eps, S, loglik, nis, cnt, ok):
        return None
    return mean_out, P_out, L_out, (eps, S, loglik, nis, cnt)


def filter_constants(name, n, options):
    """The update kernel's constants of filter ``name`` on ``n`` states with keyword ``options``: ``(code,
    spread, center, Wm, Wc, h, gamma, iterations, n_pu)`` (kept for the options' last few values)."""
    if not options:
        return _constants_of(name, n, ())
    items = tuple(sorted(options.items()))
    try:
        hash(items)
    except TypeError:    # an option value that is not hashable
        return _constants_of.__wrapped__(name, n, items)
    return _constants_of(name, n, items)


@lru_cache(maxsize=64)
def _constants_of(name, n, items):
    options = dict(items)
    spread, center, Wm, Wc = 1.0, 1, _NO_WEIGHTS, _NO_WEIGHTS
    h, gamma, iterations, n_pu = H_STIRLING, HUBER_GAMMA, 10, 1
    filt = filter_code(name)
    if name in ("ukf", "huber_ukf"):
        spread, Wm, Wc = _merwe(merwe_weights, n, options.get("alpha", 1.0), options.get("beta", 2.0),
                                options.get("kappa", 0.0))
        gamma = float(options.get("gamma", HUBER_GAMMA))
        iterations = int(options.get("iterations", 10))
    elif name == "ckf":
        center, spread = 0, float(np.sqrt(n))
        Wm = Wc = _ckf_weights(n)
    elif name in ("cdkf", "srcdkf"):
        h = float(options.get("h", H_STIRLING))
    elif name == "puekf":
        n_pu = int(options.get("n_pu", N_PU))
        if n_pu < 1:
            raise ValueError(f"n_pu must be >= 1, got {n_pu}")
    return filt, spread, center, Wm, Wc, h, gamma, iterations, n_pu


def noise_variances(model):
    """The model's measurement noise variances as a contiguous float array (no copy when they are one)."""
    return np.ascontiguousarray(model.R, dtype=float)


@lru_cache(maxsize=64)
def _all_read(m):
    """The mask of a step that reads every channel: one row, which the kernel uses for every element."""
    return np.ones((1, m), dtype=bool)


_NO_WEIGHTS = np.zeros(1)
_NO_COV = np.zeros((1, 1, 1))


@lru_cache(maxsize=64)
def no_sqrt(n):
    """The covariance-form predict's (empty) square root of Q, (1, n, 0)."""
    return np.zeros((1, n, 0))


@lru_cache(maxsize=64)
def _shared_sqrt(n, data):
    """The square root of a shared Q (the columns of :func:`sqrt_psd` that are not zero) as (1, n, k)."""
    sq = sqrt_psd(np.frombuffer(data, dtype=float).reshape(n, n))
    return np.ascontiguousarray(sq[:, np.abs(sq).max(axis=0) > 0]).reshape(1, n, -1)


@lru_cache(maxsize=64)
def _ckf_weights(n):
    return np.full(2 * n, 0.5 / n)


@lru_cache(maxsize=64)
def _merwe(weights, n, alpha, beta, kappa):
    """The unscented weights as writable arrays (a read-only array is another compiled signature)."""
    spread, Wm, Wc = weights(n, alpha, beta, kappa)
    return spread, Wm.copy(), Wc.copy()


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
