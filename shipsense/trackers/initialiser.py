"""The global initialiser: where is the passage, with no prior on its position (beyond the source studies).

The fields are linear in the moment (and in ``p``), so for every candidate
trajectory of a grid (start range and bearing from the array centroid,
course, speed) the best moment is a closed-form least-squares solve
(:func:`linear_basis`, :func:`grid_minima`); the best distinct grid minima are refined by batched
Levenberg-Marquardt fits (:func:`~shipsense.trackers.batchfit.fit_passages`)
over a window that starts at the detection (:func:`detection_start`), and
checked by a chi-square goodness-of-fit test (:func:`chi2_limit`).
:func:`global_init` returns the fits as the hypotheses of a bank
(:class:`GlobalInit`).
"""

from __future__ import annotations

import math
import os
import threading
import weakref
from dataclasses import dataclass

import numpy as np
from numba import njit

from shipsense import numba_cache
from shipsense.trackers.batchfit import FIT_CHUNK_BYTES, fit_passages, powers, shared_powers
from shipsense.trackers.compiled_linalg import solve_in_place
from shipsense.trackers.measurement import _wrap


@dataclass(frozen=True)
class GlobalInit:
    """Hypotheses from :func:`global_init` for R passages (SI units).

    Attributes
    ----------
    start : ndarray of int, shape (R,)
        First sample the bank processes (after the fitted window).
    seeds : ndarray, shape (R, M, n)
        Means at ``start`` (the batch fits propagated to it).
    P0 : ndarray, shape (R, M, n, n)
        Their covariances (batch-fit covariance propagated, plus the process noise).
    loglik : ndarray, shape (R, M)
        ``-chi2 / 2`` of each batch fit: the bank's prior log-likelihoods.
    window : ndarray, shape (R, M, W, n)
        The fitted trajectories over the window (estimates before ``start``).
    k0 : ndarray of int, shape (R,)
        First sample of the window (the detection).
    fit_ok : ndarray of bool, shape (R,), optional
        Whether the passage's best fit passes the chi-square goodness-of-fit
        test (:func:`global_init`'s ``gof``); a failed passage is still seeded
        from its best fit.
    """

    start: np.ndarray
    seeds: np.ndarray
    P0: np.ndarray
    loglik: np.ndarray
    window: np.ndarray
    k0: np.ndarray
    fit_ok: np.ndarray | None = None


def _parameter_slots(model):
    labels = model.labels
    slots = [labels.index(c) for c in ("mx", "my", "mz", "p") if c in labels]
    # |E| of an electrode is p |E(p = 1)| (linear in p >= 0, like the envelope); |B| is not linear in the moment
    if any(k == "magnitude" and t == "magnetometer" for t, k in zip(model.array.types, model.array.kinds)):
        raise ValueError("the global initialiser needs measurements linear in the moment (not magnetometer "
                         "'magnitude')")
    return slots


def candidate_grid(model, ranges, bearings_deg, courses_deg, speeds, source_z=None):
    """Candidate initial states (C, n) (internal units, parameters zero) around the array centroid.

    Read-only (a view that cannot be made writeable) and shared: the last few grids are kept, so a tracker
    asking for its grid at every window gets the same array back, whose terms :func:`grid_terms` then finds
    without hashing it."""
    args = tuple(np.asarray(a, dtype=float) for a in (ranges, bearings_deg, courses_deg, speeds))
    z = None if source_z is None else float(source_z)
    key = (id(model), *((a.shape, a.tobytes()) for a in args), z)
    with _CACHE_LOCK:
        hit = _GRID_CACHE.pop(key, None)
        if hit is None or hit[0] is not model:
            hit = (model, _candidate_grid(model, *args, z))
            _MADE[id(hit[1])] = hit[1]
            if len(_GRID_CACHE) >= _TERMS_CACHE_SIZE:
                _GRID_CACHE.pop(next(iter(_GRID_CACHE)))
        _GRID_CACHE[key] = hit                       # the most recently used last
    return hit[1]


def _candidate_grid(model, ranges, bearings_deg, courses_deg, speeds, source_z):
    centre = model.array.positions[:, :2].mean(axis=0)
    R_, B_, C_, V_ = np.meshgrid(ranges, np.deg2rad(bearings_deg), np.deg2rad(courses_deg), speeds, indexing="ij")
    R_, B_, C_, V_ = (a.ravel() for a in (R_, B_, C_, V_))
    theta = np.zeros((R_.size, model.n))
    theta[:, 0] = centre[0] + R_ * np.cos(B_)
    theta[:, 1] = centre[1] + R_ * np.sin(B_)
    theta[:, 2] = V_ * np.cos(C_)
    theta[:, 3] = V_ * np.sin(C_)
    if "z" in model.labels:
        theta[:, model.labels.index("z")] = model.source_z if source_z is None else source_z
    # over a bytes object, so that neither it nor its base can be made writeable (grid_terms keeps its terms
    # by its identity, not its values)
    return np.frombuffer(theta.tobytes(), dtype=float).reshape(theta.shape)


_GRID_CACHE: dict = {}
_TERMS_CACHE: dict = {}
_TERMS_CACHE_SIZE = 4
_MADE = weakref.WeakValueDictionary()   # id -> a grid candidate_grid made (whose values cannot change)
_CACHE_LOCK = threading.RLock()         # the caches are shared by the threads of a process


def _new_lock_in_child():
    """A forked child gets a lock of its own: the parent's may have been held by another thread (e.g. the
    background thread's run-ins, :func:`shipsense.parallel.background`), which does not exist in the child, and
    it would wait for it forever.  (The caches are consistent: the fork happens between two bytecodes.)"""
    global _CACHE_LOCK
    _CACHE_LOCK = threading.RLock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_new_lock_in_child)

_INVERSES: dict = {}   # id of a Gram matrix array grid_terms made -> (a weak reference to it, its ridge inverses)


def linear_basis(model, theta, steps, stride=1):
    """Offset (C, W, m) and unit-parameter basis (C, W, m, P) of candidate passages (internal units).

    The measurements are linear in the moment (and ``p``) for vector, tmi,
    envelope and electrode magnitude (``p >= 0``) channels: ``h = offset + basis @ params``; bearing
    channels are in the offset (and only there: a field channel's offset is zero, a bearing's basis zero).
    The grid search keeps these, whitened and window-major, in :func:`grid_terms`.
    """
    return _linear_basis(model, np.ascontiguousarray(theta, dtype=float), steps, stride)


def grid_terms(model, theta, steps, stride=1, reserve=0):
    """The grid search's terms of candidates ``theta`` over a window of ``steps`` samples taken every
    ``stride``: whitened field-channel basis ``G`` (W', mF, C*P), bearing offsets ``off`` (W', mB, C) and the
    Gram matrices ``A`` (C, P, P) of ``G`` over the window's W' samples (every sample present).

    ``G`` and ``off`` are window-major, so a shorter window is a prefix (a view, no copy): the last few grids'
    terms are kept for the longest window asked so far, and a longer one extends them to at least twice
    its length -- a tracker whose windows vary from passage to passage computes them a few times, not once
    per window; ``reserve`` (steps) sizes terms that must be computed for at least that window (a tracker
    passes its longest, so that each stride is computed once).  The Gram matrices of each window length asked
    for are kept with them, each continued from the longest shorter one's (:func:`_gram_on`: the sums a fresh
    one would make).  Treat the results as read-only.
    """
    theta = np.ascontiguousarray(theta, dtype=float)
    with _CACHE_LOCK:
        return _grid_terms(model, theta, steps, stride, reserve)


def _grid_terms(model, theta, steps, stride, reserve=0):
    """:func:`grid_terms` under the caches' lock."""
    frozen = _MADE.get(id(theta)) is theta                        # (candidate_grid's: its values cannot change)
    key = next((k for k, v in _TERMS_CACHE.items() if v["theta"] is theta and k[0] == id(model) and k[-1] == stride),
               None) if frozen else None                          # a grid of candidate_grid's: not hashed again
    if key is None:
        key = (id(model), theta.shape, hash(theta.tobytes()), stride)
    hit = _TERMS_CACHE.pop(key, None)
    if hit is not None and hit["model"] is not model:
        hit = None
    if hit is not None:
        _TERMS_CACHE[key] = hit                      # the most recently used last
    if hit is None or hit["steps"] < steps:
        longest = max(steps, int(reserve)) if hit is None else max(steps, int(reserve), 2 * hit["steps"])
        G, off = _grid_arrays(model, theta, longest, stride)
        hit = {"model": model, "theta": theta if frozen else None, "steps": longest, "G": G,
               "off": off, "P": len(_parameter_slots(model)), "grams": {}}
        _TERMS_CACHE.pop(key, None)
        if len(_TERMS_CACHE) >= _TERMS_CACHE_SIZE:
            _TERMS_CACHE.pop(next(iter(_TERMS_CACHE)))
        _TERMS_CACHE[key] = hit
    W = len(range(0, steps, stride))
    G, off = hit["G"][:W], hit["off"][:W]
    grams = hit["grams"]
    if W not in grams:          # from the longest shorter window's: only the samples after it are added
        rows = G.shape[1]
        below = max((w for w in grams if w < W), default=0)
        start = grams[below].copy() if below else np.zeros((len(theta), hit["P"], hit["P"]))   # (writeable: one
        # compiled signature of _gram_on)
        full = hit["G"].reshape(hit["G"].shape[0] * rows, hit["G"].shape[2])
        A = _gram_on(start, full, below * rows, W * rows)
        # over a bytes object, so that neither it nor a base can be made writeable: its inverses are kept
        grams[W] = np.frombuffer(A.tobytes(), dtype=float).reshape(A.shape)
        key = id(grams[W])      # its inverses, for grid_fit's windows with every sample present
        _INVERSES[key] = (weakref.ref(grams[W], lambda _, key=key: _INVERSES.pop(key, None)),
                          ridge_inverses(grams[W]))
    return G, off, grams[W]


_BASIS_CHUNK = 512
"""Candidates per :func:`linear_basis` call while :func:`_grid_arrays` fills a grid's terms: the basis and
its whitened, transposed copies are then a chunk's, not the grid's."""


def _grid_arrays(model, theta, steps, stride):
    """:func:`_window_major` of candidates ``theta`` (C, n), filled :data:`_BASIS_CHUNK` candidates at a time."""
    C, P, W = len(theta), len(_parameter_slots(model)), len(range(0, steps, stride))
    G = np.empty((W, int((~model.axial).sum()), C * P))
    off = np.empty((W, int(model.axial.sum()), C))
    for c0 in range(0, C, _BASIS_CHUNK):
        c1 = min(c0 + _BASIS_CHUNK, C)
        G[:, :, c0 * P:c1 * P], off[:, :, c0:c1] = _window_major(model, *linear_basis(model, theta[c0:c1], steps,
                                                                                      stride))
    for a in (G, off):
        a.flags.writeable = False
    return G, off


def _window_major(model, offset, basis):
    """Whitened field-channel basis (W, mF, C*P) and bearing offsets (W, mB, C), read-only, from
    :func:`linear_basis`'s (C, W, m, P) and (C, W, m)."""
    field, bearing = ~model.axial, model.axial
    if np.any(offset[..., field]) or np.any(basis[..., bearing, :]):
        raise ValueError("grid terms need offsets on bearing channels only and a basis on field channels only")
    C, W, _, P = basis.shape
    std = np.sqrt(model.R)
    G = np.ascontiguousarray((basis[:, :, field] / std[field, None]).transpose(1, 2, 0, 3))
    G = G.reshape(W, int(field.sum()), C * P)
    off = np.ascontiguousarray(offset[:, :, bearing].transpose(1, 2, 0))
    for a in (G, off):
        a.flags.writeable = False
    return G, off


@njit(cache=True, nogil=True)
def _gram_on(A0, G, k0, k1):
    """The Gram matrices ``A[c] = sum_k G[k, c P:(c + 1) P]^T G[k, c P:(c + 1) P]`` (C, P, P) of rows ``k0:k1``
    of a whitened basis ``G`` (K, C*P) added, in row order, to ``A0``, those of its rows before ``k0`` (not
    changed; zeros for ``k0 = 0``): the same sums, in the same order, as from zeros over rows ``:k1``."""
    C, P = A0.shape[0], A0.shape[1]
    A = A0.copy()
    for k in range(k0, k1):
        for c in range(C):
            base = c * P
            for p in range(P):
                g = G[k, base + p]
                for q in range(p + 1):
                    A[c, p, q] += g * G[k, base + q]
    for c in range(C):
        for p in range(P):
            for q in range(p):
                A[c, q, p] = A[c, p, q]
    return A


def _linear_basis(model, theta, steps, stride):
    """Each sensor type evaluated only for what it depends on: field channels are linear and homogeneous in
    their own source (the moment for magnetometers, ``p`` for electrodes), so their offset is zero and each
    parameter slot needs only its own sensors; bearings are the offset.  (A fused model's electric field --
    the dearest kernel -- is then evaluated once, not once per parameter.)"""
    from shipsense.trackers.models import _channel_columns, subset_model

    slots = _parameter_slots(model)
    Ak = powers(model.A, steps)[::stride]
    X = np.einsum("kij,cj->cki", Ak, theta)
    X[..., slots] = 0.0
    offset = np.zeros(X.shape[:-1] + (model.m,))
    basis = np.zeros(offset.shape + (len(slots),))
    types = model.array.types
    labels = model.labels
    for kind in dict.fromkeys(types):
        keep = [i for i, t in enumerate(types) if t == kind]
        sub = subset_model(model, keep) if len(keep) < len(types) else model
        cols = _channel_columns(model.array, keep)
        Xs = X[..., [labels.index(c) for c in sub.labels]]
        if kind == "accelerometer":
            offset[..., cols] = sub.h(Xs)
            continue
        for j, s in enumerate(slots):
            if labels[s] not in sub.labels:
                continue
            Xj = Xs.copy()
            Xj[..., sub.labels.index(labels[s])] = 1.0
            basis[..., cols, j] = sub.h(Xj)
    return offset, basis


def window_samples(model, K, window_s=15.0):
    """Samples W of the fitted window: ``window_s`` seconds, at least 4, less than the K samples."""
    return int(np.clip(round(window_s / model.period), 4, K - 1))


def strongest_snr(model, y):
    """The strongest field channel's SNR per sample (R, K) of measurements in internal units (R, K, m):
    ``max_i |y_i| / sqrt(R_i)`` over the field channels, a missing value counting 0 and an infinite one the
    dtype's largest (compiled, :func:`_strongest`; the tracker calls it every sample)."""
    a = np.asarray(y)
    big = _DOUBLE_MAX
    if a.dtype != np.float64 or not a.dtype.isnative:     # (the tracker's own samples, native doubles, as they are)
        if a.dtype.kind == "c":
            a = np.abs(a)                                 # the modulus
        if a.dtype.kind != "f":
            a = a.astype(float)
        big = float(np.finfo(a.dtype).max)
        if a.dtype not in (np.float32, np.float64) or not a.dtype.isnative:   # (float16, long double, byte-swapped)
            with np.errstate(over="ignore", invalid="ignore"):
                a = np.minimum(np.abs(a), big).astype(float)   # clamped at their own largest, then as doubles
            big = _DOUBLE_MAX
    out = np.empty(a.shape[:-1])
    _strongest(np.ascontiguousarray(a).reshape(-1, a.shape[-1]), ~model.axial, np.sqrt(model.R), big,
               out.reshape(-1))
    return out if out.ndim else out[()]


_DOUBLE_MAX = float(np.finfo(np.float64).max)


@njit(cache=True, error_model="numpy", nogil=True)
def _strongest(y, field, std, big, out):
    """``out[s] = max_i (min(|y[s, i]|, big) / std[i] if field[i] else 0)`` (NaN -> 0; the max NaN if any
    ratio is, as numpy's)."""
    for s in range(y.shape[0]):
        best = 0.0
        for i in range(y.shape[1]):
            v = 0.0
            if field[i]:
                a = abs(y[s, i])
                if a != a:
                    a = 0.0
                v = min(a, big) / std[i]
            if i == 0:
                best = v
            elif best == best and not v <= best:
                best = v
        out[s] = best


def detection_start(model, measurements, snr_start=5.0, window=0):
    """First sample (R,) at which some field channel exceeds ``snr_start`` noise standard deviations.

    The adaptive start of :func:`global_init`'s window (0 if never; at most
    ``K - window - 1`` so that the window fits).  ``measurements`` (R, K, m) SI.
    """
    y = np.asarray(measurements, dtype=float) / model.y_scale
    K = y.shape[1]
    snr = strongest_snr(model, y)
    above = snr > snr_start
    k0 = np.where(above.any(axis=1), np.argmax(above, axis=1), 0)
    return np.minimum(k0, K - window - 1).clip(0)


def fit_end(model, measurements, k0, window, through_peak=None):
    """End (exclusive, (R,)) of the refinement window that starts at ``k0``: ``k0 + window``, or with
    ``through_peak`` (a fraction) the first later sample at which the strongest channel's SNR has
    fallen below that fraction of its maximum since ``k0`` -- the fit then spans the closest
    approach -- if the passage gets there (else ``k0 + window``); at most ``K - 1``."""
    y = np.asarray(measurements, dtype=float) / model.y_scale
    R, K = y.shape[:2]
    k0 = np.asarray(k0, dtype=int)
    end = np.minimum(k0 + window, K - 1)
    if through_peak is None:
        return end
    snr = strongest_snr(model, y)
    k = np.arange(K)[None, :]
    since = np.where(k >= k0[:, None], snr, 0.0)
    peak = np.maximum.accumulate(since, axis=1)
    past = (k >= end[:, None]) & (since < through_peak * peak) & (k < K - 1)
    return np.where(past.any(axis=1), np.argmax(past, axis=1), end)


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
    present ones when fewer; compiled, :func:`_grid_solve_kernel`, the candidates in chunks on the CPUs); the
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
    with _CACHE_LOCK:
        hit = _INVERSES.get(id(A))
    inverses = hit[1] if hit is not None and hit[0]() is A else ridge_inverses(A)
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
        in_chunks(lambda c_lo, c_hi, args=args: _grid_solve_kernel(*args, c_lo, c_hi), C, split_min=256)
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
def _grid_solve_kernel(b, G, A_all, inverses, present, dd, yb, off, std_b, clamp, chi2, params, c_lo, c_hi):
    """:func:`grid_fit` for candidates ``c_lo:c_hi``: per passage, the parameters from the normal equations
    with a ``1e-9`` ridge -- with every sample present the Gram matrix ``A_all``'s, through its ridge
    ``inverses`` (:func:`ridge_inverses`), else ``A_all`` less the missing samples' outer products (or the
    present samples' when fewer) solved by Gaussian elimination with partial pivoting
    (:func:`~shipsense.trackers.compiled_linalg.solve_in_place`) --, the clamp, and the chi-square from the
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
                    e = _wrap(e) / std_b[j]
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
    """:func:`_grid_solve_kernel` of passage ``r`` with every sample present: the parameters from the ridge
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
    made per candidate; with such a view and this helper inlined, 6,912 candidates took 0.40 ms, 0.21 as it
    is, 0.16 written out in the caller.)"""
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


@njit(cache=True, error_model="numpy", nogil=True)
def ridge_inverses(A):
    """``(A_c + 1e-9 I)^-1`` (C, P, P) of Gram matrices ``A`` (C, P, P), a column at a time by
    :func:`~shipsense.trackers.compiled_linalg.solve_in_place` (the ridge of :func:`grid_fit`'s solves):
    :func:`grid_terms` keeps them with its Gram matrices."""
    C, P = A.shape[0], A.shape[1]
    out = np.empty((C, P, P))
    M = np.empty((P, P))
    col = np.empty(P)
    for c in range(C):
        for j in range(P):
            for p in range(P):
                for q in range(P):
                    M[p, q] = A[c, p, q]
                M[p, p] += 1e-9
                col[p] = 1.0 if p == j else 0.0
            solve_in_place(M, col, P)
            for p in range(P):
                out[c, p, j] = col[p]
    return out


def depth_prior(model, z_std, source_z=None):
    """Gaussian prior ``(mean, information)`` (internal units) on the source depth around ``source_z``
    (default the model's) with standard deviation ``z_std`` (m), for :func:`fit_passages`; None when
    ``z_std`` is None or the model has no depth."""
    if z_std is None or "z" not in model.labels:
        return None
    iz = model.labels.index("z")
    mean, weight = np.zeros(model.n), np.zeros(model.n)
    mean[iz] = (model.source_z if source_z is None else source_z) / model.x_scale[iz]
    weight[iz] = (model.x_scale[iz] / z_std) ** 2
    return mean, weight


def _refine_stages(refine, keep):
    """Cumulative numbers of grid minima refined per stage (each at least ``keep``, increasing)."""
    if refine is None:
        return [keep]
    stages = [int(refine)] if np.isscalar(refine) else [int(r) for r in refine]
    if any(r < 1 for r in stages) or any(b <= a for a, b in zip(stages, stages[1:])):
        raise ValueError(f"refine must be a positive count or increasing counts, got {refine!r}")
    return [max(keep, r) for r in stages]


def _dof(model, yfit, prior):
    """Degrees of freedom (R,) of passage fits to ``yfit`` (R, W, m): samples present, plus the prior's
    rows, minus the states."""
    rows = 0 if prior is None else int(np.count_nonzero(prior[1]))
    return np.maximum(np.isfinite(yfit).sum(axis=(1, 2)) + rows - model.n, 1)


def chi2_expected(model, yfit, prior, huber=None):
    """Mean (R,) of the chi-square (Huber cost) of fits to ``yfit`` at the noise level."""
    dof = _dof(model, yfit, prior).astype(float)
    return dof if huber is None else dof * huber.moments[0]


def chi2_limit(model, yfit, prior, gof, huber=None):
    """Chi-square (R,) above which a fit to ``yfit`` fails the goodness-of-fit test at level ``gof``.

    With ``huber`` (robust fits) the statistic is the Huber cost, and its limit the normal approximation of
    its distribution under the noise's outlier model (:meth:`~shipsense.trackers.batchfit.Huber.limit`).
    """
    from scipy import special  # chdtri(dof, q) = scipy.stats.chi2.isf(q, dof), without scipy.stats' 40 MB

    if gof is None:
        return np.full(yfit.shape[0], np.inf)
    dof = _dof(model, yfit, prior)
    return special.chdtri(dof, gof) if huber is None else huber.limit(dof, gof)


def distinct_rows(chi2, positions, M, distinct_m):
    """Indices (R, M) of each row's ``M`` lowest finite ``chi2`` (R, C) whose ``positions`` ((R or 1), C, 2)
    are more than ``distinct_m`` apart, and whether each is a pick (R, M) (False: fewer were distinct, the
    index repeats the row's best; a row with no finite ``chi2`` has none, index 0).

    Greedy: each pick the best candidate not within ``distinct_m`` of an earlier pick.  Each row's candidates
    are walked in ascending ``chi2`` (a stable sort: ties in index order), each kept unless within
    ``distinct_m`` of a pick (:func:`_distinct_walk`, every row in one compiled call).
    """
    chi2 = np.ascontiguousarray(np.where(np.isfinite(chi2), chi2, np.inf), dtype=float)   # (never picked)
    idx = np.zeros((chi2.shape[0], M), dtype=np.int64)
    count = _distinct_walk(chi2, np.ascontiguousarray(positions, dtype=float), float(distinct_m) ** 2, idx)
    found = np.arange(M)[None, :] < count[:, None]
    return np.where(found, idx, idx[:, :1]), found


@njit(cache=True, nogil=True)
def _distinct_walk(chi2, positions, limit2, picks):
    """The picks (R, M) of every row of :func:`distinct_rows` (``chi2`` (R, C), non-finite as ``inf``) into
    ``picks``; returns their counts (R,).

    A row's finite candidates are taken from a binary heap ordered by ``(chi2, index)`` -- the stable sort's
    order -- only as far as the walk needs them: a grid's 20 picks were among its lowest 250 of 6,912 in
    every window of 32 tracked passages (a whole stable sort of them cost ~0.5 ms a row)."""
    R, M = picks.shape
    C = chi2.shape[1]
    count = np.zeros(R, dtype=np.int64)
    heap = np.empty(C, dtype=np.int64)
    for r in range(R):
        row = chi2[r]
        pos = positions[r if positions.shape[0] > 1 else 0]
        size = 0
        for c in range(C):
            if row[c] < np.inf:
                heap[size] = c
                size += 1
        for i in range(size // 2 - 1, -1, -1):
            _sift(heap, i, size, row)
        n = 0
        while size > 0 and n < M:
            c = heap[0]
            size -= 1
            heap[0] = heap[size]
            _sift(heap, 0, size, row)
            keep = True
            for i in range(n):
                d0 = pos[c, 0] - pos[picks[r, i], 0]
                d1 = pos[c, 1] - pos[picks[r, i], 1]
                if not d0 * d0 + d1 * d1 > limit2:
                    keep = False
                    break
            if keep:
                picks[r, n] = c
                n += 1
        count[r] = n
    return count


@njit(cache=True, nogil=True, inline="always")
def _sift(heap, i, size, key):
    """Sift ``heap[i]`` down a min-heap of ``size`` indices ordered by ``(key[index], index)``."""
    item = heap[i]
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        other = child + 1
        if other < size and (key[heap[other]] < key[heap[child]] or
                             (key[heap[other]] == key[heap[child]] and heap[other] < heap[child])):
            child = other
        c = heap[child]
        if key[c] < key[item] or (key[c] == key[item] and c < item):
            heap[i] = c
            i = child
        else:
            break
    heap[i] = item


def distinct_loglik(chi2, found):
    """Log-likelihoods ``-chi2 / 2`` (R, M) of fits picked by :func:`distinct_rows`, ``-inf`` for the repeats
    that fill a row (no weight in a mixture); a row's first is always finite (its best, or a failed fit's
    very low value) so that every bank has a hypothesis to select."""
    first = np.arange(np.shape(chi2)[1]) == 0
    return np.where(found | first, -0.5 * np.minimum(chi2, 1e300), -np.inf)


@dataclass(frozen=True)
class WindowFits:
    """The distinct fits of passages' windows, at each window's first sample (internal units).

    Attributes
    ----------
    theta : ndarray, shape (R, M, n)
        Fitted initial states, best first.
    chi2 : ndarray, shape (R, M)
        Their chi-square (Huber cost for robust fits).
    info : ndarray, shape (R, M, n, n)
        Gauss-Newton information at the fits.
    found : ndarray of bool, shape (R, M)
        False where a passage had fewer distinct fits (the entry repeats its best).
    limit : ndarray, shape (R,)
        The goodness-of-fit test's limit on the chi-square.
    expected : ndarray, shape (R,)
        The chi-square's mean for a fit at the noise level (its degrees of freedom; for Huber fits, times
        the cost's mean per residual).
    """

    theta: np.ndarray
    chi2: np.ndarray
    info: np.ndarray
    found: np.ndarray
    limit: np.ndarray
    expected: np.ndarray

    @property
    def fit_ok(self):
        """Whether each passage's best fit passes the goodness-of-fit test (R,)."""
        return self.chi2[:, 0] <= self.limit

    @property
    def loglik(self):
        """The fits' log-likelihoods ``-chi2 / 2`` (R, M), ``-inf`` for repeats (:func:`distinct_loglik`)."""
        return distinct_loglik(self.chi2, self.found)


def grid_minima(model, yw, grid, window, stride, count, distinct_m, mid, reserve=0):
    """The ``count`` best distinct grid candidates of each passage (R, count, n), best first, with their
    least-squares moments (:func:`grid_fit`): a candidate more than ``distinct_m`` from every better pick at
    the window's middle (``mid`` (2, n): the state's position there), the best repeated when fewer are
    distinct (:func:`distinct_rows`).

    ``yw`` (R, W', m) are the window's samples at steps ``0, stride, ...`` (internal units, NaN = missing);
    the grid's candidate trajectories are evaluated on the same steps (:func:`grid_terms`).  The grid's
    chi-square and moments (C and C x P per passage) exist for a chunk of passages at a time.
    """
    slots = _parameter_slots(model)
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


def _window_middle(model, W):
    """The position at the middle of a ``W``-sample window as a linear map of its first state (2, n): where
    the distinct minima are told apart."""
    return shared_powers(model.A, W)[W // 2][:2]


def refine_minima(model, yfit, starts, *, stages, keep, distinct_m, prior, gof, explore_samples, taus=None,
                  huber=None):
    """The ``keep`` best distinct Levenberg-Marquardt fits of each passage's window ``yfit`` (R, W, m),
    started from its best distinct grid minima ``starts`` (R, stages[-1], n) (:func:`grid_minima`), refined
    in ``stages`` (a passage whose best fit so far fails the chi-square test gets the next stage's minima);
    :class:`WindowFits`."""
    R, W, _ = yfit.shape
    mid = _window_middle(model, W)
    M = stages[-1]
    if explore_samples is not None and explore_samples < 2:
        raise ValueError(f"explore_samples must be at least 2, got {explore_samples!r}")
    explore = 1 if explore_samples is None else max(1, W // int(explore_samples))
    ysub = yfit[:, ::explore]
    tsub = None if taus is None else taus[:, ::explore]
    limit = chi2_limit(model, ysub, prior, gof, huber)
    theta = np.zeros((R, M, model.n))
    chi2 = np.full((R, M), np.inf)
    info = np.zeros((R, M, model.n, model.n))
    todo, lo = np.arange(R), 0
    for hi in stages:
        first = starts[todo, lo:hi].reshape(-1, model.n)
        t, c, j = fit_passages(model, np.repeat(ysub[todo], hi - lo, axis=0), first, W, stride=explore,
                               return_information=True, prior=prior, huber=huber,
                               taus=None if tsub is None else np.repeat(tsub[todo], hi - lo, axis=0))
        theta[todo, lo:hi] = t.reshape(todo.size, hi - lo, -1)
        chi2[todo, lo:hi] = np.where(np.isfinite(c), c, np.inf).reshape(todo.size, hi - lo)
        info[todo, lo:hi] = j.reshape(todo.size, hi - lo, model.n, model.n)
        todo, lo = np.flatnonzero(chi2.min(axis=1) > limit), hi
        if todo.size == 0:
            break
    # the best ``keep`` distinct refined fits (fits that converged to the same minimum count once: a repeat of
    # the best fills a passage's row at log-likelihood -inf, no weight)
    sel, found = distinct_rows(chi2, theta @ mid.T, keep, distinct_m)
    pick = (np.arange(R)[:, None], sel)
    theta, chi2, info = (a[pick] for a in (theta, chi2, info))
    if explore > 1:   # polish the kept fits on every sample of the window
        t, c, j = fit_passages(model, np.repeat(yfit, keep, axis=0), theta.reshape(R * keep, -1), W,
                               return_information=True, prior=prior, huber=huber,
                               taus=None if taus is None else np.repeat(taus, keep, axis=0))
        theta, chi2, info = t.reshape(R, keep, -1), c.reshape(R, keep), j.reshape(R, keep, model.n, model.n)
        limit = chi2_limit(model, yfit, prior, gof, huber)
    return WindowFits(theta, np.where(np.isfinite(chi2), chi2, np.inf), info, found, limit,
                      chi2_expected(model, yfit, prior, huber))


def window_fits(model, yfit, *, ranges, speeds, taus=None, bearing_step_deg=15.0, course_step_deg=30.0,
                grid_samples=16, keep=5, distinct_m=15.0, source_z=None, z_std=None, refine=None, gof=0.01,
                explore_samples=None, huber=None, grid_reserve=0):
    """Global fits of given windows ``yfit`` (R, W, m) (internal units, NaN = missing): the grid search on
    every ``W // grid_samples``-th sample (at least ``grid_samples`` of them and fewer than twice as many, or
    all of a window shorter than that;
    ``grid_reserve``: :func:`grid_terms`' ``reserve``), then :func:`refine_minima`.  ``taus`` (R, W),
    optional: the samples' times (s) after each window's first (irregular sampling; the grid search then uses
    the nominal steps, the fits the times).  Options as for :func:`global_init`; returns :class:`WindowFits`."""
    R, W, _ = yfit.shape
    stride = max(1, W // int(grid_samples))
    grid = candidate_grid(model, ranges, np.arange(0.0, 360.0, bearing_step_deg),
                          np.arange(0.0, 360.0, course_step_deg), speeds, source_z)
    stages = _refine_stages(refine, keep)
    starts = grid_minima(model, yfit[:, ::stride], grid, W, stride, stages[-1], distinct_m,
                         _window_middle(model, W), grid_reserve)
    return refine_minima(model, yfit, starts, stages=stages, keep=keep,
                         distinct_m=distinct_m, prior=depth_prior(model, z_std, source_z), gof=gof,
                         explore_samples=explore_samples, taus=taus, huber=huber)


def global_init(model, measurements, *, ranges, speeds, bearing_step_deg=15.0, course_step_deg=30.0,
                window_s=15.0, grid_samples=16, keep=5, distinct_m=15.0, snr_start=5.0, inflate=2.0,
                source_z=None, common_start=False, through_peak=None, z_std=None, refine=None, gof=0.01,
                explore_samples=None, huber=None):
    """Global initialisation of passages from a grid search with the moment eliminated in closed form.

    Parameters
    ----------
    model : FieldModel
    measurements : ndarray, shape (R, K, m)
        SI units, NaN = missing.
    ranges, speeds : sequence of float
        Grid of start ranges from the array centroid (m) and speeds (m/s).
    bearing_step_deg, course_step_deg : float
        Grid steps of the start bearing and the course.
    window_s : float
        Duration (s) fitted from the detection on (W samples); the grid search
        uses about ``grid_samples`` of them, the refinement all.
    keep : int
        Distinct minima kept per passage (M): the best ones more than ``distinct_m`` apart (5: on the
        wide study, 4 lost two-magnetometer passages and 6 cost more than the bank, EXPERIMENTS.md).
    refine : int or sequence of int, optional
        Distinct grid minima refined by the batch fit (default ``keep``); the
        best ``keep`` distinct refined fits seed the bank.  At high SNR the
        global minimum's basin can be narrower than the grid spacing, so it
        may not be among the ``keep`` best grid points (EXPERIMENTS.md).
        Increasing counts, e.g. ``(5, 20, 60)``, refine in stages: the first
        count for every passage, each further one only for the passages whose
        best fit so far fails the chi-square test (``gof``), so that the cost
        goes to the passages that need it.
    gof : float or None
        Level of the chi-square goodness-of-fit test of the fits (default
        1 %): a fit whose chi-square exceeds the ``1 - gof`` quantile for
        its degrees of freedom has not explained the data to the noise
        level (a local minimum, or a source the model does not describe).
        At 0.1 % a single-magnetometer fit 21 m off passed (EXPERIMENTS.md).
        It drives the staged ``refine`` and gives ``GlobalInit.fit_ok``.
        (Scaling a failed fit's covariance by its reduced chi-square, the
        Birge ratio, was tried and dropped: on 500 two-magnetometer passages
        the first bank from the larger covariances went from 3.8x to 5.2x
        the constant-velocity bound, EXPERIMENTS.md.)
    explore_samples : int, optional
        The refinement's fits of the grid minima use about this many samples
        of the window, evenly spaced (and the staged test those samples); the
        ``keep`` fits kept are then polished on every sample.  Exploring many
        minima then costs that much less: on S0 (150-sample windows), 60
        minima explored on 15 samples missed the global minimum of none of
        100 passages, where 5, 20 and 60 in stages on every sample missed 16
        (EXPERIMENTS.md).  None: every sample.
    snr_start : float
        The window starts at the first sample with some channel above this SNR (adaptive start).
    inflate : float
        Factor on the batch-fit covariance (linearisation of a nonlinear fit).
    z_std : float, optional
        Standard deviation (m) of a Gaussian prior on the source depth around
        ``source_z`` (models with electrodes): the batch fits are then MAP fits
        and their covariances include it.  The envelope fits otherwise often
        settle on a wrong depth, the depth and ``p`` trading off in the far
        field (EXPERIMENTS.md); the studies' bank starts with the same prior
        (``BankConfig.z_std``).
    common_start : bool
        Start every passage's window at the latest detection of the batch, so
        that one bank runs them all (:func:`track_with_global_init`).
    through_peak : float, optional
        Extend the refinement (not the grid search) past the window until the
        strongest channel has fallen below this fraction of its peak
        (:func:`fit_end`): the batch fit then spans the closest approach, and
        the bank starts after it.

    huber : Huber, optional
        Robust (Huber) fits and their test under the noise's outlier model
        (:class:`~shipsense.trackers.batchfit.Huber`).

    Returns
    -------
    GlobalInit
    """
    y_si = np.asarray(measurements, dtype=float)
    R, K, m = y_si.shape
    window = window_samples(model, K, window_s)
    y = y_si / model.y_scale
    k0 = detection_start(model, y_si, snr_start, window)
    if common_start:   # one bank start for the whole batch: every window starts at the latest detection
        k0 = np.full(R, k0.max())
    yfit = y[np.arange(R)[:, None], k0[:, None] + np.arange(window)[None, :]]           # (R, W, m)
    fits = window_fits(model, yfit, ranges=ranges, speeds=speeds, bearing_step_deg=bearing_step_deg,
                       course_step_deg=course_step_deg, grid_samples=grid_samples, keep=keep, distinct_m=distinct_m,
                       source_z=source_z, z_std=z_std, refine=refine, gof=gof,
                       explore_samples=explore_samples, huber=huber)
    prior = depth_prior(model, z_std, source_z)
    theta, chi2, info, limit = fits.theta.reshape(R * keep, -1), fits.chi2.reshape(-1), fits.info, fits.limit
    end = fit_end(model, y_si, k0, window, through_peak)
    if common_start:
        end = np.full(R, end.max())
    Wf = int((end - k0).max())
    if Wf > window:   # continue every fit through the closest approach, from the window's solution
        ks = k0[:, None] + np.arange(Wf)[None, :]
        yfit = y[np.arange(R)[:, None], np.minimum(ks, K - 1)]                           # (R, Wf, m)
        yfit = np.where((ks < end[:, None])[..., None], yfit, np.nan)                   # each passage to its end
        theta, chi2, info = fit_passages(model, np.repeat(yfit, keep, axis=0), theta, Wf, return_information=True,
                                         prior=prior, huber=huber)
        limit = chi2_limit(model, yfit, prior, gof, huber)
    theta, chi2 = theta.reshape(R, keep, -1), chi2.reshape(R, keep)
    cov = np.linalg.pinv(info, hermitian=True).reshape(R, keep, model.n, model.n) * inflate
    # propagate to the first sample after the fitted stretch
    Ak = powers(model.A, Wf + 1)
    Aw = Ak[np.minimum(end - k0, Wf)]                                                   # (R, n, n)
    seeds = np.einsum("rij,rmj->rmi", Aw, theta)
    P0 = Aw[:, None] @ cov @ np.swapaxes(Aw, -1, -2)[:, None] + (end - k0)[:, None, None, None] * model.Q
    traj = np.einsum("kij,rmj->rmki", Ak[:Wf], theta)
    xs = model.x_scale
    return GlobalInit(start=end, seeds=seeds * xs, P0=P0 * np.outer(xs, xs),
                      loglik=distinct_loglik(chi2, fits.found), window=traj * xs, k0=k0,
                      fit_ok=chi2.min(axis=1) <= limit)


def unalign(values, start, K, fill=np.nan):
    """Values on a bank's aligned axis (R, J, ...) (:func:`track_with_global_init`) back on the samples (R, K, ...)."""
    values = np.asarray(values)
    R, J = values.shape[:2]
    out = np.full((R, K) + values.shape[2:], fill, dtype=np.result_type(values, np.asarray(fill)))
    src = np.asarray(start, dtype=int)[:, None] + np.arange(J)[None, :]
    inside = src < K
    rows = np.broadcast_to(np.arange(R)[:, None], src.shape)
    out[rows[inside], src[inside]] = values[inside]
    return out


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
