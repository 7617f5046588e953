"""Passage-v1 and its native vector env: checkers, budget, uncapped reward, seeds, vector = single, greedy."""

from math import comb

import gymnasium as gym
import numpy as np
import pytest
from env_checks import (
    assert_gymnasium_checker_passes,
    assert_sb3_checker_passes,
    assert_seed_fixes_the_episode,
    assert_vector_equals_singles,
    random_rollout,
)
from reference import odd_observer_outputs

import shipsense  # noqa: F401  (registers the environments)
from shipsense.envs import PASSAGE_V1_VARIANTS
from shipsense.envs.passage_v1 import CHI2_2_95, PassageV1Env, PassageV1VectorEnv
from shipsense.envs.prefetch import PASSAGE_BLOCK

EASY = "shipsense/PassageEasy-v1"
KW = {"scenario": "S2", "overrides": {"steps": 50}}   # S2: the run-in ends near sample 30, ~20 agent steps


def test_variants_registered_with_vector_entry_points_and_v0_retired():
    from shipsense.envs import register_envs

    register_envs()                                          # (idempotent: registered already on import)
    assert "shipsense/Passage-v0" not in gym.registry
    for vid in PASSAGE_V1_VARIANTS:
        spec = gym.registry[vid]
        assert spec.entry_point.endswith("PassageV1Env") and spec.vector_entry_point.endswith("PassageV1VectorEnv")
        assert spec.reward_threshold is not None
    envs = gym.make_vec(EASY, num_envs=2, vectorization_mode="vector_entry_point", overrides={"steps": 50})
    assert isinstance(envs.unwrapped, PassageV1VectorEnv)


def _make_in_child(queue):
    import gymnasium as gym_

    env = gym_.make("shipsense:shipsense/PassageEasy-v1", overrides={"steps": 50})
    obs, _ = env.reset(seed=1)
    queue.put(obs.shape)


def test_make_in_a_spawned_process():
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=_make_in_child, args=(q,))
    p.start()
    shape = q.get(timeout=120)
    p.join(timeout=60)
    assert p.exitcode == 0 and shape == PassageV1Env(**KW).observation_space.shape


def test_resets_with_missing_first_samples_never_crash():
    """S0 with 30 % dropouts: passages whose first samples are missing reset to finite observations."""
    env = PassageV1Env(scenario="S0", overrides={"noise": {"dropout": 0.3}, "steps": 40})
    for seed in range(25):
        obs, _ = env.reset(seed=seed)
        assert np.isfinite(obs).all() and env.observation_space.contains(obs)


def test_gymnasium_checker_passes_without_warnings():
    assert_gymnasium_checker_passes(gym.make(EASY, render_mode="rgb_array", overrides={"steps": 50}).unwrapped)


def test_stable_baselines_checker_passes():
    assert_sb3_checker_passes(PassageV1Env(**KW))


@pytest.mark.parametrize("k", [1, 2, 3])
def test_the_action_space_cannot_exceed_the_budget(k):
    env = PassageV1Env(k=k, **KW)
    table = env.subsets
    assert env.action_space.n == len(table) == sum(comb(3, j) for j in range(k + 1))
    assert table.sum(axis=1).max() == k and not table[0].any()
    assert len({tuple(r) for r in table}) == len(table)           # every subset once
    env.reset(seed=0)
    for a in range(env.action_space.n):
        _, r, term, _, info = env.step(a)
        assert info["reads"] == table[a].sum() <= k
        assert info["energy_term"] == pytest.approx(-0.01 * table[a].sum())
        if term:
            env.reset(seed=1)
    with pytest.raises(ValueError, match="action"):
        env.step(env.action_space.n)


def test_reward_is_uncapped_so_a_diverged_observer_pays_for_it():
    env = PassageV1Env(**KW)
    env.reset(seed=3)
    core = env.core
    update = core.tracker.update
    rewards = {}
    for off in (1.0, 100.0, 1e4, 1e6):
        def diverged(t, y, passages=None, off=off):
            s = update(t, y, passages=passages)
            s.estimate[:, 0] += off                       # the observer's estimate is `off` metres away
            return s
        core.tracker.update = diverged
        _, r, term, _, info = env.step(1)
        rewards[off] = r - info["energy_term"]
        assert info["error"] == pytest.approx(off, abs=0.5)   # plus the tracking error (cm)
        assert info["error_term"] == pytest.approx(-np.log1p(info["error"] / 1.0))
    assert rewards[1e6] < rewards[1e4] < rewards[100.0] < rewards[1.0]
    assert rewards[1e4] < -9.0 and rewards[1e6] < -13.0     # v0 capped the error term at -10


def test_same_seed_same_rollout_and_another_seed_another():
    assert_seed_fixes_the_episode(lambda: PassageV1Env(**KW))


def test_episode_metrics_are_the_episode_and_observations_stay_in_the_space():
    env = PassageV1Env(**KW)
    roll = random_rollout(env, seed=2)
    assert all(env.observation_space.contains(o) for o, *_ in roll)
    infos = [i for *_, i in roll[1:]]
    m = infos[-1]["episode_metrics"]
    assert all(type(v) is float for v in m.values())
    assert m["mean_error_m"] == pytest.approx(np.mean([i["error"] for i in infos]))
    assert m["coverage95"] == pytest.approx(np.mean([i["nees"] <= CHI2_2_95 for i in infos]))
    assert m["return"] == pytest.approx(sum(r for _, r, *_ in roll[1:]))
    assert m["steps"] == len(infos) and m["reads_per_step"] == pytest.approx(np.mean([i["reads"] for i in infos]))
    assert "episode_metrics" not in infos[-2]


def test_vector_env_equals_single_envs_across_autoreset_with_masks():
    def masked(i, info, vinfo):                          # a key's mask is set where its sub-environment has it
        if info is None:
            assert not vinfo["_error"][i]
            return
        assert vinfo["_error"][i] and info["error"] == pytest.approx(vinfo["error"][i], rel=0, abs=1e-6)
        if "episode_metrics" in info:
            assert vinfo["_episode_metrics"][i]
            assert all(vinfo["episode_metrics"]["_" + key][i] for key in info["episode_metrics"])

    assert_vector_equals_singles(PassageV1VectorEnv(num_envs=2, **KW), [PassageV1Env(**KW) for _ in range(2)],
                                 (21, 5), check=masked)


def test_sb3_adapter_on_the_native_vector_env_equals_single_envs_through_its_partial_reset():
    """What ``shipsense train`` runs: the native env (next-step autoreset) under SB3's adapter, which resets an
    ended sub-environment at once with ``reset(options={"reset_mask": ...})``; each sub-environment's
    episodes are those of a single env seeded alike (the same stream of passages)."""
    pytest.importorskip("stable_baselines3")
    from shipsense.envs.sb3 import VectorEnvAdapter

    n = 2
    venv = VectorEnvAdapter(PassageV1VectorEnv(num_envs=n, **KW))
    singles = [PassageV1Env(**KW) for _ in range(n)]
    venv.seed(7)
    vo = venv.reset()
    so = [s.reset(seed=7 + i)[0] for i, s in enumerate(singles)]
    np.testing.assert_allclose(vo, np.array(so), rtol=0, atol=1e-6)
    rng = np.random.default_rng(1)
    ended = 0
    for _ in range(50):
        acts = rng.integers(0, venv.action_space.n, n)
        vo, vr, vd, vinfo = venv.step(acts)
        for i, s in enumerate(singles):
            obs, r, t, _, info = s.step(int(acts[i]))
            assert vr[i] == pytest.approx(r, rel=0, abs=1e-5) and vd[i] == t
            if t:                                          # SB3 gets the last observation and the reset one
                ended += 1
                np.testing.assert_allclose(vinfo[i]["terminal_observation"], obs, rtol=0, atol=1e-6)
                assert vinfo[i]["episode_metrics"]["return"] == pytest.approx(info["episode_metrics"]["return"])
                obs, _ = s.reset()
            np.testing.assert_allclose(vo[i], obs, rtol=0, atol=1e-6)
    assert ended >= n
    with pytest.raises(ValueError, match="reset_mask"):
        venv.venv.reset(options={"reset_mask": np.ones(n + 1, dtype=bool)})


def test_an_integer_seed_is_seed_plus_index_and_a_wrong_list_is_refused():
    venv = PassageV1VectorEnv(num_envs=2, **KW)
    a, _ = venv.reset(seed=40)
    b, _ = venv.reset(seed=[40, 41])
    np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="seed"):
        venv.reset(seed=[1, 2, 3])


def test_a_seeded_partial_reset_reseeds_only_the_environments_it_resets():
    """As gymnasium's ``SyncVectorEnv``: ``reset(seed=..., options={"reset_mask": mask})`` resets the masked
    sub-environments from their seeds (sub-environment 1 from 8, as a single env reset with 8) and leaves the
    others' streams alone -- through their next episodes they are what they are with an unseeded partial
    reset."""
    mask = np.array([False, True, False, False])
    others = [0, 2, 3]

    def run(seed):
        venv = PassageV1VectorEnv(4, **KW)
        venv.reset(seed=5)
        rng = np.random.default_rng(0)
        for _ in range(10):
            venv.step(rng.integers(0, venv.single_action_space.n, 4))
        obs, _ = venv.reset(seed=seed, options={"reset_mask": mask})
        out, first, resets = [obs[others]], obs[1], np.zeros(3, dtype=int)
        for _ in range(420):     # (episodes of ~20 agent steps: past the block of passages each environment had)
            o, r, t, _, _ = venv.step(rng.integers(0, venv.single_action_space.n, 4))
            out += [o[others], r[others]]
            resets += t[others]
        return first, out, resets

    first, seeded, resets = run([7, 8, 9, 10])
    _, unseeded, _ = run(None)
    assert resets.min() > PASSAGE_BLOCK     # (each into its next block of passages)
    for a, b in zip(seeded, unseeded, strict=True):
        np.testing.assert_array_equal(a, b)
    single = PassageV1Env(**KW)
    np.testing.assert_allclose(first, single.reset(seed=8)[0], rtol=0, atol=1e-6)


def test_announced_seeded_resets_give_the_same_episodes(monkeypatch):
    """An evaluation announces the seeds of its resets (``expect_seeds``): their blocks and first run-ins are
    drawn ahead, in batches, on the background thread.  Every episode is the one plain seeded resets give, also
    when the resets depart from the announcement (an unannounced seed, then no seed) and come back; a pickled
    core leaves the announcement behind."""
    import copy
    import pickle
    import sys

    from shipsense.envs import passage_v1, prefetch

    def caller():     # the function that drew a block (not a comprehension inside it)
        frame = sys._getframe(2)
        while frame.f_code.co_name.startswith("<"):
            frame = frame.f_back
        return frame.f_code.co_name

    drawn, block = [], passage_v1.PassageV1Core.draw_block
    monkeypatch.setattr(passage_v1.PassageV1Core, "draw_block",
                        lambda self, seed: drawn.append(caller()) or block(self, seed))
    monkeypatch.setenv("SHIPSENSE_THREADS", "2")
    seeds = [50 + i for i in range(40)]

    def episodes(announce):
        drawn.clear()
        env = PassageV1Env(**KW)
        if announce:
            env.expect_seeds(seeds)
            clone = pickle.loads(pickle.dumps(env.core))
            assert env.core._expected and not clone._expected and not list(clone._to_expect)
        out, rng = [], np.random.default_rng(0)
        for seed in seeds[:5] + [999] + seeds[5:8] + [None] + seeds[8:20]:
            obs, _ = env.reset(seed=seed)
            out.append(obs)
            done = False
            while not done:
                obs, r, done, _, info = env.step(int(rng.integers(env.action_space.n)))
                out += [obs, r, info["error"]]
        if announce:     # the env itself pickles and copies, the announcement used up or not
            pickle.loads(pickle.dumps(env))
            env.expect_seeds(seeds)
            copy.deepcopy(env)
            assert len(env.core._expected) == 2 * prefetch.EXPECT_BATCH    # (two batches drawn ahead)
            env.reset(seed=seeds[0])
            assert len(env.core._expected) == 2 * prefetch.EXPECT_BATCH - 1
        env.close()
        return out, list(drawn)

    (announced, drawn_announced), (plain, drawn_plain) = episodes(True), episodes(False)
    assert drawn_announced.count("_blocks_ahead") >= 20 and drawn_announced.count("_take_block") == 1
    assert drawn_plain.count("_take_block") == 21
    for a, b in zip(announced, plain, strict=True):
        np.testing.assert_array_equal(a, b)


def test_run_episodes_announces_and_runs_every_episode_of_an_iterator(monkeypatch):
    """``run_episodes`` reads its episodes twice (the announcement, the loop): a one-pass iterator of indices
    gives the episodes a range gives."""
    from shipsense.envs.evaluation import load_policy, run_episodes

    monkeypatch.setenv("SHIPSENSE_THREADS", "2")
    env = PassageV1Env(**KW)
    greedy = load_policy(env, "greedy")
    once = run_episodes(env, greedy, 7, iter(range(6)))
    again = run_episodes(env, greedy, 7, range(6))
    assert len(once[0]) == 6 and once == again


def _brute_force_gains(model, R, x, P, subsets, h=1e-6):
    """Position log-det drop of every subset: Kalman form on the stacked channels, numerical Jacobian."""
    n = model.n
    J = np.empty((model.m, n))
    for j in range(n):
        dx = np.zeros(n)
        dx[j] = h * max(1.0, abs(x[j]))
        J[:, j] = model.residual(model.h(x + dx), model.h(x - dx)) / (2 * dx[j])
    out = []
    for row in subsets:
        ch = row[model.array.channel_sensor]
        Hs = J[ch]
        S = Hs @ P @ Hs.T + np.diag(R[ch])
        post = P - P @ Hs.T @ np.linalg.solve(S, Hs @ P)
        out.append(np.linalg.slogdet(P[:2, :2])[1] - np.linalg.slogdet(post[:2, :2])[1] if ch.any() else 0.0)
    return np.array(out)



def test_the_compiled_gains_equal_the_kalman_form_and_are_zero_where_undefined():
    """information_gains (information form, compiled) against the covariance (Kalman) form on the stacked read
    channels, for random covariances, Jacobians and subsets (the empty one: 0); a singular covariance gives 0
    instead of raising."""
    from shipsense.design.information_gain import information_gains
    from shipsense.envs.passage_v1 import subsets

    rng = np.random.default_rng(4)
    E, n, first = 6, 7, np.array([0, 3, 6, 7])          # sensors of 3, 3, 1 and 2 channels
    m, S = 9, 4
    L = rng.normal(size=(E, n, n))
    P = L @ np.swapaxes(L, -1, -2) + 0.1 * np.eye(n)
    Hm = rng.normal(size=(E, m, n))
    Rinv = rng.uniform(0.5, 4.0, m)
    table = subsets(S, 2)
    sensor = np.repeat(np.arange(S), np.diff(np.append(first, m)))
    got = information_gains(Hm, Rinv, P, first, table)
    for e in range(E):
        for t, row in enumerate(table):
            ch = row[sensor]
            Hs = Hm[e, ch]
            post = P[e] - P[e] @ Hs.T @ np.linalg.solve(Hs @ P[e] @ Hs.T + np.diag(1.0 / Rinv[ch]), Hs @ P[e])
            want = np.linalg.slogdet(P[e, :2, :2])[1] - np.linalg.slogdet(post[:2, :2])[1]
            np.testing.assert_allclose(got[e, t], max(want, 0.0), rtol=1e-9, atol=1e-12)
    assert (got[:, ~table.any(axis=1)] == 0).all() and (got[:, table.any(axis=1)] > 0).all()
    P[2] = 0.0
    assert (information_gains(Hm, Rinv, P, first, table)[2] == 0).all()


def test_the_gains_at_states_equal_the_gains_of_the_models_jacobians():
    """information_gains_at (the Jacobians from the compiled measurement kernel, in one call) equals
    information_gains of model.H bit for bit; a model without a compiled kernel (the series HED path) goes
    through model.H."""
    from shipsense import load_scenario
    from shipsense.design.information_gain import information_gains, information_gains_at
    from shipsense.envs.passage_v1 import subsets
    from shipsense.models.field_model import model_from_scenario

    rng = np.random.default_rng(5)
    from dataclasses import replace

    from shipsense.models.field_model import FieldModel
    from shipsense.models.measurement import kernel_of

    for name, series in (("S2", False), ("S1-P2", False), ("S1-P2", True)):
        model = model_from_scenario(load_scenario(name))
        if series:                                        # no compiled kernel: model.H's numpy path
            model = FieldModel(replace(model.array, electric_method="series"), model.period, model.Q, model.R)
            assert kernel_of(model) is None
        S = len(model.array.ids)
        first = np.flatnonzero(np.diff(np.concatenate([[-1], model.array.channel_sensor])))
        x = model.state_from_truth(simulate_truth(name))[:5, 10] / model.x_scale
        x = x + 0.01 * rng.normal(size=x.shape) * np.abs(x)
        L = rng.normal(size=(5, model.n, model.n))
        P = L @ np.swapaxes(L, -1, -2) + 0.1 * np.eye(model.n)
        Rinv = 1.0 / model.R
        table = subsets(S, min(2, S))
        np.testing.assert_array_equal(information_gains_at(model, x, Rinv, P, first, table),
                                      information_gains(model.H(x), Rinv, P, first, table))


def simulate_truth(name):
    from shipsense import simulate

    return simulate(name, runs=5, seed=6, random=True).truth


def _observe_numpy(c):
    """The observation table written in numpy (the reference of the compiled ``observe``)."""
    S, est, cov = c.S, c.last.estimate, c.last.cov
    obs = np.empty((c.E, c.obs_dim))
    obs[:, 0:2] = (est[:, :2] - c.centre) / c.position_scale
    obs[:, 2:4] = est[:, 2:4] * 0.1
    vx, vy, cxy = cov[:, 0, 0], cov[:, 1, 1], cov[:, 0, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        obs[:, 4] = np.log10(np.maximum(vx, 1e-12)) / 6.0
        obs[:, 5] = np.log10(np.maximum(vy, 1e-12)) / 6.0
        obs[:, 6] = cxy / np.sqrt(np.maximum(vx * vy, 1e-300))
    obs[:, 7] = c.last.status / 4.0
    obs[:, 8] = c.k / max(c.K - 1, 1)
    obs[:, 9:9 + S] = c.since / max(c.K - 1, 1)
    g = np.maximum(c.gains[:, 1:1 + S], 0.0)
    with np.errstate(invalid="ignore"):
        obs[:, 9 + S:] = g / (1.0 + g)
    obs = np.nan_to_num(obs, nan=0.0, posinf=1.0, neginf=-1.0)
    return np.clip(obs, -1.0, 1.0).astype(np.float32)


def test_the_compiled_observation_and_measures_equal_numpys_with_nan_and_inf():
    """observe (within one float32 ulp: numba's log10 and numpy's differ in the last bit of some float64s) and
    _measure (exactly) against numpy, on states with NaN, infinities, zero and negative variances."""
    from shipsense.envs.passage_v1 import PassageV1Core

    rng = np.random.default_rng(8)
    c = PassageV1Core(num_envs=40, **KW)
    E = c.E
    odd_observer_outputs(c.last, rng)
    c.last.status[:] = rng.integers(0, 5, E)
    c.k[:] = rng.integers(0, c.K, E)
    c.since[:] = rng.integers(0, c.K, (E, c.S))
    c.gains[:] = rng.normal(0, 3, c.gains.shape)
    c.gains[7, 1] = np.nan
    c.gains[8, 2] = np.inf
    c.truth[:] = rng.normal(0, 300, c.truth.shape)
    obs = c.observe()
    assert obs.dtype == np.float32 and np.isfinite(obs).all()
    np.testing.assert_array_max_ulp(obs, _observe_numpy(c), maxulp=1)
    envs = rng.permutation(E)[:25]
    error, nees = c._measure(envs)
    k = c.k[envs]
    d = c.last.estimate[envs, :2] - c.truth[envs, k, :2]
    cov = c.last.cov[envs, :2, :2]
    a, b, cc = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    with np.errstate(all="ignore"):
        want = (cc * d[:, 0] ** 2 - 2 * b * d[:, 0] * d[:, 1] + a * d[:, 1] ** 2) / (a * cc - b * b)
    np.testing.assert_array_equal(nees, np.where(np.isfinite(want), want, np.inf))
    np.testing.assert_array_equal(error, np.hypot(d[:, 0], d[:, 1]))
    np.testing.assert_array_equal(c.errors[envs, k], error)
    np.testing.assert_array_equal(c.inside[envs, k], nees <= CHI2_2_95)
    np.testing.assert_array_equal(c.est_hist[envs, k], c.last.estimate[envs, :2])

def test_greedy_is_the_brute_force_argmax_of_the_predicted_gain():
    env = PassageV1Env(k=2, **KW)
    greedy = env.baseline("greedy")
    checked = 0
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        c = env.core
        for _ in range(5):
            if c.last.status[0] >= 2:                        # the observer has a track
                xs = c.model.x_scale
                x = c.model.A @ (c.last.estimate[0] / xs)
                P = c.model.A @ (c.last.cov[0] / np.outer(xs, xs)) @ c.model.A.T
                brute = _brute_force_gains(c.model, c.tracker.filter_model.R, x, P, c.subsets)
                np.testing.assert_allclose(c.gains[0], brute, rtol=1e-3, atol=1e-6)
                full = np.flatnonzero(c.subsets.sum(axis=1) == 2)
                assert greedy(obs) == full[np.argmax(brute[full])]
                assert np.allclose(obs[9 + 3:], np.maximum(brute[1:4], 0) / (1 + np.maximum(brute[1:4], 0)),
                                   atol=1e-5)
                checked += 1
            obs, *_ = env.step(greedy(obs))
    assert checked >= 5


def test_round_robin_cycles_and_random_reads_k():
    env = PassageV1Env(k=1, **KW)
    obs, _ = env.reset(seed=0)
    rr, rnd = env.baseline("round-robin"), env.baseline("random", seed=1)
    seen = [rr(obs) for _ in range(1)]
    for _ in range(5):
        obs, *_ = env.step(seen[-1])
        seen.append(rr(obs))
    assert seen[:6] == [1, 2, 3, 1, 2, 3]
    assert all(env.subsets[rnd(obs)].sum() == 1 for _ in range(20))
    with pytest.raises(ValueError, match="'best'.*random, round-robin, greedy"):
        env.baseline("best")


@pytest.mark.parametrize("kwargs, name", [
    ({"energy_cost": -0.1}, "energy_cost"), ({"k": 4}, "k"), ({"k": 0}, "k"), ({"k": 1.5}, "k"),
    ({"error_scale": 0.0}, "error_scale"), ({"scenario": "no-such-scenario"}, "scenario"),
    ({"overrides": {"steps": -3}}, "overrides"), ({"render_mode": "ascii"}, "render_mode"),
])
def test_bad_kwargs_raise_one_value_error_naming_the_argument(kwargs, name):
    with pytest.raises(ValueError, match=name) as exc:
        PassageV1Env(**{**KW, **kwargs})
    assert "\n" not in str(exc.value)


def test_render_rgb_array_shows_the_episode():
    env = PassageV1Env(render_mode="rgb_array", **KW)
    env.reset(seed=0)
    env.step(2)
    img = env.render()
    assert img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8 and img.std() > 0


def test_a_passage_the_observer_never_tracks_leaves_one_step_and_no_gains():
    """Moments of a few A m^2: no detection; the run-in lasts to the last step but one, gains are 0 (the prior's
    mean is the centroid, where S2's accelerometer sits: a linearisation there divided by zero) and greedy
    falls back to round-robin."""
    prior = {"range": [60.0, 120.0], "bearing_deg": [0.0, 360.0], "course_offset_deg": [-20.0, 20.0],
             "speed": [3.0, 7.0], "moment": [1.0, 2.0]}
    env = PassageV1Env(scenario="S2", overrides={"steps": 40, "prior": prior})
    obs, _ = env.reset(seed=0)
    assert env.core.k[0] == 38 and obs[7] * 4 <= 1 and not obs[12:].any()
    assert env.baseline("greedy")(obs) == env.baseline("round-robin")(obs)
    _, r, term, _, info = env.step(1)
    assert term and info["episode_metrics"]["steps"] == 1.0 and info["error"] > 10.0 and np.isfinite(r)


def test_the_run_ins_in_one_batch_observe_what_one_at_a_time_did(monkeypatch):
    """The observers' run-ins run side by side on a sibling tracker (every queued passage of the environments
    reset together, their window fits deferred to the end: ``Tracker.fit_pending``) and are carried into the
    environments (``Tracker.set_passage_states``): observations, rewards and errors equal, to the bit, those of
    each passage's run-in alone, its window fitted at the sample it completes (the loop before, replayed
    here), over reset cycles of a vector env."""
    from shipsense.envs import passage_core, passage_v1

    def one_at_a_time(self, entries):                                # the run-in before: one passage, its
        for entry in entries:                                       # window fitted at the sample it completes
            trk, y, k = self.tracker.sibling(1), entry[0][None], 0
            last = trk.update(self.times[0], y[:, 0])
            while self._blind_status(last.status)[0] and k < self.K - 2:
                k += 1
                last = trk.update(self.times[k], y[:, k])
            record = {name: np.copy(getattr(last, name)[0]) for name in passage_core.RECORDED}
            entry[2] = (k, record, trk.passage_states([0])[0])

    def run():
        out = []
        venv = gym.make_vec("shipsense/Passage-v1", num_envs=12, vectorization_mode="vector_entry_point")
        obs, _ = venv.reset(seed=3)
        out.append(obs)
        rng = np.random.default_rng(0)
        for _ in range(2 * venv.unwrapped.core.K):                      # two reset cycles
            o, r, _, _, info = venv.step(rng.integers(0, venv.single_action_space.n, 12))
            out += [o, r, info["error"]]
        return out

    together = run()
    monkeypatch.setattr(passage_v1.PassageV1Core, "run_ins", one_at_a_time)
    for a, b in zip(together, run(), strict=True):
        np.testing.assert_array_equal(a, b)


def test_the_core_refuses_an_action_out_of_range_before_writing_anything():
    env = PassageV1Env(**KW)
    env.reset(seed=0)
    core = env.core
    before = (core.k.copy(), core.since.copy(), core.returns.copy())
    for bad in (-1, len(core.subsets)):
        with pytest.raises(ValueError, match=r"actions must be integers in \[0, "):
            core.step(np.array([bad]))
    for a, b in zip(before, (core.k, core.since, core.returns)):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="action must be an integer"):
        env.step(len(core.subsets))
    with pytest.raises(ValueError, match="actions must be integers"):
        core.step(np.array([1.5]))
    venv = PassageV1VectorEnv(2, **KW)
    venv.reset(seed=0)
    for bad in (np.array([1.5, 2.0]), np.array([True, False])):
        with pytest.raises(ValueError, match="actions must be integers"):
            venv.step(bad)


def _vector_rollout(steps, seed=5, num_envs=4):
    venv = PassageV1VectorEnv(num_envs, **KW)
    obs, _ = venv.reset(seed=seed)
    out, rng = [obs], np.random.default_rng(0)
    for _ in range(steps):
        o, r, _, _, info = venv.step(rng.integers(0, venv.single_action_space.n, num_envs))
        out += [o, r, info["error"], info["status"]]
    return venv, out


def test_run_ins_left_to_the_background_change_nothing(monkeypatch):
    """With two threads a reset leaves the run-ins its environments need later (the rest of their blocks, their
    next block from the seed that will empty the block) to the background thread; with one everything is done
    when needed.  Over more than one block per environment, every observation, reward, error and status is
    the same to the bit."""
    import sys

    from shipsense.envs import passage_v1

    drawn, block = [], passage_v1.PassageV1Core.draw_block
    monkeypatch.setattr(passage_v1.PassageV1Core, "draw_block",
                        lambda self, seed: drawn.append(sys._getframe(1).f_code.co_name) or block(self, seed))
    monkeypatch.setenv("SHIPSENSE_THREADS", "2")
    venv, ahead = _vector_rollout(800)
    # every block but the first of each environment drawn ahead (by the work left to the background; by the
    # reset that needs it if the background had not started it) and used: none drawn again at its reset
    assert drawn.count("_take_block") == 4 and len(drawn) > 8      # (drawn by the reset that needs it)
    monkeypatch.setenv("SHIPSENSE_THREADS", "1")
    venv, alone = _vector_rollout(800)
    assert not venv.core._next
    for a, b in zip(ahead, alone, strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_block_drawn_ahead_is_dropped_when_its_seed_does_not_come(monkeypatch):
    """A block is drawn ahead from the seed the reset that empties the current block will get -- if nothing else
    draws from the environment's generator meanwhile.  A user's draw moves that seed: the block drawn ahead
    is dropped and the passages are those of an environment that never drew ahead."""
    def run(threads):
        monkeypatch.setenv("SHIPSENSE_THREADS", threads)
        env = PassageV1Env(**KW)
        obs, _ = env.reset(seed=0)
        out, resets = [obs], 0
        while resets < 40:
            obs, r, term, _, info = env.step(1)
            out += [obs, r, info["error"]]
            if term:
                resets += 1
                if resets % 7 == 0:
                    env.np_random.integers(10)            # a draw the environment did not foresee
                out.append(env.reset()[0])
        return out

    for a, b in zip(run("2"), run("1"), strict=True):
        np.testing.assert_array_equal(a, b)


def test_pickling_and_copying_wait_for_the_work_in_flight(monkeypatch):
    import copy
    import pickle

    monkeypatch.setenv("SHIPSENSE_THREADS", "2")
    env = PassageV1Env(**KW)
    env.reset(seed=0)
    for _ in range(3):                     # non-fresh resets: work left to the background
        while not env.step(1)[2]:
            pass
        env.reset()
    clones = [pickle.loads(pickle.dumps(env)), copy.deepcopy(env)]
    for _ in range(60):                    # into the next passages, from the states copied
        outs = [e.step(2) for e in (env, *clones)]
        for out in outs[1:]:
            np.testing.assert_array_equal(out[0], outs[0][0])
            assert out[1:4] == outs[0][1:4]
        if outs[0][2]:
            for e in (env, *clones):
                e.reset()


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="needs fork")
def test_work_in_flight_when_the_process_forks_is_done_in_the_child():
    """A forked child (an AsyncVectorEnv worker, a multiprocessing pool) has the parent's queue entries but not
    its background thread: work that was running there is done in the child, not waited for forever."""
    import os
    import threading
    import time

    from shipsense.envs.prefetch import _Later

    parent, gate = os.getpid(), threading.Event()
    running = _Later(lambda: os.getpid() if os.getpid() != parent else (gate.wait(30), os.getpid())[1])
    deadline = time.monotonic() + 10
    while not running._future.running() and time.monotonic() < deadline:
        time.sleep(0.01)
    pid = os.fork()
    if pid == 0:        # the child: exit 0 if it did the work itself, never return into pytest
        try:
            ok = running.result() == os.getpid()
        finally:
            os._exit(0 if ok else 1)
    deadline = time.monotonic() + 60
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    gate.set()
    if not done:
        os.kill(pid, 9)
        os.waitpid(pid, 0)
    assert done and os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0
    assert running.result() == parent


def test_closing_or_dropping_an_environment_leaves_the_background_no_work_of_its(monkeypatch):
    """``close()`` cancels the run-ins not yet started (what was running finishes), and work still queued holds
    its environment weakly: a dropped environment is freed."""
    import gc
    import threading
    import time
    import weakref

    from shipsense import parallel

    monkeypatch.setenv("SHIPSENSE_THREADS", "2")
    gate = threading.Event()
    blocker = parallel.background().submit(lambda: gate.wait(30))   # the background busy: the work queues
    try:                                       # (a reset needing queued work does it itself)
        venv, _ = _vector_rollout(400)
        jobs = list({id(part.job): part.job for part in venv.core._next.values()}.values())   # (blocks shared)
        assert jobs and not any(job._done for job in jobs)
        venv.close()
    finally:
        gate.set()
    blocker.result(30)
    assert all(job._future.cancelled() for job in jobs)
    deadline = time.monotonic() + 30
    while parallel.background().busy and time.monotonic() < deadline:
        time.sleep(0.01)
    assert parallel.background().busy == 0
    gate.clear()
    blocker = parallel.background().submit(lambda: gate.wait(30))   # (nothing of it running: all of it queued)
    try:
        ref = weakref.ref(_vector_rollout(300)[0].core)
        gc.collect()
        assert ref() is None
    finally:
        gate.set()
    blocker.result(30)


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="needs fork")
def test_a_forked_child_does_not_wait_for_a_cache_lock_another_thread_held():
    """The grid caches' lock may be held by the background thread when the process forks: the child gets its
    own lock (the parent's holder does not exist there)."""
    import os
    import threading

    from shipsense.trackers.init import grid_basis as initialiser

    held, release = threading.Event(), threading.Event()

    def hold():
        with initialiser._CACHE_LOCK:
            held.set()
            release.wait(30)

    threading.Thread(target=hold, daemon=True).start()
    assert held.wait(10)
    pid = os.fork()
    if pid == 0:
        try:
            ok = initialiser._CACHE_LOCK.acquire(timeout=5)
        finally:
            os._exit(0 if ok else 1)
    status = os.waitpid(pid, 0)[1]
    release.set()
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0
    with initialiser._CACHE_LOCK:             # (the parent's lock works as before)
        pass


def test_a_seeded_reset_cancels_the_work_left_for_the_passages_it_drops(monkeypatch):
    """An evaluation resets with a seed every episode: the work left to the background for the rest of the
    blocks it drops is cancelled (not started), so no backlog builds up."""
    import threading

    from shipsense import parallel

    monkeypatch.setenv("SHIPSENSE_THREADS", "2")
    gate = threading.Event()
    blocker = parallel.background().submit(lambda: gate.wait(30))   # the background busy: the work queues
    try:
        venv, _ = _vector_rollout(60)
        assert len(venv.core._next) == 4                  # each environment's next block, left to the background
        jobs = [part.job for part in venv.core._next.values()] + [
            entry[3] for queue in venv.core._passages.values() for entry in queue if entry[3] is not None]
        jobs = [job for job in jobs if not job._done]     # (not done by a reset that needed it)
        assert jobs
        venv.reset(seed=99)
    finally:
        gate.set()
    blocker.result(30)
    assert all(job._future.cancelled() for job in jobs) and not venv.core._next


def test_a_failure_in_the_background_is_done_again_where_the_work_is_needed(monkeypatch):
    """Work the background thread failed is done again by the reset that needs it (which raises if it fails
    there too), so a passing failure there changes no episode."""
    import threading

    from shipsense.envs import passage_v1

    monkeypatch.setenv("SHIPSENSE_THREADS", "2")
    _, clean = _vector_rollout(500)
    calls, run_ins = [0], passage_v1.PassageV1Core.run_ins

    def flaky(self, entries):
        if threading.current_thread().name == "shipsense-background":
            calls[0] += 1
            if calls[0] % 3 == 2:
                raise RuntimeError("a passing failure")
        return run_ins(self, entries)

    monkeypatch.setattr(passage_v1.PassageV1Core, "run_ins", flaky)
    _, failing = _vector_rollout(500)
    assert calls[0] >= 3
    for a, b in zip(clean, failing, strict=True):
        np.testing.assert_array_equal(a, b)


def test_next_blocks_of_several_environments_are_left_together_and_dropped_apart(monkeypatch):
    """The next blocks of several environments are one piece of background work (their run-ins in one batch); a
    seeded reset of one environment drops its block alone -- the others' are still used, and every episode is
    the one the environments have with everything done when needed."""
    import threading

    from shipsense import parallel

    def run(threads, check=False):
        monkeypatch.setenv("SHIPSENSE_THREADS", threads)
        gate = threading.Event()
        blocker = parallel.background().submit(lambda: gate.wait(30))   # the background busy: the work queues
        try:
            venv, out = _vector_rollout(300)
            parts = dict(venv.core._next)
            if check:
                assert len(parts) == 4 and len({id(part.job) for part in parts.values()}) == 1
            mask = np.array([False, True, False, False])
            obs, _ = venv.reset(seed=[7, 8, 9, 10], options={"reset_mask": mask})
            if check:    # environment 1's block dropped, the work kept for the other three
                assert 1 not in venv.core._next and set(venv.core._next) == {0, 2, 3}
                assert not parts[0].job._future.cancelled()
        finally:
            gate.set()
        blocker.result(30)
        out.append(obs)
        rng = np.random.default_rng(1)
        for _ in range(600):
            o, r, _, _, info = venv.step(rng.integers(0, venv.single_action_space.n, 4))
            out += [o, r, info["error"], info["status"]]
        return out

    for a, b in zip(run("2", check=True), run("1"), strict=True):
        np.testing.assert_array_equal(a, b)
