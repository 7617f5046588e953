"""Commands on passages: ``scenarios``, ``simulate``, ``demo`` and ``track``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from shipsense.cli.common import EXIT_OK, QUIET, BadInput, first_use, progress_bar, within_budget, writable


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
    if args.out is not None:
        from shipsense.recording.formats import SUFFIXES

        suffixes = (".npz", *(s for v in SUFFIXES.values() for s in v))
        if Path(args.out).suffix.lower() not in suffixes:
            raise BadInput(f"--out must end in {', '.join(suffixes)}, got {args.out!r}")
        if Path(args.out).suffix.lower() != ".npz":
            from shipsense.recording.formats import check_writable

            check_writable(args.out)
        if Path(args.out).suffix.lower() in SUFFIXES["miniseed"] and (args.runs or sc.runs) != 1:
            raise BadInput(f"--out {args.out}: a miniSEED file holds one recording; add --runs 1 (or write .csv "
                           "or .nc for several runs)")
    if args.plot is not None and Path(args.plot).suffix != ".png":
        raise BadInput(f"--plot must end in .png, got {args.plot!r}")
    if args.truth is not None and Path(args.truth).suffix.lower() != ".csv":
        raise BadInput(f"--truth must end in .csv, got {args.truth!r}")
    if args.truth is not None and args.out is not None and Path(args.truth).resolve() == Path(args.out).resolve():
        raise BadInput(f"--truth and --out name the same file {args.truth!r}")
    if args.random and sc.prior is None:
        raise BadInput(f"scenario {sc.name!r} has no [prior] section; --random needs one")
    within_budget(args, budget.simulation(sc, args.runs or sc.runs))
    for flag, path in (("--out", args.out), ("--plot", args.plot), ("--truth", args.truth)):
        if path is not None:
            writable(flag, path)
    bar = progress_bar(4, f"simulate {sc.name}")
    sim = simulate(sc, runs=args.runs, seed=args.seed, random=args.random)
    bar.update(1)
    # every file or none: each is written to a temporary name and renamed once all are written
    with (atomic_path(args.out) if args.out else nullcontext()) as out_tmp, \
            (atomic_path(args.plot) if args.plot else nullcontext()) as plot_tmp, \
            (atomic_path(args.truth) if args.truth else nullcontext()) as truth_tmp:
        if args.out:
            bar.set_description(f"write {args.out}")
            if Path(args.out).suffix.lower() == ".npz":
                sim.save_npz(out_tmp)
            else:
                from shipsense.recording import write_recording

                write_recording(sim, out_tmp)
        bar.update(1)
        if args.plot:
            from shipsense.plotting import plot_simulation

            bar.set_description(f"plot {args.plot}")
            plot_simulation(sim, plot_tmp)
        bar.update(1)
        if args.truth:
            bar.set_description(f"write {args.truth}")
            from shipsense.recording.tidy_csv import write_truth

            write_truth(sim, truth_tmp)
        bar.update(1)
    bar.close()
    _print_summary(sim)
    for what, path in (("measurements", args.out), ("plot", args.plot), ("truth", args.truth)):
        if path:
            print(f"wrote {what}: {path}")
    return EXIT_OK


def _print_summary(sim):
    """A short table per sensor: closest approach, peak field, peak SNR (run 0)."""
    arr = sim.array
    pos = sim.positions[0]
    print(f"scenario {sim.scenario.name}: {sim.runs} run(s) x {sim.times.size} steps of {sim.scenario.period:g} s, "
          f"{arr.n_channels} channels from {len(arr.ids)} sensors")
    if sim.ship_count is not None:
        print(f"  ships in run 0: {int(sim.ship_count[0])} (closest approach below: ship 0's; peaks: all ships' "
              "readings together)")
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
    from shipsense.atomic import staged_directory
    from shipsense.cli.track import describe, track_to_files
    from shipsense.config import load_scenario
    from shipsense.plotting import plot_simulation, plot_track
    from shipsense.simulator import simulate

    out = Path(args.out)
    writable("--out", out, directory=True)
    sc = load_scenario("demo")
    first_use("demo")
    bar = progress_bar(3, "demo: simulate")
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


def cmd_track(args) -> int:
    from shipsense import budget
    from shipsense.atomic import staged_directory
    from shipsense.cli.track import describe, track_to_files
    from shipsense.config import load_scenario
    from shipsense.trackers.filters import FILTER_NAMES

    sc = load_scenario(args.scenario)
    if args.filter is not None and args.filter not in FILTER_NAMES:
        raise BadInput(f"--filter must be one of {', '.join(FILTER_NAMES)}, got {args.filter!r}")
    if args.passage_gap is not None and not (args.passage_gap > 0 and np.isfinite(args.passage_gap)):
        raise BadInput(f"--passage-gap must be a positive number of seconds, got {args.passage_gap!r}")
    if args.ships != "1" and (args.method != "tracker" or args.filter is not None):
        raise BadInput("--ships 2|auto runs the several-ship tracker: --method bank and --filter do not apply")
    out = Path(args.out)
    writable("--out", out, directory=True)
    if args.data:
        from shipsense.cli.recordings import track_recordings

        return track_recordings(args, sc)
    for flag in ("mapping", "passage_gap"):
        if getattr(args, flag) is not None:
            raise BadInput(f"--{flag.replace('_', '-')} applies to recordings (--data)")
    within_budget(args, budget.tracking(sc, sc.steps, what=f"a simulated passage of {sc.name} ({sc.steps} steps)"))
    from shipsense.simulator import simulate

    sim = simulate(sc, runs=1, seed=args.seed, random=args.random)
    times, y, truth = sim.times, sim.measurements[0], sim.truth[0]
    used_seed = sc.seed if args.seed is None else args.seed
    source = f"simulated {'random' if args.random else 'nominal'} passage of {sc.name} (seed {used_seed})"
    first_use("track", args.filter)
    if args.ships != "1":
        return _track_ships(args, sc, out, sim, source)
    with staged_directory(out) as stage:   # the tables and the plot, or nothing
        try:
            summary = track_to_files(sc, times, y, stage, truth=truth, method=args.method, unit=args.filter,
                                     progress=not QUIET["on"])
        except ValueError as err:
            raise BadInput(str(err)) from None
        if not args.no_plot:
            from shipsense.plotting import plot_track

            plot_track(summary, times, stage / "track.png", truth=truth,
                       title=f"{sc.name}: {args.method} (2-sigma ellipses)")
    for line in describe(summary, source):
        print(line)
    print(f"wrote {out / 'estimates.csv'}, {out / 'selection_log.csv'}"
          + ("" if args.no_plot else f" and {out / 'track.png'}"))
    return EXIT_OK


def _track_ships(args, sc, out, sim, source) -> int:
    """``track --ships 2|auto`` of a simulated passage: the several-ship tracker (:mod:`shipsense.cli.ships`)."""
    from shipsense.atomic import staged_directory
    from shipsense.cli.ships import describe_ships, track_ships_into

    truth = sim.ships[0] if sim.companions is not None else sim.truth[:1]
    with staged_directory(out) as stage:
        summary = track_ships_into(sc, sim.times, sim.measurements[0], stage, args,
                                   f"{sc.name}: several ships (2-sigma ellipses)", truth=truth)
    for line in describe_ships(summary, source):
        print(line)
    print(f"wrote {out / 'estimates.csv'}" + ("" if args.no_plot else f" and {out / 'track.png'}"))
    return EXIT_OK
