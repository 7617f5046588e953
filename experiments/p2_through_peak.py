"""P2 wide-prior family: the global initialiser's batch fit over its window only, or continued
through the closest approach (``global_init(..., through_peak=0.5)``), same passages.

Run:  python experiments/p2_through_peak.py [--runs 200] [--seed 0] [--through-peak 0.5]

Prints, for both variants, the wide study's metrics (convergence, MRMSE_r, RMSE over the
bounds, NEES over the bank's samples) and the initialiser's seconds per passage, beside the
studies' 12-hypothesis bank's seconds per passage on the same passages.
"""

import argparse
import time

from shipsense.reproduce import wide
from shipsense.reproduce.common import track_global
from shipsense.trackers.bank.bank import run_bank
from shipsense.trackers.bank.seeding import seed_hypotheses


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--through-peak", type=float, default=0.5)
    args = ap.parse_args(argv)
    name = "envelope_p2"
    sc, model, unit, y, truth, ends = wide.family_passages(name, args.runs, args.seed)
    seeds, P0 = seed_hypotheses(model, y[:, 0], sc.tracker.bank)
    t0 = time.perf_counter()
    run_bank(unit, model, y, seeds, P0)
    print(f"12-hypothesis bank: {(time.perf_counter() - t0) / args.runs:.3f} s per passage")
    bounds = wide.position_bounds(model, truth, P0)
    for label, peak in (("window only", None), (f"through the peak ({args.through_peak})", args.through_peak)):
        t0 = time.perf_counter()
        est, pos_cov, t_init = track_global(unit, model, y, sc, **wide.init_options(name, sc), through_peak=peak)
        m = wide.method_row(est, pos_cov, truth, bounds, (time.perf_counter() - t0) / args.runs, ends)
        shown = ", ".join(f"{k} {v:.3g}" for k, v in m.items() if v is not None)
        print(f"{label}: initialiser {t_init / args.runs:.3f} s per passage; {shown}")


if __name__ == "__main__":
    main()
