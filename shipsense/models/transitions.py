"""Transitions of the constant-velocity state over time: ``A(tau)`` and the powers ``A^k``.

A passage is its initial state ``theta``; its state ``k`` samples later is
``A^k theta`` (:func:`powers`), and ``tau`` seconds later ``A(tau) theta``
(:func:`transitions`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np


def powers(A, K):
    """A^k for k = 0..K-1, shape (K, n, n)."""
    out = np.empty((K,) + A.shape)
    out[0] = np.eye(A.shape[0])
    for k in range(1, K):
        out[k] = A @ out[k - 1]
    return out


def shared_powers(A, K):
    """:func:`powers`, read-only and kept for the last few ``(A, K)`` (the window fits ask for the same ones at
    every window: K matrix products each time)."""
    A = np.ascontiguousarray(A, dtype=float)
    return _shared_powers(A.tobytes(), A.shape, int(K))


@lru_cache(maxsize=32)
def _shared_powers(data, shape, K):
    out = powers(np.frombuffer(data, dtype=float).reshape(shape), K)
    out.flags.writeable = False
    return out


def transitions(model, taus):
    """Constant-velocity transitions ``A(tau)`` (..., n, n) over ``taus`` (...) seconds (negative: backwards).

    ``A(tau) = I + (tau / T)(A - I)``: the model's one-period transition moves positions by ``T v`` and
    leaves the rest, so a time ``tau`` moves them by ``tau v``.
    """
    taus = np.asarray(taus, dtype=float)
    A = np.ascontiguousarray(model.A, dtype=float)
    eye, step = _identity_and_step(A.tobytes(), A.shape)
    return eye + (taus[..., None, None] / model.period) * step


@lru_cache(maxsize=32)
def _identity_and_step(data, shape):
    """``(I, A - I)`` of a transition ``A`` (by its bytes), read-only: kept for :func:`transitions`, which the
    trackers call several times a refit (the same numbers as forming them each time, in half the time)."""
    A = np.frombuffer(data, dtype=float).reshape(shape)
    eye = np.eye(shape[0])
    step = A - eye
    eye.flags.writeable = step.flags.writeable = False
    return eye, step
