"""Planning baselines of Passage-v1: greedy-threshold, rollout (from the observer's belief only, common random
numbers) and the offline hindsight reference (exact on short problems, never below greedy there)."""

import copy
import itertools
import json

import gymnasium as gym
import numpy as np
import pytest

import shipsense  # noqa: F401  (registers the environments)
from shipsense.envs import planning
from shipsense.envs.evaluation import evaluate
from shipsense.trackers.tracker.results import TRACKING

ENV = "shipsense/Passage-v1"
KW = {"overrides": {"steps": 50}}     # the run-in ends near sample 20: ~30 agent steps


def _env(seed):
    env = gym.make(ENV, **KW)
    obs, _ = env.reset(seed=seed)
    return env, obs


def test_threshold_zero_is_greedy_and_a_large_one_reads_nothing_once_tracking():
    env, obs = _env(3)
    core = env.unwrapped.core
    greedy, zero = env.unwrapped.baseline("greedy"), planning.planner(env, "greedy-threshold", threshold=0.0)
    never = planning.GreedyThreshold(core, threshold=1e3)
    tracked = 0
    while True:
        a = zero(obs)
        assert a == greedy(obs)
        if core.last.status[0] >= TRACKING:                  # (while blind it is greedy's round-robin)
            tracked += 1
            assert never(obs) == 0
        obs, _, term, trunc, _ = env.step(a)
        if term or trunc:
            break
    assert tracked > 10
    assert zero.describe() == {"threshold": 0.0}


def test_threshold_fit_is_the_grid_best_on_training_episodes_and_the_batch_matches_single_episodes():
    env, _ = _env(0)
    core = env.unwrapped.core
    fit = planning.fit_threshold(core, thresholds=(0.0, 0.05, 10.0), episodes=3, seed=500)
    assert fit["threshold"] == fit["grid"][int(np.argmax(fit["mean_return"]))]
    # threshold 0's mean return is greedy's over the same seeds, run one episode at a time
    greedy = env.unwrapped.baseline("greedy")
    returns = []
    for s in range(500, 503):
        obs, _ = env.reset(seed=s)
        total = 0.0
        while True:
            obs, r, term, _, _ = env.step(greedy(obs))
            total += r
            if term:
                break
        returns.append(total)
    assert fit["mean_return"][0] == pytest.approx(np.mean(returns), abs=1e-9)


def test_rollout_never_reads_the_true_passage_nor_the_environments_generator():
    """Decisions with the passage's truth and its samples from the next one on overwritten by garbage are the
    same as with them intact (the policy's own generator restored in between), and neither the passage nor the
    environment's generator is touched."""
    env, obs = _env(7)
    core = env.unwrapped.core
    policy = planning.planner(env, "rollout", seed=1, horizon=2, samples=4)
    for step in range(6):
        k = int(core.k[0])
        truth, y = core.truth.copy(), core.y.copy()
        rng_env = copy.deepcopy(env.unwrapped.np_random.bit_generator.state)
        rng = copy.deepcopy(policy.rng)
        a = policy(obs)
        q = policy.last_values
        np.testing.assert_array_equal(core.truth, truth)
        np.testing.assert_array_equal(core.y, y)
        assert env.unwrapped.np_random.bit_generator.state == rng_env
        core.truth[:] = 1e9 * np.random.default_rng(step).standard_normal(core.truth.shape)
        core.y[:, k + 1:] = -3e5
        policy.rng = rng
        assert policy(obs) == a
        if q is not None:
            np.testing.assert_array_equal(policy.last_values, q)
        core.truth[:], core.y[:] = truth, y
        obs, _, term, _, _ = env.step(a)
        assert not term


def test_rollout_meets_every_action_with_the_same_futures():
    env, _ = _env(11)
    policy = planning.planner(env, "rollout", seed=2, horizon=3, samples=5)
    q = policy.values(0)
    twin, A, F = policy.twin, policy.A, policy.samples
    k = int(env.unwrapped.core.k[0])
    truth = twin.truth[:, k:k + 4].reshape(A, F, 4, -1)
    y = twin.y[:, k:k + 4].reshape(A, F, 4, -1)
    for a in range(1, A):
        np.testing.assert_array_equal(truth[a], truth[0])
        np.testing.assert_array_equal(y[a], y[0])
    assert np.unique(truth[0, :, 0, 0]).size == F           # (distinct futures)
    # the error terms differ between actions only through the reads: reading nothing costs no energy
    assert q.shape == (A,) and np.all(np.isfinite(q))


def test_belief_futures_follow_the_motion_model_and_the_observers_spread():
    env, _ = _env(5)
    core = env.unwrapped.core
    truth, y = planning.belief_futures(core, 0, np.random.default_rng(0), 4000, 3)
    np.testing.assert_allclose(truth[:, 0].mean(axis=0)[:4], core.last.estimate[0, :4],
                               atol=5 * np.sqrt(np.diag(core.last.cov[0]))[:4].max() / np.sqrt(4000))
    # constant velocity: x_{j+1} - x_j = v T
    T = core.scenario.period
    np.testing.assert_allclose(truth[:, 1, :2] - truth[:, 0, :2], T * truth[:, 0, 2:4], rtol=1e-9, atol=1e-9)
    assert np.all(np.isnan(y[:, 0])) and np.isfinite(y[:, 1:]).mean() > 0.99


def _small_problem(steps):
    env, obs = _env(2)
    core = env.unwrapped.core
    hind = planning.Hindsight(core)
    info0, J, Ainv = hind.problem(0)
    greedy = env.unwrapped.baseline("greedy")
    schedule = []
    for _ in range(steps):
        a = greedy(obs)
        schedule.append(a)
        obs, *_ = env.step(a)
    return core, info0, J[:steps], Ainv, np.array(schedule)


def test_hindsight_is_exact_on_short_problems_and_never_below_greedy():
    """With every schedule in the beam the plan is the brute-force optimum of the linearised return, hence at
    least greedy's schedule's (and round-robin's, and reading nothing)."""
    T = 5
    core, info0, J, Ainv, greedy = _small_problem(T)
    A = len(core.subsets)
    every = np.array(list(itertools.product(range(A), repeat=T)))
    values = planning.linearised_rewards(info0, J, Ainv, core.subsets, every, core.energy_cost, core.error_scale)
    plan, value = planning.plan_schedule(info0, J, Ainv, core.subsets, core.energy_cost, core.error_scale,
                                         beam=A ** T)
    assert value == pytest.approx(values.max(), abs=1e-9)
    assert planning.linearised_rewards(info0, J, Ainv, core.subsets, plan[None], core.energy_cost,
                                       core.error_scale)[0] == pytest.approx(value, abs=1e-12)
    g = planning.linearised_rewards(info0, J, Ainv, core.subsets, greedy[None], core.energy_cost,
                                    core.error_scale)[0]
    assert value >= g
    # a narrow beam with coordinate ascent is never above the optimum and never below its own beam's best
    narrow, v_narrow = planning.plan_schedule(info0, J, Ainv, core.subsets, core.energy_cost, core.error_scale,
                                              beam=2)
    beam_only = planning.plan_schedule(info0, J, Ainv, core.subsets, core.energy_cost, core.error_scale,
                                       beam=2, sweeps=0)[1]
    assert beam_only <= v_narrow <= value + 1e-12


def test_linearised_information_adds_up_and_a_dropout_gives_none():
    env, _ = _env(4)
    core = env.unwrapped.core
    J = planning.sensor_information(core, 0)
    assert J.shape[:2] == (core.K - 1 - int(core.start[0]), core.S)
    np.testing.assert_allclose(J, np.swapaxes(J, -1, -2), rtol=1e-12, atol=0)
    assert np.all(np.linalg.eigvalsh(J) > -1e-9 * np.abs(J).max())
    t = 3
    k = int(core.start[0]) + 1 + t
    core.y[0, k, core.sensor_of == 1] = np.nan
    assert np.all(planning.sensor_information(core, 0)[t, 1] == 0.0)


def test_hindsight_replays_its_plan_through_the_environment():
    env, obs = _env(9)
    policy = planning.planner(env, "hindsight", beam=8)
    actions = []
    while True:
        actions.append(policy(obs))
        obs, _, term, _, _ = env.step(actions[-1])
        if term:
            break
    np.testing.assert_array_equal(actions, policy.schedule)


def test_evaluate_reports_compute_per_decision_and_the_policys_settings(capsys):
    from shipsense.cli import main

    r = evaluate(ENV, "rollout", 1, 2_000_000, env_kwargs=KW, policy_kwargs={"horizon": 1, "samples": 2})
    assert r["seconds_per_decision"] > 0 and r["policy_settings"]["horizon"] == 1
    assert r["policy_kwargs"] == {"horizon": 1, "samples": 2}
    with pytest.raises(ValueError, match="policy_kwargs: rollout takes"):
        evaluate(ENV, "rollout", 1, 0, env_kwargs=KW, policy_kwargs={"beam": 3})
    with pytest.raises(ValueError, match="policy_kwargs are options of a planning baseline"):
        evaluate(ENV, "greedy", 1, 0, env_kwargs=KW, policy_kwargs={"beam": 3})
    assert main(["--quiet", "evaluate", ENV, "--env-kwargs", json.dumps(KW), "--policy", "hindsight",
                 "--policy-kwargs", '{"horizon": 3}']) == 2
    assert "--policy-kwargs: hindsight takes beam" in capsys.readouterr().err
