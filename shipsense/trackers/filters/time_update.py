"""The compiled time update shared by every filter unit: ``x = A x`` and ``P = A P A^T + Q`` (or, for the
square-root filter, the factor ``tria([A L, Q^(1/2)])``), one numba loop over the batch, each element with its own
or a shared transition (:mod:`~shipsense.trackers.filters.fused` and the tracker's compiled step call it).  The
numpy form, :func:`shipsense.trackers.filters.core.predict`, is the generic path of models without a compiled
measurement kernel and the reference this one is tested against.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from shipsense import numba_cache
from shipsense.models.measurement import loop_jit
from shipsense.trackers.linalg import cholesky_into, tria_into


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
            ok_out[b] = tria_into(M, L_out[b], Asc, vsc, nzs)
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
            ok_out[b] = cholesky_into(Pout, L_out[b])


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
