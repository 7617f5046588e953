"""Checks the environment tests share: a seeded random rollout, a seed fixes an episode, a native vector env
equals single envs, and the gymnasium and stable-baselines3 checkers pass."""

import warnings

import numpy as np
import pytest


def random_rollout(env, seed, policy_seed=0):
    """The episode of ``env`` reset with ``seed`` under uniformly random actions (their generator seeded with
    ``policy_seed``): ``[(obs, reward, terminated, info), ...]``, the first entry the reset's observation."""
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(policy_seed)
    out = [(obs, None, None, None)]
    while True:
        obs, r, term, trunc, info = env.step(int(rng.integers(env.action_space.n)))
        out.append((obs, r, term, info))
        if term or trunc:
            return out


def assert_seed_fixes_the_episode(make_env):
    """Two environments from ``make_env()`` reset with one seed give the same episode (observations, rewards,
    ends, info keys); another seed gives another first observation."""
    a = random_rollout(make_env(), seed=7)
    b = random_rollout(make_env(), seed=7)
    assert len(a) == len(b)
    for (oa, ra, ta, ia), (ob, rb, tb, ib) in zip(a, b):
        np.testing.assert_array_equal(oa, ob)
        assert ra == rb and ta == tb
        if ia is not None:
            assert ia.keys() == ib.keys()
    c = random_rollout(make_env(), seed=8)
    assert not np.array_equal(a[0][0], c[0][0])


def assert_vector_equals_singles(venv, singles, seeds, steps=60, check=None):
    """Step the native vector env ``venv`` and single envs ``singles`` (one per sub-environment, reset with
    ``seeds``) with the same random actions across next-step autoresets: observations, rewards and ends agree
    (to 1e-6), and ended episodes' metrics too; ``check(i, info, vinfo)`` adds a test of each single step's
    ``info`` against the vector's (``info`` None at an autoreset step). Returns how many episodes ended (at
    least one per sub-environment)."""
    n = len(singles)
    vo, _ = venv.reset(seed=list(seeds))
    so = [s.reset(seed=sd)[0] for s, sd in zip(singles, seeds)]
    np.testing.assert_allclose(vo, np.array(so), rtol=0, atol=1e-6)
    rng = np.random.default_rng(0)
    pending, ended = [False] * n, 0
    for _ in range(steps):
        acts = rng.integers(0, venv.single_action_space.n, n)
        vo, vr, vt, vtr, vinfo = venv.step(acts)
        for i, s in enumerate(singles):
            if pending[i]:                                   # next-step autoreset
                obs, _ = s.reset()
                r, t = 0.0, False
                pending[i] = False
                if check is not None:
                    check(i, None, vinfo)
            else:
                obs, r, t, _, info = s.step(int(acts[i]))
                if check is not None:
                    check(i, info, vinfo)
                pending[i] = t
                if t:
                    ended += 1
                    for key, v in info["episode_metrics"].items():
                        assert vinfo["episode_metrics"][key][i] == pytest.approx(v, rel=1e-9, abs=1e-6)
            np.testing.assert_allclose(vo[i], obs, rtol=0, atol=1e-6)
            assert vr[i] == pytest.approx(r, rel=0, abs=1e-6) and vt[i] == t
        assert not vtr.any()
    assert ended >= n
    return ended


def assert_gymnasium_checker_passes(env):
    """gymnasium's ``check_env`` (rendering included) on the unwrapped ``env`` warns nothing from gymnasium or
    shipsense."""
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=False)
    assert not [str(w.message) for w in caught if "shipsense" in str(w.filename) or "gymnasium" in str(w.filename)]


def assert_sb3_checker_passes(env):
    """stable-baselines3's ``check_env`` on ``env`` warns nothing from its checker or shipsense (skipped without
    the ``rl`` extra)."""
    sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3.check_env(env, warn=True)
    assert not [w for w in caught if "shipsense" in str(w.filename) or "env_checker" in str(w.filename)], \
        [str(w.message) for w in caught]
