"""A recursive filter's covariance collapse after a batch refit, against the batch fit of the same samples.

Run:  python experiments/filter_collapse.py [--passage 85] [--at 224] [--steps 6]   (about 10 s)

S0 passage 85 of the consistency study (seed 0): the window's fits are
nearly tied and the likelihood is curved (banana-shaped) in position and
moment.  The passage is re-fitted at sample ``at`` (every sample before it);
the script prints, for the next ``steps`` samples, the position standard
deviation (sqrt of the trace) and error of

* the batch fit of every sample so far (``refit_at`` at each sample), and
* the EKF, UKF, CKF and CDKF run from the fit at ``at``.

Each filter step adds the information of one sample, linearised where the
filter's mean is then; the batch fit re-linearises every sample at one
point.  This is why the project's tracker re-fits a bank whose covariance
falls below a quarter of its fit's (``track_with_restarts(collapse=0.25)``).
"""

import argparse

import numpy as np

from shipsense.config import load_scenario
from shipsense.models.field_model import model_from_scenario
from shipsense.reproduce.common import prior_grid
from shipsense.reproduce.studies import track_with_global_init
from shipsense.reproduce.wide import init_options
from shipsense.simulator import simulate
from shipsense.trackers.bank.bank import run_bank
from shipsense.trackers.bank.selection import mixture_mse
from shipsense.trackers.filters import get_filter
from shipsense.trackers.init.global_init import global_init
from shipsense.trackers.tracker.restarts import refit_at


def fit_at_last(model, gi, inv_A, mixture):
    """A refit's estimate (R, n) and position covariance (R, 2, 2) (SI) at its last fitted sample ``gi.start - 1``:
    the best hypothesis, and its covariance or (``mixture``) its mean-square-error matrix under the
    hypotheses' likelihood weights."""
    xs = model.x_scale
    x = np.einsum("ij,rhj->rhi", inv_A, gi.seeds / xs) * xs                             # (R, H, n)
    P = inv_A @ (gi.P0 / np.outer(xs, xs)) @ inv_A.T * np.outer(xs, xs)
    best = np.argmax(gi.loglik, axis=1)
    rows = np.arange(len(best))
    if not mixture:
        return x[rows, best], P[rows, best, :2, :2]
    w = np.exp(gi.loglik - gi.loglik[rows, best][:, None])
    w /= w.sum(axis=1, keepdims=True)
    return x[rows, best], mixture_mse(w, x[..., :2], P[..., :2, :2], x[rows, best][:, None, :2])

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passage", type=int, default=85)
    ap.add_argument("--at", type=int, default=224)
    ap.add_argument("--steps", type=int, default=6)
    args = ap.parse_args(argv)
    sc = load_scenario("S0")
    model = model_from_scenario(sc).without_process_noise()
    sim = simulate(sc, runs=args.passage + 1, seed=0, random=True)
    r = slice(args.passage, args.passage + 1)
    y, truth = sim.measurements[r], model.state_from_truth(sim.truth[r])
    gi = global_init(model, y, **prior_grid(sc), **init_options("one_magnetometer", sc))
    est, _ = track_with_global_init(get_filter("ukf"), model, y, gi)
    ks = np.arange(args.at, args.at + args.steps)

    def sd(P):
        return np.sqrt(P[..., 0, 0] + P[..., 1, 1])

    print(f"S0 passage {args.passage}, window {int(gi.k0[0])}..{int(gi.start[0]) - 1}, refit at {args.at}")
    print(f"{'':>10}" + "".join(f"{k:>14}" for k in ks))
    rows = {"batch fit": []}
    inv_A = np.linalg.inv(model.A)
    for k in ks:   # the fit of samples up to k, at k (the refit for a bank from k + 1, at its last sample)
        x, P = fit_at_last(model, refit_at(model, y, gi, est, np.array([k + 1])), inv_A, mixture=False)
        rows["batch fit"].append((sd(P[0]), np.hypot(*(x[0, :2] - truth[0, k, :2]))))
    fit = refit_at(model, y, gi, est, np.array([args.at]))
    for name in ("ekf", "ukf", "ckf", "cdkf"):
        b = run_bank(get_filter(name), model, y[:, ks], fit.seeds, fit.P0)
        rows[name] = list(zip(sd(b.pos_cov[0, 0]), np.hypot(*(b.means[0, 0, :, :2] - truth[0, ks, :2]).T)))
    print(f"{'':>10}" + f"{'prior (fit)':>14}" + f"  sd {sd(fit.P0[0, 0]):.2f} m")
    for name, vals in rows.items():
        print(f"{name:>10}" + "".join(f"{s:6.2f} ({e:4.1f})" for s, e in vals))
    print("(position standard deviation, m, and in brackets the error, m)")


if __name__ == "__main__":
    main()
