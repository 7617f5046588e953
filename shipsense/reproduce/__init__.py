"""The reference experiments: ``shipsense reproduce S0|S1|S2``, ``wide`` (the wide-prior study), and ``all``.

Each study's ``run(runs, out, seed, progress)`` writes ``summary.json``, CSV
tables and PNG figures into ``out`` and returns the summary.  The keys of
``summary.json`` are stable (see docs: Results).

They run on the sweep's path (:func:`shipsense.sweep.runner.execute`):
S0, S1 and S2 are one task each -- run in a scratch folder on a worker, their
files returned and written atomically into ``OUT/<study>`` by this process,
``summary.json`` last, in a folder marked by ``run.json``
(:class:`~shipsense.tasks.TaskStore`), so a finished study is skipped when the
same command runs again -- and the wide study is its chunks
(:func:`shipsense.reproduce.wide.run`).  ``all`` runs the three studies side
by side on one Dask cluster, then the wide study's chunks on it.
"""

from __future__ import annotations

import json
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

EXPERIMENTS = {"S0": ("shipsense.reproduce.s0", 200), "S1": ("shipsense.reproduce.s1", 100),
               "S2": ("shipsense.reproduce.s2", 100), "WIDE": ("shipsense.reproduce.wide", 500)}
STUDIES = ("S0", "S1", "S2")


def run(name: str, runs: int | None = None, out=None, seed: int = 0, progress: bool = True, **options):
    """Run the experiment set ``name`` (S0, S1, S2 or wide) into ``out`` (default ``results/NAME``).

    ``options``: ``workers`` (0: in this process, the default for one study; N: a local Dask cluster of N
    processes; None: one per core), ``scheduler`` (an existing cluster), ``restart`` (start afresh in a
    folder holding this run's or another run's results) -- see :func:`run_studies` and
    :func:`shipsense.reproduce.wide.run`."""
    from importlib import import_module

    key = name.upper()
    if key not in EXPERIMENTS:
        raise ValueError(f"unknown experiment set {name!r}; choose one of {', '.join(EXPERIMENTS)}")
    module, default_runs = EXPERIMENTS[key]
    folder = "wide" if key == "WIDE" else key
    if key == "WIDE":
        return import_module(module).run(runs=runs or default_runs, out=out or f"results/{folder}", seed=seed,
                                         progress=progress, **options)
    return run_studies([key], runs, Path(out or f"results/{folder}").parent, seed, progress,
                       folders={key: Path(out or f"results/{folder}")}, **options)[key]


@dataclass(frozen=True)
class StudyTask:
    """One reference study (S0, S1 or S2) as a task."""

    study: str
    runs: int
    seed: int

    @property
    def name(self) -> str:
        return self.study

    def identity(self) -> dict:
        return {"study": self.study, "runs": self.runs, "seed": self.seed}


def run_study(task: StudyTask) -> dict:
    """Run a study in a scratch folder (on a worker or here); returns its summary and its files' bytes."""
    from importlib import import_module

    module, _ = EXPERIMENTS[task.study]
    with tempfile.TemporaryDirectory(prefix=f"shipsense-{task.study}-") as tmp:
        summary = import_module(module).run(runs=task.runs, out=tmp, seed=task.seed, progress=False)
        files = {str(p.relative_to(tmp)): p.read_bytes() for p in sorted(Path(tmp).rglob("*")) if p.is_file()}
    return {"summary": summary, "files": files}


def _summary(store) -> Path:
    return store.folder / "summary.json"


def run_studies(names, runs=None, out="results", seed=0, progress=True, *, workers=0, scheduler=None, client=None,
                restart=False, folders=None, log=print):
    """Run studies ``names`` (of S0, S1, S2) as tasks, each into ``out/<name>`` (or ``folders[name]``), a
    :class:`~shipsense.tasks.TaskStore` whose identity is the study, runs and seed.  A study is finished when
    its folder holds its ``summary.json`` (written last): then it is skipped and its summary read back; another
    run's folder is refused; ``restart`` runs a study afresh in either.  Returns {name: summary}."""
    from shipsense.atomic import atomic_write_bytes
    from shipsense.parallel import dask_client
    from shipsense.sweep.runner import execute
    from shipsense.tasks import TaskStore

    tasks = [StudyTask(n, runs or EXPERIMENTS[n][1], seed) for n in names]
    stores = {t.study: TaskStore(Path((folders or {}).get(t.study, Path(out) / t.study)), t.identity(),
                                 what=f"{t.study} run", owns=("summary.json",)) for t in tasks}
    todo = [t for t in tasks if not (stores[t.study].check(restart) and _summary(stores[t.study]).is_file())]
    if len(todo) < len(tasks):
        log(f"reproduce: {len(tasks) - len(todo)} of {len(tasks)} studies already finished, {len(todo)} to run")
    summaries = {}

    def keep(task, result):
        folder = stores[task.study]
        folder.begin()   # (a restart's summary removed first: the study is not finished until it is back)
        files = result["files"]
        for rel in sorted(files, key=lambda rel: rel == "summary.json"):
            path = folder.folder / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(path, files[rel])
        summaries[task.study] = result["summary"]

    t0 = time.perf_counter()
    with dask_client(workers, scheduler, client, needed=bool(todo), log=log) as client:
        execute(todo, run_study, keep, client, None if progress else False, key="shipsense-reproduce")
    for t in tasks:
        if t.study not in summaries:   # finished before: read back
            summaries[t.study] = json.loads(_summary(stores[t.study]).read_text())
    log(f"reproduce: {', '.join(names)} in {time.perf_counter() - t0:.1f} s")
    return summaries


def run_all(runs=None, out="results", seed=0, progress=True, *, workers=None, scheduler=None, restart=False,
            log=print):
    """S0, S1 and S2 side by side, then the wide study's chunks, on one Dask cluster (``workers``: None = one
    per core, 0 = this process); returns {name: summary}."""
    from shipsense.parallel import dask_client
    from shipsense.reproduce import wide

    with dask_client(workers, scheduler, log=log) as client:
        out_all = run_studies(STUDIES, runs, out, seed, progress, client=client, workers=0, restart=restart, log=log)
        out_all["WIDE"] = wide.run(runs=runs or EXPERIMENTS["WIDE"][1], out=Path(out) / "wide", seed=seed,
                                   progress=progress, client=client, workers=0, restart=restart, log=log)
    return out_all
