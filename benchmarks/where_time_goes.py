"""Where the time and memory go: the probes behind the figures of benchmarks/LOG.md.

Run:  PYTHONPATH=. python benchmarks/where_time_goes.py stages S0|S1          # each stage's peak memory
      PYTHONPATH=. python benchmarks/where_time_goes.py passage [--steps 1500]  # cProfile of Passage-v1 steps
      PYTHONPATH=. python benchmarks/where_time_goes.py wide                    # one wide-study task of each kind
      PYTHONPATH=. python benchmarks/where_time_goes.py v1cycles [--cycles 3]   # Passage-v1 vector: who is busy
      PYTHONPATH=. python benchmarks/where_time_goes.py runins [--profile]      # Passage-v1 run-ins by batch size

``stages`` resets the process's peak resident memory (Linux ``/proc/self/clear_refs``) at the start of each
stage of the study and prints the stage's starting, peak and final resident memory (MB).  ``passage`` and
``wide`` print the functions of most own time (``cProfile``, one thread: ``SHIPSENSE_THREADS=1``), or with
``--sort cumulative`` (before the command) of most time with their callees.  ``v1cycles`` steps Passage-v1's
native vector env (64 envs, the first k-subset every step, as ``benchmarks/envs.py``) through block cycles
after an untimed one, with its background thread, and prints per cycle the env-steps per second, the CPUs the
process used, and the stepping thread's share of the wall time and CPU an env-step against the other threads'
(the background's run-ins, the pool's chunks), then the rate of the timed cycles together.  ``runins`` times
the run-ins of 12 blocks of Passage-v1 passages (CPU a passage, one thread) one passage at a time and in batches
of one, two and six blocks, and with ``--profile`` profiles the batches of six.
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import re
import sys
import tempfile
import time


def _status(key):
    with open("/proc/self/status") as f:
        return int(re.search(key + r":\s+(\d+)", f.read()).group(1)) / 1024


def stages(study):
    """Run ``reproduce <study>`` in this process and print each stage's memory."""
    import importlib

    from shipsense.reproduce import common

    step, done = common.Stages.step, common.Stages.done

    def step_(self, name):
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")                                    # reset VmHWM to the current resident size
        self._probe = (name, _status("VmRSS"))
        return step(self, name)

    def done_(self):
        name, start = self._probe
        print(f"{name:<22}{start:>10.0f}{_status('VmHWM'):>10.0f}{_status('VmRSS'):>10.0f}", flush=True)
        return done(self)

    common.Stages.step, common.Stages.done = step_, done_
    print(f"{'stage':<22}{'start MB':>10}{'peak MB':>10}{'end MB':>10}")
    with tempfile.TemporaryDirectory() as out:
        importlib.import_module(f"shipsense.reproduce.{study.lower()}").run(out=out, progress=False)


SORT = "tottime"
"""The profiles' order (``--sort``): own time, or ``cumulative`` (with callees)."""


def _profile(fn, rows):
    pr = cProfile.Profile()
    t0 = time.perf_counter()
    pr.runcall(fn)
    print(f"{time.perf_counter() - t0:.1f} s under the profiler")
    pstats.Stats(pr).sort_stats(SORT).print_stats(rows)


def passage(steps, rows):
    import gymnasium as gym

    import shipsense.envs  # noqa: F401  (registers the environments)

    env = gym.make("shipsense/Passage-v1")
    env.reset(seed=0)
    action = int(env.unwrapped.core.full[0])                # the first k-subset, as benchmarks/envs.py

    def run(n):
        for _ in range(n):
            _, _, term, trunc, _ = env.step(action)
            if term or trunc:
                env.reset()

    run(200)                                                # compile or load, first episodes
    _profile(lambda: run(steps), rows)
    print(f"({steps} steps of Passage-v1, the first k-subset read)")


def wide(rows):
    from shipsense.reproduce import wide as study

    kinds = {}
    for task in study.tasks(500, 0):
        kinds.setdefault((task.family, task.part), task)
    for task in kinds.values():                             # compile or load
        study.run_task(task)
    _profile(lambda: [study.run_task(t) for t in kinds.values()], rows)
    print(f"({len(kinds)} tasks: {', '.join(t.name for t in kinds.values())})")


def _v1_vector(num_envs=64):
    import gymnasium as gym

    import shipsense.envs  # noqa: F401  (registers the environments)

    return gym.make_vec("shipsense/Passage-v1", num_envs=num_envs, vectorization_mode="vector_entry_point")


def v1cycles(cycles):
    import numpy as np

    from shipsense.envs.prefetch import PASSAGE_BLOCK

    venv = _v1_vector()
    core = venv.unwrapped.core
    actions, steps = np.full(venv.num_envs, core.full[0]), PASSAGE_BLOCK * int(core.K)
    venv.reset(seed=3)
    print(f"{'cycle':<7}{'env-steps/s':>13}{'CPUs':>7}{'stepping busy':>15}{'stepping us':>13}{'others us':>11}"
          "   (us: CPU an env-step)")
    total = 0.0
    for cycle in range(-1, cycles):              # cycle -1: untimed (the first blocks, compiles)
        t0, c0, m0 = time.perf_counter(), time.process_time(), time.thread_time()
        for _ in range(steps):
            venv.step(actions)
        wall, cpu, mine = time.perf_counter() - t0, time.process_time() - c0, time.thread_time() - m0
        n = steps * venv.num_envs
        if cycle >= 0:
            total += wall
            print(f"{cycle:<7}{n / wall:>13,.0f}{cpu / wall:>7.2f}{mine / wall:>14.0%}{mine / n * 1e6:>13.1f}"
                  f"{(cpu - mine) / n * 1e6:>11.1f}", flush=True)
    if cycles > 1:
        print(f"{'all':<7}{cycles * steps * venv.num_envs / total:>13,.0f}   (the timed cycles together)")


def runins(profile_rows=None):
    venv = _v1_vector(4)
    core = venv.unwrapped.core
    blocks = [core.draw_block(seed) for seed in range(100, 112)]
    core.run_ins(core.draw_block(99))                 # compile or load
    passages = [entry for block in blocks for entry in block]

    def run(size):
        for i in range(0, len(passages), size):
            entries = passages[i:i + size]
            for entry in entries:
                entry[2] = None
            core.run_ins(entries)

    for size in (1, len(blocks[0]), 2 * len(blocks[0]), 6 * len(blocks[0])):
        t0 = time.process_time()
        run(size)
        what = "alone" if size == 1 else f"{size // len(blocks[0])} block(s) a batch ({size} passages)"
        print(f"{what}: {(time.process_time() - t0) / len(passages) * 1e3:.2f} ms of CPU a passage", flush=True)
    if profile_rows:
        _profile(lambda: run(6 * len(blocks[0])), profile_rows)
        print(f"(the run-ins of {len(passages)} passages, six blocks a batch)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="what", required=True)
    s = sub.add_parser("stages")
    s.add_argument("study", choices=("S0", "S1"))
    p = sub.add_parser("passage")
    p.add_argument("--steps", type=int, default=1500)
    sub.add_parser("wide")
    c = sub.add_parser("v1cycles")
    c.add_argument("--cycles", type=int, default=3)
    r = sub.add_parser("runins")
    r.add_argument("--profile", action="store_true", help="then profile the batches of six blocks")
    ap.add_argument("--rows", type=int, default=20, help="profile rows to print")
    ap.add_argument("--sort", choices=("tottime", "cumulative"), default="tottime",
                    help="profile order: own time (default) or with callees")
    args = ap.parse_args(argv)
    global SORT
    SORT = args.sort
    if args.what == "stages":
        if not sys.platform.startswith("linux"):
            ap.error("stages reads /proc: Linux only")
        stages(args.study)
        return
    if args.what == "v1cycles":                      # (with the background thread: two threads at least)
        v1cycles(args.cycles)
        return
    os.environ["SHIPSENSE_THREADS"] = "1"
    if args.what == "passage":
        passage(args.steps, args.rows)
    elif args.what == "runins":
        runins(args.rows if args.profile else None)
    else:
        wide(args.rows)


if __name__ == "__main__":
    main()
