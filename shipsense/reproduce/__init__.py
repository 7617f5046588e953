"""The reference experiments (scenarios.md): ``shipsense reproduce S0|S1|S2``, and ``wide`` (issue 7).

Each ``run(runs, out, seed, progress)`` writes ``summary.json``, CSV tables
and PNG figures into ``out`` and returns the summary.  The keys of
``summary.json`` are stable (see EXPERIMENTS.md).
"""

from __future__ import annotations

EXPERIMENTS = {"S0": ("shipsense.reproduce.s0", 200), "S1": ("shipsense.reproduce.s1", 100),
               "S2": ("shipsense.reproduce.s2", 100), "WIDE": ("shipsense.reproduce.wide", 500)}


def run(name: str, runs: int | None = None, out=None, seed: int = 0, progress: bool = True, **options):
    """Run the experiment set ``name`` (S0, S1, S2 or wide); ``options`` go to the wide study's ``run``
    (``workers``, ``scheduler``, ``restart``: :func:`shipsense.reproduce.wide.run`)."""
    from importlib import import_module

    key = name.upper()
    if key not in EXPERIMENTS:
        raise ValueError(f"unknown experiment set {name!r}; choose one of {', '.join(EXPERIMENTS)}")
    module, default_runs = EXPERIMENTS[key]
    folder = "wide" if key == "WIDE" else key
    if options and key != "WIDE":
        raise ValueError(f"{', '.join(options)}: only the wide study takes them")
    return import_module(module).run(runs=runs or default_runs, out=out or f"results/{folder}", seed=seed,
                                     progress=progress, **options)
