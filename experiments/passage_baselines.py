"""Passage-v1's soundness check: the baselines (random, round-robin, greedy) on held-out passages.

Every policy plays the same passages: sub-environment ``i`` of the native vector env is reset with seed
``seed + i`` and plays ``episodes / num_envs`` passages in a row (the passages do not depend on the actions),
so the differences between policies are paired.  The default seeds (from 1,000,000) are disjoint from any
training seeds below 1,000,000.

Run:  PYTHONPATH=. python experiments/passage_baselines.py [--episodes 200] [--num-envs 50]
      [--seed 1000000] [--variants shipsense/Passage-v1 ...] [--json PATH]

Prints, per variant and policy: mean return +- standard error, the task metric (mean position error over the
episode's steps, m) +- s.e. and its median, the share of steps with the truth inside the observer's 95 %
ellipse, reads per step; then the paired differences greedy - round-robin and round-robin - random.
A sound task shows greedy > round-robin > random in return and in error.
"""

from __future__ import annotations

import argparse
import json
import time

import gymnasium as gym
import numpy as np

import shipsense  # noqa: F401  (registers the environments)
from shipsense.envs import PASSAGE_V1_VARIANTS

POLICIES = ("random", "round-robin", "greedy")
METRICS = ("return", "mean_error_m", "coverage95", "reads_per_step", "final_error_m")


def run(env_id, policy, episodes, num_envs, seed):
    """Episode metrics (episodes,) per metric of ``policy`` on ``env_id``, ordered by (sub-env, episode)."""
    per_env = -(-episodes // num_envs)
    envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point")
    obs, _ = envs.reset(seed=[seed + i for i in range(num_envs)])
    act = envs.unwrapped.baseline(policy, seed=seed)
    done = [[] for _ in range(num_envs)]
    steps = 0
    t0 = time.perf_counter()
    while min(len(d) for d in done) < per_env:
        obs, _, term, _, info = envs.step(act(obs))
        steps += num_envs
        if term.any():
            m = info["episode_metrics"]
            for i in np.flatnonzero(term):
                done[i].append({k: float(m[k][i]) for k in METRICS})
    rate = steps / (time.perf_counter() - t0)
    envs.close()
    rows = [d for i in range(num_envs) for d in done[i][:per_env]][:episodes]
    return {k: np.array([r[k] for r in rows]) for k in METRICS}, rate


def se(x):
    return float(np.std(x, ddof=1) / np.sqrt(len(x)))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--num-envs", type=int, default=50)
    ap.add_argument("--seed", type=int, default=1_000_000)
    ap.add_argument("--variants", nargs="+", default=list(PASSAGE_V1_VARIANTS))
    ap.add_argument("--json", help="also write the per-policy summaries here")
    args = ap.parse_args(argv)
    E = min(args.num_envs, args.episodes)
    out = {}
    print(f"{args.episodes} held-out passages per variant (seeds {args.seed} + sub-env, {E} envs)\n")
    head = (f"{'variant':<28}{'policy':<13}{'return':>18}{'mean error m':>20}{'median':>9}{'cov95':>7}"
            f"{'reads':>7}{'steps/s':>9}")
    print(head)
    for vid in args.variants:
        res = {}
        for pol in POLICIES:
            m, rate = run(vid, pol, args.episodes, E, args.seed)
            res[pol] = m
            r, e = m["return"], m["mean_error_m"]
            print(f"{vid:<28}{pol:<13}{r.mean():>10.2f} +- {se(r):<5.2f}{e.mean():>11.3f} +- {se(e):<6.3f}"
                  f"{np.median(e):>9.3f}{m['coverage95'].mean():>7.3f}{m['reads_per_step'].mean():>7.2f}"
                  f"{rate:>9.0f}", flush=True)
        for a, b in (("greedy", "round-robin"), ("round-robin", "random")):
            dr = res[a]["return"] - res[b]["return"]
            de = res[a]["mean_error_m"] - res[b]["mean_error_m"]
            print(f"{'':<28}{a} - {b}: return {dr.mean():+.2f} +- {se(dr):.2f}, "
                  f"mean error {de.mean():+.3f} +- {se(de):.3f} m (paired)")
        out[vid] = {p: {k: {"mean": float(v.mean()), "se": se(v)} for k, v in m.items()} for p, m in res.items()}
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
