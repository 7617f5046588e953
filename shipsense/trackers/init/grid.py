"""The grid search of the global initialiser: the moment eliminated for every candidate passage.

The fields are linear in the moment (and in ``p``), so for every candidate
trajectory of a grid (start range and bearing from the array centroid,
course, speed) the best moment is a closed-form least-squares solve:
:func:`linear_basis` gives each candidate's offset and basis, :func:`grid_terms`
keeps them whitened and window-major (cached per grid; both in
:mod:`shipsense.trackers.init.grid_basis`, with :func:`candidate_grid`), :func:`grid_fit`
eliminates the moment for every passage and candidate, and
:func:`grid_minima` returns the best distinct candidates.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from shipsense import numba_cache
from shipsense.models.measurement import wrap_angle
from shipsense.trackers.fit.least_squares import FIT_CHUNK_BYTES
from shipsense.trackers.init.distinct import distinct_rows
from shipsense.trackers.init.grid_basis import (
    candidate_grid,
    grid_terms,
    kept_inverses,
    linear_basis,
    parameter_slots,
    ridge_inverses,
)
from shipsense.trackers.linalg import solve_in_place


def grid_fit(model, yw, G, off, A, clamp):
    """Moment-eliminated chi-square (R, C) and moments (R, C, P) of every candidate of :func:`grid_terms`
    ``(G, off, A)`` for windows ``yw`` (R, W', m) (internal units, NaN = missing).

    Per passage and candidate: the least-squares parameters of the whitened field-channel basis against
    the whitened field samples present (a ``1e-9`` ridge; the last parameter clamped at 0 if ``clamp``),
    and the chi-square of the fit plus the whitened bearing residuals (wrapped modulo pi against the
    candidate's bearings).  The field channels' ``G^T d`` of every candidate is :func:`_project` (``d`` zero
    where missing; a passage's numbers do not depend on its batch; the columns in chunks on the CPUs); the
    normal matrix is the window's Gram matrix ``A`` -- with every sample present, solved through its ridge
    inverses (:func:`ridge_inverses`, kept with :func:`grid_terms`' Gram matrices: a 3 x 3 product per
    candidate, not an elimination) -- less the outer products of the missing samples (or built from the
    present ones when fewer; compiled, :func:`grid_solve_kernel`, the candidates in chunks on the CPUs); the
    chi-square is ``|d|^2 - 2 par.b + par^T A par``.  Passages in chunks bound the
    (passages, C*P) temporaries.
    """
    from shipsense.parallel import in_chunks

    R, Wn, _ = yw.shape
    C, P = A.shape[0], A.shape[-1]
    if not (Wn == G.shape[0] == off.shape[0]):
        raise ValueError(f"the windows have {Wn} samples but the grid terms {G.shape[0]}")
    field, bearing = ~model.axial, model.axial
    if G.shape[1] != field.sum() or off.shape[1] != bearing.sum() or G.shape[2] != C * P:
        raise ValueError(f"grid terms of {G.shape[1]} field and {off.shape[1]} bearing channels for {C} "
                         f"candidates do not fit this model ({field.sum()} and {bearing.sum()})")
    inverses = kept_inverses(A)
    std = np.sqrt(model.R)
    yf = yw[:, :, field] / std[field]
    present = np.isfinite(yf).reshape(R, -1)
    d = np.where(present, yf.reshape(R, -1), 0.0)
    dd = np.einsum("rk,rk->r", d, d)
    yb = np.ascontiguousarray(yw[:, :, bearing], dtype=float)
    std_b = np.ascontiguousarray(std[bearing])
    G2 = G.reshape(G.shape[0] * G.shape[1], C * P)
    chi2, params = np.empty((R, C)), np.empty((R, C, P))
    rows = max(1, FIT_CHUNK_BYTES // (8 * C * max(P, 1)))
    buf = np.empty((min(R, rows), C * P))
    for lo in range(0, R, rows):
        hi = min(R, lo + rows)
        b = buf[:hi - lo]
        dr = np.ascontiguousarray(d[lo:hi])
        in_chunks(lambda j_lo, j_hi, dr=dr, b=b: _project(dr, G2, b, j_lo, j_hi), C * P, split_min=4096)
        args = (b, G2, A, inverses, present[lo:hi], dd[lo:hi], yb[lo:hi], off, std_b, bool(clamp), chi2[lo:hi],
                params[lo:hi])
        in_chunks(lambda c_lo, c_hi, args=args: grid_solve_kernel(*args, c_lo, c_hi), C, split_min=256)
    return chi2, params


_PROJECT_TILE = 256
"""Columns of ``G`` a :func:`_project` pass keeps in its sums (four passages' sums: 8 KB, in L1)."""


@njit(cache=True, error_model="numpy", nogil=True)
def _project(d, G, out, j_lo, j_hi):
    """``out[r, j] = sum_k d[r, k] G[k, j]`` for the columns ``j_lo:j_hi`` (passages ``d`` (R, K), a grid's
    whitened basis ``G`` (K, C*P)).

    Every sum runs over ``k`` in ascending order from 0.0, whatever the passage's neighbours, its place in
    a block or the column split: a passage's numbers do not depend on its batch (numpy's ``d @ G`` does, a
    little, through BLAS's choice of kernel by shape; a stack of one-row products does not, but reads all of
    ``G`` once per passage and, when other processes hold the CPUs, BLAS's threads wait on each other).
    ``G`` is read row by row, a tile of ``_PROJECT_TILE`` columns at a time, into the sums of four passages
    at once (each load of ``G`` serves four); the sums are local arrays, so the compiler vectorises the
    loop over columns (it cannot when the sums are ``out``'s, which might alias ``G``).  A sample that is zero
    (missing) in every passage of a block is skipped: its terms are zeros (of either sign), and a sum that
    starts at +0.0 is never -0.0, so adding them changes no sum.
    """
    R, K = d.shape
    T = _PROJECT_TILE
    s0, s1, s2, s3 = np.empty(T), np.empty(T), np.empty(T), np.empty(T)
    for t0 in range(j_lo, j_hi, T):
        t1 = min(t0 + T, j_hi)
        w = t1 - t0
        r = 0
        while r + 4 <= R:
            for j in range(w):
                s0[j] = s1[j] = s2[j] = s3[j] = 0.0
            for k in range(K):
                a0, a1, a2, a3 = d[r, k], d[r + 1, k], d[r + 2, k], d[r + 3, k]
                if a0 == 0.0 and a1 == 0.0 and a2 == 0.0 and a3 == 0.0:
                    continue                    # (missing everywhere: adds zeros)
                g = G[k, t0:t1]
                for j in range(w):
                    gj = g[j]
                    s0[j] += a0 * gj
                    s1[j] += a1 * gj
                    s2[j] += a2 * gj
                    s3[j] += a3 * gj
            for j in range(w):
                out[r, t0 + j], out[r + 1, t0 + j], out[r + 2, t0 + j], out[r + 3, t0 + j] = s0[j], s1[j], s2[j], s3[j]
            r += 4
        while r < R:                            # the last passages, one at a time: the same sums
            for j in range(w):
                s0[j] = 0.0
            for k in range(K):
                a = d[r, k]
                if a == 0.0:
                    continue
                g = G[k, t0:t1]
                for j in range(w):
                    s0[j] += a * g[j]
            for j in range(w):
                out[r, t0 + j] = s0[j]
            r += 1


@njit(cache=True, error_model="numpy", nogil=True)
def grid_solve_kernel(b, G, A_all, inverses, present, dd, yb, off, std_b, clamp, chi2, params, c_lo, c_hi):
    """:func:`grid_fit` for candidates ``c_lo:c_hi``: per passage, the parameters from the normal equations
    with a ``1e-9`` ridge -- with every sample present the Gram matrix ``A_all``'s, through its ridge
    ``inverses`` (:func:`ridge_inverses`), else ``A_all`` less the missing samples' outer products (or the
    present samples' when fewer) solved by Gaussian elimination with partial pivoting
    (:func:`~shipsense.trackers.linalg.solve_in_place`) --, the clamp, and the chi-square from the
    normal equations plus the bearings' wrapped residuals."""
    R, K = present.shape
    P = A_all.shape[1]
    W, nb = yb.shape[1], yb.shape[2]
    A3 = np.empty((1, P, P))                    # (3-D, read by _grid_chi2 as it reads A_all)
    A = A3[0]
    M = np.empty((P, P))
    x = np.empty(P)
    idx = np.empty(K, dtype=np.int64)
    bear = np.empty(c_hi - c_lo)
    sums = np.empty((c_hi - c_lo, P, P))        # the candidates' normal matrices (lower triangles)
    for r in range(R):
        missing = 0
        for k in range(K):
            if not present[r, k]:
                missing += 1
        from_present = 2 * missing > K          # fewer present than missing: sum the present samples
        count = 0
        for k in range(K):
            if present[r, k] == from_present:
                idx[count] = k
                count += 1
        sign = 1.0 if from_present else -1.0
        for c in range(c_lo, c_hi):             # the bearings' whitened wrapped residuals
            bear[c - c_lo] = 0.0
        for w in range(W):
            for j in range(nb):
                y = yb[r, w, j]
                if not math.isfinite(y):
                    continue
                for c in range(c_lo, c_hi):
                    e = y - off[w, j, c]
                    e = wrap_angle(e) / std_b[j]
                    bear[c - c_lo] += e * e
        if count == 0 and not from_present:         # every sample present: the window's Gram matrix
            _grid_full(b, A_all, inverses, dd[r], bear, clamp, chi2, params, r, c_lo, c_hi)
            continue
        for c in range(c_lo, c_hi):
            for p in range(P):
                for q in range(p + 1):
                    sums[c - c_lo, p, q] = 0.0 if from_present else A_all[c, p, q]
        for i in range(count):                  # a sample's row of G for every candidate: read in order
            k = idx[i]
            for c in range(c_lo, c_hi):
                base = c * P
                for p in range(P):
                    g = sign * G[k, base + p]
                    for q in range(p + 1):
                        sums[c - c_lo, p, q] += g * G[k, base + q]
        for c in range(c_lo, c_hi):
            base = c * P
            for p in range(P):
                for q in range(p + 1):
                    A[p, q] = sums[c - c_lo, p, q]
                    A[q, p] = A[p, q]
            for p in range(P):
                x[p] = b[r, base + p]
                for q in range(P):
                    M[p, q] = A[p, q]
                M[p, p] += 1e-9
            solve_in_place(M, x, P)
            _grid_chi2(x, A3, 0, b, r, base, P, dd[r], bear[c - c_lo], clamp, chi2, params, c)


@njit(cache=True, error_model="numpy", nogil=True)
def _grid_full(b, A_all, inverses, dd, bear, clamp, chi2, params, r, c_lo, c_hi):
    """:func:`grid_solve_kernel` of passage ``r`` with every sample present: the parameters from the ridge
    ``inverses`` of the window's Gram matrices ``A_all``."""
    P = A_all.shape[1]
    x = np.empty(P)
    for c in range(c_lo, c_hi):
        base = c * P
        for p in range(P):
            acc = 0.0
            for q in range(P):
                acc += inverses[c, p, q] * b[r, base + q]
            x[p] = acc
        _grid_chi2(x, A_all, c, b, r, base, P, dd, bear[c - c_lo], clamp, chi2, params, c)


@njit(cache=True, error_model="numpy", nogil=True)
def _grid_chi2(x, A, i, b, r, base, P, dd, bear, clamp, chi2, params, c):
    """The clamp of parameters ``x``, then passage ``r``'s chi-square ``|d|^2 - 2 x.b + x^T A[i] x`` plus its
    bearings' ``bear`` and parameters for candidate ``c``.  (``A`` is 3-D and indexed here, not a view ``A[i]``
    made per candidate: with such a view, and this helper inlined, the loop over the candidates was slower.)"""
    if clamp and P > 0 and x[P - 1] < 0.0:
        x[P - 1] = 0.0
    s = dd
    for p in range(P):
        s -= 2.0 * x[p] * b[r, base + p]
        for q in range(P):
            s += x[p] * A[i, p, q] * x[q]
    chi2[r, c] = max(s, 0.0) + bear
    for p in range(P):
        params[r, c, p] = x[p]


def grid_minima(model, yw, grid, window, stride, count, distinct_m, mid, reserve=0):
    """The ``count`` best distinct grid candidates of each passage (R, count, n), best first, with their
    least-squares moments (:func:`grid_fit`): a candidate more than ``distinct_m`` from every better pick at
    the window's middle (``mid`` (2, n): the state's position there), the best repeated when fewer are
    distinct (:func:`distinct_rows`).

    ``yw`` (R, W', m) are the window's samples at steps ``0, stride, ...`` (internal units, NaN = missing);
    the grid's candidate trajectories are evaluated on the same steps (:func:`grid_terms`).  The grid's
    chi-square and moments (C and C x P per passage) exist for a chunk of passages at a time.
    """
    slots = parameter_slots(model)
    G, off, A = grid_terms(model, grid, window, stride, reserve)
    clamp = "p" in model.labels                                   # the envelope needs p >= 0
    R, C, P = yw.shape[0], len(grid), A.shape[-1]
    mid_grid = (grid @ mid.T)[None]                                                      # (1, C, 2)
    starts = np.zeros((R, count, model.n))
    rows = max(1, FIT_CHUNK_BYTES // (8 * C * (P + 1)))
    for lo in range(0, R, rows):
        chi2, params = grid_fit(model, yw[lo:lo + rows], G, off, A, clamp)
        chosen, _ = distinct_rows(chi2, mid_grid, count, distinct_m)                   # (rows, count)
        part = starts[lo:lo + rows]
        part[:] = grid[chosen]
        part[..., slots] = np.take_along_axis(params, chosen[..., None], axis=1)
    return starts


__all__ = ["candidate_grid", "grid_fit", "grid_minima", "grid_solve_kernel", "grid_terms", "linear_basis",
           "ridge_inverses"]


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
