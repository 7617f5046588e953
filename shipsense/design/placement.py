r"""Sensor placement: convex relaxation with a certificate, rounding, swaps and ambiguity cuts.

Joshi & Boyd, "Sensor selection via convex optimization", IEEE TSP 2009, in
its Bayesian form over S passages drawn from the prior.  With per-candidate
passage Fisher matrices :math:`J_{si}` (internal units), the prior standard
deviations :math:`D` of the passage parameters and :math:`\tilde J = D J D`,

.. math::  \max_{0 \le w \le 1,\ \sum w = k}\ f(w) = \frac{1}{S}\sum_s \log\det\Big(I + \sum_i w_i \tilde J_{si}\Big)

(D-optimal; A: :math:`-\operatorname{tr} M_s^{-1}`; E: :math:`\min_s \lambda_{\min}(M_s)`).
The problem is normalised by a scalar :math:`c` (``I + X = c (I/c + X/c)``),
which leaves the optimiser unchanged and keeps the cone solver's data O(1)
(unscaled, the data span 1e9 to 2e13 on S1 and CLARABEL failed); the prior
term ``1/c`` is floored (see :func:`build_problem`).

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

from shipsense.design.fisher import _powers, passage_fim
from shipsense.design.observability import DEFAULT_CHI2, check_array

CRITERIA = ("D", "A", "E")


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


def build_problem(model, thetas, steps, k, prior_std, stride=2, prior_floor=1e-4):
    """Per-candidate Fisher matrices of passages ``thetas`` (S, n) for the candidate ``model`` (one sensor each).

    The matrices are scaled by the prior standard deviations (``D J D``, so
    the prior information is the identity) and divided by ``c``, the mean
    eigenvalue of a uniform k-sensor design, so that the data are O(1).  The
    prior term then is ``1/c``; it is floored at ``prior_floor``.  That floor is
    a deliberate regulariser: a passage carries so much information (``c``
    ~ 1e12 on S1) that the true prior term is 1e-12, and with it CLARABEL's
    A- and E-optimal solves were measured inaccurate (certified gap 6e5)
    while D-optimal designs are the same for every floor from 1e-6 to 1e-3.
    """
    J = passage_fim(model, thetas, steps, per_sensor=True, stride=stride)         # (S, N, n, n)
    D = np.asarray(prior_std, dtype=float)
    J = J * D[:, None] * D[None, :]
    c = float(k * np.mean(np.trace(J, axis1=-2, axis2=-1)) / J.shape[-1])
    c = c if c > 0 else 1.0
    return DesignProblem(J / c, max(1.0 / c, prior_floor), int(k), c)


def _matrices(problem, w):
    """M_s = eps I + sum_i w_i J_si for weights w (..., N) -> (..., S, n, n)."""
    return problem.eps * np.eye(problem.n) + np.einsum("...i,sinp->...snp", w, problem.J)


def objective(problem, w, criterion="D"):
    """The criterion (to maximise) at weights w (..., N)."""
    M = _matrices(problem, np.asarray(w, dtype=float))
    if criterion == "D":
        return np.linalg.slogdet(M)[1].mean(axis=-1)
    if criterion == "A":
        return -np.trace(np.linalg.inv(M), axis1=-2, axis2=-1).mean(axis=-1)
    if criterion == "E":
        return np.linalg.eigvalsh(M)[..., 0].min(axis=-1)
    raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")


def gradient(problem, w, criterion="D"):
    """(Super)gradient of the criterion at w (N,)."""
    M = _matrices(problem, np.asarray(w, dtype=float))                           # (S, n, n)
    if criterion == "D":
        Minv = np.linalg.inv(M)
        return np.einsum("snp,sipn->i", Minv, problem.J) / M.shape[0]
    if criterion == "A":
        Minv = np.linalg.inv(M)
        M2 = Minv @ Minv
        return np.einsum("snp,sipn->i", M2, problem.J) / M.shape[0]
    vals, vecs = np.linalg.eigh(M)
    s = int(np.argmin(vals[:, 0]))
    u = vecs[s, :, 0]
    return np.einsum("n,inp,p->i", u, problem.J[s], u)


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


def solve_first_order(problem, criterion="D", iterations=500, tol=1e-6):
    """Projected-gradient ascent on the relaxation (for large candidate sets); returns the weights."""
    w = np.full(problem.N, problem.k / problem.N)
    f = float(objective(problem, w, criterion))
    step = 1.0
    for _ in range(iterations):
        g = gradient(problem, w, criterion)
        while True:
            trial = project_capped_simplex(w + step * g, problem.k)
            ft = float(objective(problem, trial, criterion))
            if ft >= f or step < 1e-12:
                break
            step *= 0.5
        moved = np.abs(trial - w).max()
        w, f = trial, max(f, ft)
        step *= 1.5
        if moved < tol:
            break
    return w


# -- rounding ----------------------------------------------------------------------------
def _value_of_sets(problem, sets, criterion, chunk=4096):
    """Criterion of 0/1 designs given as index arrays (B, k): the chosen matrices are gathered, not weighted."""
    sets = np.asarray(sets)
    out = np.empty(len(sets))
    eye = problem.eps * np.eye(problem.n)
    for start in range(0, len(sets), chunk):
        idx = sets[start:start + chunk]
        M = eye + problem.J[:, idx].sum(axis=2)                      # (S, B, n, n)
        M = np.swapaxes(M, 0, 1)                                      # (B, S, n, n)
        if criterion == "D":
            v = np.linalg.slogdet(M)[1].mean(axis=-1)
        elif criterion == "A":
            v = -np.trace(np.linalg.inv(M), axis1=-2, axis2=-1).mean(axis=-1)
        else:
            v = np.linalg.eigvalsh(M)[..., 0].min(axis=-1)
        out[start:start + chunk] = v
    return out


def _feasible(sets, cuts, problem=None):
    sets = np.asarray(sets)
    ok = np.ones(len(sets), dtype=bool)
    if cuts:
        C = np.asarray(cuts)                                             # (ncuts, N)
        ok &= np.all(C[:, sets].sum(axis=-1) >= 1.0 - 1e-9, axis=0)
    if problem is not None and problem.costs is not None:
        ok &= problem.costs[sets].sum(axis=-1) <= problem.budget + 1e-9
    return ok


def greedy(problem, criterion="D", cuts=None):
    chosen = []
    for _ in range(problem.k):
        rest = np.setdiff1d(np.arange(problem.N), chosen)
        sets = np.array([chosen + [i] for i in rest])
        vals = _value_of_sets(problem, sets, criterion)
        if len(chosen) == problem.k - 1:
            vals = np.where(_feasible(sets, cuts, problem), vals, -np.inf)
        elif problem.costs is not None:   # keep enough budget for the cheapest completion
            spent = problem.costs[sets].sum(axis=-1)
            left = np.sort(problem.costs)[: problem.k - len(chosen) - 1].sum()
            vals = np.where(spent + left <= problem.budget + 1e-9, vals, -np.inf)
        chosen.append(int(rest[np.argmax(vals)]))
    return np.array(chosen)


def swap_refine(problem, chosen, criterion="D", cuts=None, max_rounds=50):
    """Best-improvement swaps (one in, one out) until none improves; keeps the cuts satisfied."""
    chosen = np.array(chosen)
    best = float(_value_of_sets(problem, chosen[None], criterion)[0])
    for _ in range(max_rounds):
        out = np.setdiff1d(np.arange(problem.N), chosen)
        trials = []
        for j in range(len(chosen)):
            for i in out:
                t = chosen.copy()
                t[j] = i
                trials.append(t)
        if not trials:
            break
        trials = np.array(trials)
        vals = _value_of_sets(problem, trials, criterion)
        vals = np.where(_feasible(trials, cuts, problem), vals, -np.inf)
        i = int(np.argmax(vals))
        if vals[i] <= best + 1e-12:
            break
        chosen, best = trials[i], float(vals[i])
    return np.sort(chosen), best


def round_design(problem, w, criterion="D", cuts=None):
    """Top-k and greedy rounding, each refined by swaps; the better one."""
    top = np.argsort(w)[::-1][: problem.k]
    if not _feasible(top[None], cuts, problem)[0]:
        top = greedy(problem, criterion, cuts)
    a = swap_refine(problem, top, criterion, cuts)
    b = swap_refine(problem, greedy(problem, criterion, cuts), criterion, cuts)
    return a if a[1] >= b[1] else b


# -- the whole method ----------------------------------------------------------------------
@dataclass
class Placement:
    """A placement: the chosen candidates and the figures behind them."""

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

    @property
    def certified_gap(self) -> float:
        """Upper bound minus the rounded design's value (>= 0): no k-sensor design beats it by more."""
        return float(self.upper_bound - self.value)


def pair_discrepancy(model, theta, theta_alt, steps):
    """Per-sensor discrepancy d_i (chi-square units) of two passages (internal units) for a candidate model."""
    Ak = _powers(model.A, steps)
    r = model.residual(model.h(np.einsum("kij,j->ki", Ak, theta_alt)), model.h(np.einsum("kij,j->ki", Ak, theta)))
    per_channel = np.sum((r / np.sqrt(model.R)) ** 2, axis=0)
    S = len(model.array.ids)
    return np.bincount(model.array.channel_sensor, weights=per_channel, minlength=S)


def place(problem, criterion="D", method="auto", cuts=None, first_order_above=800):
    """Solve the relaxation, certify it, round and refine; returns a :class:`Placement`."""
    t0 = time.perf_counter()
    if method == "auto":
        method = "first-order" if problem.N > first_order_above and not cuts and problem.costs is None else "convex"
    status = "first-order"
    if method == "convex":
        try:
            w, status = solve_convex(problem, criterion, cuts, return_status=True)
        except RuntimeError as err:
            if cuts or problem.costs is not None:
                raise
            w, status = solve_first_order(problem, criterion), f"first-order fallback ({err})"
    elif method == "first-order":
        if cuts or problem.costs is not None:
            raise ValueError("ambiguity cuts and costs need the convex solver")
        w = solve_first_order(problem, criterion)
    else:
        raise ValueError(f"method must be 'auto', 'convex' or 'first-order', got {method!r}")
    upper, relax = certified_bound(problem, w, criterion, cuts)
    chosen, value = round_design(problem, w, criterion, cuts)
    return Placement(chosen, w, criterion, relax, upper, value, method, time.perf_counter() - t0, list(cuts or []),
                     status=status)


def place_with_cuts(problem, candidate_model, thetas, steps, criterion="D", tau=DEFAULT_CHI2, max_rounds=6,
                    check_passages=4, starts=8, seed=0, progress=False):
    """Place sensors, then add ambiguity cuts until the rounded design passes the ambiguity check."""
    from shipsense.trackers.models import subset_model

    cuts = []
    result = None
    for _ in range(max_rounds):
        result = place(problem, criterion, "convex", cuts)
        design = subset_model(candidate_model, result.chosen)
        verdict = check_array(design, thetas[:check_passages], steps, chi2_threshold=tau, starts=starts,
                              seed=seed, progress=progress)
        result.verdict = verdict
        if verdict.verdict != "ambiguous":
            break
        for pair in verdict.pairs:
            th = candidate_model.to_internal(pair.passage)
            alt = candidate_model.to_internal(pair.alternative)
            d = pair_discrepancy(candidate_model, th, alt, steps)
            cuts.append(np.minimum(d / tau, 1.0))
    result.cuts = cuts
    return result


def enumerate_designs(problem, criterion="D"):
    """Every feasible k-subset and its value (for small candidate sets: tests and checks)."""
    sets = np.array(list(combinations(range(problem.N), problem.k)))
    sets = sets[_feasible(sets, None, problem)]
    return sets, _value_of_sets(problem, sets, criterion)
