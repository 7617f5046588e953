"""Passage-v2: Passage-v1's core with wake-up costs, a read budget and checkpoint weights -- gymnasium's and
SB3's checkers, reproducibility, the reward's parts against their definitions, the native vector version
against single environments, and the planners on it (the hindsight plan exact under the new costs)."""

import itertools

import gymnasium as gym
import numpy as np
import pytest
from env_checks import (
    assert_gymnasium_checker_passes,
    assert_sb3_checker_passes,
    assert_seed_fixes_the_episode,
    assert_vector_equals_singles,
)

import shipsense  # noqa: F401  (registers the environments)
from shipsense.envs import PASSAGE_V1_ID, PASSAGE_V1_VARIANTS, PASSAGE_V2_ID, PASSAGE_V2_VARIANTS, planning
from shipsense.envs.passage_v2 import PassageV2Env, PassageV2VectorEnv

KW = {"scenario": "S2", "overrides": {"steps": 50}}   # S2: the run-in ends near sample 30, ~20 agent steps


def test_registered_with_thresholds_vector_entry_points_and_v1_unchanged():
    for vid, kwargs in PASSAGE_V2_VARIANTS.items():
        spec = gym.registry[vid]
        assert spec.entry_point.endswith("PassageV2Env") and spec.vector_entry_point.endswith("PassageV2VectorEnv")
        assert spec.kwargs == kwargs
        assert spec.reward_threshold is not None                      # every variant measured
    assert gym.registry[PASSAGE_V1_ID].entry_point.endswith("PassageV1Env")
    assert gym.registry[PASSAGE_V2_ID].kwargs["overrides"] == PASSAGE_V1_VARIANTS[PASSAGE_V1_ID]["overrides"]
    envs = gym.make_vec(PASSAGE_V2_ID, num_envs=2, vectorization_mode="vector_entry_point", overrides=KW["overrides"])
    assert isinstance(envs.unwrapped, PassageV2VectorEnv)


def test_gymnasium_checker_passes_without_warnings():
    env = gym.make(PASSAGE_V2_ID, render_mode="rgb_array", overrides=KW["overrides"])
    assert_gymnasium_checker_passes(env.unwrapped)


def test_stable_baselines_checker_passes():
    assert_sb3_checker_passes(PassageV2Env(budget=5, **KW))


def test_same_seed_same_rollout_and_another_seed_another():
    assert_seed_fixes_the_episode(lambda: PassageV2Env(budget=8, **KW))


def test_rewards_are_the_checkpoint_weighted_error_minus_reads_and_wake_ups():
    c, cw = 0.02, 0.3
    env = PassageV2Env(energy_cost=c, wake_cost=cw, checkpoints=3, budget=None, **KW)
    core = env.core
    weights = core.error_weights
    marks = np.flatnonzero(weights)
    assert marks.size == 3 and marks[-1] == core.K - 1 and np.all(weights[marks] == core.K / 3)
    obs, _ = env.reset(seed=2)
    S = core.S
    assert obs[9 + 2 * S] == 1.0                             # no budget: all of it left
    awake = np.ones(S, dtype=bool)                           # (the run-in read every sensor)
    rng = np.random.default_rng(0)
    seen = set()
    while True:
        a = int(rng.integers(env.action_space.n))
        read = env.subsets[a]
        k_next = int(core.k[0]) + 1
        obs, r, term, _, info = env.step(a)
        wakes = int((read & ~awake).sum())
        assert info["wakes"] == wakes
        assert info["energy_term"] == pytest.approx(-(c * read.sum() + cw * wakes), abs=1e-12)
        assert info["error_term"] == pytest.approx(-weights[k_next] * np.log1p(info["error"]), abs=1e-12)
        assert r == pytest.approx(info["error_term"] + info["energy_term"], abs=1e-12)
        ahead = marks[marks >= k_next][0] - k_next
        assert obs[10 + 2 * S] == pytest.approx(ahead / (core.K - 1), abs=1e-6)
        seen.add((wakes > 0, weights[k_next] > 0))
        awake = read
        if term:
            break
    assert (True, False) in seen and (False, False) in seen and any(mark for _, mark in seen)
    m = info["episode_metrics"]
    assert m["energy"] == pytest.approx(c * m["reads_per_step"] * m["steps"] + cw * m["wakes"])
    assert m["return"] == pytest.approx(core.returns[0])


def test_a_read_beyond_the_budget_reads_nothing_and_costs_nothing():
    env = PassageV2Env(budget=3, **KW)
    obs, _ = env.reset(seed=4)
    S = env.core.S
    for left in (3, 2, 1):
        assert obs[9 + 2 * S] == pytest.approx(left / 3) and env.core.budget_left()[0] == left
        obs, _, _, _, info = env.step(1)
        assert info["reads"] == 1 and info["budget_left"] == left - 1
    for _ in range(3):
        obs, _, term, _, info = env.step(2)
        assert info["reads"] == 0 and info["energy_term"] == 0.0 and info["wakes"] == 0
        assert np.all(env.core.since[0] > 0)                  # nothing was read
    assert obs[9 + 2 * S] == 0.0


def test_vector_env_equals_single_envs_across_autoreset():
    kw = dict(budget=6, wake_cost=0.1, **KW)

    def same_budget(i, info, vinfo):
        assert info is None or info["wakes"] == vinfo["wakes"][i] and info["budget_left"] == vinfo["budget_left"][i]

    assert_vector_equals_singles(PassageV2VectorEnv(num_envs=2, **kw), [PassageV2Env(**kw) for _ in range(2)],
                                 (21, 5), check=same_budget)


@pytest.mark.parametrize("kwargs, name", [({"wake_cost": -1}, "wake_cost"), ({"budget": 2.5}, "budget"),
                                          ({"checkpoints": -1}, "checkpoints"), ({"budget": -3}, "budget")])
def test_bad_kwargs_raise_one_value_error_naming_the_argument(kwargs, name):
    with pytest.raises(ValueError, match=name):
        PassageV2Env(**KW, **kwargs)


def test_hindsight_is_exact_under_wake_ups_budget_and_checkpoints():
    """The planner's costs are the environment's: on a short problem the beam holding every schedule finds the
    brute-force optimum of the linearised return, which never reads beyond the budget."""
    env = PassageV2Env(wake_cost=0.1, budget=2, checkpoints=2, **KW)
    env.reset(seed=2)
    core = env.core
    info0, J, Ainv = planning.Hindsight(core).problem(0)
    T = 5
    costs = planning.ScheduleCosts.of(core, 0)
    costs = planning.ScheduleCosts(T, core.S, np.array([0.0, 0.0, 3.0, 0.0, 5.0]), costs.wake_cost, costs.last,
                                   costs.budget)
    A = len(core.subsets)
    every = np.array(list(itertools.product(range(A), repeat=T)))
    values = planning.linearised_rewards(info0, J[:T], Ainv, core.subsets, every, core.energy_cost,
                                         core.error_scale, costs)
    feasible = core.subsets[every].sum(axis=(1, 2)) <= 2
    assert np.all(np.isneginf(values[~feasible])) and np.all(np.isfinite(values[feasible]))
    plan, value = planning.plan_schedule(info0, J[:T], Ainv, core.subsets, core.energy_cost, core.error_scale,
                                         beam=A ** T, costs=costs)
    assert value == pytest.approx(values.max(), abs=1e-9) and core.subsets[plan].sum() <= 2
    # a wake-up costs exactly wake_cost: reading sensor 0 twice in a row against reading it with a gap
    twice, gap = np.array([[1, 1, 0, 0, 0]]), np.array([[1, 0, 1, 0, 0]])
    free = planning.ScheduleCosts(T, core.S, costs.weights, 0.0, costs.last, costs.budget)
    d_cost = [planning.linearised_rewards(info0, J[:T], Ainv, core.subsets, s, core.energy_cost, core.error_scale,
                                          c)[0] for s in (twice, gap) for c in (costs, free)]
    assert d_cost[1] - d_cost[0] == pytest.approx(0.0 if costs.last[0] else 0.1, abs=1e-12)
    assert d_cost[3] - d_cost[2] == pytest.approx(0.1 if costs.last[0] else 0.2, abs=1e-12)


@pytest.mark.parametrize("name, options", [("greedy-threshold", {"threshold": 0.02}),
                                           ("rollout", {"horizon": 2, "samples": 2}), ("hindsight", {"beam": 8})])
def test_the_planners_run_on_v2(name, options):
    from shipsense.envs.evaluation import evaluate

    r = evaluate(PASSAGE_V2_ID, name, 1, 2_000_000, env_kwargs={"overrides": {**KW["overrides"]}, "budget": 10},
                 policy_kwargs=options)
    assert np.isfinite(r["return"]["mean"]) and r["metrics"]["reads_per_step"]["mean"] * r["length"] <= 10
