"""``shipsense track`` on recordings of 1e4, 1e5 and 1e6 rows: time per row and peak memory stay flat.

Run:  python benchmarks/track_rows.py [--sizes 1e4 1e5 1e6] [--out results/bench-track]

Each recording is the demo scenario's nominal passage (19 channels: three
nodes with a vector magnetometer and an electrode triad, one of them with an
accelerometer), sampled for as long as the row count needs (10^6 rows are
52,632 samples, about 7.3 hours at 0.5 s), written as the long-format CSV that
``track --data`` reads.  Each size runs ``shipsense track demo --data FILE`` in a fresh process
(its peak resident memory is its own); the figures are the whole command:
reading, tracking and writing ``estimates.csv`` and ``selection_log.csv``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

CHANNELS = 19
CHILD = """
import json, resource, sys, time
from shipsense.cli import main
t0 = time.perf_counter()
code = main(["track", "demo", "--data", sys.argv[1], "--out", sys.argv[2]])
print(json.dumps({"code": code, "seconds": time.perf_counter() - t0,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def write_recording(path, rows):
    """The demo's nominal passage, long enough for ``rows`` rows, as a long-format CSV (written in blocks)."""
    from shipsense import load_scenario, simulate

    sc = load_scenario("demo")
    m = sc.array().n_channels
    steps = int(np.ceil(rows / m))
    sim = simulate(sc.with_updates(steps=steps), runs=1, seed=0)
    sensors = np.array([s for s, _ in sim.channels])
    names = np.array([c for _, c in sim.channels])
    with open(path, "w") as fh:
        fh.write("time,sensor,channel,value\n")
        for lo in range(0, steps, 20_000):
            t = np.repeat(sim.times[lo:lo + 20_000], m)
            v = sim.measurements[0, lo:lo + 20_000].ravel()
            n = v.size
            cols = [np.char.mod("%.6f", t), np.tile(sensors, n // m), np.tile(names, n // m),
                    np.char.mod("%.9g", v)]
            fh.write("\n".join(",".join(r) for r in zip(*cols)) + "\n")
    return steps * m


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", type=float, default=[1e4, 1e5, 1e6])
    ap.add_argument("--out", default="results/bench-track")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rates, seconds, rows_ = [], [], []
    print(f"{'rows':>9} {'samples':>8} {'seconds':>8} {'us per row':>10} {'peak MB':>8}")
    for size in args.sizes:
        rec = out / f"rec-{int(size)}.csv"
        rows = write_recording(rec, int(size))
        run = subprocess.run([sys.executable, "-c", CHILD, str(rec), str(out / f"track-{int(size)}")],
                             capture_output=True, text=True, check=True)
        res = json.loads(run.stdout.strip().splitlines()[-1])
        rate = 1e6 * res["seconds"] / rows
        rates.append(rate)
        seconds.append(res["seconds"])
        rows_.append(rows)
        print(f"{rows:>9} {rows // CHANNELS:>8} {res['seconds']:>8.1f} {rate:>10.1f} {res['peak_mb']:>8.0f}",
              flush=True)
    print(f"largest / smallest time per row of the whole command: {max(rates) / min(rates):.2f} (the fixed costs -- "
          "start-up, the window's grid search, the refits -- weigh on the smallest file)")
    marginal = [(seconds[i + 1] - seconds[i]) / (rows_[i + 1] - rows_[i]) * 1e6 for i in range(len(rows_) - 1)]
    steps = ", ".join(f"{m:.1f} us ({rows_[i]:.0e} -> {rows_[i + 1]:.0e} rows)" for i, m in enumerate(marginal))
    print("time per additional row: " + steps
          + (f"; ratio {max(marginal) / min(marginal):.2f}" if len(marginal) > 1 else ""))


if __name__ == "__main__":
    main()
