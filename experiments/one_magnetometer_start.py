"""When should the tracker start on one magnetometer?  The detection SNR against convergence and coverage.

Run:  python experiments/one_magnetometer_start.py [--snr 400 50 25] [--passages 300] [--seed 0] [--faulty]

On random S0 passages (one vector magnetometer; 30 s recordings, so many
passages end before their closest approach), for each detection threshold
``snr_start`` the project's tracker (:class:`shipsense.trackers.Tracker`,
otherwise its defaults) is run and reported: convergence (error below 10 m
over the last 10 % of each passage), separately for the passages whose
closest approach lies inside the recording and the others, and the share of
post-convergence samples inside the reported 95 % ellipse (as
``experiments/tracker_consistency.py`` counts it).  For the first threshold
it also prints the position CRLB (no process noise, the passage prior as the
prior) at the last sample of each passage that fails, and at the first
sample of its last 10 % (where convergence starts being judged), with its
error there: small bounds mean the data held the answer and the tracker
missed it, large ones that no tracker could converge.
"""

from __future__ import annotations

import argparse

import numpy as np

from shipsense import load_scenario, simulate
from shipsense.design.fisher import pcrlb
from shipsense.trackers import Tracker
from shipsense.trackers.metrics import (
    CRLB_SD_LIMIT_M,
    converged_until,
    convergence_allowed,
    crlb_sd,
    judged_sample,
    nees,
    passage_ends,
)

FAULTY = {"model": "contaminated", "eps": 0.2, "outlier_scale": 10.0, "dropout": 0.3}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--snr", type=float, nargs="+", default=[400.0, 50.0, 25.0])
    ap.add_argument("--passages", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--faulty", action="store_true", help="20 %% outliers of 10 std and 30 %% dropouts")
    args = ap.parse_args(argv)
    sc = load_scenario("S0")
    if args.faulty:
        sc = sc.with_updates(noise=FAULTY)
    N = args.passages
    sim = simulate(sc, runs=N, seed=args.seed, random=True)
    for i, snr in enumerate(args.snr):
        tr = Tracker(sc, passages=N, snr_start=snr)
        res = tr.track(sim.times, sim.measurements)
        model = tr.model
        truth = model.state_from_truth(sim.truth)
        c = model.array.positions[:, :2].mean(axis=0)
        ends = passage_ends(truth, c, sc.period)
        conv, err, valid = converged_until(res.estimates, truth, ends)
        K = truth.shape[1]
        k = np.arange(K)[None]
        dist = np.hypot(truth[..., 0] - c[0], truth[..., 1] - c[1])
        approach = np.argmin(dist, axis=1) < K - 1
        above = np.where(valid, err >= 10.0, False)
        settled = np.where(above.any(axis=1), K - np.argmax(above[:, ::-1], axis=1), 0)
        post = valid & conv[:, None] & (k >= settled[:, None]) & (res.status >= 2)
        q = nees(res.estimates, res.covs, truth)
        print(f"snr_start {snr:g}: converged {conv.mean():.3f} (approaching {conv[approach].mean():.3f} of "
              f"{approach.sum()}, the others {conv[~approach].mean():.3f}); inside the 95 % ellipse after "
              f"convergence {np.mean(q[post] <= 5.991):.3f}", flush=True)
        if i == 0 and (~conv).any():
            J0 = np.diag(model.x_scale ** 2 / np.diag(tr._prior[1]))
            b = pcrlb(model, model.to_internal(truth), J0, per_run=True, Q=np.zeros_like(model.Q))
            block = model.cov_to_si(b)[..., :2, :2]
            sd = crlb_sd(block)                      # along the bound's larger axis (the metrics module's rule)
            f = np.flatnonzero(~conv)
            sd_end = sd[f, ends[f]]
            print(f"  its {f.size} failures: position CRLB sd at their last sample median {np.median(sd_end):.2f} m, "
                  f"{np.mean(sd_end < 5.0):.2f} of them under 5 m; {np.mean(~approach[f]):.2f} of them end before "
                  f"their closest approach; samples tracked before the end (median) "
                  f"{np.median([(res.status[p, :ends[p] + 1] >= 2).sum() for p in f]):.0f}")
            # convergence asks for an error below 10 m over the last 10 % of the passage: the CRLB at the first
            # of those samples says whether the data allowed it (metrics.convergence_allowed)
            w0 = judged_sample(ends)
            sd_w0 = sd[np.arange(N), w0]
            allowed = convergence_allowed(block[np.arange(N), w0])
            print(f"  position CRLB sd at the first sample of the last 10 %: the passages that end before their "
                  f"closest approach median {np.median(sd_w0[~approach]):.2f} m, {np.mean(~allowed[~approach]):.2f} "
                  f"of them above {CRLB_SD_LIMIT_M:.2f} m (of {(~approach).sum()})")
            for p in f:
                ks = np.arange(w0[p], ends[p] + 1)
                out = ks[err[p, ks] >= 10.0]
                last = out.max()
                print(f"    passage {p}: {dist[p, w0[p]]:.0f} m out at sample {w0[p]}, CRLB sd {sd_w0[p]:.1f} m there "
                      f"and {sd[p, ends[p]]:.1f} m at the end; error {err[p, w0[p]]:.1f} m, >= 10 m on {out.size} of "
                      f"the last {ks.size} samples, the last at {last} (CRLB sd {sd[p, last]:.1f} m, reported "
                      f"{np.sqrt(np.trace(res.position_cov[p, last])):.1f} m); {tr.state.restarts[p]} restarts")

if __name__ == "__main__":
    main()
