"""`shipsense design` as a library call: design an array for a scenario, then write its report.

:func:`design_array` builds the per-candidate Fisher matrices of prior
passages (with the manoeuvres of the scenario's ``[manoeuvres]`` table, drawn as the simulator draws them,
along their true motion: :func:`~shipsense.design.manoeuvre_bound.passage_motion`), solves the relaxation
(:func:`~shipsense.design.placement.place`,
with ambiguity cuts unless disabled), scores baselines on the same passages
and returns a :class:`DesignResult`; :func:`write_design` writes the layout
(TOML), the report (JSON) and the plots, all atomically.  Errors the caller
can cause raise ``ValueError`` with one line naming the argument.

The criterion ``resolvability`` is not a relaxation's: a layout is valued by how well it tells two ships apart
at a given separation (:func:`~shipsense.design.resolvability.set_values`, from the per-candidate joint Fisher
information of twin ships abreast), over every k-subset when there are few enough of them (the design is then
optimal) and otherwise by random starts and exchanges (:func:`~shipsense.design.resolvability.best_set`); no
ambiguity cuts (the design's verdict is reported) and no cost budget.  Every design reports its resolvable
separation (:func:`~shipsense.design.resolvability.resolvable_separation`, as ``shipsense check`` does).
"""

from __future__ import annotations

import io
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from shipsense.design import placement as pl
from shipsense.design import resolvability as rv
from shipsense.json_numbers import finite_or_none

CRITERIA = (*pl.CRITERIA, "resolvability")
"""The design criteria: the relaxation's D, A and E (:data:`~shipsense.design.placement.CRITERIA`) and the
two-ship resolvability at a separation (:func:`~shipsense.design.resolvability.set_values`)."""

RANDOM_LAYOUTS = 1000
BB_GUARD_SECONDS = 120.0
"""Default time guard of the search over subsets (``--bb-seconds``): the search stops on its work; this only
keeps a much slower machine from waiting without end, and the report says when it fired."""


@dataclass
class DesignResult:
    """A designed array and the figures behind it (see :meth:`report` for the JSON keys)."""

    scenario: object            # the scenario designed for
    layout: object              # the designed layout, a scenario with the k sensors
    candidates: np.ndarray      # (N, 3), m
    placement: pl.Placement
    truth: np.ndarray           # the prior passages (S, state), SI
    thetas: np.ndarray          # the same, internal units of the candidate model
    motion: object              # their manoeuvres (a PassageMotion in the candidate model), None: straight
    model: object               # the candidate model
    k: int
    criterion: str
    prior_floor: float | None
    baselines: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    resolvability: object = None   # the design's Resolvability (its two-ship resolvable separation)
    separation: float | None = None   # the separation (m) the resolvability criterion values layouts at

    @property
    def sensors(self) -> np.ndarray:
        return self.candidates[self.placement.chosen]

    def report(self) -> dict:
        """The ``design.json`` document (with ``manoeuvring_passages``, how many of the prior passages
        manoeuvre, when the scenario's manoeuvres make some)."""
        r = self.placement
        manoeuvring = {} if self.motion is None else {"manoeuvring_passages": int(self.motion.manoeuvring.sum())}
        return {
            "criterion": self.criterion, "k": self.k, "candidates": len(self.candidates),
            "passages": len(self.thetas), "method": r.method, "solver": r.solver, "converged": r.converged,
            "solver_status": r.status, "solver_message": r.message, "prior_floor": self.prior_floor,
            "relaxation_objective": finite_or_none(r.relaxation), "upper_bound": finite_or_none(r.upper_bound),
            "design_objective": finite_or_none(r.value), "certified_gap": finite_or_none(r.certified_gap),
            "guaranteed_efficiency": r.guaranteed_efficiency,
            "branch_and_bound": r.branch_and_bound, "ambiguity_cuts": len(r.cuts),
            "verdict": r.verdict.verdict if r.verdict is not None else None,
            "min_chi2": r.verdict.min_chi2 if r.verdict is not None else None,
            "sensors": [list(map(float, p)) for p in self.sensors],
            "baselines": self.baselines,
            "separation_m": self.separation,
            "resolvability": self.resolvability.to_json() if self.resolvability is not None else None,
            "seconds": self.timings.get("total"), "timings": self.timings, **manoeuvring,
        }


def default_candidates(scenario):
    """An 11 x 11 grid around the scenario's array (at least 60 m across), at the template sensor's height."""
    pos = np.array([s.position[:2] for s in scenario.sensors])
    centre = pos.mean(axis=0)
    half = max(30.0, 1.5 * np.ptp(pos, axis=0).max())
    box = [(centre[0] - half, centre[1] - half), (centre[0] + half, centre[1] - half),
           (centre[0] + half, centre[1] + half), (centre[0] - half, centre[1] + half)]
    return pl.grid_candidates(box, 2 * half / 10, scenario.sensors[0].position[2])


def _nearest_unused(candidates, targets):
    """For each target point (x, y) in turn, the index of the nearest candidate not taken yet."""
    taken = []
    for t in targets:
        d = np.hypot(*(candidates[:, :2] - t).T)
        d[taken] = np.inf
        taken.append(int(np.argmin(d)))
    return np.array(taken)


def baseline_layouts(candidates, k, rng, random_layouts=RANDOM_LAYOUTS):
    """Index sets of the baselines: ``random`` (B, k), ``line`` (k,) and ``triangle`` (k,).

    The line runs north-south through the candidates' centre across their
    extent (the collinear layout); the triangle is equilateral, centred, with
    a circumradius of a quarter of the extent, and the k sensors spread
    evenly along its perimeter (its corners for k = 3).
    """
    xy = candidates[:, :2]
    centre = 0.5 * (xy.min(axis=0) + xy.max(axis=0))
    lo, hi = xy[:, 1].min(), xy[:, 1].max()
    line = np.column_stack([np.full(k, centre[0]), np.linspace(lo, hi, k) if k > 1 else [centre[1]]])
    r = 0.25 * np.ptp(xy, axis=0).max()
    corners = centre + r * np.column_stack([np.cos(np.pi / 2 + 2 * np.pi * np.arange(4) / 3),
                                            np.sin(np.pi / 2 + 2 * np.pi * np.arange(4) / 3)])
    s = 3.0 * np.arange(k) / k                          # perimeter position in edges
    e = np.minimum(s.astype(int), 2)
    tri = corners[e] + (s - e)[:, None] * (corners[e + 1] - corners[e])
    N = len(candidates)
    random = np.argsort(rng.random((random_layouts, N)), axis=1)[:, :k]
    return {"random": random, "line": _nearest_unused(candidates, line), "triangle": _nearest_unused(candidates, tri)}


def score_baselines(problem, candidates, placement, criterion, seed=0, random_layouts=RANDOM_LAYOUTS, values=None):
    """The baselines' criterion values on the design's own passages, and their efficiency against the design.

    Efficiency (D): ``exp((value - design value) / d)``; only layouts that
    satisfy the budget (if any) count.  ``values``: a function valuing index sets (B, k) instead of the
    problem's criterion (the resolvability criterion; ``problem`` is then unused).
    """
    k = len(placement.chosen)
    if values is None:
        def values(sets):
            return pl.value_of_sets(problem, sets, criterion)
    sets = baseline_layouts(candidates, k, np.random.default_rng(seed), random_layouts)
    out = {}
    rand = sets["random"]
    ok = pl.feasible(rand, None, problem)
    vals = np.full(len(rand), -np.inf)
    if ok.any():
        vals[ok] = values(rand[ok])
    best = int(np.argmax(vals))
    named = {f"best_of_{len(rand)}_random": rand[best], "line": sets["line"], "triangle": sets["triangle"]}
    for name, idx in named.items():
        v = float(values(np.asarray(idx)[None])[0])
        eff = _efficiency(criterion, v, placement.value, problem.n if problem is not None else placement.dimension)
        out[name] = {"value": finite_or_none(v), "efficiency_vs_design": eff,
                     "sensors": [list(map(float, p)) for p in candidates[idx]]}
    return out


def _efficiency(criterion, value, reference, d):
    if not np.isfinite(value):
        return 0.0
    if criterion == "D":
        return float(np.exp((value - reference) / d))
    if criterion == "A":
        return float(reference / value) if value < 0 else None
    if criterion == "E":
        return float(value / reference) if reference > 0 else None
    return None


def design_array(scenario, k, *, criterion="D", candidates=None, costs=None, budget=None, passages=8, seed=0,
                 solver="auto", cuts=True, prior_floor=None, stride=2, random_layouts=RANDOM_LAYOUTS,
                 bb_work=None, bb_seconds=BB_GUARD_SECONDS, check=True, progress=False, separation=None):
    """Design an array of ``k`` copies of the scenario's first sensor.

    Parameters
    ----------
    scenario : Scenario
    k : int
        Sensors to place.
    criterion : {"D", "A", "E", "resolvability"}
        ``resolvability``: the layout that best tells two ships apart at ``separation`` (module docstring).
    candidates : ndarray, shape (N, 3), optional
        Allowed positions, m (default :func:`default_candidates`).
    costs, budget : optional
        Per-candidate costs (N,) and the total allowed.
    passages : int
        Prior passages to average over (the nominal passage if the scenario
        has no ``[prior]``).
    solver : {"auto", "clarabel", "first-order"}
    cuts : bool
        Add ambiguity cuts until the design passes the check.
    prior_floor : float, optional
        Floor on the scaled prior term (:func:`~shipsense.design.placement.build_problem`);
        None uses the scenario's prior covariance (the tracker bank's initial
        standard deviations) as it is.
    random_layouts : int
        Random layouts for the best-of-random baseline.
    check : bool
        Run the ambiguity check on the design (with ``cuts=False``; the cuts
        need it).  Off only to time the rest (benchmarks): the verdict is then None.
    bb_work : int, optional
        Work limit of the search over subsets that tightens the bound for few
        sensors (:func:`~shipsense.design.placement.place`: the exact search of
        the D criterion for k <= 4, subset values computed; the branch and bound
        of A and E for k <= 3, node bounds); None: each search's default, 0: no
        search.  The search stops on its work, so that what it proves does not
        depend on the machine's load.
    bb_seconds : float
        A time guard on that search (inf: none); the report says when it fired.
    progress : bool
        A progress bar on a terminal.
    separation : float, optional
        The separation (m) the ``resolvability`` criterion values layouts at (default
        :data:`~shipsense.design.resolvability.DESIGN_SEPARATION_M`); only with that criterion.

    Returns
    -------
    DesignResult
    """
    from tqdm import tqdm

    from shipsense.design.manoeuvre_bound import passage_motion
    from shipsense.models.field_model import candidate_model, subset_model
    from shipsense.simulator import sample_manoeuvring_passages
    from shipsense.trackers.tracker.settings import resolve_settings

    t_start = time.perf_counter()
    if criterion not in CRITERIA:
        raise ValueError(f"--criterion must be one of {', '.join(CRITERIA)}, got {criterion!r}")
    if separation is not None and criterion != "resolvability":
        raise ValueError("--separation goes with --criterion resolvability only")
    if criterion == "resolvability":
        separation = rv.DESIGN_SEPARATION_M if separation is None else separation
        if not (np.isfinite(separation) and 0 < separation <= rv.SEPARATIONS_M[-1]):
            raise ValueError(f"--separation must be a number of metres in (0, {rv.SEPARATIONS_M[-1]:g}], "
                             f"got {separation!r}")
        if costs is not None:
            raise ValueError("--budget (candidate costs) is not supported with --criterion resolvability")
    if solver not in pl.SOLVERS:
        raise ValueError(f"--solver must be one of {', '.join(pl.SOLVERS)}, got {solver!r}")
    if not (bb_seconds == bb_seconds and bb_seconds > 0):
        raise ValueError(f"--bb-seconds must be a number > 0 (inf: no guard), got {bb_seconds!r}")
    if bb_work is not None and not (isinstance(bb_work, (int, np.integer)) and bb_work >= 0):
        raise ValueError(f"--bb-work must be a whole number >= 0, got {bb_work!r}")
    guard = None if bb_seconds == np.inf else float(bb_seconds)
    if prior_floor is not None and not (np.isfinite(prior_floor) and prior_floor > 0):
        raise ValueError(f"--prior-floor must be a positive number, got {prior_floor!r}")
    cands = default_candidates(scenario) if candidates is None else np.asarray(candidates, dtype=float)
    if cands.ndim != 2 or cands.shape[1] != 3 or len(cands) == 0 or not np.isfinite(cands).all():
        raise ValueError(f"candidates must be at least one finite (x, y, z) position, got shape {cands.shape}")
    if not 1 <= k <= len(cands):
        raise ValueError(f"--k must be between 1 and the number of candidates ({len(cands)}), got {k}")
    if (costs is None) != (budget is None):
        raise ValueError("--budget needs candidate costs (a 'cost' column in the candidate CSV), and vice versa")
    template = scenario.sensors[0]
    model = candidate_model(scenario, cands)
    truth, manoeuvres = sample_manoeuvring_passages(scenario, passages if scenario.prior is not None else 1,
                                                    seed=seed, random=scenario.prior is not None)
    thetas = model.to_internal(model.state_from_truth(truth))
    motion = passage_motion(model, truth, manoeuvres, scenario.times)
    bank = resolve_settings(scenario).bank
    prior_std = model.to_internal(bank.state_std(model.labels))
    timings = {}
    bar = tqdm(total=100, desc=f"design: Fisher matrices, {len(cands)} candidates x {len(thetas)} passages",
               unit="%", leave=False, disable=None if progress else True,
               bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}")
    try:
        if criterion == "resolvability":
            result, baselines = _resolvability_design(model, thetas, scenario.steps, k, cands, separation, seed,
                                                      random_layouts, timings, check, bar, motion)
        else:
            result, baselines = _relaxation_design(model, thetas, scenario.steps, k, cands, criterion, costs,
                                                   budget, prior_std, stride, prior_floor, solver, cuts, bb_work,
                                                   guard, seed, random_layouts, timings, check, bar, motion)
    finally:
        bar.close()
    resolvability = rv.resolvable_separation(subset_model(model, result.chosen), thetas, scenario.steps)
    sensors = [template.model_copy(update={"id": f"D{i + 1}", "position": tuple(map(float, p))})
               for i, p in enumerate(cands[result.chosen])]
    layout = scenario.model_copy(update={"sensors": sensors, "name": f"{scenario.name}-design-k{k}",
                                         "description": f"{criterion}-optimal layout of {k} {template.type}s "
                                                        f"({template.kind}) designed from {scenario.name}"})
    timings["total"] = time.perf_counter() - t_start
    return DesignResult(scenario, layout, cands, result, truth, thetas, motion, model, k, criterion, prior_floor,
                        baselines, timings, resolvability, separation)


def _relaxation_design(model, thetas, steps, k, cands, criterion, costs, budget, prior_std, stride, prior_floor,
                       solver, cuts, bb_work, guard, seed, random_layouts, timings, check, bar, motion):
    """The D, A and E criteria's design: per-candidate Fisher matrices (along the passages' ``motion``), the
    relaxation, rounding and ambiguity cuts (:func:`~shipsense.design.placement.place_with_cuts`), the verdict
    and the baselines; ``(Placement, baselines)``."""
    from shipsense.design.observability import check_array
    from shipsense.models.field_model import subset_model

    t0 = time.perf_counter()
    problem = pl.build_problem(model, thetas, steps, k, prior_std, stride=stride,
                               prior_floor=prior_floor, progress=lambda f: bar.update(int(100 * f) - bar.n),
                               motion=motion)
    timings["fisher"] = time.perf_counter() - t0
    if costs is not None:
        problem = problem.with_costs(costs, budget)
    bar.set_description("design: relaxation, rounding" + ("" if not cuts else " and ambiguity cuts"))
    if cuts:
        result = pl.place_with_cuts(problem, model, thetas, steps, criterion, solver=solver,
                                    bb_work=bb_work, bb_seconds=guard, motion=motion)
        timings["relaxation_and_rounding"] = result.seconds
        timings["ambiguity_check"] = result.check_seconds
    else:
        result = pl.place(problem, criterion, solver, bb_work=bb_work, bb_seconds=guard)
        timings["relaxation_and_rounding"] = result.seconds
        t0 = time.perf_counter()
        if check:
            result.verdict = check_array(subset_model(model, result.chosen), thetas[:4], steps, starts=8,
                                         motion=_first(motion, 4))
        timings["ambiguity_check"] = time.perf_counter() - t0 if check else None
    bar.set_description("design: baselines")
    t0 = time.perf_counter()
    baselines = score_baselines(problem, cands, result, criterion, seed=seed, random_layouts=random_layouts)
    timings["baselines"] = time.perf_counter() - t0
    return result, baselines


def _first(motion, count):
    """The manoeuvres of the first ``count`` passages (None: straight passages)."""
    return None if motion is None else motion.take(slice(0, count))


def _resolvability_design(model, thetas, steps, k, cands, separation, seed, random_layouts, timings, check, bar,
                          motion):
    """The ``resolvability`` criterion's design: per-candidate joint information of twin ships abreast on
    straight passages, the search over sets (:func:`~shipsense.design.resolvability.best_set`), the verdict
    (with the passages' ``motion``) and the baselines; ``(Placement, baselines)``."""
    from shipsense.design.observability import check_array
    from shipsense.models.field_model import subset_model

    t0 = time.perf_counter()
    bar.set_description("design: joint Fisher matrices of two ships")
    info = rv.candidate_information(model, thetas, steps, separation)
    timings["fisher"] = time.perf_counter() - t0

    def values(sets):
        return rv.set_values(model, info, steps, sets, separation)

    bar.set_description("design: search over sets")
    t0 = time.perf_counter()
    chosen, value, complete, evaluated = rv.best_set(values, len(cands), k, seed=seed)
    weights = np.zeros(len(cands))
    weights[chosen] = 1.0
    result = pl.Placement(chosen, weights, "resolvability", float("nan"), value if complete else float("inf"), value,
                          "exhaustive" if complete else "exchange", time.perf_counter() - t0,
                          solver=f"{evaluated:,} sets valued", converged=True,
                          status="optimal" if complete else "not proved optimal", dimension=2 * model.n)
    timings["search"] = result.seconds
    t0 = time.perf_counter()
    if check:
        result.verdict = check_array(subset_model(model, chosen), thetas[:4], steps, starts=8,
                                     motion=_first(motion, 4))
    timings["ambiguity_check"] = time.perf_counter() - t0 if check else None
    bar.set_description("design: baselines")
    t0 = time.perf_counter()
    baselines = score_baselines(None, cands, result, "resolvability", seed=seed, random_layouts=random_layouts,
                                values=values)
    timings["baselines"] = time.perf_counter() - t0
    return result, baselines


#: The files of a design report, inside its output folder.
DESIGN_FILES = {"layout": "layout.toml", "report": "design.json", "plot": "design.png", "bounds": "bounds.png"}


def design_files(result):
    """The output files of a design as ``{name: bytes}`` (nothing written; names from :data:`DESIGN_FILES`): the
    layout TOML, the report, the candidates-and-weights plot and the map of the design's position bound."""
    from shipsense.config import to_toml
    from shipsense.design.fisher import bound_map
    from shipsense.models.field_model import subset_model
    from shipsense.plotting import plot_bound_map, plot_design

    r = result.placement
    files = {DESIGN_FILES["layout"]: to_toml(result.layout).encode(),
             DESIGN_FILES["report"]: (json.dumps(result.report(), indent=2) + "\n").encode()}
    eff = r.guaranteed_efficiency
    buf = io.BytesIO()
    plot_design(result.candidates, r.weights, r.chosen, result.truth, buf,
                title=f"{result.criterion}-optimal {result.k} of {len(result.candidates)} candidates: "
                      f"{r.verdict.verdict if r.verdict is not None else 'unchecked'}"
                      + (f", guaranteed efficiency {eff:.3f}" if eff is not None else ""))
    files[DESIGN_FILES["plot"]] = buf.getvalue()
    design_model = subset_model(result.model, r.chosen)
    cands, thetas = result.candidates, result.thetas
    span = np.ptp(cands[:, :2], axis=0).max() / 2 + 40.0
    centre = cands[:, :2].mean(axis=0)
    xs = centre[0] + np.linspace(-span, span, 41)
    ys = centre[1] + np.linspace(-span, span, 41)
    bound, _ = bound_map(design_model, xs, ys, velocity=thetas[0, 2:4], params=thetas[0, 4:], per_sensor=False)
    buf = io.BytesIO()
    plot_bound_map(design_model.array, xs, ys, bound, buf,
                   title=f"position CRLB of the design (passage segments at {np.hypot(*thetas[0, 2:4]):.1f} m/s)")
    files[DESIGN_FILES["bounds"]] = buf.getvalue()
    return files


def write_design(result, out):
    """Write the design's files (see :func:`design_files`) into the folder ``out``; returns their paths.

    Everything is rendered in memory, written into a hidden folder beside ``out`` and moved in only when all
    files are written, so a failure (or Ctrl-C) leaves ``out`` as it was.
    """
    from shipsense.atomic import staged_directory

    files = design_files(result)
    with staged_directory(out) as stage:
        for name, data in files.items():
            (stage / name).write_bytes(data)
    return [Path(out) / name for name in files]


def summary_lines(result):
    """The command's printed summary."""
    r, k = result.placement, result.k
    template = result.scenario.sensors[0]
    eff = r.guaranteed_efficiency
    lines = [f"{result.criterion}-optimal design of {k} {template.type}s ({template.kind}) from "
             f"{len(result.candidates)} candidates and {len(result.thetas)} prior passages "
             f"({result.timings['total']:.1f} s)"]
    if result.motion is not None:
        lines.append(f"  {int(result.motion.manoeuvring.sum())} of the {len(result.thetas)} prior passages manoeuvre "
                     f"(the scenario's [manoeuvres]): their Fisher information follows their true motion")
    if result.criterion == "resolvability":
        d0 = result.separation
        lines.append(f"  search: {r.method} ({r.solver}): "
                     + ("every subset valued, the design is optimal" if r.status == "optimal" else
                        "the best of random sets improved by exchanges, not proved optimal"))
        lines.append(f"  objective {r.value:.4g}: at {d0:g} m, {rv.RESOLVE_SHARE:.0%} of the drawn twin pairs have "
                     f"the separation's CRLB sd at most {d0 * np.exp(-r.value):.3g} m")
    else:
        lines.append(f"  solver: {r.solver} ({r.method} relaxation), "
                     f"{'converged' if r.converged else 'NOT converged'}: {r.status}")
        if r.message:
            lines.append(f"  note: {r.message}")
        lines.append(f"  objective {r.value:.4g}; relaxation {r.relaxation:.4g}; certified upper bound "
                     f"{r.upper_bound:.4g}; gap {r.certified_gap:.3g} (no {k}-sensor design does better by more)")
    if r.branch_and_bound is not None:
        b = r.branch_and_bound
        stop = {"work": "stopped at its work limit", "time guard": "stopped by the time guard (--bb-seconds)"}
        lines.append(f"  search over subsets ({b['method']}): work {b['work']:,} in {b['seconds']:.1f} s, "
                     + ("complete: the design is optimal" if b["complete"] else
                        f"{stop[b['stopped_by']]}, proved bound {b['upper_bound']:.4g}"))
    if eff is not None:
        lines.append(f"  guaranteed efficiency {eff:.3f} against the best {k}-sensor design")
    lines.append(f"  ambiguity cuts added: {len(r.cuts)}; verdict: "
                 f"{r.verdict.verdict if r.verdict is not None else None}")
    if result.resolvability is not None:
        lines.append(f"  {result.resolvability.describe()}")
    for name, b in result.baselines.items():
        e = b["efficiency_vs_design"]
        value = "-inf" if b["value"] is None else f"{b['value']:.4g}"
        lines.append(f"  baseline {name}: objective {value}"
                     + (f" (efficiency {e:.3f} of the design)" if e is not None else ""))
    for i, p in enumerate(result.sensors):
        lines.append(f"  D{i + 1}: ({p[0]:.1f}, {p[1]:.1f}, {p[2]:.1f})")
    return lines
