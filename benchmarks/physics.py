"""Physics kernel benchmark: HED fast path vs the image series, and magnetic kernel throughput.

Run:  python benchmarks/physics.py [--n 100000]

Prints a table: for sigma_seabed = 0.04 (the target case) and 1.0, the time
of the series (rtol 1e-12) and of the fast path for N random field
evaluations (offsets 1 m - 2 km, log-uniform; sensor and source depths
uniform in the water), their ratio and the fast path's maximum relative
error; then magnetic dipole evaluations per second; then the measurement models
of the shipped scenarios (readings and Jacobian), compiled against numpy.  Timings
are the best of several repeats, in the same process.
"""

from __future__ import annotations

import argparse
import time
from functools import partial

import numpy as np

from shipsense.physics.electric import Medium, fast_hed, hed_field
from shipsense.physics.magnetic import dipole_field


def best_time(fn, repeats):
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def geometry(n, depth=15.0, seed=0):
    rng = np.random.default_rng(seed)
    rho = np.exp(rng.uniform(np.log(1.0), np.log(2000.0), n))
    az = rng.uniform(0, 2 * np.pi, n)
    sens = np.stack([rho * np.cos(az), rho * np.sin(az), rng.uniform(-depth, 0, n)], axis=-1)
    src = np.stack([np.zeros(n), np.zeros(n), rng.uniform(-depth + 0.2, -0.2, n)], axis=-1)
    th = rng.uniform(0, 2 * np.pi, n)
    p = np.stack([100 * np.cos(th), 100 * np.sin(th), np.zeros(n)], axis=-1)
    return sens, src, p


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000, help="field evaluations per timing (default 1e5)")
    args = ap.parse_args(argv)
    n = args.n
    sens, src, p = geometry(n)
    print(f"HED: {n:.0e} field evaluations, offsets 1 m - 2 km")
    print(f"{'sigma_seabed':>12} {'shells':>7} {'series [s]':>11} {'table build [s]':>16} {'fast [s]':>9} "
          f"{'speed-up':>9} {'max rel err':>12}")
    for sigma2 in (0.04, 1.0):
        medium = Medium(4.0, sigma2, 15.0)
        t0 = time.perf_counter()
        kernel = fast_hed(medium)
        t_build = time.perf_counter() - t0
        t0 = time.perf_counter()
        ref, shells = hed_field(sens, src, p, medium, rtol=1e-12, return_shells=True)
        t_series = time.perf_counter() - t0
        t_fast = best_time(partial(kernel, sens, src, p), 5)
        err = np.linalg.norm(kernel(sens, src, p) - ref, axis=-1) / np.linalg.norm(ref, axis=-1)
        print(f"{sigma2:>12g} {shells:>7d} {t_series:>11.3f} {t_build:>16.3f} {t_fast:>9.4f} "
              f"{t_series / t_fast:>8.0f}x {err.max():>12.2e}")

    rng = np.random.default_rng(1)
    s = rng.uniform(-100, 100, (n, 3))
    q = rng.uniform(-100, 100, (n, 3))
    m = rng.standard_normal((n, 3)) * 1e7
    t = best_time(partial(dipole_field, s, q, m), 10)
    print(f"\nmagnetic dipole kernel: {n / t:.3g} evaluations/s ({1e9 * t / n:.1f} ns each, batch {n:.0e})")
    measurement_models(min(n, 2400))


def measurement_models(batch):
    """Microseconds per state of the models' readings with their Jacobian (``FieldModel.h_and_H``, the compiled
    kernel of :mod:`shipsense.models.measurement`) against the numpy kernels it replaces (``_h_and_H_numpy``),
    for the shipped scenarios' models; one thread."""
    import os

    from shipsense.models.field_model import model_from_scenario

    print(f"\nmeasurement models, h and its Jacobian, batch {batch}, one thread: microseconds per state")
    print(f"{'model':<8}{'compiled':>10}{'numpy':>10}{'speed-up':>10}")
    rng = np.random.default_rng(2)
    truth = np.column_stack([rng.uniform(-150, 150, (batch, 2)), rng.uniform(-8, 8, (batch, 2)),
                             rng.uniform(-12, -2, batch), rng.uniform(-1e6, 1e6, (batch, 3)),
                             rng.uniform(50, 900, batch)])
    os.environ["SHIPSENSE_THREADS"] = "1"     # read at every split: this process's later work runs in one thread
    for name in ("S0", "S2", "S1-P1", "demo"):
        model = model_from_scenario(name)
        x = model.to_internal(model.state_from_truth(truth))
        model.h_and_H(x)                       # compile or load
        cells = [1e6 * best_time(partial(f, x), 10) / batch for f in (model.h_and_H, model._h_and_H_numpy)]
        print(f"{name:<8}{cells[0]:>10.2f}{cells[1]:>10.2f}{cells[1] / cells[0]:>9.1f}x")


if __name__ == "__main__":
    main()
