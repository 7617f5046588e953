r"""An exact search over k-subsets for the D criterion: depth-first enumeration pruned by submodular bounds.

The D criterion of a design :math:`T` (:mod:`shipsense.design.placement`),

.. math::  f(T) = \frac{1}{S}\sum_s \log\det\Big(\epsilon I + \sum_{i \in T} J_{si}\Big),

is a monotone submodular set function (each :math:`J_{si}` is positive semi-definite, and the gain
:math:`\Delta(m \mid T) = f(T \cup \{m\}) - f(T) = \frac1S\sum_s \log\det(I + M_{sT}^{-1/2} J_{sm}
M_{sT}^{-1/2})` can only fall as :math:`M_{sT}` grows; Krause & Golovin, "Submodular function
maximization", 2014, sect. 1.2).  Hence for a partial design :math:`F` and any completion :math:`T`,

.. math::  f(F \cup T) \le f(F) + \sum_{m \in T} \min_{i \in F} \Delta(m \mid \{i\}),

and :math:`\Delta(m \mid \{i\}) = f(\{i, m\}) - f(\{i\})` for every pair is one table, computed once (the N(N-1)/2
pair values).  The search enumerates the k-subsets in lexicographic order of the candidates sorted by their
single-sensor value, the best first (so that a good design is found early), and drops every branch whose bound
does not exceed the best design found: with nothing left, that design is optimal.  A node's children are
first screened with the bound that adds the largest remaining gains, then with the bound through the pair
table; only the survivors' values are computed (a Cholesky factorisation per passage).

The work is counted (the subset values computed and the children screened through the pair table) and the
search stops on it (``max_work``), not on the clock, so that what it proves does not depend on the machine's
load; a time guard can stop it too and says so.  Stopped early, the bound it proves is the largest bound of the
first-level branches it had not finished (:func:`subset_search`).

References: Krause & Golovin (2014); Nemhauser, Wolsey & Fisher, "An analysis of approximations for
maximizing submodular set functions", Math. Programming 14 (1978) (the bound of the gains); Ko, Lee &
Queyranne, "An exact algorithm for maximum entropy sampling", Oper. Res. 43 (1995) (branch and bound on
log det over subsets).
"""

from __future__ import annotations

import math
import time

import numba
import numpy as np

from shipsense import numba_cache
from shipsense.design.criteria import value_of_sets

MAX_WORK = 20_000_000
"""Default work limit of :func:`subset_search`: subset values computed plus children screened through the pair
table."""


@numba.njit(cache=True, nogil=True)
def _logdet(M, n):
    """log det of a symmetric positive-definite (n, n) matrix (its lower triangle) by an LDL^T factorisation in
    place, the pivots multiplied and one logarithm taken; -inf if not positive definite."""
    det = 1.0
    for j in range(n):
        d = M[j, j]
        for p in range(j):
            d -= M[j, p] * M[j, p] * M[p, p]
        if not d > 0.0:
            return -np.inf
        M[j, j] = d
        det *= d
        for i in range(j + 1, n):
            s = M[i, j]
            for p in range(j):
                s -= M[i, p] * M[j, p] * M[p, p]
            M[i, j] = s / d
    if 0.0 < det < np.inf:
        return math.log(det)
    total = 0.0                                 # the product left the floating-point range: a sum of logs
    for j in range(n):
        total += math.log(M[j, j])
    return total


@numba.njit(cache=True, nogil=True)
def _value(base, J, m, scratch):
    """f of the design whose matrices are ``base`` (S, n, n) plus candidate m: the mean log det."""
    S, n = base.shape[0], base.shape[1]
    total = 0.0
    for s in range(S):
        for a in range(n):
            for b in range(a + 1):
                scratch[a, b] = base[s, a, b] + J[m, s, a, b]
        total += _logdet(scratch, n)
    return total / S


@numba.njit(cache=True)
def pair_values(J, eps):
    """Values of the single designs (N,) and of every pair (N, N) (the diagonal: -inf).  ``J`` (N, S, n, n)."""
    N, S, n = J.shape[0], J.shape[1], J.shape[2]
    base = np.empty((S, n, n))
    scratch = np.empty((n, n))
    single = np.empty(N)
    pair = np.full((N, N), -np.inf)
    for i in range(N):
        for s in range(S):
            for a in range(n):
                for b in range(n):
                    base[s, a, b] = J[i, s, a, b] + (eps if a == b else 0.0)
        total = 0.0
        for s in range(S):
            for a in range(n):
                for b in range(a + 1):
                    scratch[a, b] = base[s, a, b]
            total += _logdet(scratch, n)
        single[i] = total / S
        for m in range(i + 1, N):
            v = _value(base, J, m, scratch)
            pair[i, m] = v
            pair[m, i] = v
    return single, pair


@numba.njit(cache=True, inline="always")
def _top_sum(values, start, r):
    """Sum of the r largest of values[start:] (-inf if fewer than r)."""
    if r == 0:
        return 0.0
    top = np.full(r, -np.inf)
    for q in range(start, values.shape[0]):
        _keep_top(top, r, values[q])
    return top.sum()


@numba.njit(cache=True, inline="always")
def _keep_top(top, r, v):
    """``v`` into ``top[:r]``, the r largest values so far in decreasing order (insertion)."""
    if v > top[r - 1]:
        j = r - 1
        while j > 0 and top[j - 1] < v:
            top[j] = top[j - 1]
            j -= 1
        top[j] = v


@numba.njit(cache=True)
def _top_sum_min_gain(u, pair_row, single_m, m, r, tmp):
    """The bound of child m's completions by r more candidates after m: the r largest of min(u[q], the gain of q
    given m) over q > m, summed (``pair_row[q] - single_m`` is that gain)."""
    N = u.shape[0]
    for q in range(m + 1, N):
        tmp[q] = min(u[q], pair_row[q] - single_m)
    return _top_sum(tmp, m + 1, r)


@numba.njit(cache=True)
def _suffix_top_sums(u, r, out):
    """out[q] = the sum of the r largest of u[q:] (-inf where fewer than r), for every q, in one backward pass."""
    N = u.shape[0]
    top = np.full(max(r, 1), -np.inf)
    out[N] = 0.0 if r == 0 else -np.inf
    for q in range(N - 1, -1, -1):
        if r > 0:
            _keep_top(top, r, u[q])
            out[q] = top[:r].sum()
        else:
            out[q] = 0.0


@numba.njit(cache=True)
def _feasible(chosen, k, costs, budget, cuts):
    if costs.shape[0] > 0:
        c = 0.0
        for t in range(k):
            c += costs[chosen[t]]
        if c > budget + 1e-9:
            return False
    for row in range(cuts.shape[0]):
        c = 0.0
        for t in range(k):
            c += cuts[row, chosen[t]]
        if c < 1.0 - 1e-9:
            return False
    return True


@numba.njit(cache=True)
def search_branch(i, J, eps, k, single, pair, best, best_set, costs, budget, cuts, max_work, tol):
    """Every k-subset whose first candidate (in the sorted order) is ``i``, depth first, pruned by the bounds.

    Returns (best value, work done, complete, largest bound pruned above the best); ``best_set`` (k,) is updated
    in place.  Stops, incomplete, once ``max_work`` is exceeded.
    """
    N, S, n = J.shape[0], J.shape[1], J.shape[2]
    work = 0
    pruned = -np.inf
    chosen = np.empty(k, dtype=np.int64)
    value = np.empty(k)                         # value[d]: f of chosen[:d + 1]
    u = np.empty((k, N))                        # u[d]: min over chosen[:d + 1] of the pair gains
    M = np.empty((k, S, n, n))                  # M[d]: eps I + the chosen matrices
    nxt = np.empty(k, dtype=np.int64)           # the next child to try at each depth
    suffix = np.empty((k, N + 1))               # suffix[d, q]: the k - d - 2 largest of u[d, q:], summed
    tmp = np.empty(N)
    scratch = np.empty((n, n))
    chosen[0] = i
    value[0] = single[i]
    for q in range(N):
        u[0, q] = pair[i, q] - single[i]
    for s in range(S):
        for a in range(n):
            for b in range(n):
                M[0, s, a, b] = J[i, s, a, b] + (eps if a == b else 0.0)
    if k == 1:
        if value[0] > best and _feasible(chosen, k, costs, budget, cuts):
            best = value[0]
            best_set[0] = i
        return best, work, True, pruned
    d = 0
    nxt[0] = i + 1
    _suffix_top_sums(u[0], k - 2, suffix[0])
    while d >= 0:
        if work > max_work:
            return best, work, False, pruned
        m = nxt[d]
        r = k - d - 2                           # candidates still to add after the child m
        if m > N - 1 - r:                       # no room for r more after m: this node is done
            d -= 1
            continue
        nxt[d] = m + 1
        # screening: the child's gain bound plus the r largest remaining gain bounds
        cheap = value[d] + u[d, m] + suffix[d, m + 1]
        if cheap <= best + tol:
            if cheap > best:
                pruned = max(pruned, cheap)
            continue
        if r > 0:
            work += 1
            b = value[d] + u[d, m] + _top_sum_min_gain(u[d], pair[m], single[m], m, r, tmp)
            if b <= best + tol:
                if b > best:
                    pruned = max(pruned, b)
                continue
        # the child's exact value
        if d == 0:
            v = pair[i, m]
        else:
            work += 1
            v = _value(M[d], J, m, scratch)
        chosen[d + 1] = m
        if r == 0:                              # a full design
            if v > best and _feasible(chosen, k, costs, budget, cuts):
                best = v
                best_set[:] = chosen
            continue
        value[d + 1] = v
        for q in range(N):
            u[d + 1, q] = min(u[d, q], pair[m, q] - single[m])
        nb = v + _top_sum(u[d + 1], m + 1, r)
        if nb <= best + tol:
            if nb > best:
                pruned = max(pruned, nb)
            continue
        for s in range(S):
            for a in range(n):
                for bb in range(n):
                    M[d + 1, s, a, bb] = M[d, s, a, bb] + J[m, s, a, bb]
        d += 1
        nxt[d] = m + 1
        _suffix_top_sums(u[d], k - d - 2, suffix[d])
    return best, work, True, pruned


@numba.njit(cache=True, nogil=True)
def triple_values(J, eps, pa, pb, start, lo, hi, out):
    """Values of the designs {a, b, c}, a < b < c, for the entries [lo, hi) of the triple table ``out``: the pairs
    (a, b) = (pa[p], pb[p]) in lexicographic order, pair p's row (every c > b) from ``start[p]``."""
    N, S, n = J.shape[0], J.shape[1], J.shape[2]
    base = np.empty((S, n, n))
    scratch = np.empty((n, n))
    p = np.searchsorted(start, lo, side="right") - 1
    e = lo
    while e < hi:
        a, b = pa[p], pb[p]
        for s in range(S):
            for x in range(n):
                for y in range(x + 1):
                    base[s, x, y] = J[a, s, x, y] + J[b, s, x, y] + (eps if x == y else 0.0)
        c = b + 1 + (e - start[p])
        while c < N and e < hi:
            out[e] = _value(base, J, c, scratch)
            c += 1
            e += 1
        p += 1


@numba.njit(cache=True, nogil=True)
def search_quads(a, J, eps, pair, triple, start_of, best, best_set, costs, budget, cuts, max_work, tol):
    """Every 4-subset {a, b, c, d} (a < b < c < d) for a fixed first candidate a, with the triple bounds
    ``f(abcd) <= f(abc) + min(gain(d | ab), gain(d | ac), gain(d | bc))``, the gains read from the triple table
    (``triple[start_of[x, y] + z - y - 1]`` = f({x, y, z})).  Same returns as ``search_branch``."""
    N, S, n = J.shape[0], J.shape[1], J.shape[2]
    work = 0
    pruned = -np.inf
    chosen = np.empty(4, dtype=np.int64)
    chosen[0] = a
    smax = np.empty(N + 1)
    base = np.empty((S, n, n))
    scratch = np.empty((n, n))
    for b in range(a + 1, N - 2):
        fab = pair[a, b]
        ab = start_of[a, b] - b - 1
        # suffix maxima of gain(. | ab), and the pair's bound: f(ab) + its two largest gains
        smax[N] = -np.inf
        top1 = -np.inf
        top2 = -np.inf
        for c in range(N - 1, b, -1):
            g = triple[ab + c] - fab
            smax[c] = max(smax[c + 1], g)
            if g > top1:
                top2 = top1
                top1 = g
            elif g > top2:
                top2 = g
        pb_ = fab + top1 + top2
        if pb_ <= best + tol:
            if pb_ > best:
                pruned = max(pruned, pb_)
            continue
        chosen[1] = b
        for c in range(b + 1, N - 1):
            v3 = triple[ab + c]
            cheap = v3 + smax[c + 1]
            if cheap <= best + tol:
                if cheap > best:
                    pruned = max(pruned, cheap)
                continue
            if work > max_work:
                return best, work, False, pruned
            work += 1
            chosen[2] = c
            fac, fbc = pair[a, c], pair[b, c]
            ac = start_of[a, c] - c - 1
            bc = start_of[b, c] - c - 1
            built = False
            for d in range(c + 1, N):
                bound = v3 + min(triple[ab + d] - fab, triple[ac + d] - fac, triple[bc + d] - fbc)
                if bound <= best + tol:
                    if bound > best:
                        pruned = max(pruned, bound)
                    continue
                if not built:
                    for s in range(S):
                        for x in range(n):
                            for y in range(x + 1):
                                base[s, x, y] = (J[a, s, x, y] + J[b, s, x, y] + J[c, s, x, y]
                                                 + (eps if x == y else 0.0))
                    built = True
                work += 1
                v = _value(base, J, d, scratch)
                chosen[3] = d
                if v > best and _feasible(chosen, 4, costs, budget, cuts):
                    best = v
                    best_set[:] = chosen
    return best, work, True, pruned


def subset_search(problem, incumbent=None, max_work=MAX_WORK, time_guard=None, tol=1e-9, cuts=None):
    """The D-optimal k-subset by enumeration pruned with submodular bounds, or the bound it proved.

    Parameters
    ----------
    problem : shipsense.design.placement.DesignProblem
        Its candidates' information (S, N, n, n); costs and a budget, if any, are kept at the leaves.
    incumbent : array of int, optional
        A design to start from (its value is the first pruning level).
    max_work : int
        Work limit: subset values computed plus children screened through the pair table (the pair table itself
        counts N(N-1)/2).
    time_guard : float, optional
        Seconds after which the search stops between first-level branches, whatever the work (a guard; the
        result says that it fired).
    tol : float
        Branches whose bound is within ``tol`` of the best design are dropped (the proved bound accounts for
        them).
    cuts : list of arrays (N,), optional
        Ambiguity cuts (:func:`shipsense.design.placement.place_with_cuts`): a design must have
        ``sum_{i in T} cut_i >= 1`` for each; kept, like the costs, at the leaves (the bounds hold for every
        design, so they hold for the feasible ones).

    Returns
    -------
    dict
        ``chosen`` (k,) in the problem's candidate indices, ``value``, ``upper_bound`` (no k-subset is better),
        ``complete`` (every subset was accounted for: the design is optimal within ``tol``), ``work``,
        ``stopped_by`` (None, "work" or "time guard"), ``seconds`` and ``method``.
    """

    t0 = time.perf_counter()
    N, k = problem.N, problem.k
    if N * (N - 1) // 2 > max_work:   # the pair table alone is beyond the work limit (and its memory with it)
        return {"chosen": None, "value": -np.inf, "upper_bound": np.inf, "complete": False, "work": 0,
                "stopped_by": "work", "seconds": time.perf_counter() - t0, "method": METHODS["pair"]}
    J = np.ascontiguousarray(np.swapaxes(problem.J, 0, 1), dtype=float)       # (N, S, n, n)
    single, pair = pair_values(J, float(problem.eps))
    order = np.argsort(-single, kind="stable")                              # the best single sensor first
    J = np.ascontiguousarray(J[order])
    single = np.ascontiguousarray(single[order])
    pair = np.ascontiguousarray(pair[np.ix_(order, order)])
    rank = np.empty(N, dtype=np.int64)
    rank[order] = np.arange(N)
    costs = np.zeros(0) if problem.costs is None else np.ascontiguousarray(problem.costs[order], dtype=float)
    budget = np.inf if problem.budget is None else float(problem.budget)
    cuts = np.zeros((0, N)) if not cuts else np.ascontiguousarray(np.asarray(cuts, dtype=float)[:, order])
    best_set = np.full(k, -1, dtype=np.int64)
    best = -np.inf
    if incumbent is not None:
        inc = np.sort(rank[np.asarray(incumbent, dtype=np.int64)])
        best = float(value_of_sets(problem, np.asarray(incumbent)[None], "D")[0])
        best_set[:] = inc
    # first-level bounds: f({i}) + the k - 1 largest gains after i (what an unfinished branch can still hold)
    gains = pair - single[:, None]
    first = np.array([single[i] + (np.sort(gains[i, i + 1:])[::-1][: k - 1].sum() if k > 1 else 0.0)
                      if N - 1 - i >= k - 1 else -np.inf for i in range(N)])
    work = N * (N - 1) // 2
    pruned = -np.inf
    stopped_by = None
    unfinished = -np.inf
    triples = None
    if k == 4:
        triples, start_of, work = _triple_table(J, float(problem.eps), work, max_work)
        if triples is None:
            stopped_by = "work"
            unfinished = float(first.max())
    for i in range(N - k + 1) if stopped_by is None else ():
        if first[i] <= best + tol:
            pruned = max(pruned, first[i]) if first[i] > best else pruned
            continue
        if work > max_work:
            stopped_by = "work"
        elif time_guard is not None and time.perf_counter() - t0 > time_guard:
            stopped_by = "time guard"
        if stopped_by is not None:
            unfinished = max(unfinished, float(first[i:].max()))
            break
        if triples is not None:
            best, w, done, pr = search_quads(i, J, float(problem.eps), pair, triples, start_of, best, best_set, costs,
                                             budget, cuts, max_work - work, tol)
        else:
            best, w, done, pr = search_branch(i, J, float(problem.eps), k, single, pair, best, best_set, costs,
                                              budget, cuts, max_work - work, tol)
        work += int(w)
        pruned = max(pruned, pr)
        if not done:
            stopped_by = "work"
            unfinished = max(unfinished, float(first[i:].max()))
            break
    complete = stopped_by is None
    upper = max(best, pruned, unfinished)
    chosen = np.sort(order[best_set]) if best_set[0] >= 0 else None
    value = float(value_of_sets(problem, chosen[None], "D")[0]) if chosen is not None else -np.inf
    return {"chosen": chosen, "value": value, "upper_bound": float(max(upper, value)), "complete": bool(complete),
            "work": int(work), "stopped_by": stopped_by, "seconds": time.perf_counter() - t0,
            "method": METHODS["triple" if k == 4 else "pair"]}


METHODS = {"pair": "enumeration pruned by submodular bounds from the pair values",
           "triple": "enumeration pruned by submodular bounds from every triple's value"}
"""The names :func:`subset_search` reports: k <= 3 pruned through the pair table, k = 4 through the triple table
(its C(N, 3) values computed first)."""


def _triple_table(J, eps, work, max_work):
    """The values of every triple, a < b < c (a flat table, the rows of the pairs (a, b) in lexicographic order,
    ``start_of[a, b]`` where pair (a, b)'s row begins), computed on the CPUs; (None, None, work) if the table
    alone would exceed ``max_work``."""
    from shipsense.parallel import in_chunks

    N = J.shape[0]
    total = N * (N - 1) * (N - 2) // 6
    if work + total > max_work:
        return None, None, work
    pa, pb = np.triu_indices(N, 1)
    lengths = N - 1 - pb
    start = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    start_of = np.zeros((N, N), dtype=np.int64)
    start_of[pa, pb] = start[:-1]
    out = np.empty(total)
    pa, pb = pa.astype(np.int64), pb.astype(np.int64)
    in_chunks(lambda lo, hi: triple_values(J, eps, pa, pb, start, lo, hi, out), total, split_min=1 << 16)
    return out, start_of, work + total


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
