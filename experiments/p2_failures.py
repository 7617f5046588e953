"""Where the global initialiser's P2 failures come from: the same passages with the initialiser's
envelope options switched on one at a time, and what the remaining failures look like.

Run:  python experiments/p2_failures.py [--runs 200] [--seed 0]     (about 3 minutes for 200)

Every passage's bank starts from its own window (``track_with_global_init`` aligns them).  The
variants: no depth prior and five refined grid minima (the first version's initialiser); the bank's
depth prior (``z_std``); and the wide study's staged refinement on top (``refine=(10, 30, 60)``).
For every failure it prints the best fit's chi-square and depth and the best seed's error: a failed
fit (chi-square far above the number of samples) or a good fit the bank then loses.
"""

import argparse

import numpy as np

from shipsense.reproduce import wide
from shipsense.reproduce.common import track_global
from shipsense.trackers.init.global_init import global_init


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    name = "envelope_p2"
    sc, model, unit, y, truth, ends = wide.family_passages(name, args.runs, args.seed)
    full = wide.init_options(name, sc)
    variants = {"first version (no depth prior, 5 refined)": {"snr_start": full["snr_start"]},
                "depth prior": {"snr_start": full["snr_start"], "z_std": full["z_std"]},
                "depth prior + staged refinement (study)": full}
    grid = dict(ranges=np.geomspace(20.0, 1.2 * sc.prior.range[1], 8), speeds=np.linspace(*sc.prior.speed, 3))
    iz = model.labels.index("z")
    for label, opts in variants.items():
        est, _, _ = track_global(unit, model, y, sc, **opts)
        fail = np.flatnonzero(~wide.converged(est, truth, ends)[0])
        print(f"{label}: {1 - fail.size / args.runs:.3f} converged, failures {fail.tolist()}")
        if fail.size:
            gi = global_init(model, y[fail], **grid, **opts)
            b = np.argmax(gi.loglik, axis=1)
            seed = gi.seeds[np.arange(fail.size), b]
            err = np.hypot(*(seed[:, :2] - truth[fail, gi.start, :2]).T)
            for i, r in enumerate(fail):
                print(f"  passage {r}: window from sample {gi.k0[i]}, best fit chi2 {-2 * gi.loglik[i, b[i]]:.3g} "
                      f"over {(gi.start[i] - gi.k0[i]) * model.m} values, depth {seed[i, iz]:.2f} m "
                      f"(true {truth[r, 0, iz]:.2f}), seed error {err[i]:.2f} m")


if __name__ == "__main__":
    main()
