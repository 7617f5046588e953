"""Commands on layouts: ``check`` (the CI gate) and ``design``."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from shipsense.cli.common import (
    EXIT_BAD_INPUT,
    EXIT_OK,
    QUIET,
    VERDICT_EXIT,
    BadInput,
    first_use,
    within_budget,
    writable,
)
from shipsense.errors import ShipsenseError


def cmd_check(args) -> int:
    import json

    from shipsense import budget
    from shipsense.atomic import atomic_write_bytes
    from shipsense.config import load_scenario
    from shipsense.design.gate import check_layouts, junit_xml, worst
    from shipsense.design.observability import first_use_notice

    if args.junit is not None and Path(args.junit).suffix != ".xml":
        raise BadInput(f"--junit must end in .xml, got {args.junit!r}")
    budget.check_limits(args.max_memory, args.max_minutes)
    if args.junit is not None:
        writable("--junit", args.junit)
    works = []   # the whole run is within the limits, not each file (a file that does not load is its own error)
    for layout in args.layout:
        try:
            works.append(budget.check(load_scenario(layout), args.passages))
        except (ShipsenseError, OSError):
            pass
    if works:
        within_budget(args, budget.sequence(works, f"checking {len(works)} layout(s) on {args.passages} passages "
                                             "each", works[0].fewer + " or files"))
    first_use("check", notice=first_use_notice)
    results = check_layouts(args.layout, passages=args.passages, seed=args.seed,
                            progress=not (args.json or QUIET["on"]), errors=(ShipsenseError, OSError))
    if args.junit is not None:
        Path(args.junit).parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(Path(args.junit), junit_xml(results))
    if args.json:
        docs = [{"layout": r.layout, "verdict": "error", "error": r.detail} if r.verdict == "error"
                else {"layout": r.layout, **r.detail.to_json(), "resolvability": r.resolvability.to_json()}
                for r in results]
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
    # labelled by the file (or shipped name) as given, as the JSON and the JUnit report are: two files may hold
    # scenarios of one name
    print(f"{result.layout}: {verdict.verdict.upper()}  ({len(sc.sensors)} sensors, {verdict.passages} passage(s) "
          f"{'from the prior' if sc.prior is not None else '(the nominal one)'}"
          f"{f', {verdict.manoeuvring} manoeuvring' if verdict.manoeuvring else ''}; {result.seconds:.1f} s)")
    print(f"  Fisher information: rank {verdict.fim_rank} of {len(verdict.labels)}, "
          f"condition number {verdict.fim_condition:.3g} (internal units)")
    print(f"  closest far-apart passage: chi-square {verdict.min_chi2:.3g} (ambiguous below 25)")
    print(f"  {result.resolvability.describe()}")
    for p in verdict.pairs[:5]:
        a, b = p.passage, p.alternative
        print(f"  ambiguous pair ({p.source}): start ({a[0]:.0f}, {a[1]:.0f}) m heading "
              f"{np.degrees(np.arctan2(a[3], a[2])):.0f} deg  vs  ({b[0]:.0f}, {b[1]:.0f}) m heading "
              f"{np.degrees(np.arctan2(b[3], b[2])):.0f} deg; chi-square {p.chi2:.3g}, {p.distance_m:.0f} m apart")


def cmd_design(args) -> int:
    from shipsense import budget
    from shipsense.config import load_scenario
    from shipsense.design.candidates import load_candidates
    from shipsense.design.designer import default_candidates, design_array, summary_lines, write_design
    from shipsense.design.observability import first_use_notice

    out = Path(args.out)
    if out.suffix.lower() in (".toml", ".json", ".png"):
        raise BadInput(f"--out is the report folder (it gets layout.toml, design.json, design.png, bounds.png), "
                        f"not a file: got {args.out}")
    writable("--out", out, directory=True)
    sc = load_scenario(args.scenario)
    cands, costs = (None, None) if not args.candidates else load_candidates(args.candidates, sc)
    n_cands = len(cands) if cands is not None else len(default_candidates(sc))
    within_budget(args, budget.design(sc, n_cands, args.passages if sc.prior is not None else 1,
                                      budget.subset_search(args.k, n_cands, args.bb_work, args.bb_seconds)))
    first_use("design", notice=first_use_notice)
    try:
        result = design_array(sc, args.k, criterion=args.criterion, candidates=cands, costs=costs, budget=args.budget,
                              passages=args.passages, seed=args.seed, solver=args.solver, cuts=not args.no_cuts,
                              prior_floor=args.prior_floor, bb_work=args.bb_work, bb_seconds=args.bb_seconds,
                              progress=not QUIET["on"], separation=args.separation)
    except ValueError as err:
        raise BadInput(str(err)) from None
    paths = write_design(result, out)
    for line in summary_lines(result):
        print(line)
    print(f"wrote {out}/: " + ", ".join(p.name for p in paths) + f" (check the layout with `shipsense check "
          f"{paths[0]}`)")
    return EXIT_OK
