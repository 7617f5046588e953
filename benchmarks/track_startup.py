"""``shipsense track --data`` start-up: one small recording end to end, and the cost of each further recording
in one call.

Run:  PYTHONPATH=. python benchmarks/track_startup.py [--recordings 8] [--repeats 5] [--repo PATH]

(``--repo``: time the package of another checkout, e.g. a worktree of the commit before a change, with its own
compiled kernels; by default this one's.)

Writes ``--recordings`` small recordings (S2's passages, 80 samples of 7 channels, CSV) and times fresh
processes (``python -m shipsense.cli --quiet track S2 --data ...``), the median of ``--repeats`` each:

* one recording, with and without the figure (``--no-plot``);
* all of them in one call, with and without the figure: the cost of each further recording is
  ``(T_all - T_one) / (recordings - 1)``;
* ``import numpy`` in a fresh process, the unit of the ratios (an interpreter's start-up included in every
  figure), so that the ratios transfer between machines where the seconds do not;
* the floor under any command that runs a compiled kernel: a fresh process that imports numpy and numba and
  calls one trivial kernel from numba's cache (numba's first call sets up its code generator and typing
  registries, which imports scipy.linalg for its BLAS check, whatever the kernel).

Each figure is the median wall time and, in brackets after the ratio, the median CPU time (user + system) of
the process: on a shared machine the wall time grows with the load and the CPU time much less.  The compiled
kernels must be on disk already (a first run compiles them; it is run once untimed).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


FLOOR = """
import numba


@numba.njit(cache=True)
def total(n):
    s = 0.0
    for i in range(n):
        s += i
    return s
"""
"""The floor's module: one trivial kernel cached by numba."""


def wall(args, repeats, root=ROOT):
    """Median wall seconds and median CPU seconds (user + system) of a fresh ``python args`` (from the
    repository ``root``, with its package first)."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    times, cpus = [], []
    for _ in range(repeats):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run([sys.executable, *args], check=True, cwd=root, env=env, stdout=subprocess.DEVNULL)
        times.append(time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return statistics.median(times), statistics.median(cpus)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recordings", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--repo", type=Path, default=ROOT, help="the checkout whose package is timed")
    args = ap.parse_args(argv)
    n = args.recordings
    root = args.repo.resolve()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        files = []
        for seed in range(n):
            f = tmp / f"rec{seed}.csv"
            subprocess.run([sys.executable, "-m", "shipsense.cli", "--quiet", "simulate", "S2", "--runs", "1",
                            "--random", "--seed", str(seed), "--out", str(f)], check=True, cwd=root,
                           env={**os.environ, "PYTHONPATH": str(root)}, stdout=subprocess.DEVNULL)
            files.append(str(f))
        track = ["-m", "shipsense.cli", "--quiet", "track", "S2", "--out", str(tmp / "out"), "--data"]
        wall(track + files[:1], 1, root)   # compiles the kernels if they are not on disk yet
        (tmp / "floor_kernel.py").write_text(FLOOR)
        floor = ["-c", f"import sys; sys.path.insert(0, {str(tmp)!r}); import floor_kernel; floor_kernel.total(3)"]
        wall(floor, 1)               # compiles the floor's kernel
        unit = wall(["-c", "import numpy"], args.repeats)
        floors = {"import numpy, numba": wall(["-c", "import numpy, numba"], args.repeats),
                  "+ one cached kernel (floor)": wall(floor, args.repeats)}
        rows = {}
        for plot in (True, False):
            extra = [] if plot else ["--no-plot"]
            one = wall(track + files[:1] + extra, args.repeats, root)
            every = wall(track + files + extra, args.repeats, root)
            rows[plot] = (one, every, tuple((e - o) / (n - 1) for e, o in zip(every, one)))
    u = unit[0]

    def cell(s):
        return f"{s[0]:.3f} s ({s[0] / u:.1f}x, cpu {s[1]:.2f} s)"

    print(f"package: {root}")
    print(f"fresh `import numpy`: {u:.3f} s (cpu {unit[1]:.2f} s), the unit of the ratios; median of "
          f"{args.repeats} fresh processes")
    for label, s in floors.items():
        print(f"{label:<28}{cell(s):>32}")
    print(f"{'':<28}{'one recording':>32}{f'{n} in one call':>32}{'each further one':>32}")
    for plot, (one, every, extra) in rows.items():
        label = "track (with track.png)" if plot else "track --no-plot"
        print(f"{label:<28}" + "".join(f"{cell(s):>32}" for s in (one, every, extra)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
