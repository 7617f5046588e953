"""Design benchmark: `shipsense design` end to end at site scale, and the relaxation solvers against N and S.

Run:  python benchmarks/design.py                      # end to end: N = 1600, S = 32, k = 6 and k = 32
      python benchmarks/design.py --ks 32 --side 100   # N = 10,000 candidates
      python benchmarks/design.py --relaxation          # solve + rounding only, CLARABEL vs first-order

End to end is what the command does (the S1-P2 template, envelope
electrodes, on a square grid of ``side`` x ``side`` candidates 120 m
across, 32 prior passages, ambiguity cuts on): the Fisher matrices, the
relaxation and rounding with the exchange search, the ambiguity check, the
baselines and the report files (written to a temporary folder), timed per
stage; imports and the FastHED table are built once before timing.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from shipsense import load_scenario, tune_allocator
from shipsense.design import placement as pl
from shipsense.design.designer import design_array, write_design
from shipsense.models.field_model import candidate_model
from shipsense.simulator import sample_passages


def grid(side, half=60.0, z=-15.0):
    xs = np.linspace(-half, half, side)
    pts = np.stack(np.meshgrid(xs, xs), -1).reshape(-1, 2)
    return np.column_stack([pts, np.full(len(pts), z)])


def end_to_end(args):
    sc = load_scenario("S1-P2")
    cands = grid(args.side)
    design_array(sc, 3, candidates=cands[:9], passages=1, cuts=False, random_layouts=10)   # warm-up (FastHED table)
    print(f"{'N':>6} {'k':>4} {'S':>4} {'fisher':>7} {'solve+round':>12} {'ambiguity':>10} {'baselines':>10} "
          f"{'write':>6} {'total [s]':>10} {'solver':>19} {'gap':>7} {'guar. eff.':>10} {'verdict':>11}")
    for k in args.ks:
        t0 = time.perf_counter()
        res = design_array(sc, k, candidates=cands, passages=args.passages, seed=0, solver=args.solver,
                           cuts=not (args.no_cuts or args.no_check), check=not args.no_check)
        t1 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            write_design(res, Path(tmp) / "design")
        t2 = time.perf_counter()
        t, r = res.timings, res.placement
        verdict = r.verdict.verdict if r.verdict is not None else "-"
        print(f"{len(cands):>6} {k:>4} {args.passages:>4} {t['fisher']:>7.1f} {t['relaxation_and_rounding']:>12.1f} "
              f"{t['ambiguity_check'] or float('nan'):>10.1f} {t['baselines']:>10.1f} {t2 - t1:>6.1f} {t2 - t0:>10.1f} "
              f"{r.solver:>19} {r.certified_gap:>7.3f} {r.guaranteed_efficiency:>10.3f} {verdict:>11}",
              flush=True)


def relaxation(args):
    sc = load_scenario("S1-P2")
    print(f"{'N':>6} {'S':>4} {'fisher [s]':>11} {'solver':>19} {'solve+round [s]':>16} {'certified gap':>14}")
    for N in args.sizes:
        cands = grid(int(np.ceil(np.sqrt(N))))[:N]
        model = candidate_model(sc, cands)
        for S in args.samples:
            thetas = model.to_internal(model.state_from_truth(sample_passages(sc, S, seed=1)))
            prior = model.to_internal(np.array([30.0, 30.0, 2.0, 2.0, 1.0, 50.0]))
            t0 = time.perf_counter()
            problem = pl.build_problem(model, thetas, sc.steps, 6, prior)
            t_fim = time.perf_counter() - t0
            for method in (["clarabel", "first-order"] if N <= args.conic_max else ["first-order"]):
                t0 = time.perf_counter()
                res = pl.place(problem, "D", method=method)
                dt = time.perf_counter() - t0
                print(f"{N:>6} {S:>4} {t_fim:>11.2f} {res.solver:>19} {dt:>16.2f} {res.certified_gap:>14.4g}",
                      flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ks", type=int, nargs="+", default=[6, 32])
    ap.add_argument("--side", type=int, default=40, help="candidate grid side (default 40: N = 1600)")
    ap.add_argument("--passages", type=int, default=32)
    ap.add_argument("--solver", default="auto")
    ap.add_argument("--no-cuts", action="store_true")
    ap.add_argument("--no-check", action="store_true", help="no ambiguity check (nor cuts): time the rest")
    ap.add_argument("--relaxation", action="store_true", help="the solver table instead of end to end")
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 400, 1600])
    ap.add_argument("--samples", type=int, nargs="+", default=[8, 32])
    ap.add_argument("--conic-max", type=int, default=400, help="largest N solved with CLARABEL in --relaxation")
    args = ap.parse_args(argv)
    tune_allocator()
    (relaxation if args.relaxation else end_to_end)(args)


if __name__ == "__main__":
    main()
