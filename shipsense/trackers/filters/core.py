"""Shared pieces of the filter units: beliefs, innovations, predict, masking, safe factorisation.

Every array has leading batch axes.  A belief is a mean (..., n), a lower
Cholesky factor (..., n, n) of its covariance and a flag (...) that turns
False, per batch element, once that element's covariance lost positive
definiteness or became non-finite (it is then repaired so that the rest of
the batch is unaffected).
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple

import numpy as np

LOG_2PI = float(np.log(2.0 * np.pi))


class Belief(NamedTuple):
    """Gaussian belief: mean (..., n), lower Cholesky factor (..., n, n), health flag (...).

    Filter steps may return a belief that also carries the covariance its
    factor came from (to save re-forming it).  Treat beliefs as immutable:
    after writing into their arrays in place, rebuild with ``Belief(*belief)``,
    which drops that cache.
    """

    mean: np.ndarray
    chol: np.ndarray
    ok: np.ndarray

    @property
    def cov(self) -> np.ndarray:
        """Covariance ``L L^T`` (..., n, n)."""
        cached = getattr(self, "_cov", None)   # set by predict on the covariance it factorised
        return cached if cached is not None else self.chol @ transposed(self.chol)

    @classmethod
    def from_cov(cls, mean, cov):
        """A belief from a mean and a covariance (factorised here)."""
        mean = np.asarray(mean, dtype=float)
        L, ok = safe_cholesky(np.broadcast_to(cov, mean.shape + mean.shape[-1:]))
        return cls(mean, L, ok)


class BeliefWithCov(Belief):
    """A :class:`Belief` that also keeps the covariance its factor was computed from.

    Returned by :func:`predict` (covariance form) and :func:`gain_update` so
    that the next step does not form ``L L^T`` again; it iterates, indexes
    and compares as a plain three-field :class:`Belief` (indexing drops the
    cache).
    """

    @classmethod
    def with_cov(cls, mean, chol, ok, cov):
        out = cls(mean, chol, ok)
        out._cov = cov
        return out

    def with_mean(self, mean):
        """The same covariance (and its cache) with another mean."""
        return type(self).with_cov(mean, self.chol, self.ok, self._cov)


class _Posterior(BeliefWithCov):
    """A belief after a gain update, whose factor is computed from its covariance on first use.

    The next time update forms ``A P A^T + Q`` from the covariance and
    factorises that, so a filter that only steps never needs this factor
    (one of the three Cholesky factorisations of a UKF step).  Reading
    ``chol`` or ``ok``, iterating, indexing or pickling factorises (once); an
    element whose covariance is then found not positive definite is flagged
    and repaired as by :func:`safe_cholesky` (its mean keeps the update, whose
    gain came from a valid innovation covariance).
    """

    @classmethod
    def pending(cls, mean, ok, cov):
        out = tuple.__new__(cls, (mean, None, ok))
        out._cov = cov
        return out

    def _factor(self):
        f = self.__dict__.get("_f")
        if f is None:
            chol, health = tuple.__getitem__(self, 1), tuple.__getitem__(self, 2)
            if chol is None:
                L, ok = safe_cholesky(self._cov)
                f = (L, health & ok)
            else:   # built from three fields (e.g. unpickled)
                f = (chol, health)
            self._f = f
        return f

    chol = property(lambda self: self._factor()[0])
    ok = property(lambda self: self._factor()[1])

    def __iter__(self):
        return iter((self.mean, self.chol, self.ok))

    def __getitem__(self, i):
        return tuple(self)[i]

    def __getnewargs__(self):
        return tuple(self)

    def with_mean(self, mean):
        if "_f" in self.__dict__:
            return BeliefWithCov.with_cov(mean, self.chol, self.ok, self._cov)
        return _Posterior.pending(mean, tuple.__getitem__(self, 2), self._cov)


def prior_health(belief):
    """The health flag a belief carries without factorising a pending posterior (see :class:`_Posterior`)."""
    return tuple.__getitem__(belief, 2)


class Innovation(NamedTuple):
    """What an update saw: innovation ``eps`` (..., m), its covariance ``S`` (..., m, m),
    the log-likelihood ``ln N(eps; 0, S)`` over the present components (...), the
    normalised innovation squared ``eps^T S^-1 eps`` (...) and the number of present
    components (...).  Masked components have ``eps = 0`` and unit, uncoupled rows in ``S``.
    ``R`` (..., m): the noise variances on ``S``'s diagonal where a filter reweights them (the Huber UKF);
    None when they are the model's."""

    eps: np.ndarray
    S: np.ndarray
    loglik: np.ndarray
    nis: np.ndarray
    m: np.ndarray
    R: np.ndarray | None = None


def transposed(a):
    """``a^T`` over the last two axes as a contiguous array.

    ``np.matmul`` on a batch of small matrices is several times slower when an
    operand is a transposed view than copying first.
    """
    return np.ascontiguousarray(np.swapaxes(a, -1, -2))


def symmetrize(P):
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def tria(M):
    """Lower-triangular ``S`` with ``S S^T = M M^T`` for M (..., n, k), k >= n, by QR (no covariance formed)."""
    r = np.linalg.qr(np.swapaxes(M, -1, -2), mode="r")
    S = np.swapaxes(r, -1, -2)
    d = np.sign(np.diagonal(S, axis1=-2, axis2=-1))
    return S * np.where(d == 0, 1.0, d)[..., None, :]


def safe_cholesky(P):
    """Batched Cholesky factor of symmetric P with per-element failure handling.

    Returns ``(L, ok)``.  Only the lower triangle is read (LAPACK ``potrf``).
    Elements that are non-finite or not positive definite are flagged
    ``ok = False`` and repaired (non-finite ones replaced by the identity,
    indefinite ones by clipping eigenvalues to a small positive floor) so
    that one bad element never stops the batch -- nor changes the other
    elements' factors: below the unrolled form's batch, every element gets
    the factor it would get alone (:func:`_factor_or_repair`).
    """
    P = np.asarray(P, dtype=float)
    n = P.shape[-1]
    if n <= _UNROLL_MAX_N and P.size >= UNROLL_MIN_BATCH * n ** 2:
        with np.errstate(invalid="ignore", divide="ignore"):
            L = _cholesky_unrolled(P)
        if np.isfinite(L).all():
            return L, np.ones(L.shape[:-2], dtype=bool)
        return _repair(P)
    L, ok = _factor_or_repair(P.reshape(-1, n, n))
    return L.reshape(P.shape), ok.reshape(P.shape[:-2])


def _lapack(P):
    """LAPACK's factors of the stack ``P`` (B, n, n), or None if one of them fails (indefinite or NaN)."""
    try:
        L = np.linalg.cholesky(P)  # raises on an indefinite element; NaN propagates to the diagonal
    except np.linalg.LinAlgError:
        return None
    n = L.shape[-1]
    return L if math.isfinite(L.reshape(-1, n * n)[:, ::n + 1].sum()) else None   # the diagonals' sum: finite
    # iff all are


def _factor_or_repair(P):
    """:func:`safe_cholesky` of a stack ``P`` (B, n, n): LAPACK's factor of every element it factorises, the
    stack halved around the elements it does not (a few calls per bad element), which :func:`_repair`
    repairs one by one."""
    L = _lapack(P)
    if L is not None:
        return L, np.ones(len(P), dtype=bool)
    if len(P) == 1:
        return _repair(P)
    halves = [_factor_or_repair(part) for part in (P[:len(P) // 2], P[len(P) // 2:])]
    return tuple(np.concatenate(a) for a in zip(*halves))


def _repair(P):
    """The factors and flags of elements of ``P`` that LAPACK does not factorise (or of a batch the unrolled
    form failed on): non-finite elements replaced by the identity, eigenvalues clipped to ``1e-12`` of the
    largest (flagged), then factorised."""
    P = symmetrize(P)
    n = P.shape[-1]
    finite = np.isfinite(P).all(axis=(-1, -2))
    P = np.where(finite[..., None, None], P, np.eye(n))
    w, V = np.linalg.eigh(P)
    scale = np.maximum(np.abs(w).max(axis=-1, keepdims=True), 1e-300)
    floor = 1e-12 * scale
    bad = (w <= floor).any(axis=-1)
    w = np.maximum(w, floor)
    P = (V * w[..., None, :]) @ np.swapaxes(V, -1, -2)
    return np.linalg.cholesky(symmetrize(P)), finite & ~bad


_UNROLL_MAX_N = 10
UNROLL_MIN_BATCH = 512


def _cholesky_unrolled(P):
    """Cholesky factor of many small matrices, vectorised over the batch.

    LAPACK's ``potrf`` is called once per matrix by ``np.linalg.cholesky``;
    for thousands of 7x7 matrices that per-call cost dominates.  Here the
    entries are computed by the Cholesky-Banachiewicz recursion in a
    workspace with the batch on the last (contiguous) axis, each entry one
    vector operation over the whole batch (faster than LAPACK for the small
    n of the trackers' states at batches of thousands; slower for small
    batches, hence the threshold in :func:`safe_cholesky`).  Reads the lower triangle
    only; an indefinite element gets NaN entries (its caller flags and
    repairs it).
    """
    n = P.shape[-1]
    batch = P.shape[:-2]
    A = np.moveaxis(P.reshape(-1, n, n), 0, -1)          # (n, n, B) view
    L = np.zeros(A.shape)
    for j in range(n):
        d = A[j, j] - (L[j, :j] ** 2).sum(axis=0) if j else A[j, j]
        ljj = np.sqrt(d)
        L[j, j] = ljj
        if j < n - 1:
            col = A[j + 1:, j] - (L[j + 1:, :j] * L[j, :j]).sum(axis=1) if j else A[j + 1:, j]
            np.divide(col, ljj, out=L[j + 1:, j])
    return L.reshape(n * n, -1).T.copy().reshape(batch + (n, n))


def predict(belief: Belief, model, square_root: bool = False) -> Belief:
    """Time update of the linear motion model, ``x = A x``, ``P = A P A^T + Q``.

    Every filter unit shares it: for a linear transition the unscented,
    cubature and central-difference predictions equal this one exactly.
    With ``square_root`` the factor is propagated as ``tria([A L, Q^(1/2)])``
    (QR, no covariance formed; the SR-CDKF's form); otherwise the covariance
    is formed and factorised (cheaper for small states).  ``model.A`` and
    ``model.Q`` are (n, n), or (..., n, n) per batch element (irregular
    sampling: :meth:`~shipsense.models.field_model.FieldModel.stepped`).
    """
    A = model.A
    if A.ndim > 2:
        return _predict_batched(belief, A, model.Q, square_root)
    mean = belief.mean @ A.T
    cached = getattr(belief, "_cov", None)
    if cached is not None and not square_root:   # A P A^T + Q from the covariance the update formed
        P = _transition(A, cached, both_sides=True)
        P += model.Q
        chol, ok = safe_cholesky(P)
        health = prior_health(belief)
        if ok.all():
            return BeliefWithCov.with_cov(mean, chol, health, P)
        return Belief(mean, chol, health & ok)
    AL = _transition(A, belief.chol)
    if square_root:
        sq = sqrt_psd(model.Q)
        sq = sq[:, np.abs(sq).max(axis=0) > 0]   # a rank-deficient Q (e.g. DWNA) needs fewer columns
        chol = tria(np.concatenate([AL, np.broadcast_to(sq, AL.shape[:-2] + sq.shape)], axis=-1))
        ok = np.isfinite(chol).all(axis=(-1, -2))
    else:
        P = AL @ transposed(AL)
        P += model.Q
        chol, ok = safe_cholesky(P)
        if ok.all():
            return BeliefWithCov.with_cov(mean, chol, belief.ok, P)
    return Belief(mean, chol, belief.ok & ok)


def _predict_batched(belief, A, Q, square_root):
    """:func:`predict` with a transition ``A`` and noise ``Q`` per batch element (..., n, n)."""
    mean = np.einsum("...ij,...j->...i", A, belief.mean)
    AL = A @ belief.chol
    if square_root:
        w, V = np.linalg.eigh(np.broadcast_to(Q, AL.shape))
        chol = tria(np.concatenate([AL, V * np.sqrt(np.clip(w, 0.0, None))[..., None, :]], axis=-1))
        ok = np.isfinite(chol).all(axis=(-1, -2))
        return Belief(mean, chol, belief.ok & ok)
    P = AL @ transposed(AL) + Q
    chol, ok = safe_cholesky(P)
    if ok.all():
        return BeliefWithCov.with_cov(mean, chol, belief.ok, P)
    return Belief(mean, chol, belief.ok & ok)


def _transition(A, M, both_sides=False):
    """``A M`` (or ``A M A^T`` with ``both_sides``) for M (..., n, k), by row and column operations.

    Used when ``A`` is the identity plus a few entries whose rows are not
    also their sources (the constant-velocity transition: two entries); a
    batched matmul of thousands of small matrices costs several times more.
    Falls back to matmul otherwise.
    """
    plan = _transition_plan(A.shape[0], np.ascontiguousarray(A, dtype=float).tobytes())
    if plan is None or M.size < UNROLL_MIN_BATCH * A.shape[0]:   # small: one matmul call is cheaper
        out = A @ M
        return out @ A.T if both_sides else out
    out = M.copy()
    for i, j, v in plan:
        out[..., i, :] += v * out[..., j, :]
    if both_sides:
        for i, j, v in plan:
            out[..., :, i] += v * out[..., :, j]
    return out


@lru_cache(maxsize=64)
def _transition_plan(n, data):
    """Off-diagonal entries ``(i, j, value)`` of ``A - I`` if row operations can apply it, else None."""
    off = np.frombuffer(data, dtype=float).reshape(n, n) - np.eye(n)
    nz = np.argwhere(off != 0)
    if len(nz) > n or set(nz[:, 0]) & set(nz[:, 1]):
        return None
    return tuple((int(i), int(j), float(off[i, j])) for i, j in nz)


def sqrt_psd(Q):
    """A square root of a PSD matrix (Cholesky, or eigen for singular Q)."""
    try:
        return np.linalg.cholesky(Q)
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(Q)
        return V * np.sqrt(np.clip(w, 0.0, None))


def prepare(y, model, mask):
    """Measurement, effective mask and masked noise variances for an update.

    Missing components are those with ``mask`` False or a non-finite ``y``.
    Returns ``(y, present, R)`` where ``y`` is zero and ``R`` is one at
    missing components (so that they contribute exactly nothing).
    """
    y = np.asarray(y, dtype=float)
    present = np.isfinite(y)
    if mask is not None:
        present = present & np.asarray(mask, dtype=bool)
    y = np.where(present, y, 0.0)
    R = np.where(present, model.R, 1.0)
    return y, present, R


def add_noise(M, R):
    """``M + diag(R)`` for M (..., m, m) and variances R (..., m); M is consumed (its diagonal is updated in
    place when it has R's batch shape and owns its memory)."""
    m = M.shape[-1]
    if M.shape[:-1] != R.shape or not (M.flags.c_contiguous and M.flags.owndata and M.flags.writeable):
        return M + R[..., :, None] * np.eye(m)
    M.reshape(M.shape[:-2] + (m * m,))[..., ::m + 1] += R
    return M


def gain_update(belief: Belief, eps, Pxy, S, present, P=None):
    """Kalman update from an innovation ``eps`` (..., m), cross-covariance ``Pxy`` (..., n, m) and ``S``.

    ``x+ = x + K eps``, ``P+ = P - K S K^T`` with ``K = Pxy S^-1``; the new
    covariance is factorised with :func:`safe_cholesky` when its factor is
    first needed (:class:`_Posterior`).  With ``S = Ls Ls^T``
    and ``[W | w] = Ls^-1 [Pxy^T | eps]`` (one forward substitution) this is
    ``x+ = x + W^T w``, ``P+ = P - W^T W`` and ``eps^T S^-1 eps = |w|^2``.
    Small batches solve with ``S`` by one LAPACK call instead (a Python loop
    of row operations costs more there; above it, one LAPACK call per matrix
    costs more).
    """
    Ls, ok_s = safe_cholesky(S)
    if P is None:
        P = belief.cov
    n = Pxy.shape[-2]
    batch = S.shape[:-2]
    if Pxy.shape[:-2] != batch or eps.shape[:-1] != batch:
        batch = np.broadcast_shapes(batch, Pxy.shape[:-2], eps.shape[:-1])
    PyxT = np.swapaxes(Pxy, -1, -2)
    if PyxT.shape[:-2] != batch or eps.shape[:-1] != batch:
        PyxT = np.broadcast_to(PyxT, batch + PyxT.shape[-2:])
        eps = np.broadcast_to(eps, batch + eps.shape[-1:])
    rhs = np.concatenate([PyxT, eps[..., None]], axis=-1)
    if math.prod(batch) <= _LAPACK_SOLVE_MAX_BATCH and ok_s.all():
        X = np.linalg.solve(S if S.shape[:-2] == batch else np.broadcast_to(S, batch + S.shape[-2:]), rhs)
        mean = belief.mean + np.einsum("...mn,...m->...n", X[..., :n], eps)
        P = P - transposed(X[..., :n]) @ rhs[..., :n]
        nis = np.sum(eps * X[..., n], axis=-1)
    else:
        Z = solve_lower(Ls, rhs)                                                 # [W | w]
        W = Z[..., :n]
        mean = belief.mean + np.einsum("...mn,...m->...n", W, Z[..., n])
        P = P - transposed(W) @ np.ascontiguousarray(W)
        nis = np.sum(Z[..., n] ** 2, axis=-1)
    inn = innovation(eps, S, Ls, present, nis)
    if ok_s.all():   # the factor of P+ is computed when first needed (a time update does not need it)
        return _Posterior.pending(mean, prior_health(belief), P), inn
    L, ok = safe_cholesky(P)
    ok = ok & ok_s
    mean = np.where(ok[..., None], mean, np.nan_to_num(belief.mean))   # a failed element keeps its prior mean
    return Belief(mean, L, belief.ok & ok), inn


_LAPACK_SOLVE_MAX_BATCH = 64
"""Batches up to this size solve with LAPACK (one call); larger ones by row-loop substitution."""


def innovation(eps, S, Ls, present, nis=None) -> Innovation:
    """Innovation record with ``ln L = -1/2 (m ln 2 pi + ln det S + eps^T S^-1 eps)``.

    ``nis`` (``eps^T S^-1 eps``) is computed from ``Ls`` unless given.
    """
    if nis is None:
        w = solve_lower(Ls, eps[..., None])[..., 0]
        nis = np.sum(w * w, axis=-1)
    m = present.sum(axis=-1)
    logdet = 2.0 * np.sum(np.log(np.diagonal(Ls, axis1=-2, axis2=-1)), axis=-1)
    return Innovation(eps, S, -0.5 * (m * LOG_2PI + logdet + nis), nis, m)


def solve_lower(L, B):
    """Solve ``L X = B`` for lower-triangular L (..., k, k), B (..., k, c) by forward substitution.

    A loop over the k rows (k is a state or measurement dimension, <= ~20) of
    batched row operations: much faster than a batched LU for small k.
    """
    shape = np.broadcast_shapes(L.shape[:-2], B.shape[:-2]) + B.shape[-2:]
    X = np.empty(shape, dtype=np.result_type(L, B))
    for i in range(B.shape[-2]):
        acc = B[..., i, :]
        if i:
            acc = acc - (L[..., i:i + 1, :i] @ X[..., :i, :])[..., 0, :]
        X[..., i, :] = acc / L[..., i, i, None]
    return X


def solve_upper_t(L, B):
    """Solve ``L^T X = B`` for lower-triangular L by back substitution."""
    shape = np.broadcast_shapes(L.shape[:-2], B.shape[:-2]) + B.shape[-2:]
    X = np.empty(shape, dtype=np.result_type(L, B))
    k = B.shape[-2]
    for i in range(k - 1, -1, -1):
        acc = B[..., i, :]
        if i < k - 1:
            acc = acc - (np.swapaxes(L[..., i + 1:, i:i + 1], -1, -2) @ X[..., i + 1:, :])[..., 0, :]
        X[..., i, :] = acc / L[..., i, i, None]
    return X


def chol_solve(L, B):
    """Solve ``(L L^T) X = B`` for X, batched."""
    return solve_upper_t(L, solve_lower(L, B))
