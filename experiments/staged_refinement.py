"""The global initialiser's chi-square test and staged refinement on S0's single magnetometer.

Run:  python experiments/staged_refinement.py [--runs 100] [--seed 0] [--gof 0.01] [--refine '5;20,60@15']
      (about 2 minutes for 100 with the default settings)

S0's passages (the consistency study's, SNR-400 window) are initialised with
``refine`` = 5 (one stage), 20 and 60 for every passage, and in stages
(5, 20, 60): later stages only for the passages whose best fit fails the
chi-square test.  For each it prints how many best fits fail the test, how
many are more than 10 m off at the bank's start (and of those, how many pass
the test), how many miss the window's global minimum (best chi-square more
than 2 above that of a fit started at the truth), the best fits' position
NEES there with the fit's own covariance (not inflated, no process noise
added; mean and median) and the initialiser's time.  A setting ``20,60@15``
explores the grid minima on about 15 samples of the window
(``explore_samples``) and polishes the kept fits on all of them.  A fit
that passes the test and is far off should say so in its covariance; one
that fails it has not explained the data.
"""

import argparse
import time

import numpy as np

from shipsense.config import load_scenario
from shipsense.models.field_model import model_from_scenario
from shipsense.simulator import simulate
from shipsense.trackers.fit.least_squares import fit_passages
from shipsense.trackers.init.global_init import global_init
from shipsense.trackers.metrics import nees


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--gof", type=float, default=0.01, help="level of the chi-square test (default 0.01)")
    ap.add_argument("--refine", default="5;20;60;5,20,60;20,60@15;60@15",
                    help="refine settings, ';'-separated (counts, optionally @explore_samples)")
    args = ap.parse_args(argv)
    sc = load_scenario("S0")
    model = model_from_scenario(sc).without_process_noise()   # P0: the fit's own covariance, propagated
    sim = simulate(sc, runs=args.runs, seed=args.seed, random=True)
    y, truth = sim.measurements, model.state_from_truth(sim.truth)
    grid = dict(ranges=np.geomspace(20.0, 1.2 * sc.prior.range[1], 8), speeds=np.linspace(*sc.prior.speed, 3),
                snr_start=400.0, inflate=1.0, gof=args.gof)
    r = np.arange(args.runs)
    print(f"S0, {args.runs} passages (seed {args.seed}), test at {args.gof}; best fit at the bank's start")
    print(f"{'refine':>14}  {'fail test':>9}  {'> 10 m':>6}  {'of them pass':>12}  {'miss':>4}  {'NEES mean':>9}  "
          f"{'median':>6}  {'seconds':>7}")
    floor = None
    for spec in args.refine.split(";"):
        counts, _, explore = spec.partition("@")
        refine = tuple(int(v) for v in counts.split(","))
        refine = refine[0] if len(refine) == 1 else refine
        t0 = time.perf_counter()
        gi = global_init(model, y, refine=refine, explore_samples=int(explore) if explore else None, **grid)
        seconds = time.perf_counter() - t0
        if floor is None:   # every setting has the same windows: the fit started at the truth on each
            W = int((gi.start - gi.k0).max())
            ks = gi.k0[:, None] + np.arange(W)
            yw = np.where((ks < gi.start[:, None])[..., None],
                          y[r[:, None], np.minimum(ks, y.shape[1] - 1)] / model.y_scale, np.nan)
            _, floor = fit_passages(model, yw, truth[r, gi.k0] / model.x_scale, W)
        miss = int(np.sum(-2 * gi.loglik.max(axis=1) > floor + 2.0))
        b = np.argmax(gi.loglik, axis=1)
        x, P, t = gi.seeds[r, b], gi.P0[r, b], truth[r, gi.start]
        far = np.hypot(*(x[:, :2] - t[:, :2]).T) > 10.0
        q = nees(x, P, t)
        print(f"{spec:>14}  {int((~gi.fit_ok).sum()):>9}  {int(far.sum()):>6}  "
              f"{int((far & gi.fit_ok).sum()):>12}  {miss:>4}  {q.mean():>9.3g}  {np.median(q):>6.2f}  {seconds:>7.1f}")


if __name__ == "__main__":
    main()
