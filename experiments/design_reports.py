"""The design report of `shipsense design` for S0, S1-P2 and S2 (k = 3, the default candidate grid), as a table.

Run:  python experiments/design_reports.py [--k 3] [--passages 8] [--out results/design]

Each scenario is designed exactly as `shipsense design SCENARIO --k K` does
(default 11 x 11 candidate grid around the array, 8 prior passages, solver
auto, ambiguity cuts, the search over subsets for k <= 4 stopped on its work) and its files
are written to OUT/SCENARIO/; the table (markdown) gives the criterion, the
certified bound, the design's value, the guaranteed efficiency, the solver,
the time, the verdict and the baselines' efficiency relative to the design.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from shipsense import load_scenario, tune_allocator
from shipsense.design.designer import design_array, write_design


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--k", type=int, default=3)
    ap.add_argument("--passages", type=int, default=8)
    ap.add_argument("--scenarios", nargs="+", default=["S0", "S1-P2", "S2"])
    ap.add_argument("--out", default="results/design")
    args = ap.parse_args(argv)
    tune_allocator()
    rows = []
    for name in args.scenarios:
        res = design_array(load_scenario(name), args.k, passages=args.passages)
        write_design(res, Path(args.out) / name)
        r, b = res.placement, res.baselines
        bb = r.branch_and_bound
        rows.append(f"| {name} | {res.criterion} | {r.upper_bound:.2f} | {r.value:.2f} | "
                    f"{r.guaranteed_efficiency:.3f} | "
                    f"{r.solver}{' + search ' + ('complete' if bb['complete'] else 'stopped') if bb else ''} | "
                    f"{res.timings['total']:.1f} | {r.verdict.verdict if r.verdict else '-'} | "
                    + " / ".join(f"{b[key]['efficiency_vs_design']:.3f}"
                                 for key in ("best_of_1000_random", "line", "triangle")) + " |")
        print(rows[-1], flush=True)
    print()
    print("| scenario | criterion | certified bound | design value | guaranteed efficiency | solver | time [s] "
          "| verdict | baselines: random best of 1000 / line / triangle (efficiency vs the design) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
