"""Small dense linear algebra for the compiled loops (numba, inlined): what LAPACK does for one small system,
without a call out of the loop -- solves by elimination (the fits, the grid search, the environments' gains)
and the filters' Cholesky factorisations, triangular solves and triangularisation (their kernels,
:mod:`~shipsense.trackers.filters.kernels`)."""

from __future__ import annotations

import math

from numba import njit

from shipsense import numba_cache


@njit(cache=True, error_model="numpy", inline="always")
def solve_many_in_place(M, X, n, c):
    """``X[:n, :c] <- M^-1 X[:n, :c]`` for the leading ``n x n`` block of ``M`` (overwritten) by Gaussian
    elimination with partial pivoting, as LAPACK's ``gesv``: one elimination for ``c`` right-hand sides, each
    column getting the operations it gets alone (the same numbers, whatever the other columns)."""
    for k in range(n):
        piv = k
        for i in range(k + 1, n):
            if abs(M[i, k]) > abs(M[piv, k]):
                piv = i
        if piv != k:
            for q in range(n):
                M[k, q], M[piv, q] = M[piv, q], M[k, q]
            for j in range(c):
                X[k, j], X[piv, j] = X[piv, j], X[k, j]
        for i in range(k + 1, n):
            f = M[i, k] / M[k, k]
            for q in range(k, n):
                M[i, q] -= f * M[k, q]
            for j in range(c):
                X[i, j] -= f * X[k, j]
    for k in range(n - 1, -1, -1):
        for j in range(c):
            t = X[k, j]
            for q in range(k + 1, n):
                t -= M[k, q] * X[q, j]
            X[k, j] = t / M[k, k]


@njit(cache=True, error_model="numpy", inline="always")
def matmul_into(A, B, out, rows, inner, cols):
    """``out[:rows, :cols] <- A[:rows, :inner] @ B[:inner, :cols]``, each entry summed in index order (the
    numbers of the loop written out; ``B`` may be a transposed view)."""
    for a in range(rows):
        for j in range(cols):
            t = 0.0
            for i in range(inner):
                t += A[a, i] * B[i, j]
            out[a, j] = t


@njit(cache=True, error_model="numpy", inline="always")
def solve_in_place(M, x, n):
    """``x <- M^-1 x`` for the leading ``n x n`` block by Gaussian elimination with partial pivoting (``M``
    overwritten), as LAPACK's ``gesv``: :func:`solve_many_in_place` of one column (``x`` contiguous)."""
    solve_many_in_place(M, x.reshape((x.shape[0], 1)), n, 1)


# -- the filters' small dense factorisations, one element at a time (inlined into their kernels) --------

@njit(cache=True, error_model="numpy", inline="always")
def cholesky_into(A, L):
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
def forward_into(L, b, out):
    """Solve ``L out = b`` (lower triangular) for a vector."""
    for i in range(L.shape[0]):
        t = b[i]
        for k in range(i):
            t -= L[i, k] * out[k]
        out[i] = t / L[i, i]


@njit(cache=True, error_model="numpy", inline="always")
def tria_into(M, S, A, v, nz):
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
def cho_solve_into(L, B, X):
    """Solve ``L L^T X = B`` (``L`` lower triangular (k, k), ``B`` and ``X`` (k, c)) column by column: forward
    substitution (:func:`forward_into`) then backward (:func:`backward_into`)."""
    for j in range(B.shape[1]):
        forward_into(L, B[:, j], X[:, j])
        backward_into(L, X[:, j])


@njit(cache=True, error_model="numpy", inline="always")
def whitened(Ls, eps, w):
    """``(eps^T S^-1 eps, log det S)`` from ``S = Ls Ls^T``; ``w`` gets ``Ls^-1 eps``."""
    forward_into(Ls, eps, w)
    nis = 0.0
    logdet = 0.0
    for i in range(Ls.shape[0]):
        nis += w[i] * w[i]
        logdet += 2.0 * math.log(Ls[i, i])
    return nis, logdet

@njit(cache=True, error_model="numpy", inline="always")
def backward_into(L, w):
    """Solve ``L^T out = w`` in place (``L`` lower triangular)."""
    for i in range(L.shape[0] - 1, -1, -1):
        t = w[i]
        for q in range(i + 1, L.shape[0]):
            t -= L[q, i] * w[q]
        w[i] = t / L[i, i]


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
