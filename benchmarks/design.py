"""Design benchmark: relaxation solve time and certified gap against candidates N and prior samples S (k = 6),
and the time of `shipsense check` on S1.

Run:  python benchmarks/design.py [--sizes 100 400 1600] [--samples 1 8 32]

Envelope electrodes (the S1-P2 template) on a square grid; "conic" is cvxpy
with CLARABEL, "first-order" the projected-gradient path (used automatically
above 800 candidates).  Time is wall-clock for building nothing but the solve
and the rounding (the Fisher matrices are computed once per (N, S) first and
reported separately).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

import numpy as np

from shipsense import load_scenario
from shipsense.design import placement as pl
from shipsense.simulator import sample_passages
from shipsense.trackers.models import candidate_model


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 400, 1600])
    ap.add_argument("--samples", type=int, nargs="+", default=[1, 8, 32])
    ap.add_argument("--k", type=int, default=6)
    ap.add_argument("--conic-max", type=int, default=400, help="largest N solved with the conic solver")
    args = ap.parse_args(argv)
    sc = load_scenario("S1-P2")
    print(f"{'N':>6} {'S':>4} {'fisher [s]':>11} {'method':>12} {'solve+round [s]':>16} {'certified gap':>14}")
    for N in args.sizes:
        side = int(np.ceil(np.sqrt(N)))
        half = 60.0
        xs = np.linspace(-half, half, side)
        pts = np.stack(np.meshgrid(xs, xs), -1).reshape(-1, 2)[:N]
        cands = np.column_stack([pts, np.full(len(pts), -15.0)])
        model = candidate_model(sc, cands)
        for S in args.samples:
            thetas = model.to_internal(model.state_from_truth(sample_passages(sc, S, seed=1)))
            prior = model.to_internal(np.array([30.0, 30.0, 2.0, 2.0, 1.0, 50.0]))
            t0 = time.perf_counter()
            problem = pl.build_problem(model, thetas, sc.steps, args.k, prior, stride=4)
            t_fim = time.perf_counter() - t0
            methods = ["convex", "first-order"] if N <= args.conic_max else ["first-order"]
            for method in methods:
                t0 = time.perf_counter()
                res = pl.place(problem, "D", method=method)
                dt = time.perf_counter() - t0
                print(f"{N:>6} {S:>4} {t_fim:>11.2f} {method:>12} {dt:>16.2f} {res.certified_gap:>14.4g}", flush=True)
    t0 = time.perf_counter()
    rc = subprocess.run([sys.executable, "-m", "shipsense.cli", "check", "S1-P1", "--passages", "8"],
                        capture_output=True, text=True).returncode
    print(f"\n`shipsense check S1-P1 --passages 8`: {time.perf_counter() - t0:.1f} s (exit {rc})")
    t0 = time.perf_counter()
    rc = subprocess.run([sys.executable, "-m", "shipsense.cli", "check", "S1-P2", "--passages", "8"],
                        capture_output=True, text=True).returncode
    print(f"`shipsense check S1-P2 --passages 8`: {time.perf_counter() - t0:.1f} s (exit {rc})")


if __name__ == "__main__":
    main()
