"""Small dense linear algebra for the compiled loops (numba, inlined): what LAPACK does for one small system,
without a call out of the loop."""

from __future__ import annotations

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
def solve_in_place(M, x, n):
    """``x <- M^-1 x`` for the leading ``n x n`` block by Gaussian elimination with partial pivoting (``M``
    overwritten), as LAPACK's ``gesv``: :func:`solve_many_in_place` of one column (``x`` contiguous)."""
    solve_many_in_place(M, x.reshape((x.shape[0], 1)), n, 1)


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
