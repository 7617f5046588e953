"""The exact search over subsets of the D criterion against an enumeration of every subset (an independent
computation: numpy's slogdet of the gathered matrices)."""

from dataclasses import replace

import numpy as np
import pytest

from shipsense.design import placement as pl
from shipsense.design.subsets import METHODS, subset_search


def random_problem(N, k, n=4, S=3, seed=0, eps=1e-3):
    """Random positive semi-definite information of rank 2 per candidate and passage (a sensor alone sees only
    part of the state, so that sensors complement each other and the pair bounds are not exact)."""
    rng = np.random.default_rng(seed)
    H = rng.normal(size=(S, N, 2, n)) * rng.uniform(0.2, 2.0, size=(1, N, 1, 1))
    J = np.einsum("snki,snkj->snij", H, H)
    return pl.DesignProblem(np.ascontiguousarray(J), eps, k, 1.0)


@pytest.mark.parametrize("k", [1, 2, 3, 4])
def test_the_search_finds_the_best_subset_and_a_bound_no_subset_exceeds(k):
    problem = random_problem(16, k, seed=k)
    sets, values = pl.enumerate_designs(problem, "D")
    res = subset_search(problem)
    assert res["complete"] and res["stopped_by"] is None
    assert res["value"] == pytest.approx(values.max(), abs=1e-9)
    assert set(res["chosen"]) == set(sets[np.argmax(values)])
    assert values.max() <= res["upper_bound"] + 1e-12 and res["upper_bound"] <= values.max() + 1e-8
    assert res["method"] == METHODS["triple" if k == 4 else "pair"]


def test_the_bounds_prune_subsets():
    """Beyond its tables (k = 3: the pairs; k = 4: the pairs and the triples) the search computes fewer subset
    values and screens fewer children than there are subsets."""
    for k, tables in ((3, 30 * 29 // 2), (4, 30 * 29 // 2 + 30 * 29 * 28 // 6)):
        problem = random_problem(30, k, seed=7)
        res = subset_search(problem)
        n_sets = len(pl.enumerate_designs(problem, "D")[0])
        assert res["complete"] and res["work"] - tables < n_sets, (k, res["work"], n_sets)


def test_stopped_on_its_work_it_still_proves_a_true_bound_and_the_same_one_every_time():
    problem = random_problem(24, 3, seed=3)
    values = pl.enumerate_designs(problem, "D")[1]
    runs = [subset_search(problem, max_work=24 * 23 // 2 + 5) for _ in range(2)]
    for r in runs:
        assert not r["complete"] and r["stopped_by"] == "work"
        assert r["upper_bound"] >= values.max() - 1e-12
    assert runs[0]["upper_bound"] == runs[1]["upper_bound"] and runs[0]["work"] == runs[1]["work"]
    none = subset_search(problem, max_work=24 * 23 // 2 - 1)                 # not even the pair table
    assert none["work"] == 0 and none["upper_bound"] == np.inf and none["chosen"] is None
    guarded = subset_search(problem, time_guard=0.0)
    assert guarded["stopped_by"] == "time guard" and guarded["upper_bound"] >= values.max() - 1e-12


def test_costs_and_cuts_are_kept():
    problem = random_problem(14, 3, seed=5)
    rng = np.random.default_rng(1)
    costs = rng.uniform(1, 3, 14)
    constrained = problem.with_costs(costs, 5.0)
    cut = (rng.random(14) < 0.3).astype(float)
    sets, values = pl.enumerate_designs(constrained, "D")
    ok = pl.feasible(sets, [cut], constrained)
    res = subset_search(constrained, cuts=[cut])
    assert res["complete"] and res["value"] == pytest.approx(values[ok].max(), abs=1e-9)
    assert costs[res["chosen"]].sum() <= 5.0 + 1e-9 and cut[res["chosen"]].sum() >= 1


def test_place_certifies_the_optimum_for_k_up_to_4():
    for k in (3, 4):
        problem = replace(random_problem(18, k, seed=11 + k))
        values = pl.enumerate_designs(problem, "D")[1]
        res = pl.place(problem, "D", bb_work=None)
        assert res.branch_and_bound["complete"] and res.value == pytest.approx(values.max(), abs=1e-9)
        assert res.guaranteed_efficiency == pytest.approx(1.0, abs=1e-9)
