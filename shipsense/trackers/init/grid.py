"""The grid search of the global initialiser: candidate passages and their linear terms.

The fields are linear in the moment (and in ``p``), so for every candidate
trajectory of a grid (start range and bearing from the array centroid,
course, speed) the best moment is a closed-form least-squares solve:
:func:`linear_basis` gives each candidate's offset and basis, :func:`grid_terms`
keeps them whitened and window-major (cached per grid), :func:`grid_fit`
eliminates the moment for every passage and candidate, and
:func:`grid_minima` returns the best distinct candidates.
"""

from __future__ import annotations

import math
import os
import threading
import weakref

import numpy as np
from numba import njit

from shipsense import numba_cache
from shipsense.models.measurement import wrap_angle
from shipsense.models.transitions import powers
from shipsense.trackers.fit.least_squares import FIT_CHUNK_BYTES
from shipsense.trackers.init.distinct import distinct_rows
from shipsense.trackers.linalg import solve_in_place


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
    from shipsense.models.field_model import channel_columns, subset_model

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
        cols = channel_columns(model.array, keep)
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


@njit(cache=True, error_model="numpy", nogil=True)
def ridge_inverses(A):
    """``(A_c + 1e-9 I)^-1`` (C, P, P) of Gram matrices ``A`` (C, P, P), a column at a time by
    :func:`~shipsense.trackers.linalg.solve_in_place` (the ridge of :func:`grid_fit`'s solves):
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


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
