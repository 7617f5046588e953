"""The certificate of small designs: the exact search over subsets on the S1-P2 400-candidate set, k = 3 and 4.

Run:  python benchmarks/design_certificate.py [--side 20] [--passages 8] [--ks 3 4]

The problem is what ``shipsense design S1-P2 --k K --candidates GRID.csv`` builds (the S1-P2 template, envelope
electrodes, a square grid of ``side`` x ``side`` candidates 120 m across at the sensors' depth, 8 prior
passages, seed 0).  For each k it prints the relaxation's own guaranteed efficiency, then the search's: its
method, whether it completed, the work it did, the proved bound, the guaranteed efficiency and the seconds it
took (the search alone; on this machine, with whatever else runs on it).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from shipsense import load_scenario, tune_allocator
from shipsense.design import placement as pl
from shipsense.models.field_model import candidate_model
from shipsense.simulator import sample_passages
from shipsense.trackers.tracker.settings import resolve_settings


def grid(side, half=60.0, z=-15.0):
    xs = np.linspace(-half, half, side)
    pts = np.stack(np.meshgrid(xs, xs), -1).reshape(-1, 2)
    return np.column_stack([pts, np.full(len(pts), z)])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--side", type=int, default=20)
    ap.add_argument("--passages", type=int, default=8)
    ap.add_argument("--ks", type=int, nargs="+", default=[3, 4])
    args = ap.parse_args(argv)
    tune_allocator()
    sc = load_scenario("S1-P2")
    cands = grid(args.side)
    model = candidate_model(sc, cands)
    thetas = model.to_internal(model.state_from_truth(sample_passages(sc, args.passages, seed=0, random=True)))
    prior_std = model.to_internal(resolve_settings(sc).bank.state_std(model.labels))
    pl.place(pl.build_problem(candidate_model(sc, cands[:8]), thetas, sc.steps, 3, prior_std), bb_work=None)  # compile
    print(f"{'N':>5} {'k':>2} {'relaxation eff.':>16} {'method':>62} {'complete':>9} {'work':>11} {'bound':>9} "
          f"{'value':>9} {'guar. eff.':>10} {'search [s]':>10}")
    for k in args.ks:
        problem = pl.build_problem(model, thetas, sc.steps, k, prior_std)
        relax = pl.place(problem, "D")
        t0 = time.perf_counter()
        res = pl.place(problem, "D", bb_work=None)
        b = res.branch_and_bound
        print(f"{len(cands):>5} {k:>2} {relax.guaranteed_efficiency:>16.3f} {b['method']:>62} {b['complete']!s:>9} "
              f"{b['work']:>11,} {res.upper_bound:>9.3f} {res.value:>9.3f} {res.guaranteed_efficiency:>10.4f} "
              f"{b['seconds']:>10.1f}   (place {time.perf_counter() - t0:.1f} s)", flush=True)


if __name__ == "__main__":
    main()
