"""The design criteria of a set of sensors: D (log-determinant), A (minus the trace of the inverse) and E (the
smallest eigenvalue) of the Fisher information matrices of a design, over the passages of the problem; shared
by the convex relaxation and its searches (:mod:`~shipsense.design.placement`) and the exact search over small
subsets (:mod:`~shipsense.design.subsets`).
"""

from __future__ import annotations

import numpy as np

CRITERIA = ("D", "A", "E")
"""The criteria: D-, A- and E-optimal design (Boyd & Vandenberghe 2004, section 7.5)."""


def criterion_value(M, criterion):
    """The criterion of matrices M (..., S, n, n), averaged (D, A) or minimised (E) over S -> (...)."""
    if criterion == "D":
        sign, logdet = np.linalg.slogdet(M)
        return np.where(sign > 0, logdet, -np.inf).mean(axis=-1)
    if criterion == "A":
        return -np.trace(np.linalg.inv(M), axis1=-2, axis2=-1).mean(axis=-1)
    if criterion == "E":
        return np.linalg.eigvalsh(M)[..., 0].min(axis=-1)
    raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")


def value_of_sets(problem, sets, criterion, chunk=None):
    """Criterion of 0/1 designs given as index arrays (B, k): the chosen matrices are gathered, not weighted."""
    sets = np.asarray(sets)
    out = np.empty(len(sets))
    if chunk is None:   # about 64 MB of gathered matrices at a time
        chunk = max(1, int(8e6 // (problem.J.shape[0] * max(1, sets.shape[-1]) * problem.n ** 2)))
    eye = problem.eps * np.eye(problem.n)
    for start in range(0, len(sets), chunk):
        idx = sets[start:start + chunk]
        M = eye + problem.J[:, idx].sum(axis=2)                      # (S, B, n, n)
        out[start:start + chunk] = criterion_value(np.swapaxes(M, 0, 1), criterion)
    return out
