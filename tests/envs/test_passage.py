"""Passage-v0 and its native vector env: checkers, determinism, spaces, vector = single, energy budget."""

import multiprocessing as mp
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from reference import odd_observer_outputs

import shipsense  # noqa: F401  (registers the environments)
from shipsense.envs.passage import PassageEnv, PassageVectorEnv

SHORT = {"overrides": {"steps": 30}}
IGNORED_WARNINGS = ()   # the ignore-list: nothing is ignored (the checkers run warning-free)


def _rollout(env, seed, actions_seed=0, steps=None):
    obs, info = env.reset(seed=seed)
    rng = np.random.default_rng(actions_seed)
    out = [(obs, None, None, None)]
    while True:
        a = rng.integers(0, 2, env.action_space.n)
        obs, r, term, trunc, info = env.step(a)
        out.append((obs, r, term, info))
        if term or trunc or (steps and len(out) > steps):
            return out


def test_gymnasium_checker_passes_without_warnings():
    from gymnasium.utils.env_checker import check_env

    env = gym.make("shipsense/Passage-v0", render_mode="rgb_array", **SHORT).unwrapped   # with its spec
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=False)
    caught = [w for w in caught if not any(s in str(w.message) for s in IGNORED_WARNINGS)]
    assert not caught, [str(w.message) for w in caught]


def test_stable_baselines_checker_passes():
    sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3.check_env(PassageEnv(**SHORT), warn=True)
    assert not [w for w in caught if "shipsense" in str(w.filename) or "env_checker" in str(w.filename)], \
        [str(w.message) for w in caught]


def test_same_seed_same_rollout_including_info():
    a = _rollout(PassageEnv(**SHORT), seed=7)
    b = _rollout(PassageEnv(**SHORT), seed=7)
    assert len(a) == len(b)
    for (oa, ra, ta, ia), (ob, rb, tb, ib) in zip(a, b):
        np.testing.assert_array_equal(oa, ob)
        assert ra == rb and ta == tb
        if ia is not None:
            assert ia.keys() == ib.keys()
            for k in ia:
                np.testing.assert_array_equal(ia[k], ib[k])
    c = _rollout(PassageEnv(**SHORT), seed=8)
    assert not np.array_equal(a[1][0], c[1][0])


def test_observations_stay_inside_the_space_and_the_episode_terminates():
    env = PassageEnv(**SHORT)
    for seed in range(3):
        roll = _rollout(env, seed=seed, actions_seed=seed)
        assert all(env.observation_space.contains(o) and np.isfinite(o).all() for o, *_ in roll)
        assert roll[-1][2] is True and len(roll) == 30       # terminated at the last sample
        info = roll[-1][3]
        assert {"truth", "error", "nees", "selected", "reads", "trimmed", "error_term", "energy_term"} <= set(info)
        assert roll[-1][1] == pytest.approx(info["error_term"] + info["energy_term"])


def test_vector_env_equals_single_envs_step_by_step_across_autoreset():
    n = 3
    venv = PassageVectorEnv(num_envs=n, **SHORT)
    singles = [PassageEnv(**SHORT) for _ in range(n)]
    vo, _ = venv.reset(seed=11)
    so = [s.reset(seed=11 + i)[0] for i, s in enumerate(singles)]
    np.testing.assert_array_equal(vo, np.array(so))
    rng = np.random.default_rng(0)
    pending = [False] * n
    for _ in range(35):                                   # one episode (29 steps) and the next one's start
        acts = rng.integers(0, 2, (n, 3))
        vo, vr, vt, vtr, vinfo = venv.step(acts)
        for i, s in enumerate(singles):
            if pending[i]:                                # next-step autoreset
                obs, _ = s.reset()
                r, t = 0.0, False
                pending[i] = False
            else:
                obs, r, t, _, info = s.step(acts[i])
                # equal to rounding: an autoreset re-seeds some rows of the vector env's bank, after which
                # its next predict re-forms the covariance from the factor instead of reusing the update's;
                # how far that rounding carries depends on the BLAS kernel (5 nm on an AVX-512 machine), so
                # errors are compared in metres at the observations' tolerance
                assert info["error"] == pytest.approx(vinfo["error"][i], rel=0, abs=1e-6)
                pending[i] = t
            np.testing.assert_allclose(vo[i], obs, rtol=0, atol=1e-6)
            assert vr[i] == pytest.approx(r, rel=0, abs=1e-6) and vt[i] == t     # error / 10 m, energy exact
        assert not vtr.any()


@settings(max_examples=15, deadline=None)
@given(max_reads=st.integers(1, 3), actions=st.lists(st.lists(st.integers(0, 1), min_size=3, max_size=3),
                                                   min_size=5, max_size=5))
def test_energy_budget_holds_at_every_step(max_reads, actions):
    env = PassageEnv(max_reads=max_reads, **SHORT)
    env.reset(seed=0)
    for a in actions:
        _, r, _, _, info = env.step(np.array(a))
        assert info["reads"] <= max_reads
        assert info["reads"] + info["trimmed"] == sum(a)
        assert info["energy_term"] == pytest.approx(-0.01 * info["reads"])


def _make_in_child(queue):
    import gymnasium as gym_

    env = gym_.make("shipsense:shipsense/Passage-v0", overrides={"steps": 20})
    obs, _ = env.reset(seed=1)
    queue.put(obs.shape)


def test_make_in_a_spawned_process():
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=_make_in_child, args=(q,))
    p.start()
    shape = q.get(timeout=120)
    p.join(timeout=60)
    assert p.exitcode == 0 and shape == PassageEnv(**SHORT).observation_space.shape


def test_registration_is_idempotent_and_vector_make_uses_the_native_env():
    from shipsense.envs import register_envs

    register_envs()
    register_envs()
    envs = gym.make_vec("shipsense/Passage-v0", num_envs=2, vectorization_mode="vector_entry_point",
                        overrides={"steps": 20})
    assert isinstance(envs.unwrapped, PassageVectorEnv)
    obs, _ = envs.reset(seed=0)
    assert obs.shape == (2,) + PassageEnv(**SHORT).observation_space.shape


def test_pickling_keeps_the_episode():
    env = PassageEnv(**SHORT)
    env.reset(seed=4)
    env.step(np.array([1, 0, 1]))
    clone = pickle.loads(pickle.dumps(env))
    a = env.step(np.array([1, 1, 0]))
    b = clone.step(np.array([1, 1, 0]))
    np.testing.assert_array_equal(a[0], b[0])
    assert a[1] == b[1]


def test_render_rgb_array():
    env = PassageEnv(render_mode="rgb_array", **SHORT)
    env.reset(seed=0)
    img = env.render()
    assert img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8


def test_ppo_smoke_run():
    pytest.importorskip("stable_baselines3")
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    env = PassageEnv(**SHORT)
    model = PPO("MlpPolicy", env, n_steps=256, batch_size=64, n_epochs=2, seed=0, device="cpu", verbose=0)
    model.learn(total_timesteps=2048)
    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(action)


def test_resets_with_missing_first_samples_never_crash_and_the_observer_is_the_tracker():
    """S0 with 30 % dropouts: a passage whose first sample is missing used to make seeding raise on reset."""
    env = gym.make("shipsense/Passage-v0", scenario="S0", overrides={"noise": {"dropout": 0.3}, "steps": 40})
    core = env.unwrapped.core
    assert core.tracker.settings.method == "tracker" and core.H == 5
    for seed in range(25):
        obs, _ = env.reset(seed=seed)
        assert np.isfinite(obs).all() and env.observation_space.contains(obs)
    status = obs[-2] * 4
    assert status in (0, 1)       # no data yet, or initialising: the tracker starts from its prior
    bank = gym.make("shipsense/Passage-v0", scenario="S0", observer="bank",
                    overrides={"noise": {"dropout": 0.3}, "steps": 40})
    assert bank.unwrapped.core.H == 12
    for seed in range(25):
        bank.reset(seed=seed)


def test_sb3_adapter_serves_the_native_vector_env_through_list_seeds_and_partial_resets():
    """``shipsense train --env shipsense/Passage-v0`` runs the native env under SB3's adapter: ``VecEnv.seed``
    hands a list of seeds, an ended episode is reset with ``reset_mask``; each sub-environment equals a single
    env seeded alike."""
    pytest.importorskip("stable_baselines3")
    from shipsense.envs.sb3 import VectorEnvAdapter

    kw = {"scenario": "S2", "overrides": {"steps": 30}}
    venv = VectorEnvAdapter(PassageVectorEnv(num_envs=2, **kw))
    singles = [PassageEnv(**kw) for _ in range(2)]
    venv.seed(4)
    np.testing.assert_allclose(venv.reset(), [s.reset(seed=4 + i)[0] for i, s in enumerate(singles)], atol=1e-6)
    ended = 0
    for _ in range(40):
        actions = np.ones((2, venv.action_space.shape[0]), dtype=np.int8)
        obs, rewards, dones, _ = venv.step(actions)
        for i, s in enumerate(singles):
            o, r, t, _, _ = s.step(actions[i])
            assert dones[i] == t and rewards[i] == pytest.approx(r, abs=1e-5)
            if t:
                ended += 1
                o, _ = s.reset()
            np.testing.assert_allclose(obs[i], o, atol=1e-6)
    assert ended >= 2


def test_both_passage_vector_envs_refuse_an_unknown_render_mode():
    """One vector-env base (``core_env.CoreVectorEnv``) for Passage-v0 and -v1: the single envs' check of
    ``render_mode`` holds for the vector ones too (v0's vector env accepted anything before)."""
    from shipsense.envs.passage_v1 import PassageV1VectorEnv

    for cls in (PassageVectorEnv, PassageV1VectorEnv):
        with pytest.raises(ValueError, match="render_mode must be one of \\['rgb_array'\\], got 'human'"):
            cls(2, render_mode="human")


def _numpy_outputs(c, read):
    """Passage-v0's rewards, info numbers and observation table written in numpy (the compiled kernels'
    reference)."""
    est, cov = c.last.estimate, c.last.cov[:, :2, :2]
    truth = c.truth[np.arange(c.E), c.k]
    d = est[:, :2] - truth[:, :2]
    a, b, cc = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    with np.errstate(all="ignore"):
        nees = (cc * d[:, 0] ** 2 - 2 * b * d[:, 0] * d[:, 1] + a * d[:, 1] ** 2) / (a * cc - b * b)
        error = np.hypot(d[:, 0], d[:, 1])
        error_term = -np.minimum(error / c.error_scale, 10.0)
        energy_term = -c.energy_cost * read.sum(axis=1)
        obs = np.empty((c.E, c.obs_dim))
        obs[:, 0:2] = (est[:, :2] - c.centre) / c.position_scale
        obs[:, 2:4] = est[:, 2:4] * 0.1
        obs[:, 4] = np.log10(np.maximum(cov[:, 0, 0], 1e-12)) / 6.0
        obs[:, 5] = np.log10(np.maximum(cov[:, 1, 1], 1e-12)) / 6.0
        cum = c.tracker.bank.cum
        obs[:, 6:6 + c.H] = (cum - cum.max(axis=1, keepdims=True)) / 50.0
    obs[:, 6 + c.H:-2] = c._snr_obs[np.arange(c.E), c.k] * c.last_read
    obs[:, -2] = c.last.status / 4.0
    obs[:, -1] = c.k / max(c.K - 1, 1)
    obs = np.clip(obs, -1.0, 1.0).astype(np.float32)
    ll = obs[:, 6:6 + c.H]
    ll[np.isnan(ll)] = -1.0
    numbers = {"truth": truth[:, :2], "estimate": est[:, :2], "error": error, "nees": nees,
               "error_term": error_term, "energy_term": energy_term, "reads": read.sum(axis=1)}
    return error_term + energy_term, numbers, np.nan_to_num(obs)


def test_the_compiled_rewards_and_observation_equal_numpys_with_nan_and_inf():
    """The step's rewards and info numbers (exactly) and the observation (within one float32 ulp: numba's log10
    and numpy's differ in the last bit of some float64s) against numpy, on states with NaN, infinities, zero
    and negative variances and banks with NaN or no finite log-likelihood."""
    from shipsense.envs.passage import PassageCore

    rng = np.random.default_rng(9)
    c = PassageCore(num_envs=40, scenario="S2", overrides={"steps": 30}, max_reads=2)
    E = c.E
    odd_observer_outputs(c.last, rng)
    c.last.status[:] = rng.integers(0, 5, E)
    c.k[:] = rng.integers(0, c.K, E)
    c.truth[:] = rng.normal(0, 300, c.truth.shape)
    c._snr_obs[:] = rng.uniform(0, 1.5, c._snr_obs.shape)
    c.last_read[:] = rng.integers(0, 2, c.last_read.shape).astype(bool)
    cum = c.tracker.bank.cum
    cum[:] = rng.normal(-100, 60, cum.shape)
    cum[6] = -np.inf                                      # no finite likelihood
    cum[7, 1] = -np.inf
    cum[8, 2] = np.nan
    read = rng.integers(0, 2, (E, c.S)).astype(bool)
    rewards, terminated, info = c._rewards(read, np.zeros(E, dtype=int))
    want_rewards, numbers, want_obs = _numpy_outputs(c, read)
    np.testing.assert_array_equal(rewards, want_rewards)
    for name, value in numbers.items():
        np.testing.assert_array_equal(info[name], value, err_msg=name)
    np.testing.assert_array_equal(terminated, c.k >= c.K - 1)
    assert not np.shares_memory(info["selected"], c.last.selected)     # later steps overwrite the core's
    obs = c._observe()
    assert obs.dtype == np.float32 and np.isfinite(obs).all()
    assert (obs[6, 6:6 + c.H] == -1).all() and (obs[8, 6:6 + c.H] == -1).all()
    np.testing.assert_array_max_ulp(obs, want_obs, maxulp=1)
