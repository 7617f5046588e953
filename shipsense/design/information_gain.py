r"""Predicted information gain of reading a subset of sensors: the drop of the position covariance's log-det.

A state with covariance :math:`P` (n, n) is to be updated by reading the sensors of a subset :math:`T`;
each sensor :math:`s` has the channels :math:`i \in C(s)` with noise variances :math:`R_i` and Jacobian rows
:math:`H_i = \partial h_i / \partial x` (1, n) at the state.  In information form, as the Fisher information
of :mod:`shipsense.design.fisher`, the sensors' information adds up:

.. math::  J_s = \sum_{i \in C(s)} H_i^T R_i^{-1} H_i, \qquad
           P_T = \Big(P^{-1} + \sum_{s \in T} J_s\Big)^{-1},

and the gain of reading :math:`T` is the drop of the log-det of the position block (the state's first
two components, x and y):

.. math::  g(T) = \ln\det P_{pp} - \ln\det (P_T)_{pp} \quad\text{(nats)},

the Kalman update's shrinkage of the position's uncertainty ellipse (:math:`e^{g/2}` the ratio of its
areas before and after); in covariance form, on the stacked read channels :math:`H_T`, :math:`R_T`,

.. math::  g(T) = \ln\det P_{pp} - \ln\det\big(P - P H_T^T (H_T P H_T^T + R_T)^{-1} H_T P\big)_{pp}.

``g`` (nats) has no physical unit: the units of the state (the tracker model's internal units) do not change
it, so long as ``P``, ``H`` and ``R`` are in the same ones (a rescaling of the state cancels in the
difference).  It is 0 for the empty subset and where it would be negative or not finite (a singular
``P``, a non-finite Jacobian row of a sensor read).

Shapes: ``E`` states, ``n`` state components, ``m`` channels grouped by sensor (``first_channel`` (S,),
increasing, the first channel of each of the ``S`` sensors), ``A`` subsets as a boolean matrix (A, S).
:func:`information_gains` takes the Jacobians (E, m, n); :func:`information_gains_at` computes them from
a measurement model at its states (E, n) in the same compiled call.  Passage-v1 predicts the gain of every
action at every step with it (:mod:`shipsense.envs.passage_v1`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from shipsense import numba_cache
from shipsense.models.measurement import FIELD, batch_kernel, kernel_of
from shipsense.trackers.linalg import solve_many_in_place


def information_gains(Hm, Rinv, P, first_channel, subsets):
    """The gain ``g`` (nats, the module docstring) of reading each of ``subsets`` (A, S) from covariances ``P``
    (E, n, n), with Jacobians ``Hm`` (E, m, n), inverse noise variances ``Rinv`` (m,) and the channels grouped
    by sensor from ``first_channel`` (S,; a sensor whose start equals the next one's has no channel).  Returns
    (E, A), 0 for a subset that reads nothing and where the drop is negative or not finite.  ``subsets`` are
    booleans (any nonzero entry reads its sensor).  Compiled (:func:`_gains`)."""
    Hm, P = (np.ascontiguousarray(a, dtype=float) for a in (Hm, P))
    out = np.empty((P.shape[0], len(subsets)))
    _gains(Hm, np.ascontiguousarray(Rinv, dtype=float), P, np.asarray(first_channel, dtype=np.int64),
           np.ascontiguousarray(subsets, dtype=np.bool_), out)
    return out


def information_gains_at(model, x, Rinv, P, first_channel, subsets):
    """:func:`information_gains` with the Jacobians of ``model`` at its internal states ``x`` (E, n): in one
    compiled call with the model's compiled measurement kernel (the Jacobians :meth:`FieldModel.H` gives, from
    the same kernel), else through ``model.H``."""
    spec = kernel_of(model)
    if spec is None or spec[0] != FIELD:
        return information_gains(model.H(x), Rinv, P, first_channel, subsets)
    P = np.ascontiguousarray(P, dtype=float)
    out = np.empty((P.shape[0], len(subsets)))
    _gains_at(np.ascontiguousarray(x, dtype=float), spec, np.ascontiguousarray(Rinv, dtype=float), P,
              np.asarray(first_channel, dtype=np.int64), np.ascontiguousarray(subsets, dtype=np.bool_), out)
    return out


@njit(cache=True, error_model="numpy", nogil=True)
def _gains_at(X, spec, Rinv, P, first_channel, subsets, out):
    """:func:`information_gains_at`: the states' Jacobians from the measurement kernel's batch (as ``model.H``),
    then :func:`_gains`."""
    E, n = X.shape
    m = Rinv.shape[0]
    Hm = np.empty((E, m, n))
    batch_kernel(X, spec, np.empty((E, m)), Hm, True)
    _gains(Hm, Rinv, P, first_channel, subsets, out)


@njit(cache=True, error_model="numpy", nogil=True)
def _gains(Hm, Rinv, P, first_channel, subsets, out):
    E, m, n = Hm.shape
    S = first_channel.size
    Js = np.empty((S, n, n))
    Pinv, M, X = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    reads = np.zeros(subsets.shape[0], dtype=np.bool_)
    for t in range(subsets.shape[0]):
        for s in range(S):
            reads[t] |= subsets[t, s]
    for e in range(E):
        for s in range(S):                      # each sensor's information sum_i H_i^T H_i / R_i
            hi = first_channel[s + 1] if s + 1 < S else m
            for a in range(n):
                for b in range(n):
                    acc = 0.0
                    for i in range(first_channel[s], hi):
                        acc += Hm[e, i, a] * Rinv[i] * Hm[e, i, b]
                    Js[s, a, b] = acc
        for a in range(n):                      # P^-1: one elimination, the identity's columns
            for b in range(n):
                M[a, b] = P[e, a, b]
                Pinv[a, b] = 1.0 if a == b else 0.0
        solve_many_in_place(M, Pinv, n, n)
        before = math.log(abs(P[e, 0, 0] * P[e, 1, 1] - P[e, 0, 1] * P[e, 1, 0]))
        for t in range(subsets.shape[0]):
            if not reads[t]:                    # (reading nothing gains nothing)
                out[e, t] = 0.0
                continue
            for a in range(n):                  # the first two columns of (P^-1 + J)^-1
                for b in range(n):
                    acc = Pinv[a, b]
                    for s in range(S):
                        if subsets[t, s]:
                            acc += Js[s, a, b]
                    M[a, b] = acc
                X[a, 0] = 1.0 if a == 0 else 0.0
                X[a, 1] = 1.0 if a == 1 else 0.0
            solve_many_in_place(M, X, n, 2)
            g = before - math.log(abs(X[0, 0] * X[1, 1] - X[0, 1] * X[1, 0]))
            out[e, t] = max(g, 0.0) if math.isfinite(g) else 0.0


__all__ = ["information_gains", "information_gains_at"]


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
