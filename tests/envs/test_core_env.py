"""Every native vector env is a ``core_env.CoreVectorEnv``: one autoreset convention, one check of ``render_mode``."""

import gymnasium as gym
import pytest
from gymnasium.envs.registration import load_env_creator
from gymnasium.vector import AutoresetMode

import shipsense  # noqa: F401  (registers the environments)
from shipsense.envs.core_env import CoreVectorEnv

NATIVE = sorted(k for k, spec in gym.registry.items() if k.startswith("shipsense/") and spec.vector_entry_point)


def test_there_are_native_vector_envs_of_both_kinds():
    assert "shipsense/Passage-v1" in NATIVE and "shipsense/ArrayDesign-v1" in NATIVE


@pytest.mark.parametrize("env_id", NATIVE)
def test_every_native_vector_env_autoresets_in_the_next_step_and_refuses_an_unknown_render_mode(env_id):
    cls = load_env_creator(gym.spec(env_id).vector_entry_point)
    assert issubclass(cls, CoreVectorEnv) and cls.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    with pytest.raises(ValueError, match="render_mode must be one of \\['rgb_array'\\], got 'human'"):
        cls(2, render_mode="human")
