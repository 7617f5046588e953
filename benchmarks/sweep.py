"""Sweep scheduling: the example sweep (108 cells) on 1 and 2 local Dask workers, in one run.

Run:  python benchmarks/sweep.py [--passages 8] [--out results/bench-sweep]

Prints, for each worker count, the wall time, the sum of the tasks' own
times, the speed-up of 2 workers over 1, and the scheduling overhead per
task: ``(wall x workers - task seconds) / tasks``, the time a worker was not
running a task (start-up, transfer, the client writing results).  The
tracker's time per passage depends on the machine; the ratios are the result.
"""

from __future__ import annotations

import argparse
import shutil
import tomllib
from pathlib import Path

from shipsense.sweep import EXAMPLE, parse_sweep, run_sweep


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passages", type=int, default=8, help="passages per cell (default 8, as the example)")
    ap.add_argument("--out", default="results/bench-sweep")
    args = ap.parse_args(argv)
    data = tomllib.loads(EXAMPLE)
    data["passages"] = args.passages
    spec = parse_sweep(data, "the example sweep")
    rows = {}
    for workers in (1, 2):
        out = Path(args.out) / f"workers-{workers}"
        shutil.rmtree(out, ignore_errors=True)
        run = run_sweep(spec, Path.cwd(), out, workers=workers, log=lambda *a: None)
        overhead = (run.wall_seconds * workers - run.task_seconds) / run.ran
        rows[workers] = run
        print(f"{workers} worker(s): {run.ran} tasks of {run.cells} cells, wall {run.wall_seconds:.1f} s, "
              f"task time {run.task_seconds:.1f} s, overhead {1000 * overhead:.0f} ms per task", flush=True)
    print(f"speed-up of 2 workers over 1: {rows[1].wall_seconds / rows[2].wall_seconds:.2f}x")


if __name__ == "__main__":
    main()
