"""Environment memory over a long run: resident memory of a native vector Passage env every so many steps.

Run:  PYTHONPATH=. python benchmarks/env_memory.py [--env shipsense/Passage-v1] [--steps 1000000] [--num-envs 64]
      [--rows 10]

Steps ``--steps`` environment steps (``--steps / --num-envs`` vector steps, autoresets included, random valid
actions from a fixed seed) and prints the process's resident memory (``VmRSS``, MB) at ``--rows`` evenly spaced
points, then the growth from the first printed point (after the first tenth: caches and the allocator's
arenas filled) to the last, in MB and per million steps.  Linux only (reads ``/proc/self/status``).
"""

from __future__ import annotations

import argparse
import re
import sys
import time
import warnings


def rss_mb():
    with open("/proc/self/status") as f:
        return int(re.search(r"VmRSS:\s+(\d+)", f.read()).group(1)) / 1024


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="shipsense/Passage-v1")
    ap.add_argument("--steps", type=float, default=1e6, help="environment steps (all sub-environments)")
    ap.add_argument("--num-envs", type=int, default=64)
    ap.add_argument("--rows", type=int, default=10)
    args = ap.parse_args(argv)
    if not sys.platform.startswith("linux"):
        ap.error("reads /proc/self/status: Linux only")
    warnings.filterwarnings("ignore", category=DeprecationWarning)
    import gymnasium as gym

    import shipsense

    shipsense.tune_allocator()              # as `shipsense train` does
    envs = gym.make_vec(args.env, num_envs=args.num_envs, vectorization_mode="vector_entry_point")
    envs.reset(seed=0)
    envs.action_space.seed(0)
    vsteps = int(args.steps) // args.num_envs
    marks = {int(vsteps * (i + 1) / args.rows) for i in range(args.rows)}
    print(f"{args.env}, native vector env of {args.num_envs}: {vsteps * args.num_envs:,} steps")
    print(f"{'env steps':>12}{'RSS MB':>10}{'seconds':>10}")
    t0, first, rows = time.perf_counter(), None, []
    for k in range(1, vsteps + 1):
        envs.step(envs.action_space.sample())
        if k in marks:
            rss = rss_mb()
            rows.append((k * args.num_envs, rss))
            first = first or (k * args.num_envs, rss)
            print(f"{k * args.num_envs:>12,}{rss:>10.1f}{time.perf_counter() - t0:>10.0f}", flush=True)
    (s0, m0), (s1, m1) = first, rows[-1]
    per = (m1 - m0) / max(s1 - s0, 1) * 1e6
    print(f"growth from {s0:,} to {s1:,} steps: {m1 - m0:+.1f} MB ({per:+.1f} MB per million steps)")
    envs.close()


if __name__ == "__main__":
    main()
