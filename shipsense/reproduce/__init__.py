"""The reference experiments of the three source studies (scenarios.md): ``shipsense reproduce S0|S1|S2``.

Each ``run(runs, out, seed, progress)`` writes ``summary.json``, CSV tables
and PNG figures into ``out`` and returns the summary.  The keys of
``summary.json`` are stable (see EXPERIMENTS.md).
"""

from __future__ import annotations

EXPERIMENTS = {"S0": ("shipsense.reproduce.s0", 200), "S1": ("shipsense.reproduce.s1", 100),
               "S2": ("shipsense.reproduce.s2", 100)}


def run(name: str, runs: int | None = None, out=None, seed: int = 0, progress: bool = True):
    """Run the experiment set of scenario ``name`` (S0, S1 or S2)."""
    from importlib import import_module

    key = name.upper()
    if key not in EXPERIMENTS:
        raise ValueError(f"unknown experiment set {name!r}; choose one of {', '.join(EXPERIMENTS)}")
    module, default_runs = EXPERIMENTS[key]
    return import_module(module).run(runs=runs or default_runs, out=out or f"results/{key}", seed=seed,
                                     progress=progress)
