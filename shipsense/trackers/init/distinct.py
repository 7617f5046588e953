"""Distinct minima: the best fits of a passage that lie apart in position.

A grid search or a set of refined fits finds many minima around the same
track; :func:`distinct_rows` keeps each row's best ones at least a distance
apart (a compiled walk over a heap), :func:`distinct_loglik` turns their
chi-squares into a bank's prior log-likelihoods.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from shipsense import numba_cache


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
    order -- only as far as the walk needs them: a grid's picks lie among a small share of its lowest
    candidates, and a whole stable sort of every row would cost more than the walk."""
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


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
