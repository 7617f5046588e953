"""Command line: ``shipsense demo | scenarios | simulate``.

Exit codes: 0 success, 2 bad input (an invalid scenario, file or argument).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from shipsense.errors import ShipsenseError

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_BAD_INPUT = 2
EXIT_AMBIGUOUS = 3
EXIT_DEGENERATE = 4
VERDICT_EXIT = {"observable": EXIT_OK, "ambiguous": EXIT_AMBIGUOUS, "degenerate": EXIT_DEGENERATE}


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2 (the usage is one --help away)
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_known_args(self, args=None, namespace=None):
        # argparse reads "--flag=--" as an empty list, bypassing the flag's type (a crash further on)
        for a in (sys.argv[1:] if args is None else args):
            if isinstance(a, str) and a.startswith("--") and a.endswith("=--"):
                self.error(f"argument {a[:-3]}: expected a value, got '--'")
        return super().parse_known_args(args, namespace)


SEED_MAX = 2**63 - 1
RUNS_MAX = 1_000_000
PASSAGES_MAX = 10_000
TIMESTEPS_MAX = 10**9


def _whole(lo, hi, what="a whole number"):
    """An argparse type: an integer in [lo, hi], else one line naming the range (exit 2)."""
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what} between {lo} and {hi}, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be between {lo} and {hi}, got {value}")
        return value

    parse.__name__ = "integer"
    return parse


SEED = _whole(0, SEED_MAX, "a non-negative whole number")


_QUIET = {"on": False}   # `shipsense --quiet ...`: no progress bars (they show only on a terminal anyway)


def _progress(total, desc):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="step", leave=False, disable=True if _QUIET["on"] else None,
                file=sys.stderr)


def _writable(flag, path, directory=False):
    """Refuse an output path that cannot be written, before any work (not a raw OS error after it)."""
    p = Path(path)
    if directory:
        if p.exists() and not p.is_dir():
            raise _BadInput(f"{flag} must be a folder, but {path} is a file")
        return
    if p.is_dir():
        raise _BadInput(f"{flag} must be a file, but {path} is a folder")
    parent = p.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not (parent.is_dir() and os.access(parent, os.W_OK)):
        raise _BadInput(f"{flag}: cannot write {path} (folder {parent} is not a writable folder)")


def _within_budget(args, work):
    """Refuse work estimated above ``--max-memory`` / ``--max-minutes`` before any of it is allocated."""
    from shipsense.budget import enforce

    return enforce(work, args.max_memory, args.max_minutes)


def cmd_scenarios(args) -> int:
    from shipsense.config import shipped_scenarios

    names = shipped_scenarios()
    width = max(map(len, names))
    for name, desc in names.items():
        print(f"{name:<{width}}  {desc}")
    return EXIT_OK


def cmd_simulate(args) -> int:
    from contextlib import nullcontext

    from shipsense import budget
    from shipsense.atomic import atomic_path
    from shipsense.config import load_scenario
    from shipsense.simulator import simulate

    sc = load_scenario(args.scenario)
    if args.out is not None and Path(args.out).suffix not in (".npz", ".csv"):
        raise _BadInput(f"--out must end in .npz or .csv, got {args.out!r}")
    if args.plot is not None and Path(args.plot).suffix != ".png":
        raise _BadInput(f"--plot must end in .png, got {args.plot!r}")
    if args.random and sc.prior is None:
        raise _BadInput(f"scenario {sc.name!r} has no [prior] section; --random needs one")
    _within_budget(args, budget.simulation(sc, args.runs or sc.runs))
    for flag, path in (("--out", args.out), ("--plot", args.plot)):
        if path is not None:
            _writable(flag, path)
    bar = _progress(3, f"simulate {sc.name}")
    sim = simulate(sc, runs=args.runs, seed=args.seed, random=args.random)
    bar.update(1)
    # both files or neither: each is written to a temporary name and renamed once both are written
    with (atomic_path(args.out) if args.out else nullcontext()) as out_tmp, \
            (atomic_path(args.plot) if args.plot else nullcontext()) as plot_tmp:
        if args.out:
            bar.set_description(f"write {args.out}")
            sim.save(out_tmp)
        bar.update(1)
        if args.plot:
            from shipsense.plotting import plot_simulation

            bar.set_description(f"plot {args.plot}")
            plot_simulation(sim, plot_tmp)
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


def _first_use(command, filter_name=None, notice=None):
    """Say on stderr, before work that runs the tracker, that its compiled kernels are about to compile (and so
    that this run's times include compiling): :func:`~shipsense.cli.track.first_use_notice`, or ``notice`` (a
    function giving another command's notice or None)."""
    from shipsense.cli.track import first_use_notice

    notice = first_use_notice(filter_name) if notice is None else notice()
    if notice:
        print(f"{command}: {notice}", file=sys.stderr)


def cmd_demo(args) -> int:
    from shipsense.atomic import staged_directory
    from shipsense.cli.track import describe, track_to_files
    from shipsense.config import load_scenario
    from shipsense.plotting import plot_simulation, plot_track
    from shipsense.simulator import simulate

    out = Path(args.out)
    _writable("--out", out, directory=True)
    sc = load_scenario("demo")
    _first_use("demo")
    bar = _progress(3, "demo: simulate")
    with staged_directory(out) as stage:   # all of the demo's files, or none
        sim = simulate(sc, runs=1)
        bar.update(1)
        bar.set_description("demo: track")
        summary = track_to_files(sc, sim.times, sim.measurements[0], stage, truth=sim.truth[0])
        bar.update(1)
        bar.set_description("demo: save and plot")
        sim.save_npz(stage / "passage.npz")
        plot_simulation(sim, stage / "measurements.png")
        plot_track(summary, sim.times, stage / "demo.png", truth=sim.truth[0],
                   title="demo: the project's tracker, fused magnetic + electric + bearing (2-sigma ellipses)")
        bar.update(1)
    bar.close()
    _print_summary(sim)
    for line in describe(summary, "the simulated passage"):
        print(line)
    print(f"wrote {out / 'demo.png'} (track), {out / 'measurements.png'} (traces), {out / 'estimates.csv'}, "
          f"{out / 'selection_log.csv'} and {out / 'passage.npz'}")
    return EXIT_OK


class _BadInput(ShipsenseError):
    """A command-line argument the user can fix (one line, exit 2)."""


def cmd_track(args) -> int:
    from shipsense import budget
    from shipsense.atomic import staged_directory
    from shipsense.cli.track import describe, track_to_files
    from shipsense.config import load_scenario
    from shipsense.plotting import plot_track
    from shipsense.recording import RecordingError, read_recording
    from shipsense.simulator import simulate
    from shipsense.trackers.filters import FILTER_NAMES

    sc = load_scenario(args.scenario)
    if args.filter is not None and args.filter not in FILTER_NAMES:
        raise _BadInput(f"--filter must be one of {', '.join(FILTER_NAMES)}, got {args.filter!r}")
    out = Path(args.out)
    _writable("--out", out, directory=True)
    truth = None
    if args.data:
        _within_budget(args, budget.recording(args.data, sc))
        try:
            times, y = read_recording(args.data, sc)
        except RecordingError as err:
            raise _BadInput(str(err)) from None
        missing = np.isnan(y).mean()
        source = f"recording {args.data} ({y.shape[0]} samples, {100 * missing:.1f} % of values missing)"
    else:
        _within_budget(args, budget.tracking(sc, sc.steps, what=f"a simulated passage of {sc.name} ({sc.steps} steps)"))
        sim = simulate(sc, runs=1, seed=args.seed, random=args.random)
        times, y, truth = sim.times, sim.measurements[0], sim.truth[0]
        used_seed = sc.seed if args.seed is None else args.seed
        source = f"simulated {'random' if args.random else 'nominal'} passage of {sc.name} (seed {used_seed})"
    _first_use("track", args.filter)
    with staged_directory(out) as stage:   # the tables and the plot, or nothing
        try:
            summary = track_to_files(sc, times, y, stage, truth=truth, method=args.method, unit=args.filter,
                                     progress=not _QUIET["on"])
        except ValueError as err:
            raise _BadInput(str(err)) from None
        plot_track(summary, times, stage / "track.png", truth=truth,
                   title=f"{sc.name}: {args.method} (2-sigma ellipses)")
    for line in describe(summary, source):
        print(line)
    print(f"wrote {out / 'estimates.csv'}, {out / 'selection_log.csv'} and {out / 'track.png'}")
    return EXIT_OK


def cmd_check(args) -> int:
    import json

    from shipsense import budget
    from shipsense.atomic import atomic_write_bytes
    from shipsense.config import load_scenario
    from shipsense.design.gate import check_layouts, junit_xml, worst
    from shipsense.design.observability import first_use_notice

    if args.junit is not None and Path(args.junit).suffix != ".xml":
        raise _BadInput(f"--junit must end in .xml, got {args.junit!r}")
    budget.check_limits(args.max_memory, args.max_minutes)
    if args.junit is not None:
        _writable("--junit", args.junit)
    works = []   # the whole run is within the limits, not each file (a file that does not load is its own error)
    for layout in args.layout:
        try:
            works.append(budget.check(load_scenario(layout), args.passages))
        except (ShipsenseError, OSError):
            pass
    if works:
        _within_budget(args, budget.sequence(works, f"checking {len(works)} layout(s) on {args.passages} passages "
                                             "each", works[0].fewer + " or files"))
    _first_use("check", notice=first_use_notice)
    results = check_layouts(args.layout, passages=args.passages, seed=args.seed,
                            progress=not (args.json or _QUIET["on"]), errors=(ShipsenseError, OSError))
    if args.junit is not None:
        Path(args.junit).parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(Path(args.junit), junit_xml(results))
    if args.json:
        docs = [{"layout": r.layout, "verdict": "error", "error": r.detail} if r.verdict == "error"
                else {"layout": r.layout, **r.detail.to_json()} for r in results]
        print(json.dumps(docs[0] if len(docs) == 1 else docs, indent=2))
    else:
        for r in results:
            _print_verdict(r)
    outcome = worst(results)
    if outcome == "error":
        for r in results:
            if r.verdict == "error":
                print(f"shipsense check: error: {r.detail}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return VERDICT_EXIT[outcome]


def _print_verdict(result):
    if result.verdict == "error":
        return
    sc, verdict = result.scenario, result.detail
    print(f"{sc.name}: {verdict.verdict.upper()}  ({len(sc.sensors)} sensors, {verdict.passages} passage(s) "
          f"{'from the prior' if sc.prior is not None else '(the nominal one)'}; {result.seconds:.1f} s)")
    print(f"  Fisher information: rank {verdict.fim_rank} of {len(verdict.labels)}, "
          f"condition number {verdict.fim_condition:.3g} (internal units)")
    print(f"  closest far-apart passage: chi-square {verdict.min_chi2:.3g} (ambiguous below 25)")
    for p in verdict.pairs[:5]:
        a, b = p.passage, p.alternative
        print(f"  ambiguous pair ({p.source}): start ({a[0]:.0f}, {a[1]:.0f}) m heading "
              f"{np.degrees(np.arctan2(a[3], a[2])):.0f} deg  vs  ({b[0]:.0f}, {b[1]:.0f}) m heading "
              f"{np.degrees(np.arctan2(b[3], b[2])):.0f} deg; chi-square {p.chi2:.3g}, {p.distance_m:.0f} m apart")


def _read_candidates(path, z_default):
    """Candidates (N, 3) and optional costs (N,) from a CSV (x,y[,z][,cost]) or a TOML [candidates] table."""
    import csv
    import tomllib

    from shipsense.design.placement import grid_candidates

    path = Path(path)
    if not path.is_file():
        raise _BadInput(f"--candidates: no such file {path}")
    if path.suffix == ".csv":
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
        if not rows or not {"x", "y"} <= set(rows[0]):
            raise _BadInput(f"{path}: a candidate CSV needs a header with x,y (and optionally z)")
        try:
            pts = np.array([[float(r["x"]), float(r["y"]), float(r.get("z") or z_default)] for r in rows])
            costs = np.array([float(r["cost"]) for r in rows]) if "cost" in rows[0] else None
        except ValueError as err:
            raise _BadInput(f"{path}: {err}") from None
    elif path.suffix == ".toml":
        try:
            c = tomllib.loads(path.read_text()).get("candidates")
        except tomllib.TOMLDecodeError as err:
            raise _BadInput(f"{path}: not valid TOML ({err})") from None
        if not isinstance(c, dict) or "polygon" not in c or "spacing" not in c:
            raise _BadInput(f"{path}: needs a [candidates] table with polygon = [[x, y], ...] and spacing")
        pts = grid_candidates(c["polygon"], float(c["spacing"]), float(c.get("z", z_default)),
                              c.get("exclusions", []), float(c.get("min_spacing", 0.0)))
        costs = None
    else:
        raise _BadInput(f"--candidates must be a .csv or .toml file, got {path.name!r}")
    if not np.isfinite(pts).all() or len(pts) == 0:
        raise _BadInput(f"{path}: candidates must be finite and at least one")
    return pts, costs


def cmd_design(args) -> int:
    from shipsense import budget
    from shipsense.config import load_scenario
    from shipsense.design.designer import default_candidates, design_array, summary_lines, write_design
    from shipsense.design.observability import first_use_notice

    out = Path(args.out)
    if out.suffix.lower() in (".toml", ".json", ".png"):
        raise _BadInput(f"--out is the report folder (it gets layout.toml, design.json, design.png, bounds.png), "
                        f"not a file: got {args.out}")
    _writable("--out", out, directory=True)
    sc = load_scenario(args.scenario)
    cands, costs = (None, None) if not args.candidates else _read_candidates(args.candidates, sc.sensors[0].position[2])
    n_cands = len(cands) if cands is not None else len(default_candidates(sc))
    search = args.bb_seconds if args.k <= 3 and np.isfinite(args.bb_seconds) else 0.0   # the branch and bound
    _within_budget(args, budget.design(sc, n_cands, args.passages if sc.prior is not None else 1, search))
    _first_use("design", notice=first_use_notice)
    try:
        result = design_array(sc, args.k, criterion=args.criterion, candidates=cands, costs=costs, budget=args.budget,
                              passages=args.passages, seed=args.seed, solver=args.solver, cuts=not args.no_cuts,
                              prior_floor=args.prior_floor, bb_seconds=args.bb_seconds, progress=not _QUIET["on"])
    except ValueError as err:
        raise _BadInput(str(err)) from None
    paths = write_design(result, out)
    for line in summary_lines(result):
        print(line)
    print(f"wrote {out}/: " + ", ".join(p.name for p in paths) + f" (check the layout with `shipsense check "
          f"{paths[0]}`)")
    return EXIT_OK


def _json_kwargs(flag, text):
    import json

    if text is None:
        return None
    try:
        value = json.loads(text)
    except json.JSONDecodeError as err:
        raise _BadInput(f"{flag} must be a JSON object, e.g. '{{\"k\": 3}}': {err}") from None
    if not isinstance(value, dict):
        raise _BadInput(f"{flag} must be a JSON object, got {text!r}")
    return value


_TRAIN_FLAGS = {"imitation_steps": "--imitation-steps", "imitate_policy": "--imitate", "shaping": "--shaping",
                "env_kwargs": "--env-kwargs", "env_id": "--env"}


def cmd_train(args) -> int:
    from shipsense import budget
    from shipsense.atomic import staged_directory
    from shipsense.envs import training

    if args.timesteps is not None and args.timesteps < 64:
        raise _BadInput(f"--timesteps must be >= 64, got {args.timesteps}")
    timesteps = args.timesteps or training.DEFAULT_TIMESTEPS[args.task]
    evaluations = max(1, timesteps // args.eval_every) if args.eval_every else 10
    imitation = args.imitation_steps if args.task == "scheduling" and args.imitate != "none" else 0
    _within_budget(args, budget.training(args.task, timesteps + imitation, evaluations, args.eval_episodes))
    env_kwargs = _json_kwargs("--env-kwargs", args.env_kwargs)
    out = args.out or f"results/train-{args.task}"
    if args.task == "scheduling":              # (Passage environments: the tracker observes)
        _first_use("train")
    try:
        with staged_directory(out) as stage:   # the models, logs, curve and summary, or nothing
            s = training.train(args.task, args.env, timesteps, stage, args.seed, args.n_envs, args.eval_every,
                               args.eval_episodes, env_kwargs, progress=not _QUIET["on"], shaping=args.shaping,
                               imitate_policy=args.imitate, imitation_steps=args.imitation_steps)
    except (RuntimeError, ValueError) as err:
        message = str(err)
        for name, flag in _TRAIN_FLAGS.items():   # the library names its arguments; the command, its flags
            if message.startswith(name):
                message = flag + message[len(name):]
                break
        raise _BadInput(message) from None
    best, final = s["best"], s["final"]
    print(f"{s['algorithm']} on {s['env']}: {s['timesteps']} steps in {s['seconds']:.0f} s "
          f"({s['frames_per_second']:.0f} frames/s, {s['n_envs']} envs)")
    for name, p in (("best", best), ("final", final)):
        r = p["return"]
        metrics = ", ".join(f"{k} {m['mean']:.4g}" for k, m in p["metrics"].items())
        print(f"  {name:<5} at {p['timesteps']:>8} steps: held-out return {r['mean']:.4g} +- {r['stderr']:.2g}"
              + (f" ({metrics})" if metrics else ""))
    if s["held_out_baselines"]:
        print("  baselines on the same held-out episodes: "
              + ", ".join(f"{k} {v:.4g}" for k, v in s["held_out_baselines"].items()))
    print(f"wrote {out}/{s['files']['best_model']} (best on held-out seeds {s['held_out_seed']}+), "
          f"{out}/{s['files']['final_model']}, {out}/learning_curve.png, {out}/evaluation.json and "
          f"{out}/tensorboard")
    return EXIT_OK


def cmd_evaluate(args) -> int:
    import json

    from shipsense import budget
    from shipsense.envs.evaluation import evaluate, summary_lines

    _within_budget(args, budget.evaluation(args.env_id, args.policy, args.episodes))
    env_kwargs = _json_kwargs("--env-kwargs", args.env_kwargs)
    if "Passage" in args.env_id:               # (the tracker observes)
        _first_use("evaluate")
    try:
        result = evaluate(args.env_id, args.policy, args.episodes, args.seed, env_kwargs,
                          progress=not _QUIET["on"])
    except ValueError as err:
        raise _BadInput(str(err)) from None
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for line in summary_lines(result):
            print(line)
    return EXIT_OK


def cmd_reproduce(args) -> int:
    from shipsense import budget
    from shipsense.reproduce import EXPERIMENTS, run, run_all
    from shipsense.sweep import SweepError

    key = args.name.upper()
    if key not in (*EXPERIMENTS, "ALL"):
        raise _BadInput(f"unknown experiment set {args.name!r}; choose one of {', '.join(EXPERIMENTS)}, all")
    workers = args.workers
    if workers is None and args.scheduler is None and key in ("S0", "S1", "S2"):
        workers = 0   # one study is one task: in this process unless a cluster is asked for
    options = {"workers": workers, "scheduler": args.scheduler, "restart": args.restart}
    _within_budget(args, budget.study(key, args.runs))
    try:
        if key == "ALL":
            out = Path(args.out or "results")
            t0 = time.perf_counter()
            summaries = run_all(runs=args.runs, out=out, seed=args.seed, progress=not _QUIET["on"], **options)
            print(f"ALL: {', '.join(summaries)} in {time.perf_counter() - t0:.1f} s; wrote {out}/<study>/")
            return EXIT_OK
        out = Path(args.out or f"results/{'wide' if key == 'WIDE' else key}")
        summary = run(key, runs=args.runs, out=out, seed=args.seed, progress=not _QUIET["on"], **options)
    except SweepError as err:
        raise _BadInput(str(err)) from None
    print(f"{key}: {summary['runs']} runs in {summary['seconds']:.1f} s; wrote {out}/summary.json, CSV tables "
          f"and PNG figures")
    return EXIT_OK


def cmd_sweep(args) -> int:
    from shipsense.sweep import EXAMPLE, SweepError, load_sweep, report, run_sweep

    try:
        if args.example:
            print(EXAMPLE, end="")
            return EXIT_OK
        if args.report is not None:
            for path in report(args.report):
                print(f"wrote {path}")
            return EXIT_OK
        if args.sweep is None or args.out is None:
            raise _BadInput("give SWEEP.toml and --out DIR (or --example, or --report DIR)")
        spec, base = load_sweep(args.sweep)
        run = run_sweep(spec, base, args.out, workers=args.workers, scheduler=args.scheduler, restart=args.restart,
                        csv=args.csv, progress=False if args.quiet else None,
                        log=(lambda *a, **k: None) if args.quiet else print)
    except SweepError as err:
        raise _BadInput(str(err)) from None
    print(f"ran {run.ran} of {run.tasks} tasks ({run.skipped} already finished) in {run.wall_seconds:.1f} s; "
          f"wrote {Path(args.out) / 'results.parquet'}" + (" and results.csv" if args.csv else "")
          + ", passages.parquet and one PNG per metric")
    return EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    from shipsense import __version__

    p = _Parser(prog="shipsense", description="Track ships from their influence fields on seabed sensors, "
                "and design the arrays.")
    p.add_argument("--version", action="version", version=f"shipsense {__version__}")
    p.add_argument("--debug", action="store_true", help="show the traceback of an unexpected error")
    p.add_argument("--quiet", dest="no_progress", action="store_true",
                   help="no progress bars (they are shown only on a terminal in any case)")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    from shipsense.budget import MEMORY_LIMIT_GB, TIME_LIMIT_MINUTES

    limits = argparse.ArgumentParser(add_help=False)   # the work budget, on every command that can be large
    limits.add_argument("--max-memory", type=float, default=MEMORY_LIMIT_GB, metavar="GB",
                        help="refuse work whose memory is estimated above this (default: %(default)g GB)")
    limits.add_argument("--max-minutes", type=float, default=TIME_LIMIT_MINUTES, metavar="MIN",
                        help="refuse work whose run time is estimated above this (default: %(default)g minutes)")

    d = sub.add_parser("demo", help="simulate a passage past the default array and plot it")
    d.add_argument("--out", default="shipsense-demo", help="output directory (default: %(default)s)")
    d.set_defaults(func=cmd_demo)

    s = sub.add_parser("scenarios", help="list the shipped scenarios")
    s.set_defaults(func=cmd_scenarios)

    m = sub.add_parser("simulate", parents=[limits], help="simulate passages of a scenario")
    m.add_argument("scenario", help="a shipped scenario name (see `shipsense scenarios`) or a TOML file")
    m.add_argument("--runs", type=_whole(1, RUNS_MAX), default=None,
                   help="Monte Carlo runs (default: the scenario's)")
    m.add_argument("--seed", type=SEED, default=None, help="random seed (default: the scenario's)")
    m.add_argument("--random", action="store_true", help="draw passages from the scenario's [prior]")
    m.add_argument("--out", default=None, help="write measurements to FILE.npz or a tidy FILE.csv")
    m.add_argument("--plot", default=None, help="write a picture of the array, passages and traces to FILE.png")
    m.set_defaults(func=cmd_simulate)

    t = sub.add_parser("track", parents=[limits], help="track a simulated passage, or a recorded one (--data)")
    t.add_argument("scenario", help="a shipped scenario name or a TOML file (the array, medium and tracker)")
    t.add_argument("--data", default=None, help="recorded long-format CSV: time,sensor,channel,value (SI units)")
    t.add_argument("--method", choices=["tracker", "bank"], default="tracker",
                   help="tracker: the project's tracker (default); bank: the source studies' bank")
    t.add_argument("--filter", default=None,
                   help="filter unit (default: ukf for the tracker, huber_ukf when robust; the bank: the scenario's)")
    t.add_argument("--out", default="shipsense-track", help="output directory (default: %(default)s)")
    t.add_argument("--seed", type=SEED, default=None, help="seed of the simulated passage")
    t.add_argument("--random", action="store_true", help="simulate a random passage from the [prior]")
    t.set_defaults(func=cmd_track)

    c = sub.add_parser("check", parents=[limits],
                       help="observability and ambiguity verdict of arrays (exit 0/3/4; a CI gate)",
                       description="Exit codes (the worst over the files): 0 observable, 3 ambiguous, 4 degenerate, "
                       "2 bad input.")
    c.add_argument("layout", metavar="SCENARIO_OR_LAYOUT", nargs="+",
                   help="shipped scenario names or TOML files (several: one verdict each)")
    c.add_argument("--json", action="store_true", help="print {verdict, min_chi2, pairs, fim_rank, fim_condition} "
                   "(a list of them, with 'layout', for several files)")
    c.add_argument("--junit", default=None, metavar="FILE.xml",
                   help="also write a JUnit XML report: one test case per layout")
    c.add_argument("--passages", type=_whole(1, PASSAGES_MAX), default=8,
                   help="passages drawn from the [prior] (default 8)")
    c.add_argument("--seed", type=SEED, default=0)
    c.set_defaults(func=cmd_check)

    g = sub.add_parser("design", parents=[limits], help="place k sensors (convex relaxation, rounding, ambiguity cuts)")
    g.add_argument("scenario", help="a shipped scenario name or a TOML file (its first sensor is the template)")
    g.add_argument("--k", type=_whole(1, 1000), required=True, help="number of sensors to place")
    g.add_argument("--criterion", default="D", help="D, A or E (default D)")
    g.add_argument("--candidates", default=None, help="candidate positions: CSV x,y[,z] or TOML [candidates] "
                   "polygon, spacing, z, exclusions, min_spacing (default: a grid around the array)")
    g.add_argument("--out", default="shipsense-design",
                   help="report folder: layout.toml, design.json, design.png, bounds.png (default: %(default)s)")
    g.add_argument("--passages", type=_whole(1, PASSAGES_MAX), default=8,
                   help="prior passages to average over (default 8)")
    g.add_argument("--seed", type=SEED, default=0)
    g.add_argument("--budget", type=float, default=None,
                   help="total cost allowed, with a 'cost' column in the candidate CSV")
    g.add_argument("--no-cuts", action="store_true", help="skip the ambiguity cuts")
    g.add_argument("--solver", default="auto",
                   help="relaxation solver: auto (CLARABEL up to 800 candidates, else first-order), clarabel "
                        "(interior point; falls back to first-order if it fails) or first-order (projected "
                        "gradient, Frank-Wolfe with cuts or a budget); default auto")
    g.add_argument("--bb-seconds", type=float, default=20.0,
                   help="time limit of the branch and bound that tightens the bound for k <= 3 (default 20; 0: off)")
    g.add_argument("--prior-floor", type=float, default=None,
                   help="floor on the scaled prior information (a regulariser; default: none, the scenario's "
                        "prior covariance as it is)")
    g.set_defaults(func=cmd_design)

    tr = sub.add_parser("train", parents=[limits],
                        help="train a sensor-scheduling (PPO) or placement (MaskablePPO) agent (needs the rl extra)")
    tr.add_argument("task", choices=["placement", "scheduling"])
    tr.add_argument("--timesteps", type=_whole(1, TIMESTEPS_MAX), default=None,
                    help="environment steps (default: 30000 for scheduling, after 30000 steps of imitation; 20000 "
                         "for placement)")
    tr.add_argument("--env", default=None, metavar="ID",
                    help="environment id (default: shipsense/ArrayDesign-v1 for placement, shipsense/Passage-v1 for "
                         "scheduling)")
    tr.add_argument("--env-kwargs", default=None, metavar="JSON", help="the environment's arguments, a JSON object")
    tr.add_argument("--n-envs", type=_whole(1, 256), default=8, help="parallel environments (default: %(default)s)")
    tr.add_argument("--eval-every", type=_whole(1, TIMESTEPS_MAX), default=None, metavar="STEPS",
                    help="held-out evaluation every this many steps (default: a tenth of --timesteps)")
    tr.add_argument("--eval-episodes", type=_whole(1, 100_000), default=20,
                    help="held-out episodes per evaluation (default: %(default)s)")
    tr.add_argument("--shaping", type=float, default=None, metavar="COEF",
                    help="weight of potential-based reward shaping with the environment's potential (Passage-v1: "
                         "the observer's position information); the optimal policies do not change "
                         "(default: 1 where the environment declares a potential, else 0)")
    tr.add_argument("--imitate", default=None, metavar="BASELINE",
                    help="scheduling: first clone this baseline of the environment by behaviour cloning, then "
                         "train PPO from it; 'none': PPO from scratch (default: greedy where the environment "
                         "offers it)")
    tr.add_argument("--imitation-steps", type=_whole(64, TIMESTEPS_MAX), default=30_000, metavar="STEPS",
                    help="environment steps of the baseline that --imitate clones (default: %(default)s)")
    tr.add_argument("--out", default=None, help="output directory (default: results/train-TASK)")
    tr.add_argument("--seed", type=SEED, default=0)
    tr.set_defaults(func=cmd_train)

    ev = sub.add_parser("evaluate", parents=[limits],
                        help="evaluate a baseline or a trained model on seeded episodes of an environment",
                        description="Mean return +- standard error and the environment's task metrics over "
                        "episodes reset with seeds S, S+1, ...")
    ev.add_argument("env_id", metavar="ENV_ID", help="e.g. shipsense/ArrayDesign-v1")
    ev.add_argument("--policy", required=True, metavar="NAME|PATH.zip",
                    help="a baseline the environment offers (random, round-robin, greedy, convex) or a "
                         "stable-baselines3 model file")
    ev.add_argument("--episodes", type=_whole(1, 10**6), default=50, help="episodes (default: %(default)s)")
    ev.add_argument("--seed", type=_whole(0, 2**31 - 1, "a non-negative whole number"), default=2_000_000,
                    help="seed of the first episode (default: %(default)s, away from training's seeds)")
    ev.add_argument("--env-kwargs", default=None, metavar="JSON", help="the environment's arguments, a JSON object")
    ev.add_argument("--json", action="store_true", help="print the result as JSON")
    ev.set_defaults(func=cmd_evaluate)

    w = sub.add_parser("sweep", help="a layout study: layouts x site conditions x passages, on Dask, resumable",
                       description="Run the cells of SWEEP.toml (layouts x site conditions) in chunks of passages "
                       "on a local Dask cluster (or --scheduler), writing each finished chunk to DIR; rerunning "
                       "skips finished chunks.  `shipsense sweep --example` prints an example sweep file.")
    w.add_argument("sweep", nargs="?", metavar="SWEEP.toml", help="the sweep file")
    w.add_argument("--out", metavar="DIR", help="results folder (resumed if it holds this sweep's results)")
    w.add_argument("--workers", type=_whole(0, 1024), default=None,
                   help="local Dask workers, one thread each (default: the cores; 0 runs serially in-process)")
    w.add_argument("--scheduler", default=None, metavar="ADDRESS", help="an existing Dask scheduler, tcp://host:8786")
    w.add_argument("--restart", action="store_true",
                   help="start afresh, discarding the results found in DIR (this sweep's or another's)")
    w.add_argument("--csv", action="store_true", help="also write results.csv")
    w.add_argument("--quiet", action="store_true", help="no progress bar or log lines")
    w.add_argument("--example", action="store_true", help="print an example sweep file (about 100 cells) and exit")
    w.add_argument("--report", default=None, metavar="DIR", help="re-draw the plots of a finished sweep in DIR")
    w.set_defaults(func=cmd_sweep)

    r = sub.add_parser("reproduce", parents=[limits],
                       help="reproduce the reference experiments of S0, S1, S2, the wide-prior study, "
                       "or all of them")
    r.add_argument("name", metavar="S0|S1|S2|wide|all")
    r.add_argument("--runs", type=_whole(2, RUNS_MAX), default=None,
                   help="Monte Carlo runs (default: 200 for S0, 100 for S1 and S2, 500 passages per family for wide)")
    r.add_argument("--out", default=None, help="output directory (default: results/NAME; all: results)")
    r.add_argument("--seed", type=SEED, default=0)
    r.add_argument("--workers", type=_whole(0, 1024), default=None,
                   help="run on a local Dask cluster of N processes (default: the cores for wide and all, this "
                        "process for one of S0, S1, S2; 0: this process); finished studies and wide's chunks are "
                        "skipped when rerun")
    r.add_argument("--scheduler", default=None, metavar="ADDRESS", help="an existing Dask scheduler, tcp://host:8786")
    r.add_argument("--restart", action="store_true",
                   help="start afresh, discarding the results found in OUT (finished studies, wide's chunks; this "
                        "run's or another's)")
    r.set_defaults(func=cmd_reproduce)
    return p


def _interrupted(err):
    """Whether ``err`` stands for an interruption: a KeyboardInterrupt in its chain of causes (a signal handler
    that raises while a compiled kernel runs surfaces as "SystemError: ... returned a result with an exception
    set", caused by the KeyboardInterrupt)."""
    seen = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, KeyboardInterrupt):
            return True
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return False


def main(argv=None) -> int:
    from shipsense.allocator import tune_allocator

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:   # a bad argument (exit 2, its message printed), --help or --version (0)
        return exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else EXIT_BAD_INPUT)
    tune_allocator()   # the command is its own process: reuse freed heap (see shipsense.allocator)
    import signal

    def terminated(signum, frame):   # a CI cancel or `timeout`: unwind like Ctrl-C, so staged outputs are removed
        raise KeyboardInterrupt

    import threading

    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
        signal.signal(signal.SIGTERM, terminated)
    _QUIET["on"] = bool(args.no_progress)
    try:
        return args.func(args)
    except (ShipsenseError, OSError) as err:   # input the user can fix: one line naming it
        print(f"shipsense {args.command}: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"shipsense {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as err:   # a bug, not the input: one line, the traceback on request
        if _interrupted(err):   # Ctrl-C or SIGTERM inside compiled code: numba wraps it in a SystemError
            print(f"shipsense {args.command}: interrupted", file=sys.stderr)
            return 130
        if args.debug:
            raise
        print(f"shipsense {args.command}: internal error: {type(err).__name__}: {err} "
              "(run with --debug for the traceback)", file=sys.stderr)
        return EXIT_INTERNAL

