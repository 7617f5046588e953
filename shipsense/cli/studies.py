"""Commands that run studies: ``reproduce`` and ``sweep``."""

from __future__ import annotations

import time
from pathlib import Path

from shipsense.cli.common import EXIT_OK, QUIET, BadInput, within_budget


def cmd_reproduce(args) -> int:
    from shipsense import budget
    from shipsense.reproduce import EXPERIMENTS, run, run_all
    from shipsense.sweep import SweepError

    key = args.name.upper()
    if key not in (*EXPERIMENTS, "ALL"):
        raise BadInput(f"unknown experiment set {args.name!r}; choose one of {', '.join(EXPERIMENTS)}, all")
    workers = args.workers
    if workers is None and args.scheduler is None and key in ("S0", "S1", "S2"):
        workers = 0   # one study is one task: in this process unless a cluster is asked for
    options = {"workers": workers, "scheduler": args.scheduler, "restart": args.restart}
    within_budget(args, budget.study(key, args.runs))
    try:
        if key == "ALL":
            out = Path(args.out or "results")
            t0 = time.perf_counter()
            summaries = run_all(runs=args.runs, out=out, seed=args.seed, progress=not QUIET["on"], **options)
            print(f"ALL: {', '.join(summaries)} in {time.perf_counter() - t0:.1f} s; wrote {out}/<study>/")
            return EXIT_OK
        out = Path(args.out or f"results/{'wide' if key == 'WIDE' else key}")
        summary = run(key, runs=args.runs, out=out, seed=args.seed, progress=not QUIET["on"], **options)
    except SweepError as err:
        raise BadInput(str(err)) from None
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
            raise BadInput("give SWEEP.toml and --out DIR (or --example, or --report DIR)")
        spec, base = load_sweep(args.sweep)
        run = run_sweep(spec, base, args.out, workers=args.workers, scheduler=args.scheduler, restart=args.restart,
                        csv=args.csv, progress=False if args.quiet else None,
                        log=(lambda *a, **k: None) if args.quiet else print)
    except SweepError as err:
        raise BadInput(str(err)) from None
    print(f"ran {run.ran} of {run.tasks} tasks ({run.skipped} already finished) in {run.wall_seconds:.1f} s; "
          f"wrote {Path(args.out) / 'results.parquet'}" + (" and results.csv" if args.csv else "")
          + ", passages.parquet and one PNG per metric")
    return EXIT_OK
