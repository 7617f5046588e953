"""The grid search's candidates and their linear terms (:mod:`shipsense.trackers.init.grid`).

:func:`candidate_grid` makes a grid of candidate passages (start range and bearing from the array centroid,
course, speed), :func:`linear_basis` gives each candidate's offset and unit-parameter basis (the fields are
linear in the moment and in ``p``), and :func:`grid_terms` keeps them whitened and window-major with their
Gram matrices and ridge inverses, cached per grid and shared by the threads of a process.
"""

from __future__ import annotations

import os
import threading
import weakref

import numpy as np
from numba import njit

from shipsense import numba_cache
from shipsense.models.transitions import powers
from shipsense.trackers.linalg import solve_in_place


def parameter_slots(model):
    """The indices of the state's source-strength components (``mx, my, mz`` and/or ``p``) the fields are linear
    in: the parameters the grid search eliminates."""
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
               "off": off, "P": len(parameter_slots(model)), "grams": {}}
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
    C, P, W = len(theta), len(parameter_slots(model)), len(range(0, steps, stride))
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

    slots = parameter_slots(model)
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


def kept_inverses(A):
    """The ridge inverses (:func:`ridge_inverses`) of Gram matrices ``A``: those :func:`grid_terms` keeps with
    them when ``A`` is one of its, else computed."""
    with _CACHE_LOCK:
        hit = _INVERSES.get(id(A))
    return hit[1] if hit is not None and hit[0]() is A else ridge_inverses(A)


__all__ = ["candidate_grid", "grid_terms", "kept_inverses", "linear_basis", "parameter_slots", "ridge_inverses"]


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
