"""Environment benchmark: steps per second of Passage-v1 or another Passage id (``--v1-id shipsense/Passage-v2``;
single, from ``gym.make`` with gymnasium's OrderEnforcing and PassiveEnvChecker, and native vector, 64 envs; the
project's tracker is its observer) and of ArrayDesign-v1 (single and native vector, 16 envs; random valid picks,
whole episodes: every episode's site set-up, i.e. its Fisher matrices, is included) against ArrayDesign-v0 (a few
steps: its terminal judge tracks 8 passages), with CartPole-v1 measured in the same run as the reference.

The reference of issue 50's targets is **raw** CartPole: ``gym.make("CartPole-v1").unwrapped`` stepped with
random actions (:func:`raw_cartpole_rate`), faster than the wrapped environment (its checkers and time limit; by
1.1-1.2x in the runs of benchmarks/LOG.md, 2026-11-28), which would make the ratios look better than they are.
The targets: a Passage step at least 1/30 of raw CartPole's step rate, the 64-environment vector env's steps
(frames) at least 0.12 of it.

Run:  PYTHONPATH=. python benchmarks/envs.py [--steps 2000] [--num-envs 64] [--allocator tuned|default]
      [--v1-id shipsense/Passage-v1] [--design-steps 400] [--design-envs 16] [--skip-passage] [--skip-design]

Passage-v1's actions read the first ``k``-sensor subset (its full budget).  Autoresets are included (with the
run-in: the observer reads every sensor until its first track).  Every rate is over three timed runs
together, each from its own seed, after one untimed run (:func:`sustained_rate`); the vector rate is three
timed block cycles after an untimed one (:func:`queued_rate`).  PPO frames per second are reported by
``shipsense train`` (docs: Results).  Passage-v0, timed here until it was retired, has its figures in
benchmarks/LOG.md.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import shipsense  # registers the environments

REPEATS = 3
"""Each rate is over this many timed runs together, each reset with its own seed."""


def sustained_rate(reset, run, frames):
    """Frames per second over ``REPEATS`` timed calls of ``run()`` together (total frames over total time), each
    after ``reset(seed)`` with its own seed (0, 1, ...), after one untimed call (seed ``REPEATS``) that pays
    the one-time costs (a Passage env's initialiser grid terms, ~0.4 s at its first window fit, and the
    compiled kernels' loading: what a training run pays once).  An environment's step cost varies from
    episode to episode (the tracker's initialisation), so every repetition meets episodes the process has
    not seen (a process-wide cache of one repetition's episodes does not serve the next) and none is picked
    as the best."""
    reset(REPEATS)
    run()
    total = 0.0
    for seed in range(REPEATS):
        reset(seed)
        t0 = time.perf_counter()
        run()
        total += time.perf_counter() - t0
    return REPEATS * frames / total


def raw_cartpole_rate(steps):
    """Steps per second of raw CartPole (``gym.make("CartPole-v1").unwrapped``: no wrappers), random actions (drawn
    beforehand), reset when an episode ends (:func:`sustained_rate`)."""
    env = gym.make("CartPole-v1").unwrapped
    return single_rate(env, steps, actions=np.random.default_rng(0).integers(0, 2, steps).tolist())


def single_rate(env, steps, action=None, actions=None):
    """Steps per second of one environment stepped with ``action`` every step, or with ``actions`` in turn."""
    actions = [action] * steps if actions is None else actions

    def run():
        for a in actions:
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                env.reset()

    return sustained_rate(lambda seed: env.reset(seed=seed), run, steps)


def vector_rate(envs, steps, actions):
    def run():
        for _ in range(steps):
            envs.step(actions)

    return sustained_rate(lambda seed: envs.reset(seed=seed), run, steps * envs.num_envs)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--num-envs", type=int, default=64)
    ap.add_argument("--allocator", choices=("tuned", "default"), default="tuned",
                    help="tuned: shipsense.tune_allocator() as the shipsense command does; default: glibc's")
    ap.add_argument("--v1-id", default="shipsense/Passage-v1", help="the Passage-v1 variant to measure")
    ap.add_argument("--design-steps", type=int, default=400, help="ArrayDesign-v1 single-env steps per timed run")
    ap.add_argument("--design-envs", type=int, default=16, help="ArrayDesign-v1 vector envs")
    ap.add_argument("--skip-passage", action="store_true", help="measure only CartPole and ArrayDesign")
    ap.add_argument("--skip-design", action="store_true", help="measure only CartPole and Passage")
    args = ap.parse_args(argv)
    tuned = args.allocator == "tuned" and shipsense.tune_allocator()
    print(f"allocator: {'tuned (shipsense.tune_allocator)' if tuned else 'default'}")
    n = args.num_envs
    raw = raw_cartpole_rate(args.steps * 10)
    cart = single_rate(gym.make("CartPole-v1"), args.steps, 1)
    cart_vec = vector_rate(gym.make_vec("CartPole-v1", num_envs=n, vectorization_mode="vector_entry_point"),
                           args.steps // 10, np.ones(n, dtype=np.int64))
    print(f"{'environment':<44}{'steps/s':>12}")
    print(f"{'CartPole-v1 raw (unwrapped, random actions)':<44}{raw:>12,.0f}")
    print(f"{'CartPole-v1 (single)':<44}{cart:>12,.0f}")
    print(f"{f'CartPole-v1 (native vector, {n} envs)':<44}{cart_vec:>12,.0f}")
    if not args.skip_passage:
        single, vec = passage_rates(args.steps, n, args.v1_id)
        print(f"{f'{args.v1_id} (single)':<44}{single:>12,.0f}")
        print(f"{f'{args.v1_id} (vector, {n} envs)':<44}{vec:>12,.0f}")
        name = args.v1_id.split("/")[-1]
        print(f"{name} / CartPole-v1: single {single / cart:.4f}, vector {vec / cart_vec:.4f}")
        print(f"{name} / raw CartPole-v1: single 1/{raw / single:.1f} (target 1/30 or better), vector "
              f"{vec / raw:.3f}x (target 0.12x or more)")
    if args.skip_design:
        return
    d = design_rates(args.design_steps, args.design_envs)
    for name, rate in d.items():
        print(f"{name:<44}{rate:>12,.1f}")
    v1 = d["shipsense/ArrayDesign-v1 (single)"]
    print(f"ArrayDesign-v1 / v0: {v1 / d['shipsense/ArrayDesign-v0 (single)']:.0f}x; "
          f"ArrayDesign-v1 / CartPole-v1: {v1 / cart:.4f}")


def passage_rates(steps, n, v1_id="shipsense/Passage-v1"):
    """Steps per second of ``v1_id`` (single, native vector of ``n``; the first k-subset every step)."""
    env = gym.make(v1_id)
    full = int(env.unwrapped.core.full[0])
    single = single_rate(env, steps, full)
    venv = gym.make_vec(v1_id, num_envs=n, vectorization_mode="vector_entry_point")
    return single, queued_rate(venv, np.full(n, full))


def queued_rate(venv, actions, cycles=REPEATS):
    """Steps per second of a Passage-v1 vector env over ``cycles`` block cycles together (``PASSAGE_BLOCK`` x K
    vector steps each, more than 16 episodes of every sub-environment) after one untimed cycle.

    Its observers' run-ins are done ahead, for every passage queued (a block of ``PASSAGE_BLOCK`` per
    sub-environment), in one batch (:meth:`~shipsense.envs.passage_core.PassageV1Core.run_ins`): a run of a
    few episodes from a reset pays for the run-ins of all the queued passages and uses two of them, and reads
    a rate far below a training run's.  After a cycle the sub-environments' queues are at different points of
    their blocks, and the timed cycles pay for the run-ins they use, as a training run does.  Cycles differ in
    their passages' work, so more than one is timed."""
    from shipsense.envs.prefetch import PASSAGE_BLOCK

    steps = PASSAGE_BLOCK * int(venv.unwrapped.core.K)
    venv.reset(seed=REPEATS)
    for _ in range(steps):
        venv.step(actions)
    t0 = time.perf_counter()
    for _ in range(int(cycles) * steps):
        venv.step(actions)
    return int(cycles) * steps * venv.num_envs / (time.perf_counter() - t0)


def design_rates(steps, num_envs):
    """Steps per second of ArrayDesign-v1 (single, vector; random valid picks) and of ArrayDesign-v0."""
    rng = np.random.default_rng(0)
    env = gym.make("shipsense/ArrayDesign-v1")
    masks = env.get_wrapper_attr("action_masks")
    for s in range(10):          # the electric kernel of each of the sites' five depths is built once per process
        env.reset(seed=s)

    def single():
        for _ in range(steps):
            _, _, term, trunc, _ = env.step(int(rng.choice(np.flatnonzero(masks()))))
            if term or trunc:
                env.reset()

    out = {"shipsense/ArrayDesign-v1 (single)": sustained_rate(lambda seed: env.reset(seed=seed), single, steps)}
    venv = gym.make_vec("shipsense/ArrayDesign-v1", num_envs=num_envs, vectorization_mode="vector_entry_point")
    vsteps = max(steps // num_envs, 8)

    def vector():
        for _ in range(vsteps):
            venv.step(np.array([rng.choice(np.flatnonzero(m)) for m in venv.unwrapped.action_masks()]))

    out[f"shipsense/ArrayDesign-v1 (vector, {num_envs} envs)"] = sustained_rate(
        lambda seed: venv.reset(seed=seed), vector, vsteps * num_envs)
    old = gym.make("shipsense/ArrayDesign-v0")
    old_masks = old.get_wrapper_attr("action_masks")
    k = old.unwrapped.k

    def v0():
        for _ in range(k):
            old.step(int(rng.choice(np.flatnonzero(old_masks()))))

    out["shipsense/ArrayDesign-v0 (single)"] = sustained_rate(lambda seed: old.reset(seed=seed), v0, k)
    return out

if __name__ == "__main__":
    main()
