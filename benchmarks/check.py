"""Check benchmark: wall-clock seconds of one layout's observability/ambiguity verdict (`shipsense check`).

Run:  python benchmarks/check.py [--passages 8] [--only NAME ...]

Each layout is checked in-process with :func:`shipsense.design.observability.check_scenario` (8 passages from
the layout's prior, the CLI's default), after one untimed warm-up check (imports, the fast HED table of the
medium), so the figure is the cost of the verdict itself.  Layouts: every shipped scenario, and larger ones
built from them -- rings and two-line barriers of 8, 12 and 16 electrode nodes (envelope triads, S1-P2's
medium, noise and prior), 8 and 16 vector magnetometers (S2's) and a line of 8 electric magnitude
sensors (an ambiguous array).  Prints wall-clock and CPU seconds (the process's, all threads) and the verdict
per layout; on a shared machine the CPU seconds are the steadier figure.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from shipsense import load_scenario, shipped_scenarios
from shipsense.design.observability import check_scenario


def _with_nodes(base, positions, kind=None, sensor_type=None):
    """``base`` with its first sensor of ``sensor_type`` copied to each of ``positions`` (N, 2) on its seabed."""
    template = next(s for s in base.sensors if sensor_type is None or s.type == sensor_type)
    z = template.position[2]
    sensors = [template.model_copy(update={"id": f"N{i}", "position": (float(x), float(y), z),
                                           "kind": kind or template.kind, "orientation": None})
               for i, (x, y) in enumerate(positions)]
    return base.model_copy(update={"sensors": sensors, "name": f"{base.name}+{len(sensors)}"})


def ring(n, radius):
    a = 2 * np.pi * np.arange(n) / n
    return radius * np.stack([np.cos(a), np.sin(a)], -1)


def barrier(n, spacing, gap):
    """Two parallel lines (y = +-gap/2) of n/2 nodes each, staggered by half a spacing."""
    half = n // 2
    x = spacing * (np.arange(half) - (half - 1) / 2)
    return np.concatenate([np.stack([x, np.full(half, gap / 2)], -1),
                           np.stack([x + spacing / 2, np.full(half, -gap / 2)], -1)])


def layouts():
    out = {name: load_scenario(name) for name in shipped_scenarios()}
    s1, s2 = load_scenario("S1-P2"), load_scenario("S2")
    for n in (8, 12, 16):
        out[f"ring-{n}-envelope"] = _with_nodes(s1, ring(n, 40.0))
        out[f"barrier-{n}-envelope"] = _with_nodes(s1, barrier(n, 20.0, 20.0))
    for n in (8, 16):
        out[f"barrier-{n}-magnetometer"] = _with_nodes(s2, barrier(n, 20.0, 20.0), sensor_type="magnetometer")
    line = np.stack([np.zeros(8), 10.0 * (np.arange(8) - 3.5)], -1)
    out["line-8-electric-magnitude"] = _with_nodes(s1, line, kind="magnitude")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passages", type=int, default=8)
    ap.add_argument("--only", nargs="+", help="layout names to run (default: all)")
    args = ap.parse_args(argv)
    todo = layouts()
    if args.only:
        todo = {k: v for k, v in todo.items() if k in args.only}
    check_scenario(load_scenario("S1-P2"), passages=1)           # warm-up: imports and the medium's table
    print(f"{'layout':<28} {'sensors':>7} {'channels':>8} {'seconds':>8} {'CPU s':>8}  verdict (min chi2)")
    total, total_cpu = 0.0, 0.0
    for name, sc in todo.items():
        t0, c0 = time.perf_counter(), time.process_time()
        v = check_scenario(sc, passages=args.passages)
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        total += dt
        total_cpu += dc
        print(f"{name:<28} {len(sc.sensors):>7} {sc.array().n_channels:>8} {dt:>8.2f} {dc:>8.2f}  {v.verdict} "
              f"({v.min_chi2:.3g})", flush=True)
    print(f"{'total':<45} {total:>8.2f} {total_cpu:>8.2f}")


if __name__ == "__main__":
    main()
