r"""Sensor placement: convex relaxation with a certificate, rounding, swaps and ambiguity cuts.

Joshi & Boyd, "Sensor selection via convex optimization", IEEE TSP 2009, in
its Bayesian form over S passages drawn from the prior.  With per-candidate
passage Fisher matrices :math:`J_{si}` (internal units), the prior standard
deviations :math:`D` of the passage parameters and :math:`\tilde J = D J D`,

.. math::  \max_{0 \le w \le 1,\ \sum w = k}\ f(w) = \frac{1}{S}\sum_s \log\det\Big(I + \sum_i w_i \tilde J_{si}\Big)

(D-optimal; A: :math:`-\operatorname{tr} M_s^{-1}`; E: :math:`\min_s \lambda_{\min}(M_s)`).
The problem is normalised by a scalar :math:`c` (``I + X = c (I/c + X/c)``),
which leaves the optimiser unchanged and keeps the cone solver's data O(1)
(unscaled, the data span many orders of magnitude and CLARABEL failed on S1); the prior
term is ``1/c`` exactly (the scenario's prior), unless a floor is asked for
(see :func:`build_problem`).

Solvers (:func:`solve_relaxation`): CLARABEL through cvxpy, projected
gradient on the capped simplex, Frank–Wolfe with a linear-programming
oracle when there are cuts or costs; the first-order ones stop on their
duality gap, and a CLARABEL failure falls back to them.  Rounding: top-k
and greedy, then an exchange search (:func:`swap_refine`); for few sensors
an exact search over the subsets (D: :mod:`shipsense.design.subsets`; A, E:
:func:`branch_and_bound`), stopped on its work, tightens the bound.

Certificate.  After every solve the objective and its (super)gradient ``g``
are recomputed in numpy from the returned weights; for a concave ``f``,
``f* <= f(w) + max_{w' feasible} g.(w' - w)`` (the Frank–Wolfe bound: the sum
of the k largest ``g_i`` minus ``g.w``).  That upper bound holds for every
k-sensor design whatever the solver said; the gap of the rounded design to it
is reported.

Ambiguity cuts.  For each ambiguous pair ``(theta, theta')`` found on the
current design, with ``d_i`` the pair's discrepancy at candidate ``i`` (chi-square
units), add ``sum_i w_i min(d_i / tau, 1) >= 1`` and solve again, until the
rounded design passes the ambiguity check.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from shipsense.design.criteria import CRITERIA, criterion_value, value_of_sets
from shipsense.design.fisher import passage_fim
from shipsense.design.observability import DEFAULT_CHI2, check_array
from shipsense.models.transitions import powers


# -- candidates -------------------------------------------------------------------
def grid_candidates(polygon, spacing, z, exclusions=(), min_spacing=0.0):
    """Grid points inside a polygon, outside exclusion zones, thinned to a minimum spacing.

    Parameters
    ----------
    polygon : sequence of (x, y)
        The deployable area.
    spacing : float
        Grid step, m.
    z : float
        Sensor height (world z), m.
    exclusions : sequence
        Each a circle ``(x, y, radius)`` or a polygon (sequence of (x, y)).
    min_spacing : float
        Greedily drop points closer than this to a kept one.
    """
    from matplotlib.path import Path

    poly = np.asarray(polygon, dtype=float)
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    xs = np.arange(lo[0], hi[0] + 1e-9, spacing)
    ys = np.arange(lo[1], hi[1] + 1e-9, spacing)
    pts = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    keep = Path(poly).contains_points(pts, radius=1e-9) | Path(poly).contains_points(pts, radius=-1e-9)
    for ex in exclusions:
        ex = np.asarray(ex, dtype=float)
        if ex.ndim == 1 and ex.size == 3:
            keep &= np.hypot(*(pts - ex[:2]).T) > ex[2]
        else:
            keep &= ~Path(ex).contains_points(pts)
    pts = pts[keep]
    if min_spacing > 0 and len(pts):
        kept = [0]
        for i in range(1, len(pts)):
            if np.min(np.hypot(*(pts[kept] - pts[i]).T)) >= min_spacing:
                kept.append(i)
        pts = pts[kept]
    return np.column_stack([pts, np.full(len(pts), float(z))])


# -- information ----------------------------------------------------------------------
@dataclass(frozen=True)
class DesignProblem:
    """Scaled per-candidate information ``J`` (S, N, n, n), the prior term ``eps`` and the number ``k``.

    Optional per-candidate ``costs`` (N,) with a ``budget``: designs must also
    satisfy ``sum_i c_i w_i <= budget``.
    """

    J: np.ndarray
    eps: float
    k: int
    scale: float
    costs: np.ndarray | None = None
    budget: float | None = None

    def with_costs(self, costs, budget):
        costs = np.asarray(costs, dtype=float)
        if costs.shape != (self.N,) or not np.all(np.isfinite(costs)) or np.any(costs < 0):
            raise ValueError(f"costs must be {self.N} finite non-negative numbers")
        if not np.isfinite(budget) or budget < np.sort(costs)[: self.k].sum():
            raise ValueError(f"budget {budget:g} cannot pay for {self.k} sensors (the cheapest cost "
                             f"{np.sort(costs)[: self.k].sum():g})")
        from dataclasses import replace

        return replace(self, costs=costs, budget=float(budget))

    @property
    def n(self):
        return self.J.shape[-1]

    @property
    def N(self):
        return self.J.shape[1]


def build_problem(model, thetas, steps, k, prior_std, stride=2, prior_floor=None, progress=None, motion=None):
    """Per-candidate Fisher matrices of passages ``thetas`` (S, n) for the candidate ``model`` (one sensor each).

    The matrices are scaled by the prior standard deviations ``prior_std``
    (``D J D``, so the prior information is the identity) and divided by
    ``c``, the mean eigenvalue of a uniform k-sensor design, so that the data
    are O(1).  The prior term then is ``1/c``: the Bayesian criterion with the
    prior covariance ``diag(prior_std**2)`` exactly.

    Parameters
    ----------
    prior_floor : float, optional
        Floor the scaled prior term at this value (a regulariser: the true
        prior term can be tiny against the data, as on S1, where CLARABEL's A-
        and E-optimal solves were inaccurate).  None (the default): no floor,
        the scenario's prior as it is.  The floor changes the criterion, not
        only the numerics: the design it picks can be less efficient than the
        Bayes-optimal one (docs: Results).
    progress : callable, optional
        Called with the fraction of the Fisher matrices built.
    motion : PassageMotion, optional
        The passages' manoeuvres (:func:`~shipsense.design.fisher.passage_fim`); default straight passages.
    """
    J = passage_fim(model, thetas, steps, per_sensor=True, stride=stride, progress=progress,
                    motion=motion)                                                           # (S, N, n, n)
    D = np.asarray(prior_std, dtype=float)
    if D.shape != (J.shape[-1],) or not np.all(np.isfinite(D)) or np.any(D <= 0):
        raise ValueError(f"prior_std must be {J.shape[-1]} positive numbers, got {D}")
    J = J * D[:, None] * D[None, :]
    c = float(k * np.mean(np.trace(J, axis1=-2, axis2=-1)) / J.shape[-1])
    c = c if c > 0 else 1.0
    eps = 1.0 / c if prior_floor is None else max(1.0 / c, float(prior_floor))
    return DesignProblem(np.ascontiguousarray(J / c), eps, int(k), c)


def _flat(problem):
    """The information as (S, N, n*n) (a view)."""
    S, N, n = problem.J.shape[0], problem.N, problem.n
    return problem.J.reshape(S, N, n * n)


def _matrices(problem, w):
    """M_s = eps I + sum_i w_i J_si for weights w (..., N) -> (..., S, n, n)."""
    w = np.asarray(w, dtype=float)
    n = problem.n
    X = np.matmul(w[..., None, None, :], _flat(problem))[..., 0, :]          # (..., S, n*n)
    return problem.eps * np.eye(n) + X.reshape(X.shape[:-1] + (n, n))


def objective(problem, w, criterion="D"):
    """The criterion (to maximise) at weights w (..., N)."""
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")
    return criterion_value(_matrices(problem, w), criterion)


def gradient(problem, w, criterion="D"):
    """(Super)gradient of the criterion at w (N,)."""
    M = _matrices(problem, np.asarray(w, dtype=float))                           # (S, n, n)
    S, n = M.shape[0], problem.n
    if criterion in ("D", "A"):
        Minv = np.linalg.inv(M)
        G = Minv if criterion == "D" else Minv @ Minv
        G = 0.5 * (G + np.swapaxes(G, -1, -2))
        return np.matmul(_flat(problem), G.reshape(S, n * n, 1))[..., 0].mean(axis=0)
    vals, vecs = np.linalg.eigh(M)
    s = int(np.argmin(vals[:, 0]))
    u = vecs[s, :, 0]
    return _flat(problem)[s] @ np.outer(u, u).ravel()


def certified_bound(problem, w, criterion="D", cuts=None):
    """Upper bound on the relaxation optimum (hence on every k-sensor design) from weights w.

    ``f(w) + max_{w' in C} g.(w' - w)``; with cuts the linear maximisation over
    the cut polytope is solved as a linear program.
    """
    w = np.clip(np.asarray(w, dtype=float), 0.0, 1.0)
    g = gradient(problem, w, criterion)
    f = float(objective(problem, w, criterion))
    if not cuts and problem.costs is None:
        best = float(np.sort(g)[::-1][: problem.k].sum())
    else:
        from scipy.optimize import linprog

        rows, rhs = [-np.asarray(c) for c in cuts or []], [-1.0] * len(cuts or [])
        if problem.costs is not None:
            rows.append(problem.costs)
            rhs.append(problem.budget)
        res = linprog(-g, A_ub=np.array(rows), b_ub=np.array(rhs), A_eq=np.ones((1, problem.N)), b_eq=[problem.k],
                      bounds=[(0, 1)] * problem.N, method="highs")
        if not res.success:
            raise RuntimeError(f"certificate LP failed: {res.message}")
        best = float(-res.fun)
    return f + best - float(g @ w), f


# -- solvers ---------------------------------------------------------------------------
def solve_convex(problem, criterion="D", cuts=None, return_status=False):
    """The relaxation by cvxpy with CLARABEL; returns the weights (N,) (and the solver status).

    An "inaccurate" status is not an error: the numpy certificate of
    :func:`certified_bound` says how far from optimal the weights are.
    """
    import warnings

    import cvxpy as cp

    N, n, S = problem.N, problem.n, problem.J.shape[0]
    w = cp.Variable(N)
    flat = problem.J.reshape(S, N, n * n)
    Ms = []
    for s in range(S):
        M = cp.reshape(flat[s].T @ w, (n, n), order="C") + problem.eps * np.eye(n)
        Ms.append((M + M.T) / 2)
    if criterion == "D":
        obj = cp.Maximize(sum(cp.log_det(M) for M in Ms) / S)
    elif criterion == "A":
        obj = cp.Minimize(sum(cp.tr_inv(M) for M in Ms) / S)
    elif criterion == "E":
        t = cp.Variable()
        obj = cp.Maximize(t)
    else:
        raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")
    cons = [w >= 0, w <= 1, cp.sum(w) == problem.k]
    if criterion == "E":
        cons += [cp.lambda_min(M) >= t for M in Ms]
    for c in cuts or []:
        cons.append(np.asarray(c) @ w >= 1)
    if problem.costs is not None:
        cons.append(problem.costs @ w <= problem.budget)
    prob = cp.Problem(obj, cons)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Solution may be inaccurate")
        try:
            prob.solve(solver=cp.CLARABEL)
        except cp.error.SolverError:
            # CLARABEL can stop with InsufficientProgress on these badly scaled problems (information many orders
            # of magnitude above the prior term), and whether it does can turn on the last bit of the data. One
            # retry with a stronger static regularisation; its status says "inaccurate" and the numpy
            # certificate says how far from optimal the weights are.
            try:
                prob.solve(solver=cp.CLARABEL, static_regularization_constant=1e-7)
            except cp.error.SolverError as err:
                raise RuntimeError(f"CLARABEL failed on the relaxation ({err})") from None
    if w.value is None:
        raise RuntimeError(f"the convex relaxation failed: {prob.status}")
    w = np.clip(np.asarray(w.value, dtype=float), 0.0, 1.0)
    return (w, prob.status) if return_status else w


def project_capped_simplex(v, k):
    """Euclidean projection of v onto {0 <= w <= 1, sum w = k} (bisection on the shift)."""
    lo, hi = v.min() - 1.0, v.max()
    for _ in range(100):
        tau = 0.5 * (lo + hi)
        s = np.clip(v - tau, 0.0, 1.0).sum()
        if s > k:
            lo = tau
        else:
            hi = tau
    return np.clip(v - 0.5 * (lo + hi), 0.0, 1.0)


def _fw_gap(problem, w, g):
    """Frank–Wolfe gap over the capped simplex: max_{w' feasible} g.(w' - w) (the k largest g_i minus g.w)."""
    return float(np.partition(g, problem.N - problem.k)[problem.N - problem.k:].sum() - g @ w)


def solve_first_order(problem, criterion="D", iterations=3000, tol=1e-4, return_info=False, w0=None):
    """Projected-gradient ascent on the relaxation, stopped by the duality (Frank–Wolfe) gap.

    The relaxation's feasible set is the capped simplex ``{0 <= w <= 1,
    sum w = k}``; each step moves along the gradient and projects back
    (:func:`project_capped_simplex`), with a backtracking step size.  For a
    concave criterion the Frank–Wolfe gap ``max_w' g.(w' - w)`` bounds the
    distance of ``f(w)`` to the relaxed optimum, so the iteration stops when
    it is below ``tol`` (nats for D).  Unconstrained only (no cuts, no costs:
    see :func:`solve_frank_wolfe` for those).

    Returns
    -------
    w : ndarray, shape (N,)
    info : dict, with ``return_info``
        ``converged`` (gap <= tol), ``iterations`` and ``gap``.
    """
    w = np.full(problem.N, problem.k / problem.N) if w0 is None else project_capped_simplex(np.asarray(w0), problem.k)
    f = float(objective(problem, w, criterion))
    step = 1.0
    gap = np.inf
    it = 0
    for _ in range(iterations):
        it += 1
        g = gradient(problem, w, criterion)
        gap = _fw_gap(problem, w, g)
        if gap <= tol:
            break
        while True:
            trial = project_capped_simplex(w + step * g, problem.k)
            ft = float(objective(problem, trial, criterion))
            if ft >= f or step < 1e-14:
                break
            step *= 0.5
        if ft < f:   # no ascent even with the smallest step: at the precision limit
            break
        w, f = trial, ft
        step *= 2.0
    info = {"converged": bool(gap <= tol), "iterations": it, "gap": float(gap)}
    return (w, info) if return_info else w


def _lmo(problem, g, cuts):
    """Linear maximisation oracle: argmax g.w over the relaxation's polytope (capped simplex, cuts, costs)."""
    from scipy.optimize import linprog

    rows, rhs = [-np.asarray(c) for c in cuts or []], [-1.0] * len(cuts or [])
    if problem.costs is not None:
        rows.append(problem.costs)
        rhs.append(problem.budget)
    res = linprog(-g, A_ub=np.array(rows) if rows else None, b_ub=np.array(rhs) if rhs else None,
                  A_eq=np.ones((1, problem.N)), b_eq=[problem.k], bounds=[(0, 1)] * problem.N, method="highs")
    if not res.success:
        raise RuntimeError(f"the relaxation is infeasible with these cuts or costs ({res.message})")
    return np.clip(res.x, 0.0, 1.0)


def solve_frank_wolfe(problem, criterion="D", cuts=None, iterations=300, tol=1e-3, return_info=False):
    """Frank–Wolfe on the relaxation with linear constraints (ambiguity cuts, a cost budget).

    Each step solves a linear program over the polytope (the oracle) and
    moves towards its vertex with a line search; the step's duality gap
    ``g.(v - w)`` stops the iteration.  Slower to converge than the conic
    solver but it cannot fail on scaling, so it is the fallback for
    constrained problems.  Same returns as :func:`solve_first_order`.
    """
    g = gradient(problem, np.full(problem.N, problem.k / problem.N), criterion)
    w = _lmo(problem, g, cuts)
    f = float(objective(problem, w, criterion))
    gap = np.inf
    it = 0
    gammas = np.array([1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125, 0.015625, 0.0078125])
    for _ in range(iterations):
        it += 1
        g = gradient(problem, w, criterion)
        v = _lmo(problem, g, cuts)
        gap = float(g @ (v - w))
        if gap <= tol:
            break
        trials = w[None] + gammas[:, None] * (v - w)[None]
        vals = objective(problem, trials, criterion)
        i = int(np.argmax(vals))
        if vals[i] <= f:
            break
        w, f = trials[i], float(vals[i])
    info = {"converged": bool(gap <= tol), "iterations": it, "gap": float(gap)}
    return (w, info) if return_info else w


# -- rounding ----------------------------------------------------------------------------
def feasible(sets, cuts, problem=None):
    sets = np.asarray(sets)
    ok = np.ones(len(sets), dtype=bool)
    if cuts:
        C = np.asarray(cuts)                                             # (ncuts, N)
        ok &= np.all(C[:, sets].sum(axis=-1) >= 1.0 - 1e-9, axis=0)
    if problem is not None and problem.costs is not None:
        ok &= problem.costs[sets].sum(axis=-1) <= problem.budget + 1e-9
    return ok


def _add_each(problem, M, criterion, subset=None, chunk=1024):
    """Criterion of ``M + J_i`` for every candidate i (or those in ``subset``): M (S, n, n) -> (N,) (-inf outside
    the subset), in chunks of candidates."""
    idx = np.arange(problem.N) if subset is None else np.asarray(subset)
    out = np.full(problem.N, -np.inf)
    for start in range(0, len(idx), chunk):
        part = idx[start:start + chunk]
        T = M[None] + np.swapaxes(problem.J[:, part], 0, 1)                      # (B, S, n, n)
        out[part] = criterion_value(T, criterion)
    return out


def greedy(problem, criterion="D", cuts=None):
    """Add, k times, the candidate that improves the criterion most (one batch of N evaluations per step)."""
    chosen = []
    M = problem.eps * np.broadcast_to(np.eye(problem.n), problem.J.shape[:1] + (problem.n, problem.n)).copy()
    C = None if not cuts else np.asarray(cuts)
    for step in range(problem.k):
        vals = _add_each(problem, M, criterion)
        vals[chosen] = -np.inf
        last = step == problem.k - 1
        if last and C is not None:
            vals = np.where(np.all(C[:, chosen].sum(axis=1)[:, None] + C >= 1.0 - 1e-9, axis=0), vals, -np.inf)
        if problem.costs is not None:   # keep enough budget for the cheapest completion
            spent = problem.costs[chosen].sum() + problem.costs
            left = np.sort(problem.costs)[: problem.k - len(chosen) - 1].sum()
            vals = np.where(spent + left <= problem.budget + 1e-9, vals, -np.inf)
        i = int(np.argmax(vals))
        chosen.append(i)
        M = M + problem.J[:, i]
    return np.array(chosen)


def swap_refine(problem, chosen, criterion="D", cuts=None, max_rounds=50, shortlist=None, full_round=True):
    """Exchange search: swap a placed sensor for a candidate while the criterion improves.

    For each placed sensor in turn, every unplaced candidate is tried in its
    place (one batch of evaluations of ``M - J_out + J_in``) and the best
    swap is kept if it improves the criterion and keeps the cuts and the
    budget satisfied; rounds repeat until a whole round changes nothing (a
    local optimum under single exchanges) or ``max_rounds``.  Never worsens.

    ``shortlist`` (indices): try only these candidates until they give no
    improvement, then one round over all candidates (which goes on with the
    full set if it still improves), so the result is a local optimum over all
    candidates either way; the shortlist only saves evaluations at large N.
    ``full_round=False`` stops when the shortlist is exhausted.

    Returns
    -------
    chosen : ndarray, shape (k,), sorted
    value : float
    """
    chosen = np.array(chosen, dtype=int)
    best = float(value_of_sets(problem, chosen[None], criterion)[0])
    if not feasible(chosen[None], cuts, problem)[0]:
        best = -np.inf                      # any feasible swap is an improvement
    C = None if not cuts else np.asarray(cuts)
    M = problem.eps * np.eye(problem.n) + problem.J[:, chosen].sum(axis=1)          # (S, n, n)
    subset = None if shortlist is None else np.unique(shortlist)
    for _ in range(max_rounds):
        improved = False
        for j in range(len(chosen)):
            out = chosen[j]
            Mj = M - problem.J[:, out]
            vals = _add_each(problem, Mj, criterion, subset)
            vals[chosen] = -np.inf
            if C is not None:
                base = C[:, chosen].sum(axis=1) - C[:, out]
                vals = np.where(np.all(base[:, None] + C >= 1.0 - 1e-9, axis=0), vals, -np.inf)
            if problem.costs is not None:
                spent = problem.costs[chosen].sum() - problem.costs[out] + problem.costs
                vals = np.where(spent <= problem.budget + 1e-9, vals, -np.inf)
            i = int(np.argmax(vals))
            if vals[i] > best + 1e-10 * max(1.0, abs(best)):
                chosen[j], best, M, improved = i, float(vals[i]), Mj + problem.J[:, i], True
        if not improved:
            if subset is None or not full_round:
                break
            subset = None                   # the shortlist is exhausted: a round over every candidate
    chosen = np.sort(chosen)
    if np.isfinite(best):   # re-evaluate from scratch (the running M accumulates round-off)
        best = float(value_of_sets(problem, chosen[None], criterion)[0])
    return chosen, best


def round_design(problem, w, criterion="D", cuts=None):
    """Top-k and greedy rounding, each refined by the exchange search; the better one.

    Above 8k candidates the exchange search starts from a shortlist: the 4k
    candidates of largest relaxed weight and the 4k of largest gradient at
    the relaxed optimum (those a swap can improve most, to first order); the
    better of the two refined designs then gets exchange rounds over every
    candidate until none improves.
    """
    shortlist = None
    if problem.N > 8 * problem.k:
        g = gradient(problem, np.clip(w, 0.0, 1.0), criterion)
        shortlist = np.union1d(np.argsort(w)[::-1][: 4 * problem.k], np.argsort(g)[::-1][: 4 * problem.k])
    top = np.argsort(w)[::-1][: problem.k]
    if not feasible(top[None], cuts, problem)[0]:
        top = greedy(problem, criterion, cuts)
    if shortlist is None:
        a = swap_refine(problem, top, criterion, cuts)
        b = swap_refine(problem, greedy(problem, criterion, cuts), criterion, cuts)
        return a if a[1] >= b[1] else b
    a = swap_refine(problem, top, criterion, cuts, shortlist=shortlist, full_round=False)
    b = swap_refine(problem, greedy(problem, criterion, cuts), criterion, cuts, shortlist=shortlist, full_round=False)
    best = a if a[1] >= b[1] else b
    return swap_refine(problem, best[0], criterion, cuts, shortlist=shortlist)   # ends with a full round


# -- branch and bound (few sensors) --------------------------------------------------------
BB_NODES = 2000
"""Default work limit of :func:`branch_and_bound`: node bounds computed."""
EXACT_MAX_K = 4
"""Largest k for which :func:`place` runs the exact search of the D criterion
(:func:`shipsense.design.subsets.subset_search`); other criteria get :func:`branch_and_bound` up to k = 3."""


def _node_bound(problem, criterion, lo, hi, w0, iterations=150, tol=1e-4):
    """Upper bound on the relaxation with ``lo <= w <= hi`` (some weights fixed at 0 or 1): projected gradient,
    then the Frank–Wolfe bound (valid whether or not the iteration converged).  Returns (bound, w)."""
    k = problem.k

    def project(v):
        a, b = (v - hi).min() - 1.0, (v - lo).max() + 1.0
        for _ in range(60):
            tau = 0.5 * (a + b)
            if np.clip(v - tau, lo, hi).sum() > k:
                a = tau
            else:
                b = tau
        return np.clip(v - 0.5 * (a + b), lo, hi)

    w = project(w0)
    f = float(objective(problem, w, criterion))
    step = 1.0
    free = lo < hi
    m = k - int(lo.sum())                 # weight left for the free candidates
    for _ in range(iterations):
        g = gradient(problem, w, criterion)
        best = g[lo == 1].sum() + (np.sort(g[free])[::-1][:m].sum() if m > 0 else 0.0)
        gap = best - g @ w
        if gap <= tol:
            break
        while True:
            trial = project(w + step * g)
            ft = float(objective(problem, trial, criterion))
            if ft >= f or step < 1e-14:
                break
            step *= 0.5
        if ft < f:
            break
        w, f = trial, ft
        step *= 2.0
    g = gradient(problem, w, criterion)
    best = g[lo == 1].sum() + (np.sort(g[free])[::-1][:m].sum() if m > 0 else 0.0)
    return f + best - float(g @ w), w


def branch_and_bound(problem, criterion="D", incumbent=None, max_nodes=BB_NODES, time_guard=None, w0=None):
    """Best-first branch and bound on the relaxation (no cuts, no costs): the optimal k-subset, or what it proved.

    Each node fixes some candidates in (w = 1) or out (w = 0); its bound is
    the certified relaxation bound with those fixings (:func:`_node_bound`, a
    fixed number of iterations).  Nodes whose bound does not beat the incumbent
    are pruned; the candidate of largest relaxed weight is branched on.
    Stopped after ``max_nodes`` node bounds (the work, so that what it proves
    does not depend on the machine's load), or by the ``time_guard`` (seconds;
    the result says so), the bound it proved is the largest bound of the open
    nodes (or the incumbent's value if none is left: then the incumbent is
    optimal).

    Returns
    -------
    dict
        ``chosen`` (k,), ``value``, ``upper_bound`` (proved), ``work`` (node bounds computed),
        ``complete`` (the tree was exhausted), ``stopped_by`` (None, "work" or "time guard"),
        ``seconds`` and ``method``.
    """
    import heapq

    t0 = time.perf_counter()
    stopped_by = None
    N, k = problem.N, problem.k
    if incumbent is None:
        incumbent = greedy(problem, criterion)
    best_set = np.sort(np.asarray(incumbent))
    best = float(value_of_sets(problem, best_set[None], criterion)[0])
    lo, hi = np.zeros(N), np.ones(N)
    w0 = np.full(N, k / N) if w0 is None else np.asarray(w0, dtype=float)
    bound, w = _node_bound(problem, criterion, lo, hi, w0)
    heap = [(-bound, 0, lo, hi, w)]
    counter, nodes = 1, 1
    tol = 1e-9
    while heap:
        if nodes >= max_nodes:
            stopped_by = "work"
            break
        if time_guard is not None and time.perf_counter() - t0 > time_guard:
            stopped_by = "time guard"
            break
        neg, _, lo, hi, w = heapq.heappop(heap)
        if -neg <= best + tol:
            heap = []                            # best-first: every other open node is worse
            break
        fixed_in = np.flatnonzero(lo == 1)
        free = np.flatnonzero(lo < hi)
        if len(fixed_in) == k or len(fixed_in) + len(free) == k:
            leaf = np.sort(np.concatenate([fixed_in, free]) if len(fixed_in) < k else fixed_in)
            v = float(value_of_sets(problem, leaf[None], criterion)[0])
            if v > best:
                best, best_set = v, leaf
            continue
        i = int(free[np.argmax(w[free])])
        for child in ("in", "out"):
            clo, chi = lo.copy(), hi.copy()
            if child == "in":
                clo[i] = 1.0
            else:
                chi[i] = 0.0
            if clo.sum() > k or chi.sum() < k:
                continue
            b, cw = _node_bound(problem, criterion, clo, chi, w)
            nodes += 1
            if b > best + tol:
                heapq.heappush(heap, (-b, counter, clo, chi, cw))
                counter += 1
    complete = not heap
    proved = best if complete else max(best, max(-h[0] for h in heap))
    return {"chosen": best_set, "value": best, "upper_bound": float(proved), "work": nodes,
            "complete": bool(complete), "stopped_by": None if complete else stopped_by,
            "seconds": time.perf_counter() - t0, "method": "branch and bound on the relaxation"}


# -- the whole method ----------------------------------------------------------------------
SOLVERS = ("auto", "clarabel", "first-order")


@dataclass
class Placement:
    """A placement: the chosen candidates and the figures behind them.

    ``method`` is "convex" when the interior-point solver's weights were
    used and "first-order" otherwise; ``solver`` names the algorithm that
    produced them (``clarabel``, ``projected-gradient``, ``frank-wolfe``),
    ``converged`` whether it met its own stopping rule, and ``message`` why
    another solver than the one asked for ran (empty otherwise).
    """

    chosen: np.ndarray
    weights: np.ndarray
    criterion: str
    relaxation: float
    upper_bound: float
    value: float
    method: str
    seconds: float
    cuts: list = field(default_factory=list)
    verdict: object = None
    status: str = "optimal"
    solver: str = ""
    converged: bool = True
    message: str = ""
    dimension: int = 0
    check_seconds: float = 0.0
    branch_and_bound: dict | None = None

    @property
    def certified_gap(self) -> float:
        """Upper bound minus the rounded design's value (>= 0): no k-sensor design beats it by more."""
        return float(self.upper_bound - self.value)

    @property
    def guaranteed_efficiency(self) -> float | None:
        """Lower bound on the design's efficiency relative to the best k-sensor design.

        D: ``exp(-gap / d)`` (d the parameter dimension: the ratio of the
        geometric-mean eigenvalues, averaged over passages); A: ``bound /
        value`` (ratio of the averaged traces of the inverse); E: ``value /
        bound``.  None where it is undefined (no dimension, E bound <= 0, another criterion).
        """
        gap = max(self.certified_gap, 0.0)
        if self.criterion == "D":
            return float(np.exp(-gap / self.dimension)) if self.dimension else None
        if self.criterion == "A":
            return float(min(1.0, self.upper_bound / self.value)) if self.value < 0 else None
        if self.criterion == "E":
            return float(min(1.0, self.value / self.upper_bound)) if self.upper_bound > 0 and self.value > 0 else None
        return None


def solve_relaxation(problem, criterion="D", solver="auto", cuts=None, first_order_above=800):
    """Solve the relaxation with the chosen (or the automatically chosen) solver, falling back on failure.

    ``auto``: CLARABEL (interior point) up to ``first_order_above``
    candidates, otherwise projected gradient (no cuts, no costs) or
    Frank–Wolfe (with them).  ``clarabel``: CLARABEL, and if it fails the
    first-order method, with a message saying so.  ``first-order``: projected
    gradient or Frank–Wolfe.

    Returns
    -------
    w : ndarray, shape (N,)
    info : dict
        ``method`` ("convex" / "first-order"), ``solver``, ``status``,
        ``converged``, ``message``.
    """
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
    constrained = bool(cuts) or problem.costs is not None
    if solver == "auto":
        solver = "clarabel" if problem.N <= first_order_above else "first-order"
    message = ""
    if solver == "clarabel":
        try:
            w, status = solve_convex(problem, criterion, cuts, return_status=True)
            info = {"method": "convex", "solver": "clarabel", "status": status, "converged": status == "optimal",
                    "message": ""}
            if not constrained and status != "optimal":
                # an inaccurate interior point (the prior term is tiny against the data): polish it by projected
                # gradient from there, stopped by the duality gap
                upper, f = certified_bound(problem, w, criterion)
                if upper - f > 1e-4:
                    w, fo = solve_first_order(problem, criterion, return_info=True, w0=w)
                    info.update(solver="clarabel+projected-gradient", converged=fo["converged"],
                                status=f"{status}; polished by projected gradient: duality gap {fo['gap']:.2g} "
                                       f"after {fo['iterations']} iterations")
            return w, info
        except Exception as err:   # cvxpy and the solver raise several types; the fallback is always safe
            message = f"CLARABEL failed ({type(err).__name__}: {err}); fell back to the first-order solver"
    if constrained:
        w, info = solve_frank_wolfe(problem, criterion, cuts, return_info=True)
        name = "frank-wolfe"
    else:
        w, info = solve_first_order(problem, criterion, return_info=True)
        name = "projected-gradient"
    status = f"{'converged' if info['converged'] else 'not converged'} after {info['iterations']} iterations " \
             f"(duality gap {info['gap']:.2g})"
    return w, {"method": "first-order", "solver": name, "status": status, "converged": info["converged"],
               "message": message}


def pair_discrepancy(model, theta, theta_alt, steps):
    """Per-sensor discrepancy d_i (chi-square units) of two passages (internal units) for a candidate model."""
    Ak = powers(model.A, steps)
    r = model.residual(model.h(np.einsum("kij,j->ki", Ak, theta_alt)), model.h(np.einsum("kij,j->ki", Ak, theta)))
    per_channel = np.sum((r / np.sqrt(model.R)) ** 2, axis=0)
    S = len(model.array.ids)
    return np.bincount(model.array.channel_sensor, weights=per_channel, minlength=S)


def place(problem, criterion="D", method="auto", cuts=None, first_order_above=800, bb_max_k=EXACT_MAX_K,
          bb_work=0, bb_seconds=None):
    """Solve the relaxation, certify it, round and refine; returns a :class:`Placement`.

    ``method``: ``auto``, ``clarabel`` (also spelled ``convex``) or
    ``first-order``; see :func:`solve_relaxation`.  A solver failure falls
    back to the first-order method (the Placement's ``message`` says so).

    For few sensors (``k <= bb_max_k``), where the relaxation is loose, a search
    over the subsets tightens the bound (and may improve the design): for the D
    criterion the exact enumeration pruned by submodular bounds
    (:func:`shipsense.design.subsets.subset_search`, which keeps cuts and costs
    at its leaves), for A and E (k <= 3, no cuts, no costs)
    :func:`branch_and_bound` on the relaxation.  It stops on its work limit
    ``bb_work`` (0, the default here: no search; None: each search's default,
    as ``shipsense design`` runs it), with
    ``bb_seconds`` only as a guard (None: none) that the result names when it
    fires; what it proved is in ``branch_and_bound``.
    """
    from shipsense.design.subsets import MAX_WORK, subset_search

    t0 = time.perf_counter()
    solver = "clarabel" if method == "convex" else method
    if solver not in SOLVERS:
        raise ValueError(f"method must be one of 'auto', 'clarabel' ('convex') or 'first-order', got {method!r}")
    w, info = solve_relaxation(problem, criterion, solver, cuts, first_order_above)
    upper, relax = certified_bound(problem, w, criterion, cuts)
    chosen, value = round_design(problem, w, criterion, cuts)
    bb = None
    if bb_work != 0 and problem.k <= bb_max_k:
        if criterion == "D":
            bb = subset_search(problem, incumbent=chosen if feasible(chosen[None], cuts, problem)[0] else None,
                               max_work=MAX_WORK if bb_work is None else bb_work, time_guard=bb_seconds, cuts=cuts)
        elif problem.k <= 3 and not cuts and problem.costs is None:
            bb = branch_and_bound(problem, criterion, incumbent=chosen, w0=w, time_guard=bb_seconds,
                                  max_nodes=BB_NODES if bb_work is None else bb_work)
    if bb is not None:
        if bb["chosen"] is not None and bb["value"] > value:
            chosen, value = bb["chosen"], bb["value"]
        upper = min(upper, bb["upper_bound"])
        bb = {k: v for k, v in bb.items() if k != "chosen"}
    upper = max(upper, value)   # the bound holds for every design; round-off never makes it lower than one
    return Placement(chosen, w, criterion, relax, upper, value, info["method"], time.perf_counter() - t0,
                     list(cuts or []), status=info["status"], solver=info["solver"], converged=info["converged"],
                     message=info["message"], dimension=problem.n, branch_and_bound=bb)


def place_with_cuts(problem, candidate_model, thetas, steps, criterion="D", tau=DEFAULT_CHI2, max_rounds=6,
                    check_passages=4, starts=8, seed=0, progress=False, solver="auto", bb_work=0, bb_seconds=None,
                    motion=None):
    """Place sensors, then add ambiguity cuts until the rounded design passes the ambiguity check.

    The check is :func:`~shipsense.design.observability.check_array` on the
    rounded design (k sensors, not the candidates); each ambiguous pair it
    finds becomes one cut, with the pair's per-candidate discrepancy computed
    for all candidates in one batch (:func:`pair_discrepancy`).  ``motion``: the passages' manoeuvres
    (:class:`~shipsense.design.fisher.PassageMotion`, for the check's Fisher information).
    """
    from shipsense.models.field_model import subset_model

    cuts = []
    result = None
    solve_seconds = check_seconds = 0.0
    messages = []
    for _ in range(max_rounds):
        result = place(problem, criterion, solver, cuts, bb_work=bb_work, bb_seconds=bb_seconds)
        solve_seconds += result.seconds
        if result.message and result.message not in messages:
            messages.append(result.message)
        t0 = time.perf_counter()
        design = subset_model(candidate_model, result.chosen)
        verdict = check_array(design, thetas[:check_passages], steps, chi2_threshold=tau, starts=starts,
                              seed=seed, progress=progress,
                              motion=None if motion is None else motion.take(slice(0, check_passages)))
        check_seconds += time.perf_counter() - t0
        result.verdict = verdict
        if verdict.verdict != "ambiguous":
            break
        t0 = time.perf_counter()
        for pair in verdict.pairs:
            th = candidate_model.to_internal(pair.passage)
            alt = candidate_model.to_internal(pair.alternative)
            d = pair_discrepancy(candidate_model, th, alt, steps)
            cuts.append(np.minimum(d / tau, 1.0))
        check_seconds += time.perf_counter() - t0
    result.cuts = cuts
    result.seconds, result.check_seconds = solve_seconds, check_seconds
    result.message = "; ".join(messages)
    return result


def enumerate_designs(problem, criterion="D"):
    """Every feasible k-subset and its value (for small candidate sets: tests and checks)."""
    sets = np.array(list(combinations(range(problem.N), problem.k)))
    sets = sets[feasible(sets, None, problem)]
    return sets, value_of_sets(problem, sets, criterion)
