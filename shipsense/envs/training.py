"""Training agents on the environments (stable-baselines3, the ``rl`` extra): ``shipsense train``.

* ``scheduling``: PPO on ``shipsense/Passage-v0`` (S2, at most one sensor read per step), evaluated
  against reading the first sensor every step ("read-all", trimmed to the budget) and round-robin,
  at equal energy, on the same held-out passages.
* ``placement``: MaskablePPO on ``shipsense/ArrayDesign-v0`` (S1-P2 envelope electrodes), its
  deterministic layout evaluated against random, line, greedy and the convex design with
  :func:`shipsense.design.evaluate.evaluate_layout` on the same held-out passages.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

HELD_OUT = 10_000
DEFAULT_TIMESTEPS = {"scheduling": 20_000, "placement": 600}
MODEL_FILES = {"scheduling": "scheduling_ppo.zip", "placement": "placement_maskableppo.zip"}


def _require_rl():
    try:
        import stable_baselines3  # noqa: F401
        import torch
    except ImportError as err:
        raise RuntimeError("training needs the rl extra: pip install 'shipsense[rl]' "
                           "(install a CPU build of torch first to avoid a multi-GB download)") from err
    torch.set_num_threads(1)


def _progress_callback(total, desc, progress=True):
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    class Bar(BaseCallback):
        def _on_training_start(self):
            self.bar = tqdm(total=total, desc=desc, unit="step", leave=False,
                            disable=None if progress else True)   # None: a bar only on a terminal

        def _on_step(self):
            self.bar.update(self.training_env.num_envs)
            return True

        def _on_training_end(self):
            self.bar.close()

    return Bar()


def _run_policy(env, policy, episodes, seed):
    """Mean position error and reads per step of a policy(obs, t) over held-out episodes."""
    errors, reads = [], []
    for e in range(episodes):
        obs, _ = env.reset(seed=seed + e)
        t = 0
        while True:
            obs, _, term, trunc, info = env.step(policy(obs, t))
            errors.append(info["error"])
            reads.append(info["reads"])
            t += 1
            if term or trunc:
                break
    return {"mean_error_m": float(np.mean(errors)), "median_error_m": float(np.median(errors)),
            "reads_per_step": float(np.mean(reads))}


def train_scheduling(timesteps=DEFAULT_TIMESTEPS["scheduling"], out="results/train-scheduling", seed=0, episodes=20,
                     progress=True):
    _require_rl()
    from stable_baselines3 import PPO

    from shipsense.envs.passage import PassageEnv

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    kwargs = {"scenario": "S2", "max_reads": 1, "energy_cost": 0.01}
    env = PassageEnv(**kwargs)
    t0 = time.perf_counter()
    model = PPO("MlpPolicy", env, n_steps=1024, batch_size=128, seed=seed, device="cpu", verbose=0)
    model.learn(total_timesteps=int(timesteps),
                callback=_progress_callback(int(timesteps), "train scheduling", progress))
    fps = timesteps / (time.perf_counter() - t0)
    model.save(out / "scheduling_ppo")
    S = env.action_space.n
    policies = {
        "agent (PPO)": lambda o, t: model.predict(o, deterministic=True)[0],
        "read-all (trimmed to 1)": lambda o, t: np.ones(S, dtype=np.int8),
        "round-robin": lambda o, t: np.eye(S, dtype=np.int8)[t % S],
    }
    results = {name: _run_policy(PassageEnv(**kwargs), p, episodes, HELD_OUT) for name, p in policies.items()}
    summary = {"task": "scheduling", "env": "shipsense/Passage-v0", "env_kwargs": kwargs,
               "timesteps": int(timesteps), "ppo_fps": fps, "held_out_episodes": episodes, "results": results}
    (out / "evaluation.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def train_placement(timesteps=DEFAULT_TIMESTEPS["placement"], out="results/train-placement", seed=0, passages=20,
                    progress=True):
    _require_rl()
    from sb3_contrib import MaskablePPO

    from shipsense.config import load_scenario
    from shipsense.design import placement as pl
    from shipsense.design.evaluate import evaluate_layout
    from shipsense.envs.array_design import ArrayDesignEnv
    from shipsense.simulator import sample_passages
    from shipsense.trackers.models import candidate_model

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    kwargs = {"scenario": "S1-P2", "k": 3, "half_width": 30.0, "spacing": 15.0, "passages": 4,
              "check_ambiguity": False}
    env = ArrayDesignEnv(**kwargs)
    t0 = time.perf_counter()
    model = MaskablePPO("MlpPolicy", env, n_steps=96, batch_size=32, seed=seed, device="cpu", verbose=0)
    model.learn(total_timesteps=int(timesteps),
                callback=_progress_callback(int(timesteps), "train placement", progress))
    fps = timesteps / (time.perf_counter() - t0)
    model.save(out / "placement_maskableppo")
    obs, _ = env.reset(seed=0)
    while True:
        a, _ = model.predict(obs, action_masks=env.action_masks(), deterministic=True)
        obs, _, term, _, _ = env.step(int(a))
        if term:
            break
    cands = env.candidates
    agent = list(env.chosen)
    sc = load_scenario(kwargs["scenario"])
    cmodel = candidate_model(sc, cands)
    thetas = cmodel.to_internal(cmodel.state_from_truth(sample_passages(sc, 8, seed=seed)))
    prior = cmodel.to_internal(np.array([30.0, 30.0, 2.0, 2.0, 1.0, 50.0]))
    problem = pl.build_problem(cmodel, thetas, sc.steps, kwargs["k"], prior)
    on_line = sorted(np.flatnonzero(np.isclose(cands[:, 0], env.centre[0])), key=lambda i: cands[i, 1])
    layouts = {
        "agent (MaskablePPO)": agent,
        "random": list(np.random.default_rng(seed).choice(len(cands), kwargs["k"], replace=False)),
        "line": [on_line[i] for i in np.linspace(0, len(on_line) - 1, kwargs["k"]).round().astype(int)],
        "greedy": list(pl.swap_refine(problem, pl.greedy(problem, "D"), "D")[0]),
        "convex": list(pl.place(problem, "D").chosen),
    }
    template = sc.sensors[0]
    results = {}
    for name, chosen in layouts.items():
        sensors = [template.model_copy(update={"id": f"L{i + 1}", "position": tuple(map(float, cands[c]))})
                   for i, c in enumerate(chosen)]
        ev = evaluate_layout(sc.model_copy(update={"sensors": sensors}), passages=passages)
        results[name] = {**ev.to_json(), "sensors": cands[chosen].tolist()}
    summary = {"task": "placement", "env": "shipsense/ArrayDesign-v0", "env_kwargs": kwargs,
               "timesteps": int(timesteps), "ppo_fps": fps, "held_out_passages": passages, "results": results}
    (out / "evaluation.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
