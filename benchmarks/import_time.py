"""``import shipsense`` start-up time, against ``import numpy`` and ``import gymnasium`` in the same runs.

Run:  python benchmarks/import_time.py [--repeats 15]

Each figure is the median wall time of a fresh interpreter running
``import X`` (so every run pays the imports cold in the interpreter, warm in
the filesystem cache), minus the median of an interpreter that imports
nothing.  ``import shipsense`` registers the gymnasium environments (so
``gymnasium.make("shipsense/Passage-v1")`` works after it) and imports
nothing else: the public names (``load_scenario``, ``simulate``, ...) are
imported on first use.  Target: under 0.3 s (issue 19); the ratio to
``import gymnasium`` is the figure that transfers between machines.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

TARGETS = {"nothing": "pass", "numpy": "import numpy", "gymnasium": "import gymnasium",
           "shipsense": "import shipsense", "shipsense + simulate": "import shipsense; shipsense.simulate"}


def wall(code, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], check=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args(argv)
    base = wall(TARGETS["nothing"], args.repeats)
    rows = {name: wall(code, args.repeats) - base for name, code in TARGETS.items() if name != "nothing"}
    print(f"interpreter start-up {base * 1e3:.0f} ms (subtracted); median of {args.repeats} fresh processes")
    for name, seconds in rows.items():
        print(f"  {name:22s} {seconds * 1e3:7.0f} ms   {seconds / rows['gymnasium']:5.2f}x import gymnasium")
    ok = rows["shipsense"] < 0.3
    print(f"import shipsense {'under' if ok else 'OVER'} the 0.3 s target")
    return 0


if __name__ == "__main__":
    sys.exit(main())
