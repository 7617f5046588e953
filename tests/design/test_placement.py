"""Placement: the certified bound, rounding, the first-order path, cuts and candidate grids."""

import numpy as np
import pytest

from shipsense import load_scenario
from shipsense.design import placement as pl
from shipsense.design.observability import check_array
from shipsense.models.field_model import candidate_model, subset_model
from shipsense.simulator import sample_passages


@pytest.fixture(scope="module")
def small():
    sc = load_scenario("S1-P2")
    cands = pl.grid_candidates([(-20, -20), (20, -20), (20, 20), (-20, 20)], 20.0, -15.0)   # 3 x 3 = 9
    cands = np.vstack([cands, [[5.0, 5.0, -15.0]]])
    model = candidate_model(sc, cands)
    thetas = model.to_internal(model.state_from_truth(sample_passages(sc, 4, seed=3)))
    prior = model.to_internal(np.array([30.0, 30.0, 2.0, 2.0, 1.0, 50.0]))
    return sc, model, thetas, pl.build_problem(model, thetas, sc.steps, 3, prior)


@pytest.mark.parametrize("criterion", ["D", "A"])
def test_relaxation_bound_is_above_every_design_and_rounding_is_within_the_gap(small, criterion):
    *_, problem = small
    res = pl.place(problem, criterion)
    sets, values = pl.enumerate_designs(problem, criterion)
    assert values.max() <= res.upper_bound + 1e-9
    assert res.value <= values.max() + 1e-9
    assert res.upper_bound - values.max() <= res.certified_gap + 1e-9
    assert res.certified_gap >= 0
    # the rounded design is the enumerated optimum here (10 candidates, k = 3)
    assert res.value == pytest.approx(values.max(), rel=1e-9, abs=1e-9)


def test_costs_and_budget_are_respected_and_certified(small):
    *_, problem = small
    costs = np.ones(problem.N)
    free = pl.place(problem, "D")
    costs[free.chosen] = 5.0                       # make the unconstrained optimum unaffordable
    constrained = problem.with_costs(costs, budget=7.0)
    res = pl.place(constrained, "D")
    sets, values = pl.enumerate_designs(constrained, "D")
    assert costs[res.chosen].sum() <= 7.0
    assert values.max() <= res.upper_bound + 1e-9 and res.value <= values.max() + 1e-9
    assert res.upper_bound <= free.upper_bound + 1e-9
    with pytest.raises(ValueError, match="cannot pay"):
        problem.with_costs(np.full(problem.N, 5.0), budget=7.0)


def test_first_order_solver_matches_the_conic_one(small):
    *_, problem = small
    conic = pl.place(problem, "D", method="convex")
    fo = pl.place(problem, "D", method="first-order")
    assert fo.relaxation == pytest.approx(conic.relaxation, abs=1e-3 * abs(conic.relaxation))
    assert fo.upper_bound >= pl.enumerate_designs(problem, "D")[1].max() - 1e-9


def test_capped_simplex_projection():
    rng = np.random.default_rng(0)
    for _ in range(20):
        v = rng.normal(size=12) * 3
        w = pl.project_capped_simplex(v, 4)
        assert w.sum() == pytest.approx(4) and w.min() >= 0 and w.max() <= 1
        for _ in range(20):   # no feasible point is closer to v
            u = pl.project_capped_simplex(rng.normal(size=12), 4)
            assert np.linalg.norm(v - w) <= np.linalg.norm(v - u) + 1e-9


def test_ambiguity_cuts_move_a_sensor_off_the_cable():
    sc = load_scenario("S1-P2")
    cable = np.array([[0.0, y, -15.0] for y in np.arange(-40.0, 41.0, 5.0)])
    spur = np.array([[3.0, 0.0, -15.0], [6.0, 0.0, -15.0]])
    cands = np.vstack([cable, spur])
    model = candidate_model(sc, cands)
    thetas = model.to_internal(model.state_from_truth(sample_passages(sc, 6, seed=2)))
    prior = model.to_internal(np.array([30.0, 30.0, 2.0, 2.0, 1.0, 50.0]))
    problem = pl.build_problem(model, thetas, sc.steps, 3, prior)
    plain = pl.place(problem, "D")
    assert np.all(cands[plain.chosen, 0] == 0.0)                                    # all on the cable...
    assert check_array(subset_model(model, plain.chosen), thetas[:4], sc.steps, starts=8).verdict == "ambiguous"
    cut = pl.place_with_cuts(problem, model, thetas, sc.steps)
    assert cut.cuts and np.any(cands[cut.chosen, 0] != 0.0)                          # ...until the cuts
    assert cut.verdict.verdict == "observable" and cut.certified_gap >= 0


def test_grid_candidates_respect_polygon_exclusions_and_spacing():
    tri = [(0, 0), (40, 0), (0, 40)]
    pts = pl.grid_candidates(tri, 5.0, -10.0, exclusions=[(0.0, 0.0, 7.0)], min_spacing=9.0)
    assert np.all(pts[:, 0] + pts[:, 1] <= 40 + 1e-9) and np.all(pts[:, 2] == -10.0)
    assert np.all(np.hypot(pts[:, 0], pts[:, 1]) > 7.0)
    d = np.linalg.norm(pts[:, None, :2] - pts[None, :, :2], axis=-1) + np.eye(len(pts)) * 1e9
    assert d.min() >= 9.0


def test_exchange_search_never_worsens_and_reaches_the_optimum(small):
    *_, problem = small
    sets, values = pl.enumerate_designs(problem, "D")
    rng = np.random.default_rng(0)
    reached = 0
    for _ in range(12):
        start = rng.choice(problem.N, problem.k, replace=False)
        before = pl.value_of_sets(problem, start[None], "D")[0]
        chosen, value = pl.swap_refine(problem, start, "D")
        assert value >= before - 1e-12
        assert value == pytest.approx(pl.value_of_sets(problem, chosen[None], "D")[0], abs=1e-12)
        reached += value >= values.max() - 1e-9
    assert reached >= 1
    assert pl.round_design(problem, pl.solve_first_order(problem), "D")[1] == pytest.approx(values.max(), abs=1e-9)


@pytest.mark.parametrize("criterion", ["D", "A"])
def test_the_guaranteed_efficiency_is_a_true_lower_bound(small, criterion):
    *_, problem = small
    sets, values = pl.enumerate_designs(problem, criterion)
    for method in ("clarabel", "first-order"):
        res = pl.place(problem, criterion, method=method)
        assert res.upper_bound >= values.max() - 1e-9
        true_eff = np.exp((res.value - values.max()) / problem.n) if criterion == "D" else values.max() / res.value
        assert res.guaranteed_efficiency <= true_eff + 1e-12


def test_first_order_stops_on_the_duality_gap(small):
    *_, problem = small
    w, info = pl.solve_first_order(problem, "D", tol=1e-6, return_info=True)
    assert info["converged"] and info["gap"] <= 1e-6
    upper, f = pl.certified_bound(problem, w, "D")
    assert upper - f <= 1e-6 + 1e-12
    conic = pl.solve_convex(problem, "D")
    assert f >= float(pl.objective(problem, conic, "D")) - 1e-5


def test_frank_wolfe_with_costs_is_certified(small):
    *_, problem = small
    costs = np.ones(problem.N)
    costs[:4] = 3.0
    constrained = problem.with_costs(costs, budget=5.0)
    res = pl.place(constrained, "D", method="first-order")
    sets, values = pl.enumerate_designs(constrained, "D")
    assert res.solver == "frank-wolfe"
    assert costs[res.chosen].sum() <= 5.0 and values.max() <= res.upper_bound + 1e-9


def test_branch_and_bound_proves_the_optimum_or_a_true_bound(small):
    *_, problem = small
    sets, values = pl.enumerate_designs(problem, "A")
    bb = pl.branch_and_bound(problem, "A", max_nodes=10_000)
    assert bb["complete"] and bb["value"] == pytest.approx(values.max(), abs=1e-9)
    assert bb["upper_bound"] == pytest.approx(values.max(), abs=1e-9)
    early = pl.branch_and_bound(problem, "A", incumbent=sets[np.argmin(values)], max_nodes=1)
    assert not early["complete"] and early["stopped_by"] == "work"
    assert early["upper_bound"] >= values.max() - 1e-9                     # stopped at once: still a true bound
    guarded = pl.branch_and_bound(problem, "A", incumbent=sets[np.argmin(values)], time_guard=0.0)
    assert guarded["stopped_by"] == "time guard" and guarded["upper_bound"] >= values.max() - 1e-9
    res = pl.place(problem, "A", bb_work=None)                              # k = 3: place runs it
    assert res.branch_and_bound["complete"] and res.guaranteed_efficiency == pytest.approx(1.0, abs=1e-9)


def test_the_search_stops_on_its_work_and_the_same_work_proves_the_same_bound(small):
    """The search's result depends on the work limit, not on the clock: two runs with the same limit prove the
    same bound, and a larger limit never proves less."""
    *_, problem = small
    runs = [pl.branch_and_bound(problem, "A", max_nodes=3) for _ in range(2)]
    assert runs[0]["upper_bound"] == runs[1]["upper_bound"] and runs[0]["work"] == runs[1]["work"] == 3
    more = pl.branch_and_bound(problem, "A", max_nodes=6)
    assert more["upper_bound"] <= runs[0]["upper_bound"] + 1e-12
