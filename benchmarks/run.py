"""The whole performance picture in one run: filter steps against FilterPy, environments against CartPole, and
the studies' wall time and peak memory.

Run:  PYTHONPATH=. python benchmarks/run.py [--steps 20] [--env-steps 2000] [--studies S0 [S1 wide ...]]
                                             [--skip-filters] [--skip-envs]

1. Filters: microseconds per filter-step (one predict + update of one hypothesis) on the S0 model for every
   filter unit at batch 1, 24 and 2400 through the compiled steps users get, and at 2400 once more in one
   thread (``SHIPSENSE_THREADS=1``; a batch of 512 or more is otherwise split across the CPUs); in brackets
   the speed-up over FilterPy's ``UnscentedKalmanFilter`` looped per filter, timed in the same process.
2. Environments: steps per second of Passage-v1 and Passage-v2, single (from ``gym.make``) and native vector
   (64 envs), autoresets included, as a fraction of raw CartPole-v1 (unwrapped) timed in the same process.  A
   Passage episode's cost depends on its passage (how often the tracker refits), so a single env's timed runs
   are ``--env-steps`` 2,000 steps each: short runs weigh the episodes of a few passages (EXPERIMENTS.md,
   "Performance log").
3. Studies: ``shipsense reproduce NAME`` for each of ``--studies`` (default S0), each in a fresh process:
   wall seconds, CPU seconds and peak resident memory.

Every ratio is of two rates measured in this one run; absolute times depend on the machine and its load.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time

import envs as env_bench
import filters as filter_bench
import gymnasium as gym
import numpy as np

import shipsense
from shipsense import parallel
from shipsense.trackers.filters import FILTER_NAMES, get_filter


def filter_table(steps, batches=(1, 24, 2400)):
    base = filter_bench.time_filterpy(24, steps)
    print(f"1. Filter steps, S0 model (n=7, m=3): microseconds per filter-step (speed-up over FilterPy's UKF "
          f"loop, {base:.1f} us per filter-step here)")
    print(f"   threads for a batch >= {parallel.SPLIT_MIN}: {parallel.threads()}\n")
    for name in FILTER_NAMES:      # compile or load the compiled steps before timing
        filter_bench.time_batched(get_filter(name), 2, 1, repeats=1)
    cols = [f"B={b}" for b in batches] + [f"B={batches[-1]}, 1 thread"]
    print(f"{'filter':<12}" + "".join(f"{c:>20}" for c in cols))
    for name in FILTER_NAMES:
        cells = [filter_bench.time_batched(get_filter(name), b, steps) for b in batches]
        os.environ["SHIPSENSE_THREADS"] = "1"
        try:
            cells.append(filter_bench.time_batched(get_filter(name), batches[-1], steps))
        finally:
            del os.environ["SHIPSENSE_THREADS"]
        print(f"{name:<12}" + "".join(f"{f'{us:.2f} ({base / us:.0f}x)':>20}" for us in cells))
    print("(puekf with N_pu = 5)")


def env_table(steps, n=64):
    print(f"\n2. Environments: steps per second (autoresets included; {env_bench.REPEATS} runs together after an "
          f"untimed one, from seeds 0, 1, ...; Passage-v1's vector env over {env_bench.REPEATS} block cycles after "
          f"an untimed one)")
    # the reference is raw CartPole (no wrappers, random actions): the wrapped environment is several times slower,
    # which would flatter the ratios
    cart = env_bench.raw_cartpole_rate(steps)
    cart_vec = env_bench.vector_rate(gym.make_vec("CartPole-v1", num_envs=n, vectorization_mode="vector_entry_point"),
                                     steps // 10, np.ones(n, dtype=np.int64))
    rows = [("CartPole-v1 (raw: unwrapped, single)", cart, cart),
            (f"CartPole-v1 (native vector, {n} envs)", cart_vec, cart)]
    for env_id in ("shipsense/Passage-v1", "shipsense/Passage-v2"):
        single, vec = env_bench.passage_rates(steps, n, env_id)
        rows += [(f"{env_id} (single)", single, cart), (f"{env_id} (native vector, {n} envs)", vec, cart)]
    print(f"{'environment':<46}{'steps/s':>12}{'/ raw CartPole':>16}")
    for name, rate, ref in rows:
        print(f"{name:<46}{rate:>12,.0f}{rate / ref:>16.4f}")
    print("(a single env from gym.make, with gymnasium's OrderEnforcing and PassiveEnvChecker; issue 50's targets "
          "for Passage-v2: single >= 0.0333 (1/30), vector >= 0.12)")


STUDY = """
import sys, time
from shipsense.cli import main
t0 = time.perf_counter()
code = main(["reproduce", sys.argv[1], "--out", sys.argv[2]])
wall = time.perf_counter() - t0
status = {line.split(":")[0]: int(line.split()[1]) / 1024 for line in open("/proc/self/status")
          if line.startswith(("VmHWM:", "RssFile:"))}
print("WALL", wall, code, status.get("VmHWM", float("nan")), status.get("RssFile", float("nan")))
"""


def study(name):
    """``shipsense reproduce NAME`` in a fresh process: (wall s, CPU s, peak resident MB, file-backed MB at exit).

    The peak is the process's own high-water mark (``VmHWM``: ``ru_maxrss`` of a child started from this
    process would count this process's pages, which the kernel carries across ``exec``); Dask workers that a
    study starts are not in it.  CPU seconds include them.  The file-backed part (``RssFile`` when the study
    has finished, where S0 peaks) is mostly the pages of numba's LLVM library (``libllvmlite.so``): how many of
    them are resident depends on the kernel's page cache, not on the study (S0 with numba 0.68.1 on one machine,
    2026-11-26: 104.5 MiB of it on the day the library was installed, 72.9 MiB hours later, the peak 318 and
    284 MiB; the heap and anonymous memory 165 MiB both times, 137 since the studies draw their figures after
    their runs; benchmarks/LOG.md).
    """
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    with tempfile.TemporaryDirectory() as tmp:
        # (from the directory that holds this run's package: ``python -c`` puts the working directory first on
        # its path, so a study started elsewhere could import another copy of shipsense)
        out = subprocess.run([sys.executable, "-c", STUDY, name, os.path.join(tmp, name)], capture_output=True,
                             text=True, cwd=os.path.dirname(os.path.dirname(os.path.abspath(shipsense.__file__))))
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("WALL ")]
    if out.returncode != 0 or not lines or lines[-1].split()[2] != "0":
        raise RuntimeError(f"reproduce {name} failed:\n{out.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    _, wall, _, mb, files = lines[-1].split()
    return float(wall), cpu, float(mb), float(files)


def study_table(names):
    print("\n3. Studies (`shipsense reproduce NAME`, default options, each in a fresh process)")
    print(f"{'study':<10}{'wall s':>10}{'CPU s':>10}{'peak MB':>10}{'files MB':>10}")
    for name in names:
        wall, cpu, mb, files = study(name)
        print(f"{name:<10}{wall:>10.1f}{cpu:>10.1f}{mb:>10.0f}{files:>10.0f}", flush=True)
    print("(peak MB: the study's own process; files MB: its file-backed pages at the end, mostly numba's LLVM\n"
          " library, resident as the page cache holds it; CPU s: with any worker processes it started)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20, help="filter steps per timed run")
    ap.add_argument("--env-steps", type=int, default=2000, help="single-environment steps per timed run")
    ap.add_argument("--studies", nargs="*", default=["S0"], help="reproduce these (S0, S1, S2, wide); none: skip")
    ap.add_argument("--skip-filters", action="store_true")
    ap.add_argument("--skip-envs", action="store_true")
    args = ap.parse_args(argv)
    tuned = shipsense.tune_allocator()
    t0 = time.perf_counter()
    print(f"shipsense {shipsense.__version__}, Python {sys.version.split()[0]}, {os.cpu_count()} CPUs, "
          f"allocator {'tuned' if tuned else 'default'}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}\n")
    if not args.skip_filters:
        filter_table(args.steps)
    if not args.skip_envs:
        env_table(args.env_steps)
    if args.studies:
        study_table(args.studies)
    print(f"\n(this run: {time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
