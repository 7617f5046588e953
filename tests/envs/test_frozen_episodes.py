"""The Passage environments' episodes stay what they were: one seeded episode per environment and baseline,
rewards and last observation frozen in ``tests/data/passage_episodes.json`` (to 1e-9). A change of dynamics,
reward or observation must bump the environment's version, not move these; regenerate the file only for a new
version's entry.

Regenerate an entry: reset ``gym.make(ENV, overrides=OVERRIDES)`` with seed 11, act with
``load_policy(env, POLICY, seed=11)`` to the end, and store the rewards and the last observation.  ``OVERRIDES``
is ``{"steps": 60}`` (which replaces the variant's), or for the variants of :data:`OWN_OVERRIDES`, whose task and
observer are in their overrides, the variant's own overrides with ``"steps": 60``."""

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import shipsense  # noqa: F401  (registers the environments)
from shipsense.envs.evaluation import load_policy

FROZEN = json.loads((Path(__file__).parents[1] / "data" / "passage_episodes.json").read_text())
OWN_OVERRIDES = ("shipsense/PassageHard-v2",)
"""Variants frozen with their own overrides (a shorter passage), not with S2's."""


def frozen_overrides(env_id):
    """The ``overrides`` an entry of ``env_id`` is frozen with (the module docstring)."""
    if env_id in OWN_OVERRIDES:
        return {**gym.registry[env_id].kwargs["overrides"], "steps": 60}
    return {"steps": 60}


@pytest.mark.parametrize("key", sorted(FROZEN))
def test_episode_is_as_frozen(key):
    env_id, policy = key.split()
    env = gym.make(env_id, overrides=frozen_overrides(env_id))
    obs, _ = env.reset(seed=11)
    act = load_policy(env, policy, seed=11)
    rewards, done = [], False
    while not done:
        obs, r, terminated, truncated, _ = env.step(act(obs))
        rewards.append(float(r))
        done = terminated or truncated
    np.testing.assert_allclose(rewards, FROZEN[key]["rewards"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.ravel(obs), FROZEN[key]["last_obs"], rtol=1e-9, atol=1e-12)
