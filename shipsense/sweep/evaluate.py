"""One sweep task, as a pure function: simulate a chunk of passages of a cell, track them, score each passage.

Per passage (``passage`` is its index in the cell; the columns of a chunk's table):

* ``converged``: the position error is below 10 m over the last 10 % of the
  passage's own samples (:func:`~shipsense.trackers.metrics.converged_until`;
  a passage ends as far past its closest approach as it started before it);
* ``rmse_m``: root-mean-square position error over the second half of the
  passage's samples;
* ``rmse_over_crlb``: that RMSE over the root-mean of the position CRLB on the
  same samples (the constant-velocity bound of the passage, conditional on its
  true manoeuvres where it makes any, with the bank's initial covariance as
  prior information);
* ``nees_mean``: mean position NEES over the same samples (2 is consistent);
  ``nees_coverage``: the share of them where the truth lies inside the
  reported 95 % ellipse (0.95 is honest; a sample without a covariance
  counts as not covered) -- :func:`~shipsense.trackers.metrics.position_nees`
  and :func:`~shipsense.trackers.metrics.coverage`;
* ``seconds``: tracking wall time per passage (the one column that depends on
  the machine).

A cell's ambiguity task gives its ``verdict`` (observable / ambiguous /
degenerate) and ``min_chi2`` from :func:`shipsense.design.observability.check_scenario`
on ``ambiguity_passages`` passages of the prior.

Tasks run in worker processes: everything here is a function of the task
alone, and BLAS is held to one thread so that results are bit-identical
wherever a task runs.
"""

from __future__ import annotations

import time
from contextlib import contextmanager

import numpy as np

from shipsense.sweep.cells import AMBIGUITY_CHUNK, Task

PASSAGE_COLUMNS = ("cell", "chunk", "passage", "converged", "rmse_m", "rmse_over_crlb", "nees_mean", "nees_coverage",
                   "seconds")
AMBIGUITY_COLUMNS = ("cell", "verdict", "min_chi2", "seconds")


@contextmanager
def one_blas_thread():
    """Hold BLAS/OpenMP to one thread (threadpoolctl), so that a result does not depend on the machine's cores."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl comes with the sweep extra
        yield
        return
    with threadpool_limits(limits=1):
        yield


def run_task(task: Task) -> dict:
    """The task's result as a table ``{column: list}`` (see the module docstring for the columns)."""
    with one_blas_thread():
        if task.chunk == AMBIGUITY_CHUNK:
            return _ambiguity(task)
        return _chunk(task)


def _scenario(task):
    from shipsense.config import Scenario

    return Scenario.model_validate(task.cell.scenario)


def _ambiguity(task):
    from shipsense.design.observability import check_scenario

    t0 = time.perf_counter()
    v = check_scenario(_scenario(task), passages=task.passages, seed=task.seed % 2**32)
    return {"cell": [task.cell.key], "verdict": [v.verdict],
            "min_chi2": [float(v.min_chi2) if np.isfinite(v.min_chi2) else np.nan],
            "seconds": [time.perf_counter() - t0]}


def _chunk(task):
    from shipsense.models.field_model import model_from_scenario
    from shipsense.simulator import simulate
    from shipsense.trackers.metrics import converged_until, coverage, passage_ends, position_nees

    sc = _scenario(task)
    model = model_from_scenario(sc)
    sim = simulate(sc, runs=task.passages, seed=task.seed, random=True)
    y, truth = sim.measurements, model.state_from_truth(sim.truth)
    t0 = time.perf_counter()
    est, pos_cov = track_passages(task.method, sc, sim.times, y)
    seconds = (time.perf_counter() - t0) / task.passages
    ends = passage_ends(truth, model.array.positions[:, :2].mean(axis=0), sc.period)
    conv, err, valid = converged_until(est, truth, ends)
    second = valid & (np.arange(truth.shape[1])[None, :] >= (ends // 2)[:, None])
    n = second.sum(axis=1)
    rmse = np.sqrt(np.nansum(np.where(second, err, 0.0) ** 2, axis=1) / n)
    ratio = np.full(task.passages, np.nan)
    if "rmse_over_crlb" in task.metrics:
        bound = crlb_position_trace(sc, model, truth, sim)
        ratio = rmse / np.sqrt(np.sum(np.where(second, bound, 0.0), axis=1) / n)
    q = position_nees(est, pos_cov, truth)
    nees_mean = np.array([np.nanmean(q[r, second[r]]) if np.isfinite(q[r, second[r]]).any() else np.nan
                          for r in range(task.passages)])
    return {"cell": [task.cell.key] * task.passages, "chunk": [task.chunk] * task.passages,
            "passage": list(range(task.first, task.first + task.passages)), "converged": conv.tolist(),
            "rmse_m": rmse.tolist(), "rmse_over_crlb": ratio.tolist(), "nees_mean": nees_mean.tolist(),
            "nees_coverage": coverage(q, second, axis=1).tolist(), "seconds": [seconds] * task.passages}


def crlb_position(sc, model, truth, sim=None):
    """The position block (R, K, 2, 2) of each passage's CRLB, m², with the prior information of the tracker's
    bank (its initial standard deviations): the constant-velocity bound, or, when the simulation ``sim`` of
    the passages has manoeuvres, the bound conditional on each passage's true manoeuvres
    (:func:`~shipsense.design.manoeuvre_bound.simulation_bound`; the same for a straight passage)."""
    from shipsense.design.fisher import pcrlb
    from shipsense.design.manoeuvre_bound import simulation_bound
    from shipsense.trackers.tracker.settings import resolve_settings

    bank = resolve_settings(sc).bank
    J0 = np.diag(model.to_internal(bank.state_std(model.labels)) ** -2.0)
    if sim is not None and np.any(sim.manoeuvre != 0):
        b = simulation_bound(model, sim, J0, Q=np.zeros_like(model.Q))
    else:
        b = pcrlb(model, model.to_internal(truth), J0, per_run=True, Q=np.zeros_like(model.Q))
    return np.ascontiguousarray(model.cov_to_si(b)[..., :2, :2])


def crlb_position_trace(sc, model, truth, sim=None):
    """Trace (R, K) of the position block of each passage's CRLB (:func:`crlb_position`), m²."""
    from shipsense.trackers.metrics import position_crlb_trace

    return position_crlb_trace(crlb_position(sc, model, truth, sim))


def track_passages(method, sc, times, y):
    """Estimates (R, K, n) and position covariances (R, K, 2, 2), SI, of passages ``y`` (R, K, m):
    :class:`~shipsense.trackers.Tracker` with ``method`` (``tracker``: the project's tracker; ``bank``: the
    studies' bank)."""
    from shipsense.trackers import Tracker

    res = Tracker(sc, passages=len(y), method=method).track(times, y)
    return res.estimates, res.position_cov
