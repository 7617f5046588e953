"""Environment benchmark: steps per second of Passage-v0 (single and native vector, 64 envs) with the
project's tracker as observer (what users get; ``--observer bank``: the studies' 12-hypothesis bank), of
Passage-v1 (single and native vector; the tracker is its only observer), and of ArrayDesign-v1 (single and
native vector, 16 envs; random valid picks, whole episodes: every episode's site set-up, i.e. its Fisher
matrices, is included) against ArrayDesign-v0 (a few steps: its terminal judge tracks 8 passages), with
CartPole-v1 measured in the same run as the reference.

Run:  PYTHONPATH=. python benchmarks/envs.py [--steps 2000] [--num-envs 64] [--observer tracker|bank]
      [--allocator tuned|default] [--v1-id shipsense/Passage-v1] [--design-steps 400] [--design-envs 16]
      [--skip-passage]

Passage-v0's actions are all-ones (read every sensor) so that every step runs the full
update; Passage-v1's read the first ``k``-sensor subset (its full budget).  Autoresets are included (for
Passage-v1 with its run-in: the observer reads every sensor until its first track).  Every rate is over
three timed runs together, each from its own seed, after one untimed run (:func:`sustained_rate`); a
Passage-v0 vector env's runs are whole episode cycles (:func:`whole_episodes`); Passage-v1's vector rate is
three timed block cycles after an untimed one (:func:`queued_rate`).  PPO frames per second are reported by
``shipsense train`` (see docs: Results).
"""

from __future__ import annotations

import argparse
import time
import warnings
from contextlib import contextmanager

import gymnasium as gym
import numpy as np

import shipsense  # registers the environments

TWELVE = {"tracker": {"filter": "ukf", "process_noise": {"model": "diagonal",
                                                         "q_diag": [1e-4, 1e-4, 1e-4, 1e-4, 2e-4, 2e-4, 2e-4]},
                      "bank": {"levels": [5e3, 2e4, 8e4], "bearings_deg": [45.0, 135.0, 225.0, 315.0],
                               "initial_velocity": [3.5, 3.5], "initial_course": "towards_array",
                               "position_std": 20.0, "moment_std": 5e4}}}


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


def single_rate(env, steps, action):
    def run():
        for _ in range(steps):
            _, _, term, trunc, _ = env.step(action)
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
    ap.add_argument("--observer", choices=("tracker", "bank"), default="tracker",
                    help="the environment's observer (default: the tracker, as users get it)")
    ap.add_argument("--design-steps", type=int, default=400, help="ArrayDesign-v1 single-env steps per timed run")
    ap.add_argument("--design-envs", type=int, default=16, help="ArrayDesign-v1 vector envs")
    ap.add_argument("--skip-passage", action="store_true", help="measure only CartPole and ArrayDesign")
    args = ap.parse_args(argv)
    kwargs = {"observer": args.observer} | ({"overrides": TWELVE} if args.observer == "bank" else {})
    tuned = args.allocator == "tuned" and shipsense.tune_allocator()
    print(f"allocator: {'tuned (shipsense.tune_allocator)' if tuned else 'default'}")
    n = args.num_envs
    cart = single_rate(gym.make("CartPole-v1"), args.steps, 1)
    cart_vec = vector_rate(gym.make_vec("CartPole-v1", num_envs=n, vectorization_mode="vector_entry_point"),
                           args.steps // 10, np.ones(n, dtype=np.int64))
    print(f"{'environment':<44}{'steps/s':>12}")
    print(f"{'CartPole-v1 (single)':<44}{cart:>12,.0f}")
    print(f"{f'CartPole-v1 (native vector, {n} envs)':<44}{cart_vec:>12,.0f}")
    if not args.skip_passage:
        single, vec, single1, vec1 = passage_rates(args.steps, n, kwargs, args.v1_id)
        print(f"{f'shipsense/Passage-v0 (single, {args.observer})':<44}{single:>12,.0f}")
        print(f"{f'shipsense/Passage-v0 (vector, {n} envs)':<44}{vec:>12,.0f}")
        print(f"{f'{args.v1_id} (single)':<44}{single1:>12,.0f}")
        print(f"{f'{args.v1_id} (vector, {n} envs)':<44}{vec1:>12,.0f}")
        print(f"Passage-v0 / CartPole-v1: single {single / cart:.3f}, vector {vec / cart_vec:.3f}")
        print(f"Passage-v1 / CartPole-v1: single {single1 / cart:.4f}, vector {vec1 / cart_vec:.4f}")
    d = design_rates(args.design_steps, args.design_envs)
    for name, rate in d.items():
        print(f"{name:<44}{rate:>12,.1f}")
    v1 = d["shipsense/ArrayDesign-v1 (single)"]
    print(f"ArrayDesign-v1 / v0: {v1 / d['shipsense/ArrayDesign-v0 (single)']:.0f}x; "
          f"ArrayDesign-v1 / CartPole-v1: {v1 / cart:.4f}")


def passage_rates(steps, n, kwargs=None, v1_id="shipsense/Passage-v1"):
    """Steps per second of Passage-v0 (single, native vector of ``n``; all-ones actions, made with ``kwargs``)
    and of ``v1_id`` (single, native vector; the first k-subset every step)."""
    kwargs = kwargs or {}
    with _v0_on_purpose():
        env = gym.make("shipsense/Passage-v0", **kwargs)
    single = single_rate(env, steps, np.ones(3, dtype=np.int8))
    with _v0_on_purpose():
        venv = gym.make_vec("shipsense/Passage-v0", num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
    vec = vector_rate(venv, whole_episodes(venv, steps // 10), np.ones((n, 3), dtype=np.int8))
    env1 = gym.make(v1_id)
    full = int(env1.unwrapped.core.full[0])
    single1 = single_rate(env1, steps, full)
    venv1 = gym.make_vec(v1_id, num_envs=n, vectorization_mode="vector_entry_point")
    vec1 = queued_rate(venv1, np.full(n, full))
    return single, vec, single1, vec1


@contextmanager
def _v0_on_purpose():
    """Gymnasium's "out of date" warning for Passage-v0 silenced: it is measured on purpose (issue 20's figures
    are its)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*Passage-v0 is out of date", category=DeprecationWarning)
        yield


def queued_rate(venv, actions, cycles=REPEATS):
    """Steps per second of a Passage-v1 vector env over ``cycles`` block cycles together (``PASSAGE_BLOCK`` x K
    vector steps each, more than 16 episodes of every sub-environment) after one untimed cycle.

    Its observers' run-ins are done ahead, for every passage queued (a block of ``PASSAGE_BLOCK`` per
    sub-environment), in one batch (:meth:`~shipsense.envs.passage_v1.PassageV1Core._run_ins`): a run of a
    few episodes from a reset pays for the run-ins of all the queued passages and uses two of them (the
    first measure of this kind, 200 steps from each of three resets, read 5,498 env-steps/s where this one
    reads 11,246).  After a cycle the sub-environments' queues are at different points of their blocks, and
    the timed cycles pay for the run-ins they use, as a training run does.  Cycles differ in their passages'
    work (one machine, 2026-11-26, six cycles from the same reset: 18.7k to 20.8k env-steps/s), so more than
    one is timed."""
    from shipsense.envs.passage_v1 import PASSAGE_BLOCK

    steps = PASSAGE_BLOCK * int(venv.unwrapped.core.K)
    venv.reset(seed=REPEATS)
    for _ in range(steps):
        venv.step(actions)
    t0 = time.perf_counter()
    for _ in range(int(cycles) * steps):
        venv.step(actions)
    return int(cycles) * steps * venv.num_envs / (time.perf_counter() - t0)


def whole_episodes(venv, steps):
    """At least ``steps`` vector steps, rounded up to whole episode cycles (K - 1 steps and the autoreset step).

    A passage lasts K samples, so the vector env's sub-environments, reset together, stay in step: each
    cycle starts every tracker (its window fits) at about the same sample.  A timed run from a reset that
    ends mid-cycle weighs those starts by where it ends (40 steps of S2's 80 counted them twice); whole
    cycles give the rate a training run sees."""
    K = int(venv.unwrapped.core.K)
    return K * max(1, -(-int(steps) // K))


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
