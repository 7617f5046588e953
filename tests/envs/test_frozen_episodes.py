"""The Passage environments' episodes stay what they were: one seeded episode per environment and baseline,
rewards and last observation frozen in ``tests/data/passage_episodes.json`` (to 1e-9). A change of dynamics,
reward or observation must bump the environment's version, not move these; regenerate the file only for a new
version's entry.

Regenerate an entry: reset ``gym.make(ENV, overrides={"steps": 60})`` with seed 11, act with
``load_policy(env, POLICY, seed=11)`` to the end, and store the rewards and the last observation."""

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import shipsense  # noqa: F401  (registers the environments)
from shipsense.envs.evaluation import load_policy

FROZEN = json.loads((Path(__file__).parents[1] / "data" / "passage_episodes.json").read_text())


@pytest.mark.parametrize("key", sorted(FROZEN))
def test_episode_is_as_frozen(key):
    env_id, policy = key.split()
    env = gym.make(env_id, overrides={"steps": 60})
    obs, _ = env.reset(seed=11)
    act = load_policy(env, policy, seed=11)
    rewards, done = [], False
    while not done:
        obs, r, terminated, truncated, _ = env.step(act(obs))
        rewards.append(float(r))
        done = terminated or truncated
    np.testing.assert_allclose(rewards, FROZEN[key]["rewards"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.ravel(obs), FROZEN[key]["last_obs"], rtol=1e-9, atol=1e-12)
