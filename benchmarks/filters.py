"""Filter-unit benchmark: microseconds per filter-step on the S0 magnetic model, against FilterPy, in one run.

Run:  PYTHONPATH=. python benchmarks/filters.py [--steps 20] [--batches 1 24 2400] [--no-numpy] [--no-compile]
                                                [--no-reproduce] [--allocator tuned|default]

A filter-step is one predict plus one update of one hypothesis.  Every unit
runs as one batch of B hypotheses, through ``FilterUnit`` (the compiled steps
of :mod:`shipsense.trackers.filters.fused` on this model) and, for comparison,
through the numpy steps of the filter modules (the generic path every model
without a compiled kernel runs).  The baseline is FilterPy's
UnscentedKalmanFilter looped over filters (one Python object per hypothesis),
timed in the same process on the same measurements; every cell prints
microseconds per filter-step and the speed-up over that loop.

Then, each in a fresh process: the compiled steps' first-call time with an
empty numba cache (compilation) and with the cache this checkout keeps
(loading), and ``shipsense reproduce S0`` (200 runs) wall time and peak memory.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

from shipsense import simulate, tune_allocator
from shipsense.models.field_model import model_from_scenario
from shipsense.trackers.filters import FILTER_NAMES, UPDATES, Belief, get_filter, predict


def setup(batch):
    sim = simulate("S0", runs=1, seed=0)
    model = model_from_scenario("S0")
    y = sim.measurements[0] / model.y_scale                       # (steps, m) internal units
    truth = model.to_internal(sim.truth[0, 0, [0, 1, 2, 3, 5, 6, 7]])
    rng = np.random.default_rng(0)
    x0 = truth + rng.normal(0, 1, (batch, model.n)) * np.array([10, 10, 0.5, 0.5, 5, 5, 5])
    P0 = np.diag([100.0, 100.0, 1.0, 1.0, 100.0, 100.0, 100.0])
    return model, y, x0, P0


class NumpyUnit:
    """A filter unit that always runs the numpy steps (what models without a compiled kernel get)."""

    def __init__(self, name):
        self.name = name

    def predict(self, belief, model):
        return predict(belief, model, square_root=self.name == "srcdkf")

    def update(self, belief, y, model):
        return UPDATES[self.name](belief, y, model, None)


def time_batched(unit, batch, steps, repeats=3):
    model, y, x0, P0 = setup(batch)
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


def time_filterpy(n_filters, steps, repeats=3):
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
    best = np.inf
    for _ in range(repeats):
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
        best = min(best, time.perf_counter() - t0)
    return 1e6 * best / (steps * n_filters)


FIRST_CALL = """
import time
t0 = time.perf_counter()
import numpy as np
from shipsense.trackers.filters import FILTER_NAMES, Belief, get_filter
from shipsense.models.field_model import model_from_scenario
model = model_from_scenario("S0")
t1 = time.perf_counter()
b = Belief.from_cov(np.ones((2, 7)), np.eye(7))
each = []
for name in FILTER_NAMES:
    u = get_filter(name)
    t2 = time.perf_counter()
    u.update(u.predict(b, model), np.ones((2, 3)), model)
    each.append(f"{name}={time.perf_counter() - t2:.1f}")
print(" ".join(each))
print(time.perf_counter() - t1)
"""


def first_call_seconds(cache_dir=None):
    """Seconds of the first predict + update of every unit in a fresh process (imports excluded), in all and
    per unit in the order they ran (``"ukf=11.0 ekf=15.1 ..."``: each unit compiles its own update)."""
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    out = subprocess.run([sys.executable, "-c", FIRST_CALL], env=env, capture_output=True, text=True, check=True)
    each, total = out.stdout.strip().splitlines()[-2:]
    return float(total), each


REPRODUCE = """
import sys, time
from shipsense.cli import main
t0 = time.perf_counter()
code = main(["reproduce", "S0", "--out", sys.argv[1]])
hwm = [line.split()[1] for line in open("/proc/self/status") if line.startswith("VmHWM:")]
print(time.perf_counter() - t0, int(hwm[0]) / 1024 if hwm else float("nan"), code)
"""
# the peak is the process's VmHWM: its ru_maxrss would include the benchmark process's pages, which the kernel
# carries across the exec of a child started from it


def reproduce_s0():
    """``shipsense reproduce S0`` in a fresh process: (wall seconds, peak resident MB)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run([sys.executable, "-c", REPRODUCE, os.path.join(tmp, "S0")], capture_output=True,
                             text=True, check=True)
    seconds, mb, code = out.stdout.strip().splitlines()[-1].split()
    if code != "0":
        raise RuntimeError(f"reproduce S0 exited {code}")
    return float(seconds), float(mb)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--batches", type=int, nargs="+", default=[1, 24, 2400])
    ap.add_argument("--allocator", choices=("tuned", "default"), default="tuned",
                    help="tuned: shipsense.tune_allocator() as the shipsense command does; default: glibc's")
    ap.add_argument("--filterpy-filters", type=int, default=24, help="filters in the FilterPy loop")
    ap.add_argument("--no-numpy", action="store_true", help="skip the numpy-path rows")
    ap.add_argument("--no-compile", action="store_true", help="skip the first-call (compile) measurement")
    ap.add_argument("--no-reproduce", action="store_true", help="skip `reproduce S0`")
    args = ap.parse_args(argv)
    tuned = args.allocator == "tuned" and tune_allocator()
    print(f"allocator: {'tuned (shipsense.tune_allocator)' if tuned else 'default'}")
    for name in FILTER_NAMES:      # compile or load the compiled steps before timing
        time_batched(get_filter(name), 2, 1, repeats=1)
    base = time_filterpy(args.filterpy_filters, args.steps)
    print(f"S0 model (n=7, m=3); FilterPy UKF loop: {base:.1f} us per filter-step "
          f"({args.filterpy_filters} filters x {args.steps} steps, best of 3)\n")
    head = "".join(f"{f'B={b}':>18}" for b in args.batches)
    print(f"{'filter':<10}{'path':<10}{head}")
    for name in FILTER_NAMES:
        paths = [("compiled", get_filter(name))] + ([] if args.no_numpy else [("numpy", NumpyUnit(name))])
        for label, unit in paths:
            cells = []
            for b in args.batches:
                us = time_batched(unit, b, args.steps)
                cells.append(f"{us:>9.2f} ({base / us:>5.0f}x)")
            print(f"{name:<10}{label:<10}" + "".join(f"{c:>18}" for c in cells))
    print("\ncells: microseconds per filter-step (speed-up over the FilterPy loop); puekf with N_pu = 5")
    if not args.no_compile:
        with tempfile.TemporaryDirectory() as tmp:
            cold, each = first_call_seconds(tmp)
        warm, _ = first_call_seconds()
        print(f"\nfirst predict + update of all 7 units in a fresh process: {cold:.1f} s with an empty numba cache "
              f"(compilation; per unit, s: {each}), {warm:.2f} s with this checkout's cache")
    if not args.no_reproduce:
        seconds, mb = reproduce_s0()
        print(f"\nshipsense reproduce S0 (200 runs, fresh process): {seconds:.1f} s wall, peak memory {mb:.0f} MB")


if __name__ == "__main__":
    main()
