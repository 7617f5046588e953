"""Running a sweep: serially or on Dask, resumable, each finished task written atomically.

Output folder ``DIR``::

    sweep.json           the sweep's hash, its spec, seed, versions, counts and timing
    chunks/*.parquet     one file per finished task (``<cell>-c<chunk>``, ``<cell>-ambiguity``)
    results.parquet      one row per cell and metric (and results.csv with ``csv=True``)
    passages.parquet     one row per passage
    <metric>.png         the metric by layout and condition, with 95 % intervals

Results are written by the process that runs the sweep, as tasks finish
(a temporary file, then an atomic rename), so workers need no shared
filesystem and a task that runs twice (a worker lost mid-task) rewrites the
same file with the same rows.  The folder is a :class:`~shipsense.tasks.TaskStore`
marked by ``sweep.json``: rerunning the same sweep into the same folder skips
the finished tasks; a different sweep is refused unless ``restart``, which
starts afresh.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

from shipsense.parallel import dask_client
from shipsense.sweep.cells import Task, build_cells, make_tasks
from shipsense.sweep.spec import SweepError, SweepSpec
from shipsense.sweep.store import table_bytes
from shipsense.tasks import TaskStore, canonical_hash

OWN_FILES = ("results.parquet", "results.csv", "passages.parquet", "*.png")
"""What a sweep writes into its folder beside the marker and the chunks (removed with them on a restart)."""


@dataclass
class SweepRun:
    """What :func:`run_sweep` did: the folder, task counts and timing (seconds)."""

    out: Path
    cells: int
    tasks: int
    skipped: int
    ran: int
    wall_seconds: float
    task_seconds: float
    workers: int


FORMAT = 3
"""Version of the folder layout and of the seed derivation (2: common random numbers per condition; 3: a cell's
key leaves out the scenario's description, :data:`~shipsense.sweep.cells.DESCRIPTIVE`, so its tasks' file names
changed); part of the sweep hash, so that a folder written by another scheme is never resumed."""


def sweep_hash(spec: SweepSpec) -> str:
    """The identity of a sweep: the hash of its validated spec (formatting and comments do not count) and of
    :data:`FORMAT`.  (A folder written by another shipsense version with the same scheme is resumed: the
    versions are in ``sweep.json``.)"""
    return canonical_hash({"format": FORMAT, "spec": spec.model_dump(mode="json")})


def _meta(spec: SweepSpec) -> dict:
    """What ``sweep.json`` records beside the hash: the sweep's name and seed, and the package versions."""
    from importlib.metadata import PackageNotFoundError, version

    versions = {"python": sys.version.split()[0]}
    for pkg in ("shipsense", "numpy", "scipy", "dask", "distributed", "pandas", "pyarrow"):
        try:
            versions[pkg] = version(pkg)
        except PackageNotFoundError:
            versions[pkg] = None
    return {"name": spec.name, "seed": spec.seed, "versions": versions}


def sweep_store(out, spec: SweepSpec) -> TaskStore:
    """The sweep's output folder ``out`` (:class:`~shipsense.tasks.TaskStore`), marked by ``sweep.json``."""
    return TaskStore(out, {"sweep_hash": sweep_hash(spec)}, marker="sweep.json", what="sweep", owns=OWN_FILES,
                     error=SweepError)


def run_sweep(spec: SweepSpec, base_dir, out, *, workers: int | None = None, scheduler: str | None = None,
              client=None, restart: bool = False, csv: bool = False, progress: bool | None = None,
              log=print) -> SweepRun:
    """Run (or resume) a sweep into ``out``; returns what was done.

    Parameters
    ----------
    spec : SweepSpec
    base_dir : path
        Folder the sweep file's relative paths are taken from.
    out : path
        Output folder (see the module docstring).
    workers : int, optional
        ``0``: run serially in this process; ``N``: a local Dask cluster of N
        single-threaded worker processes (default: the machine's cores).
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``) instead of a local cluster.
    client : distributed.Client, optional
        An existing client (overrides ``workers`` and ``scheduler``).
    restart : bool
        Start afresh in a folder holding this sweep's or another sweep's results (discarding them).
    csv : bool
        Also write ``results.csv``.
    progress : bool, optional
        A progress bar (default: only on a terminal).
    """
    from shipsense.sweep.results import summarise

    out = Path(out)
    cells = build_cells(spec, Path(base_dir))
    tasks = make_tasks(spec, cells)
    store = sweep_store(out, spec)
    done = store.finished() if store.check(restart) else set()
    todo = [t for t in tasks if t.name not in done]
    skipped = len(tasks) - len(todo)
    log(f"sweep {spec.name!r}: {len(cells)} cells, {len(tasks)} tasks"
        + (f"; {skipped} already finished in {out}, {len(todo)} to run" if skipped else ""))
    t0 = time.perf_counter()
    # the client first: a scheduler that does not answer leaves no folder behind
    with dask_client(workers, scheduler, client, needed=bool(todo), log=log) as client:
        store.begin(**_meta(spec), status="running", cells=len(cells), tasks=len(tasks))
        task_seconds, n_workers = _execute(todo, store, client, progress)
    wall = time.perf_counter() - t0
    summarise(spec, cells, out, csv=csv)
    store.mark(**_meta(spec), status="complete", cells=len(cells), tasks=len(tasks), skipped=skipped, ran=len(todo),
               wall_seconds=wall, task_seconds=task_seconds, workers=n_workers, sweep=spec.model_dump(mode="json"))
    return SweepRun(out, len(cells), len(tasks), skipped, len(todo), wall, task_seconds, n_workers)


def _progress_bar(total, enabled):
    from tqdm import tqdm

    return tqdm(total=total, desc="sweep", unit="task", file=sys.stderr,
                disable=(not enabled) if enabled is not None else not sys.stderr.isatty())


def _store(store: TaskStore, task: Task, table: dict) -> float:
    store.write(f"{task.name}.parquet", table_bytes(table))
    return float(sum(table["seconds"])) if task.chunk < 0 else float(table["seconds"][0]) * task.passages


def _execute(todo, store, client, progress):
    """Run the sweep's tasks ``todo`` and store each result as it arrives; returns (task seconds, workers)."""
    from shipsense.sweep.evaluate import run_task

    spent = [0.0]

    def keep(task, table):
        spent[0] += _store(store, task, table)

    def describe(task):
        return f"task {task.name} (layout {task.cell.layout!r}, condition {task.cell.condition})"

    workers = execute(todo, run_task, keep, client, progress, describe=describe, key="shipsense-sweep")
    return spent[0], workers


def execute(tasks, run, store, client=None, progress=None, *, describe=None, key="shipsense"):
    """Run ``run(task)`` for every task -- in this process without a ``client``, else on its Dask cluster --
    and call ``store(task, result)`` in this process as each result arrives (so workers need no shared
    filesystem).  A task's own failure cancels the rest and raises :class:`SweepError` naming it
    (``describe(task)``, default its ``name``); what was stored before stays.  Returns the number of
    workers (0 when run here).  The sweep and ``shipsense reproduce wide`` run on it."""
    if not tasks:
        return 0
    describe = describe or (lambda t: f"task {t.name}")
    bar = _progress_bar(len(tasks), progress)
    try:
        if client is None:
            for task in tasks:
                store(task, run(task))
                bar.update(1)
            return 0
        from distributed import as_completed

        n_workers = len(client.scheduler_info().get("workers", {}))
        futures = {client.submit(run, t, key=f"{key}-{t.name}", pure=False, retries=2): t for t in tasks}
        for fut in as_completed(futures):
            task = futures[fut]
            try:
                result = fut.result()
            except Exception as err:   # a task's own failure: name it, keep what finished
                for f in futures:
                    f.cancel()
                raise SweepError(f"{describe(task)} failed: {type(err).__name__}: {err}") from err
            store(task, result)
            bar.update(1)
        return n_workers
    finally:
        bar.close()
