"""Command line: ``shipsense demo | scenarios | simulate``.

Exit codes: 0 success, 2 bad input (an invalid scenario, file or argument).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

EXIT_OK = 0
EXIT_BAD_INPUT = 2


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse exits 2 as well; keep its usage line
        self.print_usage(sys.stderr)
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def _progress(total, desc):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="step", leave=False, disable=None, file=sys.stderr)


def cmd_scenarios(args) -> int:
    from shipsense.config import shipped_scenarios

    names = shipped_scenarios()
    width = max(map(len, names))
    for name, desc in names.items():
        print(f"{name:<{width}}  {desc}")
    return EXIT_OK


def cmd_simulate(args) -> int:
    from shipsense.config import load_scenario
    from shipsense.simulator import simulate

    sc = load_scenario(args.scenario)
    if args.out is not None and Path(args.out).suffix not in (".npz", ".csv"):
        raise _BadInput(f"--out must end in .npz or .csv, got {args.out!r}")
    if args.plot is not None and Path(args.plot).suffix != ".png":
        raise _BadInput(f"--plot must end in .png, got {args.plot!r}")
    if args.runs is not None and args.runs < 1:
        raise _BadInput(f"--runs must be >= 1, got {args.runs}")
    if args.random and sc.prior is None:
        raise _BadInput(f"scenario {sc.name!r} has no [prior] section; --random needs one")
    bar = _progress(3, f"simulate {sc.name}")
    sim = simulate(sc, runs=args.runs, seed=args.seed, random=args.random)
    bar.update(1)
    if args.out:
        bar.set_description(f"write {args.out}")
        sim.save(args.out)
    bar.update(1)
    if args.plot:
        from shipsense.plotting import plot_simulation

        bar.set_description(f"plot {args.plot}")
        plot_simulation(sim, args.plot)
    bar.update(1)
    bar.close()
    _print_summary(sim)
    for what, path in (("measurements", args.out), ("plot", args.plot)):
        if path:
            print(f"wrote {what}: {path}")
    return EXIT_OK


def _print_summary(sim):
    """A short table per sensor: closest approach, peak field, peak SNR (run 0)."""
    arr = sim.array
    pos = sim.positions[0]
    print(f"scenario {sim.scenario.name}: {sim.runs} run(s) x {sim.times.size} steps of {sim.scenario.period:g} s, "
          f"{arr.n_channels} channels from {len(arr.ids)} sensors")
    std = sim.scenario.channel_std
    print(f"  {'sensor':<10} {'type':<13} {'kind':<9} {'closest [m]':>11} {'peak':>14} {'peak SNR':>9}")
    display = {"T": (1e9, "nT"), "V/m": (1e6, "uV/m"), "rad": (180 / np.pi, "deg")}
    for s, sid in enumerate(arr.ids):
        cols = np.flatnonzero(arr.channel_sensor == s)
        closest = np.min(np.linalg.norm(pos - arr.positions[s], axis=-1))
        scale, unit = display[arr.channel_units[cols[0]]]
        if arr.kinds[s] == "bearing":
            peak, snr = "-", "-"
        else:
            amp = np.abs(sim.clean[0][:, cols]).max(axis=0)
            peak = f"{scale * amp.max():.3g} {unit}"
            snr = f"{(amp / std[cols]).max():.3g}"
        print(f"  {sid:<10} {arr.types[s]:<13} {arr.kinds[s]:<9} {closest:>11.1f} {peak:>14} {snr:>9}")


def cmd_demo(args) -> int:
    from shipsense.config import load_scenario
    from shipsense.plotting import plot_simulation
    from shipsense.simulator import simulate

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sc = load_scenario("demo")
    bar = _progress(3, "demo: simulate")
    sim = simulate(sc, runs=1)
    bar.update(1)
    bar.set_description("demo: save")
    sim.save_npz(out / "passage.npz")
    bar.update(1)
    bar.set_description("demo: plot")
    plot_simulation(sim, out / "demo.png")
    bar.update(1)
    bar.close()
    _print_summary(sim)
    print("tracking: no tracker is available yet in this version (filters are the next milestone);")
    print("          the demo stops at simulated measurements.")
    print(f"wrote {out / 'demo.png'} and {out / 'passage.npz'}")
    return EXIT_OK


class _BadInput(Exception):
    pass


def build_parser() -> argparse.ArgumentParser:
    from shipsense import __version__

    p = _Parser(prog="shipsense", description="Track ships from their influence fields on seabed sensors, "
                "and design the arrays.")
    p.add_argument("--version", action="version", version=f"shipsense {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    d = sub.add_parser("demo", help="simulate a passage past the default array and plot it")
    d.add_argument("--out", default="shipsense-demo", help="output directory (default: %(default)s)")
    d.set_defaults(func=cmd_demo)

    s = sub.add_parser("scenarios", help="list the shipped scenarios")
    s.set_defaults(func=cmd_scenarios)

    m = sub.add_parser("simulate", help="simulate passages of a scenario")
    m.add_argument("scenario", help="a shipped scenario name (see `shipsense scenarios`) or a TOML file")
    m.add_argument("--runs", type=int, default=None, help="Monte Carlo runs (default: the scenario's)")
    m.add_argument("--seed", type=int, default=None, help="random seed (default: the scenario's)")
    m.add_argument("--random", action="store_true", help="draw passages from the scenario's [prior]")
    m.add_argument("--out", default=None, help="write measurements to FILE.npz or a tidy FILE.csv")
    m.add_argument("--plot", default=None, help="write a picture of the array, passages and traces to FILE.png")
    m.set_defaults(func=cmd_simulate)
    return p


def main(argv=None) -> int:
    from shipsense.config import ScenarioError

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ScenarioError, _BadInput) as err:
        print(f"shipsense {args.command}: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as err:
        print(f"shipsense {args.command}: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
