"""Filter-unit benchmark: microseconds per filter-step on the S0 magnetic model.

Run:  python benchmarks/filters.py [--steps 20] [--batches 1 12 240 2400]

A filter-step is one predict plus one update of one hypothesis.  Every unit
runs as one batch of B hypotheses; the baseline is FilterPy's
UnscentedKalmanFilter looped over filters (one Python object per hypothesis),
timed in the same process on the same measurements.  The table prints
microseconds per filter-step and the speed-up over the FilterPy loop.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

from shipsense import simulate, tune_allocator
from shipsense.trackers.filters import FILTER_NAMES, Belief, get_filter
from shipsense.trackers.models import model_from_scenario


def setup(batch):
    sim = simulate("S0", runs=1, seed=0)
    model = model_from_scenario("S0")
    y = sim.measurements[0] / model.y_scale                       # (steps, m) internal units
    truth = model.to_internal(sim.truth[0, 0, [0, 1, 2, 3, 5, 6, 7]])
    rng = np.random.default_rng(0)
    x0 = truth + rng.normal(0, 1, (batch, model.n)) * np.array([10, 10, 0.5, 0.5, 5, 5, 5])
    P0 = np.diag([100.0, 100.0, 1.0, 1.0, 100.0, 100.0, 100.0])
    return model, y, x0, P0


def time_batched(name, batch, steps, repeats=3):
    model, y, x0, P0 = setup(batch)
    unit = get_filter(name)
    best = np.inf
    for _ in range(repeats):
        belief = Belief.from_cov(x0, np.broadcast_to(P0, (batch, model.n, model.n)))
        belief, _ = unit.update(belief, y[0], model)
        t0 = time.perf_counter()
        for k in range(1, steps + 1):
            belief = unit.predict(belief, model)
            belief, _ = unit.update(belief, y[k], model)
        best = min(best, time.perf_counter() - t0)
    return 1e6 * best / (steps * batch)


def time_filterpy(n_filters, steps):
    model, y, x0, P0 = setup(n_filters)
    points = MerweScaledSigmaPoints(model.n, alpha=1.0, beta=2.0, kappa=0.0)
    sensor = model.array.positions[0]
    z = model.source_z

    def hx(x):  # a lean single-point measurement function (nT), as a FilterPy user would write it
        r = sensor - np.array([x[0], x[1], z])
        m = x[4:7] * model.moment_unit
        r2 = r @ r
        return 1e-7 * (3.0 * (m @ r) * r - r2 * m) / r2**2.5 / 1e-9

    A = model.A
    filters = []
    for i in range(n_filters):
        f = UnscentedKalmanFilter(model.n, model.m, model.period, hx=hx, fx=lambda x, dt: A @ x, points=points)
        f.x, f.P, f.Q, f.R = x0[i].copy(), P0.copy(), model.Q.copy(), np.diag(model.R)
        filters.append(f)
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        for f in filters:
            f.predict()
            f.update(y[k])
    return 1e6 * (time.perf_counter() - t0) / (steps * n_filters)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--batches", type=int, nargs="+", default=[1, 12, 240, 2400])
    ap.add_argument("--allocator", choices=("tuned", "default"), default="tuned",
                    help="tuned: shipsense.tune_allocator() as the shipsense command does; default: glibc's")
    ap.add_argument("--filterpy-filters", type=int, default=24, help="filters in the FilterPy loop")
    args = ap.parse_args(argv)
    tuned = args.allocator == "tuned" and tune_allocator()
    print(f"allocator: {'tuned (shipsense.tune_allocator)' if tuned else 'default'}")
    base = time_filterpy(args.filterpy_filters, args.steps)
    print(f"S0 model (n=7, m=3); FilterPy UKF loop: {base:.1f} us per filter-step "
          f"({args.filterpy_filters} filters x {args.steps} steps)\n")
    head = "".join(f"{f'B={b}':>18}" for b in args.batches)
    print(f"{'filter':<10}{head}")
    for name in FILTER_NAMES:
        cells = []
        for b in args.batches:
            us = time_batched(name, b, args.steps)
            cells.append(f"{us:>9.2f} ({base / us:>5.0f}x)")
        print(f"{name:<10}" + "".join(f"{c:>18}" for c in cells))
    print("\ncells: microseconds per filter-step (speed-up over the FilterPy loop)")


if __name__ == "__main__":
    main()
