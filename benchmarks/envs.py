"""Environment benchmark: steps per second of Passage-v0 (single and native vector, 64 envs) with the
project's tracker as observer (what users get; ``--observer bank``: the studies' 12-hypothesis bank), and of
Passage-v1 (single and native vector; the tracker is its only observer), with CartPole-v1 measured in the same
run as the reference.

Run:  PYTHONPATH=. python benchmarks/envs.py [--steps 2000] [--num-envs 64] [--observer tracker|bank]
      [--allocator tuned|default] [--v1-id shipsense/Passage-v1]

Passage-v0's actions are all-ones (read every sensor) so that every step runs the full
update; Passage-v1's read the first ``k``-sensor subset (its full budget).  Autoresets are included (for
Passage-v1 with its run-in: the observer reads every sensor until its first track, about 0.5 s per
passage of the initialiser's grid search).  Every rate is the best of three timed runs.  PPO frames per
second are reported by ``shipsense train`` (see EXPERIMENTS.md).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import shipsense  # registers the environments

TWELVE = {"tracker": {"filter": "ukf", "process_noise": {"model": "diagonal",
                                                         "q_diag": [1e-4, 1e-4, 1e-4, 1e-4, 2e-4, 2e-4, 2e-4]},
                      "bank": {"levels": [5e3, 2e4, 8e4], "bearings_deg": [45.0, 135.0, 225.0, 315.0],
                               "initial_velocity": [3.5, 3.5], "initial_course": "towards_array",
                               "position_std": 20.0, "moment_std": 5e4}}}


REPEATS = 3
"""Each rate is the best of this many timed runs (the machine is shared; the best run is the least disturbed)."""


def best_rate(reset, run, frames):
    """Best frames per second of ``REPEATS`` timed calls of ``run()``, each after ``reset()``."""
    best = 0.0
    for _ in range(REPEATS):
        reset()
        t0 = time.perf_counter()
        run()
        best = max(best, frames / (time.perf_counter() - t0))
    return best


def single_rate(env, steps, action):
    def run():
        for _ in range(steps):
            _, _, term, trunc, _ = env.step(action)
            if term or trunc:
                env.reset()

    return best_rate(lambda: env.reset(seed=0), run, steps)


def vector_rate(envs, steps, actions):
    def run():
        for _ in range(steps):
            envs.step(actions)

    return best_rate(lambda: envs.reset(seed=0), run, steps * envs.num_envs)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--num-envs", type=int, default=64)
    ap.add_argument("--allocator", choices=("tuned", "default"), default="tuned",
                    help="tuned: shipsense.tune_allocator() as the shipsense command does; default: glibc's")
    ap.add_argument("--v1-id", default="shipsense/Passage-v1", help="the Passage-v1 variant to measure")
    ap.add_argument("--observer", choices=("tracker", "bank"), default="tracker",
                    help="the environment's observer (default: the tracker, as users get it)")
    args = ap.parse_args(argv)
    kwargs = {"observer": args.observer} | ({"overrides": TWELVE} if args.observer == "bank" else {})
    tuned = args.allocator == "tuned" and shipsense.tune_allocator()
    print(f"allocator: {'tuned (shipsense.tune_allocator)' if tuned else 'default'}")
    n = args.num_envs
    cart = single_rate(gym.make("CartPole-v1"), args.steps, 1)
    cart_vec = vector_rate(gym.make_vec("CartPole-v1", num_envs=n, vectorization_mode="vector_entry_point"),
                           args.steps // 10, np.ones(n, dtype=np.int64))
    env = gym.make("shipsense/Passage-v0", **kwargs)
    print(f"observer: {args.observer}")
    single = single_rate(env, args.steps, np.ones(3, dtype=np.int8))
    venv = gym.make_vec("shipsense/Passage-v0", num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
    vec = vector_rate(venv, max(args.steps // 10, 20), np.ones((n, 3), dtype=np.int8))
    env1 = gym.make(args.v1_id)
    full = int(env1.unwrapped.core.full[0])
    single1 = single_rate(env1, args.steps, full)
    venv1 = gym.make_vec(args.v1_id, num_envs=n, vectorization_mode="vector_entry_point")
    vec1 = vector_rate(venv1, max(args.steps // 10, 20), np.full(n, full))
    print(f"{'environment':<40}{'steps/s':>12}")
    print(f"{'CartPole-v1 (single)':<40}{cart:>12,.0f}")
    print(f"{f'CartPole-v1 (native vector, {n} envs)':<40}{cart_vec:>12,.0f}")
    print(f"{f'shipsense/Passage-v0 (single, {args.observer})':<40}{single:>12,.0f}")
    print(f"{f'shipsense/Passage-v0 (vector, {n} envs)':<40}{vec:>12,.0f}")
    print(f"{f'{args.v1_id} (single)':<40}{single1:>12,.0f}")
    print(f"{f'{args.v1_id} (vector, {n} envs)':<40}{vec1:>12,.0f}")
    print(f"\nPassage-v0 / CartPole-v1: single {single / cart:.3f}, vector {vec / cart_vec:.3f}")


if __name__ == "__main__":
    main()
