"""``shipsense track --data`` start-up: one small recording end to end, and the cost of each further recording
in one call.

Run:  PYTHONPATH=. python benchmarks/track_startup.py [--recordings 8] [--repeats 5]

Writes ``--recordings`` small recordings (S2's passages, 80 samples of 7 channels, CSV) and times fresh
processes (``python -m shipsense.cli --quiet track S2 --data ...``), the median of ``--repeats`` each:

* one recording, with and without the figure (``--no-plot``);
* all of them in one call, with and without the figure: the cost of each further recording is
  ``(T_all - T_one) / (recordings - 1)``;
* ``import numpy`` in a fresh process, the unit of the ratios (an interpreter's start-up included in every
  figure), so that the ratios transfer between machines where the seconds do not.

The compiled kernels must be on disk already (a first run compiles them; it is run once untimed).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def wall(args, repeats):
    """Median wall seconds of a fresh ``python args`` (from the repository, with its package first)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, *args], check=True, cwd=ROOT, env=env, stdout=subprocess.DEVNULL)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recordings", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    n = args.recordings
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        files = []
        for seed in range(n):
            f = tmp / f"rec{seed}.csv"
            subprocess.run([sys.executable, "-m", "shipsense.cli", "--quiet", "simulate", "S2", "--runs", "1",
                            "--random", "--seed", str(seed), "--out", str(f)], check=True, cwd=ROOT,
                           env={**os.environ, "PYTHONPATH": str(ROOT)}, stdout=subprocess.DEVNULL)
            files.append(str(f))
        track = ["-m", "shipsense.cli", "--quiet", "track", "S2", "--out", str(tmp / "out"), "--data"]
        wall(track + files[:1], 1)   # compiles the kernels if they are not on disk yet
        unit = wall(["-c", "import numpy"], args.repeats)
        rows = {}
        for plot in (True, False):
            extra = [] if plot else ["--no-plot"]
            one = wall(track + files[:1] + extra, args.repeats)
            every = wall(track + files + extra, args.repeats)
            rows[plot] = (one, every, (every - one) / (n - 1))
    print(f"fresh `import numpy`: {unit:.3f} s (the unit of the ratios); median of {args.repeats} fresh processes")
    print(f"{'':<28}{'one recording':>22}{f'{n} in one call':>22}{'each further one':>22}")
    for plot, (one, every, extra) in rows.items():
        label = "track (with track.png)" if plot else "track --no-plot"
        print(f"{label:<28}" + "".join(f"{f'{s:.3f} s ({s / unit:.1f}x)':>22}" for s in (one, every, extra)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
