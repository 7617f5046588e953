"""Train stable-baselines3 agents on gymnasium's native vector environments: :class:`VectorEnvAdapter`.

SB3's ``VecEnv`` resets an environment in the step that ends it and hands the last observation over in
``infos[i]["terminal_observation"]``; a gymnasium 1.x ``VectorEnv`` says how it autoresets in
``metadata["autoreset_mode"]``:

* ``SAME_STEP`` (gymnasium's ``SyncVectorEnv`` as training makes it for an environment without a native vector
  version): the observation is already the reset one, the last one is in ``info["final_obs"]`` and its info in
  ``info["final_info"]``;
* ``NEXT_STEP`` (gymnasium's default, every shipsense native vector env:
  :class:`~shipsense.envs.core_env.CoreVectorEnv`): the adapter resets the ended environments at once with
  ``reset(options={"reset_mask": done})`` (gymnasium's ``SyncVectorEnv`` / ``AsyncVectorEnv`` support it; a
  native env in this mode must too);
* ``DISABLED``: the same ``reset_mask`` reset.

Per-environment infos are rebuilt from gymnasium's ``{key: array, "_key": mask}`` dictionaries (nested ones
too), so ``infos[i]["episode_metrics"]`` reaches callbacks.  ``env_method("action_masks")`` and
``get_attr`` work on the vector env's batched methods (one row per environment), so sb3-contrib's
MaskablePPO finds the masks.  Requires the ``rl`` extra.

:class:`PotentialShaping` adds potential-based reward shaping (Ng, Harada & Russell 1999) for training.
"""

from __future__ import annotations

import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvWrapper


def unbatch_info(info, num_envs):
    """gymnasium's vector info ``{key: array, "_key": mask}`` -> a list of ``num_envs`` per-environment dicts."""
    out = [{} for _ in range(num_envs)]
    every = range(num_envs)
    for key, value in info.items():
        if key.startswith("_") or key in ("final_obs", "final_info"):
            continue
        mask = info.get(f"_{key}")
        if isinstance(value, dict):
            rows = unbatch_info(value, num_envs)
        elif isinstance(value, np.ndarray) and value.ndim == 1 and value.dtype != object:
            rows = value.tolist()         # (Python numbers, as each element's .item(); in one call)
        else:
            rows = [v.item() if isinstance(v, np.generic) else v for v in value]
        for i in every if mask is None else np.flatnonzero(mask).tolist():
            out[i][key] = rows[i]
    return out


class VectorEnvAdapter(VecEnv):
    """An SB3 ``VecEnv`` over a gymnasium ``VectorEnv`` (see the module docstring for autoreset handling)."""

    def __init__(self, venv):
        self.venv = venv
        self.mode = venv.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
        if isinstance(self.mode, str):
            self.mode = AutoresetMode(self.mode)
        self._actions = None
        self._obs = None
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)

    # -- stepping -----------------------------------------------------------------------------
    def reset(self):
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        options = self._options[0] if any(self._options) else None
        obs, info = self.venv.reset(seed=seeds, options=options)
        self.reset_infos = unbatch_info(info, self.num_envs)
        self._reset_seeds()
        self._reset_options()
        self._obs = obs
        return obs

    def step_async(self, actions):
        self._actions = actions

    def step_wait(self):
        obs, rewards, terminated, truncated, info = self.venv.step(self._actions)
        done = np.logical_or(terminated, truncated)
        infos = unbatch_info(info, self.num_envs)
        if self.mode == AutoresetMode.SAME_STEP:
            final_obs = info.get("final_obs")
            final_info = unbatch_info(info["final_info"], self.num_envs) if "final_info" in info else None
            for i in np.flatnonzero(done):
                if final_info is not None:
                    infos[i].update(final_info[i])
                infos[i]["terminal_observation"] = final_obs[i]
        elif done.any():
            for i in np.flatnonzero(done):
                infos[i]["terminal_observation"] = obs[i].copy()
            obs = obs.copy()
            reset_obs, reset_info = self.venv.reset(options={"reset_mask": done})
            obs[done] = reset_obs[done]
        for i in np.flatnonzero(done):
            infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        self._obs = obs
        return obs, np.asarray(rewards, dtype=np.float32), done, infos

    def close(self):
        self.venv.close()

    # -- attributes and methods -----------------------------------------------------------------
    def _indices(self, indices):
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)

    def get_attr(self, attr_name, indices=None):
        idx = self._indices(indices)
        if hasattr(self.venv, "get_attr") and not hasattr(self.venv, attr_name):   # Sync/AsyncVectorEnv
            values = self.venv.get_attr(attr_name)
            return [values[i] for i in idx]
        value = getattr(self.venv, attr_name)       # an AttributeError when absent (VecEnv.has_attr relies on it)
        return [value for _ in idx]

    def set_attr(self, attr_name, value, indices=None):
        if hasattr(self.venv, "set_attr"):
            self.venv.set_attr(attr_name, value)
        else:
            setattr(self.venv, attr_name, value)

    def env_method(self, method_name, *method_args, indices=None, **method_kwargs):
        """A batched method of the vector env (one row per environment), or the sub-environments' method."""
        idx = self._indices(indices)
        method = getattr(self.venv, method_name, None)
        if callable(method):
            result = method(*method_args, **method_kwargs)
        elif hasattr(self.venv, "call"):
            result = self.venv.call(method_name, *method_args, **method_kwargs)
        else:
            raise AttributeError(f"{type(self.venv).__name__} has no method {method_name!r}")
        return [result[i] for i in idx]

    def env_is_wrapped(self, wrapper_class, indices=None):
        return [False for _ in self._indices(indices)]

    def get_images(self):
        images = self.venv.render()
        return list(images) if images is not None else [None] * self.num_envs


class PotentialShaping(VecEnvWrapper):
    """Potential-based reward shaping of an SB3 ``VecEnv`` (Ng, Harada & Russell 1999), for training.

    Each step's reward gets ``coef * (gamma * phi(obs') - phi(obs))``, with ``phi(obs') = 0`` when the step ended
    the episode.  Over an episode the added terms sum (discounted by ``gamma``) to ``-coef * phi(obs_0)``,
    which no action changes: the optimal policies of the discounted task stay what they were, while an action
    whose benefit shows in ``phi`` at once (a read that shrinks the observer's covariance) is credited in its own
    step instead of through many noisy later rewards.  ``gamma`` must be the agent's discount.  The unshaped
    reward is in ``infos[i]["unshaped_reward"]``; SB3's episode statistics (``VecMonitor`` inside this
    wrapper) and the held-out evaluations see only the environment's own reward.

    Parameters
    ----------
    venv : VecEnv
    potential : callable
        ``phi(obs)`` for a batch of observations (N, ...) -> (N,), finite.
    coef : float
        Weight of the shaping term (> 0).
    gamma : float
        The agent's discount factor.
    """

    def __init__(self, venv, potential, coef, gamma):
        super().__init__(venv)
        self.potential, self.coef, self.gamma = potential, float(coef), float(gamma)
        self._phi = None

    def reset(self):
        obs = self.venv.reset()
        self._phi = np.asarray(self.potential(obs), dtype=float)
        return obs

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        phi = np.asarray(self.potential(obs), dtype=float)   # after a done: the next episode's first observation
        shaping = self.coef * (self.gamma * np.where(dones, 0.0, phi) - self._phi)
        for i, info in enumerate(infos):
            info["unshaped_reward"] = float(rewards[i])
        self._phi = phi
        return obs, (rewards + shaping).astype(np.float32), dones, infos
