"""Episodes of an environment for the environment tests: a seeded random rollout, and the check that a seed
fixes an episode."""

import numpy as np


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
