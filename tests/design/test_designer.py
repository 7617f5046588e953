"""The design command's library layer: solver choice and fallback, explicit priors, the report and its files."""

import json
from itertools import combinations

import numpy as np
import pytest
from candidate_grids import s1p2_grid

from shipsense import load_scenario
from shipsense.cli import main
from shipsense.design import designer
from shipsense.design import placement as pl
from shipsense.design.fisher import passage_fim
from shipsense.models.field_model import candidate_model, subset_model
from shipsense.simulator import sample_passages
from shipsense.trackers.tracker.settings import resolve_settings


@pytest.fixture(scope="module")
def small():
    sc, cands, model, thetas = s1p2_grid(20.0, 20.0)   # 3 x 3
    prior = model.to_internal(np.array([30.0, 30.0, 2.0, 2.0, 1.0, 50.0]))
    return sc, cands, model, thetas, pl.build_problem(model, thetas, sc.steps, 3, prior)


def _fail(*args, **kwargs):
    raise RuntimeError("CLARABEL failed on the relaxation (monkeypatched)")


def test_a_clarabel_failure_falls_back_with_a_message(small, monkeypatch):
    *_, problem = small
    monkeypatch.setattr(pl, "solve_convex", _fail)
    res = pl.place(problem, "D", method="clarabel")
    assert res.solver == "projected-gradient" and res.method == "first-order"
    assert "CLARABEL failed" in res.message and "fell back" in res.message
    assert res.upper_bound >= pl.enumerate_designs(problem, "D")[1].max() - 1e-9
    # with cuts (or costs) the fallback is Frank-Wolfe over the cut polytope, and still no traceback
    cut = np.zeros(problem.N)
    cut[[0, 1, 2]] = 1.0                               # at least one of the first three candidates
    res = pl.place(problem, "D", method="clarabel", cuts=[cut])
    assert res.solver == "frank-wolfe" and "CLARABEL failed" in res.message
    assert np.any(np.isin(res.chosen, [0, 1, 2]))
    sets, values = pl.enumerate_designs(problem, "D")
    ok = pl.feasible(sets, [cut], problem)
    assert res.upper_bound >= values[ok].max() - 1e-9 and res.value == pytest.approx(values[ok].max(), abs=1e-9)


def test_the_cli_reports_the_fallback_and_exits_zero(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(pl, "solve_convex", _fail)
    cands = tmp_path / "c.csv"
    cands.write_text("x,y\n" + "\n".join(f"{x},{y}" for x in (-20, 0, 20) for y in (-20, 0, 20)))
    out = tmp_path / "o"
    assert main(["design", "S1-P2", "--k", "3", "--candidates", str(cands), "--passages", "2", "--solver", "clarabel",
                 "--no-cuts", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "CLARABEL failed" in printed and "projected-gradient" in printed
    report = json.loads((out / "design.json").read_text())
    assert report["solver"] == "projected-gradient" and "fell back" in report["solver_message"]
    assert 0 < report["guaranteed_efficiency"] <= 1 and report["converged"] in (True, False)
    for key in ("method", "solver_status", "relaxation_objective", "upper_bound", "design_objective",
                "certified_gap", "ambiguity_cuts", "verdict", "min_chi2", "sensors", "seconds", "baselines"):
        assert key in report
    assert {"best_of_1000_random", "line", "triangle"} <= set(report["baselines"])
    for b in report["baselines"].values():   # the design is optimal here: no baseline beats it
        assert b["value"] <= report["design_objective"] + 1e-9
    assert main(["design", "S1-P2", "--k", "3", "--solver", "simplex"]) == 2
    assert "--solver must be one of" in capsys.readouterr().err
    assert main(["design", "S1-P2", "--k", "10", "--candidates", str(cands)]) == 2
    assert main(["design", "S1-P2", "--k", "3", "--prior-floor", "-1"]) == 2


def test_a_failure_while_writing_leaves_nothing(tmp_path, monkeypatch, small):
    sc, cands, *_ = small
    result = designer.design_array(sc, 2, candidates=cands, passages=2, cuts=False, random_layouts=10)

    def broken(*args, **kwargs):
        raise RuntimeError("no plot today")

    monkeypatch.setattr("shipsense.plotting.plot_bound_map", broken)
    with pytest.raises(RuntimeError):
        designer.write_design(result, tmp_path / "design")
    assert list(tmp_path.iterdir()) == []


def test_the_prior_is_the_scenarios_unless_a_floor_is_named(small):
    sc, cands, model, thetas, problem = small
    assert problem.eps == pytest.approx(1.0 / problem.scale)                         # no floor by default
    prior = model.to_internal(np.array([30.0, 30.0, 2.0, 2.0, 1.0, 50.0]))
    floored = pl.build_problem(model, thetas, sc.steps, 3, prior, prior_floor=1e-4)
    assert floored.eps == 1e-4 and problem.eps < 1e-6
    # the unscaled criterion with the prior information diag(1/std^2): the scaled problem is it, shifted by a constant
    w = np.zeros(problem.N)
    w[[0, 4, 8]] = 1.0
    J = passage_fim(subset_model(model, [0, 4, 8]), thetas, sc.steps, stride=2)
    direct = np.mean(np.linalg.slogdet(np.diag(prior ** -2.0) + J)[1])
    shift = problem.n * np.log(problem.scale) - 2 * np.sum(np.log(prior))
    assert pl.objective(problem, w) + shift == pytest.approx(direct, rel=1e-9, abs=1e-6)
    assert pl.objective(floored, w) + shift > direct + 1e-3                           # the floor adds information


def test_the_s0_design_under_the_scenario_prior_is_the_brute_force_bayes_optimum():
    sc = load_scenario("S0")
    cands = pl.grid_candidates([(-30, -30), (30, -30), (30, 30), (-30, 30)], 30.0, -20.0)   # 3 x 3
    model = candidate_model(sc, cands)
    thetas = model.to_internal(model.state_from_truth(sample_passages(sc, 4, seed=1)))
    bank = resolve_settings(sc).bank
    std = model.to_internal(bank.state_std(model.labels))
    problem = pl.build_problem(model, thetas, sc.steps, 2, std)
    res = pl.place(problem, "D")
    # independently: each pair's own Fisher matrices (the whole array at once) and the prior diag(1/std^2)
    P0inv = np.diag(std ** -2.0)
    best, best_pair = -np.inf, None
    for pair in combinations(range(len(cands)), 2):
        J = passage_fim(subset_model(model, list(pair)), thetas, sc.steps, stride=2)
        v = np.mean(np.linalg.slogdet(P0inv + J)[1])
        if v > best:
            best, best_pair = v, pair
    assert tuple(res.chosen) == best_pair
    assert res.upper_bound >= res.value and 0 < res.guaranteed_efficiency <= 1
