"""The grid search's projection ``G^T d``: the compiled per-passage sums against a stack of one-row BLAS
products (what it replaced), on S2's grid, in the same process.

Run:  PYTHONPATH=. python benchmarks/grid_projection.py [--passages 1 4 16 64] [--repeats 7]

S2's window fits' grid (8 ranges x 24 bearings x 12 courses x 3 speeds, 3 moment components, 17 samples
of 6 field channels: ``G`` is 102 x 20,736, 17 MB) and random whitened windows with 10 % of the samples
missing.  Prints milliseconds per passage (best of ``--repeats``) for each batch size and their ratio.
Both give every passage its own sums (neither depends on the batch); the BLAS product reads all of ``G``
once per passage with BLAS's threads, the compiled one reads it once per four passages in the package's
threads.  Run it alone, and again beside a CPU load (e.g. two ``yes > /dev/null``), where BLAS's threads
wait on each other.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from shipsense.config import load_scenario
from shipsense.models.field_model import model_from_scenario
from shipsense.parallel import in_chunks
from shipsense.reproduce.common import prior_grid
from shipsense.trackers.init.grid import _project, candidate_grid, grid_terms


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passages", type=int, nargs="+", default=[1, 4, 16, 64])
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args(argv)
    sc = load_scenario("S2")
    model = model_from_scenario(sc)
    grid = candidate_grid(model, prior_grid(sc)["ranges"], np.arange(0.0, 360.0, 15.0), np.arange(0.0, 360.0, 30.0),
                          prior_grid(sc)["speeds"])
    G, _, _ = grid_terms(model, grid, 150, 9)
    G2 = G.reshape(G.shape[0] * G.shape[1], -1)
    rng = np.random.default_rng(0)
    print(f"G: {G2.shape[0]} x {G2.shape[1]} ({G2.nbytes / 1e6:.0f} MB); ms per passage, best of {args.repeats}")
    print(f"{'passages':>9}{'BLAS stack':>12}{'compiled':>10}{'ratio':>8}")
    for R in args.passages:
        d = rng.normal(size=(R, G2.shape[0]))
        d[rng.uniform(size=d.shape) < 0.1] = 0.0
        out = np.empty((R, G2.shape[1]))

        def blas(d=d, out=out):
            np.matmul(d[:, None, :], G2, out=out[:, None, :])

        def compiled(d=d, out=out):
            in_chunks(lambda lo, hi: _project(d, G2, out, lo, hi), G2.shape[1], split_min=4096)

        times = []
        for fn in (blas, compiled):
            fn()
            best = np.inf
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                fn()
                best = min(best, time.perf_counter() - t0)
            times.append(1e3 * best / R)
        print(f"{R:>9}{times[0]:>12.3f}{times[1]:>10.3f}{times[0] / times[1]:>8.2f}")


if __name__ == "__main__":
    main()
