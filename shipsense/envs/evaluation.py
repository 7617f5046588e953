"""Evaluate a policy on an environment over seeded episodes: ``shipsense evaluate``.

A policy is a baseline the environment offers (its unwrapped class lists them in ``BASELINES`` and builds them
with ``baseline(name)``: a callable ``obs -> action`` that may read the environment's internal state), a planning
baseline of a Passage environment (:mod:`shipsense.envs.planning`: ``greedy-threshold``, ``rollout``, the offline
``hindsight``) or a stable-baselines3 model file ``PATH.zip`` (PPO, or MaskablePPO, predicting with the
environment's ``action_masks`` when it has them).  Episode ``i`` is reset with ``seed + i``, so every policy meets
the same episodes.  Returned: the mean return and its standard error, and each task metric the environment reports
at the end of an episode (``info["episode_metrics"]``) averaged the same way, and the policy's compute per
decision.
"""

from __future__ import annotations

import inspect
import math
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from shipsense.arguments import number


def _mean_stderr(values):
    x = np.asarray(values, dtype=float)
    stderr = float(x.std(ddof=1) / math.sqrt(len(x))) if len(x) > 1 else float("nan")
    return {"mean": float(x.mean()), "stderr": stderr}


def _is_maskable(path):
    """Whether an SB3 model file holds a MaskablePPO (its saved policy class is sb3-contrib's maskable one)."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as z:
            data = z.read("data").decode("utf-8", "replace")
    except (zipfile.BadZipFile, KeyError) as err:
        raise ValueError(f"policy: {path} is not a stable-baselines3 model file ({err})") from None
    return "maskable" in data.lower()


def load_policy(env, name_or_path, seed=None, policy_kwargs=None):
    """A callable ``obs -> action`` for ``env``: one of its baselines by name, a planning baseline of a Passage
    environment (:data:`~shipsense.envs.planning.PLANNERS`, with its options ``policy_kwargs``), or an SB3
    model ``PATH.zip``.

    ``seed`` goes to a baseline whose ``baseline(name, seed=...)`` takes one (a random policy with its own
    generator) and to a planner's own generator, so that an evaluation is reproducible under its seed.

    A name the environment does not offer, a missing file or a model for other observations raises one
    ``ValueError`` naming the policy.
    """
    from shipsense.envs import planning

    base = env.unwrapped
    name = str(name_or_path)
    if name in planning.PLANNERS and planning.offers(env):
        return planning.planner(env, name, seed=seed, **(policy_kwargs or {}))
    if policy_kwargs:
        raise ValueError(f"policy {name}: policy_kwargs are options of a planning baseline "
                         f"({', '.join(planning.PLANNERS)})")
    if name.endswith(".zip"):
        path = Path(name)
        if not path.is_file():
            raise ValueError(f"policy: no model file {path}")
        try:
            import torch

            torch.set_num_threads(1)
            if _is_maskable(path):
                from sb3_contrib import MaskablePPO as Algo
            else:
                from stable_baselines3 import PPO as Algo
        except ImportError as err:
            raise ValueError(f"policy {name}: loading a model needs the rl extra (pip install 'shipsense[rl]'): "
                             f"{err}") from None
        model = Algo.load(path, device="cpu")
        if model.observation_space.shape != env.observation_space.shape:
            raise ValueError(f"policy {name}: the model observes {model.observation_space.shape}, the environment "
                             f"{env.observation_space.shape}: it was trained on another environment")
        masked = hasattr(base, "action_masks") and "maskable" in type(model).__name__.lower()

        def agent(obs):
            kw = {"action_masks": base.action_masks()} if masked else {}
            action, _ = model.predict(obs, deterministic=True, **kw)
            return action.item() if np.ndim(action) == 0 else action

        return agent
    offered = tuple(getattr(type(base), "BASELINES", ())) + (planning.PLANNERS if planning.offers(env) else ())
    spec = getattr(env, "spec", None)
    env_id = spec.id if spec is not None else type(base).__name__
    if name not in offered:
        raise ValueError(f"policy {name!r} is not offered by {env_id} (offered: "
                         f"{', '.join(offered) if offered else 'none'}; or a model PATH.zip)")
    if "seed" in inspect.signature(base.baseline).parameters:
        return base.baseline(name, seed=seed)
    return base.baseline(name)


def run_episodes(env, act, seed, episodes, progress=None, clock=None):
    """Run ``act`` on ``env`` for the episodes ``episodes`` (indices, e.g. a range; episode ``i``
    reset with ``seed + i``): lists of returns and lengths, and ``{metric: list}`` of ``info["episode_metrics"]``.
    ``clock``: a list whose first entry the seconds spent in ``act`` are added to.

    An environment that takes the coming seeds (``expect_seeds``, e.g. Passage-v1's: 18 % less time for 200
    greedy episodes) is told them first, so it can prepare those episodes ahead (the same episodes).
    ``progress``: keyword arguments of a tqdm bar over the episodes, or None."""
    if not isinstance(episodes, Sequence):     # (read twice: by the announcement and by the loop)
        episodes = list(episodes)
    expect = getattr(env.unwrapped, "expect_seeds", None)
    if expect is not None:
        expect(seed + e for e in episodes)
    if progress is not None:
        from tqdm import tqdm

        episodes = tqdm(episodes, **progress)
    returns, lengths, metrics = [], [], {}
    for e in episodes:
        obs, _ = env.reset(seed=seed + e)
        total, steps = 0.0, 0
        while True:
            t0 = time.perf_counter()
            action = act(obs)
            if clock is not None:
                clock[0] += time.perf_counter() - t0
            obs, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            steps += 1
            if terminated or truncated:
                break
        returns.append(total)
        lengths.append(steps)
        for key, value in info.get("episode_metrics", {}).items():
            metrics.setdefault(key, []).append(value)
    return returns, lengths, metrics


def summarise(returns, metrics):
    """Mean and standard error of the returns and of each metric."""
    return {"return": _mean_stderr(returns), "metrics": {k: _mean_stderr(v) for k, v in metrics.items()}}


def evaluate(env_id, policy, episodes, seed, env_kwargs=None, progress=False, policy_kwargs=None):
    """Run ``policy`` for ``episodes`` episodes of ``env_id`` (episode ``i`` reset with ``seed + i``).

    ``policy_kwargs``: options of a planning baseline (:func:`~shipsense.envs.planning.planner`).

    Returns
    -------
    dict
        ``env``, ``policy``, ``episodes``, ``seed``, ``env_kwargs``, ``policy_kwargs``, ``return`` (``mean``,
        ``stderr``), ``length`` (mean steps), ``metrics`` (``{name: {"mean", "stderr"}}`` of
        ``info["episode_metrics"]``), ``seconds`` (wall time of the evaluation), ``setup_seconds`` (building the
        policy: a fit, a model's loading), ``seconds_per_decision`` (the policy's compute per step, s),
        ``policy_settings`` (what a policy with ``describe()`` ran with: a fitted threshold, a planner's sizes)
        and ``per_episode`` (``{"return": [...], name: [...]}``, in seed order: paired comparisons between
        policies evaluated on the same seeds).
    """
    import gymnasium as gym

    from shipsense.envs import register_envs

    register_envs()

    episodes = number("episodes", episodes, 1, 10**7, integer=True)
    seed = number("seed", seed, 0, 2**32 - 1 - episodes, integer=True)
    if env_kwargs is not None and not isinstance(env_kwargs, dict):
        raise ValueError(f"env_kwargs must be a dict, got {type(env_kwargs).__name__}")
    if env_id not in gym.registry:
        known = sorted(k for k in gym.registry if k.startswith("shipsense/"))
        raise ValueError(f"env_id {env_id!r} is not registered (shipsense's: {', '.join(known)})")
    if policy_kwargs is not None and not isinstance(policy_kwargs, dict):
        raise ValueError(f"policy_kwargs must be a dict, got {type(policy_kwargs).__name__}")
    env = gym.make(env_id, **(env_kwargs or {}))
    try:
        t0 = time.perf_counter()
        act = load_policy(env, policy, seed=seed, policy_kwargs=policy_kwargs)
        setup = time.perf_counter() - t0
        clock = [0.0]
        t0 = time.perf_counter()
        returns, lengths, metrics = run_episodes(env, act, seed, range(episodes), progress={
            "desc": f"evaluate {policy}", "unit": "episode", "leave": False, "disable": None if progress else True},
            clock=clock)
        seconds = time.perf_counter() - t0
    finally:
        env.close()
    describe = getattr(act, "describe", None)
    return {"env": env_id, "policy": str(policy), "episodes": episodes, "seed": seed, "env_kwargs": env_kwargs or {},
            "policy_kwargs": policy_kwargs or {}, **summarise(returns, metrics), "length": float(np.mean(lengths)),
            "seconds": seconds, "setup_seconds": setup, "seconds_per_decision": clock[0] / max(sum(lengths), 1),
            "policy_settings": describe() if describe is not None else {},
            "per_episode": {"return": returns, **metrics}}


def summary_lines(result):
    """The command's printed summary of :func:`evaluate`'s result."""
    r = result["return"]
    lines = [f"{result['env']}, policy {result['policy']}: {result['episodes']} episodes from seed {result['seed']} "
             f"({result['seconds']:.1f} s)",
             f"  return {r['mean']:.4g} +- {r['stderr']:.2g} (standard error); {result['length']:.1f} steps/episode",
             f"  policy compute {1e3 * result['seconds_per_decision']:.3g} ms/decision"
             + (f" (set-up {result['setup_seconds']:.1f} s)" if result["setup_seconds"] >= 0.05 else "")]
    settings = {k: v for k, v in result.get("policy_settings", {}).items() if k != "fit"}
    if settings:
        lines.append("  settings " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                               for k, v in settings.items()))
    for key, m in result["metrics"].items():
        lines.append(f"  {key:<14} {m['mean']:.4g} +- {m['stderr']:.2g}")
    return lines
