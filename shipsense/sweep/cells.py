"""A sweep's cells (layout x site condition) and its tasks (chunks of passages), with their derived seeds.

A cell is a validated scenario: the base scenario with the layout's sensors
and the condition applied.  Its key is a hash of the layout's name, that
scenario and the way it is scored, so it names the cell whatever else the
sweep holds (two methods that design the same layout are two cells).  A
task is ``passages`` consecutive passages of one cell (or the cell's
ambiguity check); its seed is derived from the sweep seed and the cell's
condition (:class:`numpy.random.SeedSequence` with ``spawn_key =
(condition, chunk)``), so a task's result is a pure function of the task,
however the work is scheduled.  Every layout under one condition sees the
same draws (common random numbers): the differences between layouts are
the layouts', not passage-to-passage noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shipsense.sweep.spec import MAX_TASKS, LayoutSpec, SweepError, SweepSpec
from shipsense.tasks import canonical_hash

AMBIGUITY_CHUNK = -1
"""Chunk number of a cell's ambiguity check (one per cell, when the metric is asked for)."""
DESCRIPTIVE = ("description",)
"""Scenario fields left out of a cell's key: prose, which does not change what a result is (editing a
scenario's description keeps its cells' finished tasks)."""


@dataclass(frozen=True)
class Cell:
    """One layout under one site condition."""

    index: int
    key: str         # the hash of what the cell's results are: layout, scenario (less DESCRIPTIVE), method, metrics
    layout: str
    condition: dict
    scenario: dict   # a validated scenario, JSON-able (``Scenario.model_dump(mode="json")``)
    draws: str       # key of the cell's random draws: its condition's (common to every layout under it)


@dataclass(frozen=True)
class Task:
    """A unit of work: passages ``first .. first + passages - 1`` of a cell, or its ambiguity check."""

    cell: Cell
    chunk: int
    first: int
    passages: int
    seed: int
    method: str
    metrics: tuple

    @property
    def name(self) -> str:
        """File stem of the task's result: ``<cell key>-c<chunk>`` or ``<cell key>-ambiguity``."""
        return f"{self.cell.key}-ambiguity" if self.chunk == AMBIGUITY_CHUNK else f"{self.cell.key}-c{self.chunk:05d}"


def layout_positions(layout: LayoutSpec, z: float) -> np.ndarray:
    """Sensor positions (N, 3) of a generated layout, centred on ``layout.center`` at height ``z``.

    ``line``: ``n`` sensors ``spacing`` apart along the direction ``angle_deg``
    (counter-clockwise from east; 90 is a north-south line); ``triangle``: an
    equilateral triangle of side ``side`` whose first vertex lies in the
    direction ``angle_deg`` from its centroid; ``grid``: ``shape`` = (columns,
    rows) sensors ``spacing`` apart, rotated by ``angle_deg - 90``.
    """
    a = math.radians(layout.angle_deg)
    if layout.generator == "line":
        s = (np.arange(layout.n) - (layout.n - 1) / 2) * layout.spacing
        xy = s[:, None] * np.array([math.cos(a), math.sin(a)])
    elif layout.generator == "triangle":
        r = layout.side / math.sqrt(3.0)
        ang = a + np.array([0.0, 2.0, 4.0]) * math.pi / 3
        xy = r * np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    else:
        nx, ny = layout.shape
        gx, gy = np.meshgrid((np.arange(nx) - (nx - 1) / 2) * layout.spacing,
                             (np.arange(ny) - (ny - 1) / 2) * layout.spacing, indexing="ij")
        t = a - math.pi / 2
        rot = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
        xy = np.stack([gx.ravel(), gy.ravel()], axis=-1) @ rot.T
    xy = xy + np.asarray(layout.center)
    return np.column_stack([xy, np.full(len(xy), z)])


def _resolve(ref: str, base_dir: Path) -> str | Path:
    from shipsense.config import shipped_scenarios

    path = base_dir / ref
    if path.is_file():
        return path
    if ref.lower() in {n.lower() for n in shipped_scenarios()}:
        return ref
    raise SweepError(f"{ref}: no such file (relative to {base_dir}), and not a shipped scenario")


def _layout_sensors(spec: SweepSpec, layout: LayoutSpec, base, base_dir: Path) -> list[dict]:
    from shipsense.config import ScenarioError, load_scenario

    if layout.file is not None:
        try:
            sc = load_scenario(_resolve(layout.file, base_dir))
        except ScenarioError as err:
            raise SweepError(f"layouts[{layout.name!r}].file: {err}") from None
        return [s.model_dump(mode="json") for s in sc.sensors]
    ids = [s.id for s in base.sensors]
    if spec.template is not None and spec.template not in ids:
        raise SweepError(f"template: {spec.template!r} is not a sensor of the base scenario ({', '.join(ids)})")
    template = base.sensors[ids.index(spec.template) if spec.template is not None else 0]
    positions = layout_positions(layout, template.position[2])
    t = template.model_dump(mode="json")
    return [{**t, "id": f"{layout.name}-{i + 1}", "position": [float(v) for v in p]} for i, p in enumerate(positions)]


def _apply(data: dict, sensors: list[dict], condition: dict) -> dict:
    """The base scenario's fields with a layout's sensors and a condition applied (plain dicts)."""
    data = {**data, "sensors": [dict(s) for s in sensors]}
    medium = dict(data.get("medium") or {})
    passage, prior, noise = dict(data["passage"]), dict(data.get("prior") or {}), dict(data.get("noise") or {})
    base_depth = medium.get("water_depth")
    for key, v in condition.items():
        if key == "water_depth":
            for s in data["sensors"]:   # a sensor on the seabed stays on it
                if base_depth is not None and abs(s["position"][2] + base_depth) < 1e-9:
                    s["position"] = [s["position"][0], s["position"][1], -float(v)]
            medium["water_depth"] = v
        elif key in ("sigma_water", "sigma_seabed"):
            medium[key] = v
        elif key == "noise_scale":
            for s in data["sensors"]:
                if s.get("noise_std") is not None:
                    s["noise_std"] = _scaled(s["noise_std"], v)
                else:
                    s["noise_var"] = _scaled(s["noise_var"], v * v)
        elif key == "source_scale":
            for d in (passage, prior):
                if d.get("moment") is not None:
                    d["moment"] = _scaled(d["moment"], v)
                if d.get("p") is not None:
                    d["p"] = _scaled(d["p"], v)
        elif key.startswith("prior_"):
            prior[key.removeprefix("prior_")] = list(v)
        elif key == "dropout":
            noise["dropout"] = v
        elif key == "outlier_eps":
            noise["model"], noise["eps"] = ("contaminated", v) if v > 0 else ("gaussian", noise.get("eps", 0.1))
        elif key == "manoeuvre_probability":
            manoeuvres = dict(data.get("manoeuvres") or {})
            manoeuvres["random"] = {**(manoeuvres.get("random") or {}), "probability": v}
            data["manoeuvres"] = manoeuvres
    if medium:
        data["medium"] = medium
    data.update(passage=passage, prior=prior or None, noise=noise or None)
    return {k: v for k, v in data.items() if v is not None}


def _scaled(v, f):
    return [x * f for x in v] if isinstance(v, list) else v * f


def build_cells(spec: SweepSpec, base_dir: Path) -> list[Cell]:
    """Every (layout, condition) cell of a sweep, as a validated scenario; raises :class:`SweepError`."""
    from shipsense.config import ScenarioError, load_scenario, validate_scenario

    try:
        base = load_scenario(_resolve(spec.scenario, base_dir))
    except ScenarioError as err:
        raise SweepError(f"scenario: {err}") from None
    if base.prior is None:
        raise SweepError(f"scenario: {spec.scenario} has no [prior]: a sweep draws its passages from it")
    data = base.model_dump(mode="json", exclude_none=True)
    conditions = spec.condition_sets()
    cells = []
    for layout in spec.layouts:
        sensors = _layout_sensors(spec, layout, base, base_dir)
        for cond in conditions:
            where = f"layout {layout.name!r}" + (f" under {cond}" if cond else "")
            try:
                sc = validate_scenario(_apply(data, sensors, cond), f"{where}: the cell's scenario")
            except ScenarioError as err:
                raise SweepError(str(err)) from None
            scenario = sc.model_dump(mode="json")
            what = {k: v for k, v in scenario.items() if k not in DESCRIPTIVE}   # (prose is not what a result is)
            key = canonical_hash({"layout": layout.name, "scenario": what, "method": spec.method,
                                  "metrics": sorted(spec.metrics), "ambiguity_passages": spec.ambiguity_passages})[:16]
            draws = canonical_hash({"condition": cond})[:16]
            cells.append(Cell(len(cells), key, layout.name, dict(cond), scenario, draws))
    if len({c.key for c in cells}) != len(cells):   # names are unique, so only a repeated condition does this
        raise SweepError("conditions: a combination of conditions is repeated (combine = 'list' with equal rows?)")
    return cells


def derive_seed(sweep_seed: int, draws_key: str, chunk: int) -> int:
    """A task's seed: ``SeedSequence(sweep_seed, spawn_key=(draws, chunk))`` as one 63-bit integer (``draws``:
    the key of the cell's condition, :attr:`Cell.draws`)."""
    ss = np.random.SeedSequence(sweep_seed, spawn_key=(int(draws_key[:8], 16), chunk % 2**32))
    hi, lo = ss.generate_state(2, dtype=np.uint32)
    return (int(hi) << 31) ^ int(lo)


def make_tasks(spec: SweepSpec, cells: list[Cell]) -> list[Task]:
    """The sweep's tasks in a fixed order: for each cell its chunks, then its ambiguity check."""
    per_cell = math.ceil(spec.passages / spec.chunk) + ("ambiguity" in spec.metrics)
    if per_cell * len(cells) > MAX_TASKS:
        raise SweepError(f"chunk: {len(cells)} cells x {per_cell} tasks each is over {MAX_TASKS:,} tasks; "
                         "raise chunk or lower passages")
    metrics = tuple(spec.metrics)
    tasks = []
    for cell in cells:
        for c, first in enumerate(range(0, spec.passages, spec.chunk)):
            n = min(spec.chunk, spec.passages - first)
            tasks.append(Task(cell, c, first, n, derive_seed(spec.seed, cell.draws, c), spec.method, metrics))
        if "ambiguity" in spec.metrics:
            tasks.append(Task(cell, AMBIGUITY_CHUNK, 0, spec.ambiguity_passages,
                              derive_seed(spec.seed, cell.draws, AMBIGUITY_CHUNK), spec.method, metrics))
    return tasks
