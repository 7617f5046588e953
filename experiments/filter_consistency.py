"""Consistency (NEES) of every filter unit on S0, started inside the convergence basin.

Run:  python experiments/filter_consistency.py [--runs 200] [--offset 10] [--out results/consistency]

Each filter starts 10 m (``--offset``) from the true position in a random
direction, with the true velocity and a zero moment (covariance: 20 m, 1 m/s,
1e8 A·m² standard deviations), and tracks the S0 passage for every process
noise setting below.  For each it reports the position RMSE over the second
half of the passage and the run-averaged position NEES over the same steps,
against the two-sided 95 % chi-square band of that average (2 degrees of
freedom, ``runs`` runs).  Writes ``consistency.csv`` and ``consistency.json``
to ``--out`` and prints a table.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy import stats

from shipsense import load_scenario, simulate
from shipsense.config import ProcessNoiseConfig
from shipsense.models.field_model import model_from_scenario
from shipsense.trackers.filters import FILTER_NAMES
from shipsense.trackers.filters.run import run_filter
from shipsense.trackers.metrics import nees, position_error

SETTINGS = {
    "study: Q = 0.1 I": ProcessNoiseConfig(model="identity", sigma_q=0.1),
    "dwna 0.05, moment 1e8": ProcessNoiseConfig(model="dwna", sigma_a=(0.05, 0.05), param_var=[1e8] * 3),
    "dwna 0.2, moment 1e10": ProcessNoiseConfig(model="dwna", sigma_a=(0.2, 0.2), param_var=[1e10] * 3),
    "dwna 0.5, moment 1e11": ProcessNoiseConfig(model="dwna", sigma_a=(0.5, 0.5), param_var=[1e11] * 3),
    "dwna 1.0, moment 5e11": ProcessNoiseConfig(model="dwna", sigma_a=(1.0, 1.0), param_var=[5e11] * 3),
    "default: dwna 1.0, moment 6e11": ProcessNoiseConfig(model="dwna", sigma_a=(1.0, 1.0), param_var=[6e11] * 3),
}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--offset", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="results/consistency")
    args = ap.parse_args(argv)
    sc = load_scenario("S0")
    sim = simulate(sc, runs=args.runs, seed=args.seed)
    truth = sim.truth[..., [0, 1, 2, 3, 5, 6, 7]]
    rng = np.random.default_rng(args.seed + 1)
    ang = rng.uniform(0, 2 * np.pi, args.runs)
    x0 = truth[:, 0].copy()
    x0[:, 0] += args.offset * np.cos(ang)
    x0[:, 1] += args.offset * np.sin(ang)
    x0[:, 4:] = 0.0
    P0 = np.diag([400.0, 400.0, 1.0, 1.0, 1e16, 1e16, 1e16])
    half = sc.steps // 2
    lo, hi = (stats.chi2.ppf(q, 2 * args.runs) / args.runs for q in (0.025, 0.975))
    rows = []
    print(f"S0, {args.runs} runs, start {args.offset:g} m off; position NEES 95% band for the run average: "
          f"[{lo:.2f}, {hi:.2f}]")
    print(f"{'process noise':<32}{'filter':<11}{'RMSE [m]':>9}{'NEES':>10}{'consistent':>11}")
    for label, pn in SETTINGS.items():
        model = model_from_scenario(sc, process_noise=pn)
        for name in FILTER_NAMES:
            run = run_filter(name, model, sim.measurements, x0, P0)
            err = position_error(run.means, truth)[:, half:]
            rmse = float(np.sqrt(np.mean(err**2)))
            avg = nees(run.means, run.covs, truth).mean(axis=0)[half:]   # run average per step
            mean_nees = float(avg.mean())
            inside = float(np.mean((avg >= lo) & (avg <= hi)))
            ok = lo <= mean_nees <= hi
            rows.append(dict(process_noise=label, filter=name, rmse_m=rmse, nees_mean=mean_nees,
                             fraction_of_steps_in_band=inside, consistent=bool(ok)))
            print(f"{label:<32}{name:<11}{rmse:>9.2f}{mean_nees:>10.2f}{'yes' if ok else 'no':>11}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "consistency.csv", "w") as fh:
        fh.write(",".join(rows[0]) + "\n")
        for r in rows:
            fh.write(",".join(str(v) for v in r.values()) + "\n")
    (out / "consistency.json").write_text(json.dumps({"band": [lo, hi], "rows": rows}, indent=2))
    print(f"wrote {out / 'consistency.csv'}")


if __name__ == "__main__":
    main()
