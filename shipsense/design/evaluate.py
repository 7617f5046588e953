"""Judge a layout by the tracker itself on held-out passages (every placement method uses this).

For passages drawn from the scenario's prior (a seed separate from design),
the project's tracker (:class:`~shipsense.trackers.Tracker`; ``method="bank"``:
the studies' bank, kept to reproduce earlier figures) tracks each one;
reported are the convergence rate, the mean TRMSE of the reported estimate
(the tracker reports the passage prior until its first fit, and that counts),
its RMSE over the second half of the passage, the same over the samples
where the method reports a track (the tracker: `tracking` or `restarted`;
the bank always does) with their share, against the posterior CRLB on those
samples (the ratio; for manoeuvring passages each one's PCRLB conditional on its true manoeuvres,
:mod:`~shipsense.design.manoeuvre_bound`), and the ambiguity verdict of the array.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from shipsense.design.fisher import pcrlb
from shipsense.design.manoeuvre_bound import simulation_bound
from shipsense.design.observability import check_array
from shipsense.models.field_model import model_from_scenario
from shipsense.trackers.bank.bank import run_bank
from shipsense.trackers.bank.seeding import seed_hypotheses
from shipsense.trackers.metrics import convergence_rate, position_crlb_trace, position_error, trmse

HELD_OUT_SEED = 10_000


@dataclass(frozen=True)
class Evaluation:
    """Tracking quality of a layout on held-out passages."""

    passages: int
    convergence_rate: float
    trmse_m: float
    rmse_second_half_m: float
    rmse_tracked_m: float
    tracked_share: float
    bound_m: float
    ratio_to_bound: float
    verdict: str
    min_chi2: float

    def to_json(self):
        return {k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in asdict(self).items()}


def evaluate_layout(scenario, passages=50, seed=HELD_OUT_SEED, filter_name=None, check_passages=3,
                    method="tracker"):
    """Evaluate a scenario's array on ``passages`` random passages from its prior, tracked by the project's
    tracker (``method="tracker"``) or the studies' bank (``"bank"``, with the scenario's filter or
    ``filter_name``).  The bound's prior is the bank's initial spread in both cases."""
    from shipsense.config import load_scenario
    from shipsense.simulator import simulate
    from shipsense.trackers.tracker.settings import resolve_settings

    sc = load_scenario(scenario)
    if sc.prior is None:
        raise ValueError(f"scenario {sc.name!r} has no [prior]: held-out passages need one")
    model = model_from_scenario(sc)
    sim = simulate(sc, runs=passages, seed=seed, random=True)
    truth = model.state_from_truth(sim.truth)
    if method not in ("tracker", "bank"):
        raise ValueError(f"method must be 'tracker' or 'bank', got {method!r}")
    override = {"unit": filter_name} if filter_name and method == "bank" else {}
    settings = resolve_settings(sc, method=method, **override)
    unit, bank_cfg = settings.filter_unit(), settings.bank
    seeds, P0 = seed_hypotheses(model, sim.measurements[:, 0], bank_cfg)
    if method == "bank":
        bank = run_bank(unit, model, sim.measurements, seeds, P0, prune_nats=bank_cfg.prune_nats)
        est = bank.selected_means
        tracked = np.ones(est.shape[:2], dtype=bool)
    else:
        from shipsense.trackers import Tracker
        from shipsense.trackers.tracker.results import RESTARTED, TRACKING

        res = Tracker(sc, passages=passages, settings=settings).track(sim.times, sim.measurements)
        est, tracked = res.estimates, np.isin(res.status, (TRACKING, RESTARTED))
    half = sc.steps // 2
    err = position_error(est, truth)[:, half:]
    tracked = tracked[:, half:]
    P0i = model.cov_to_internal(P0)
    if sim.manoeuvres.any:   # each passage's bound conditional on its true manoeuvres
        bounds = simulation_bound(model, sim, np.linalg.inv(P0i))[:, half:]
    else:
        bounds = pcrlb(model, model.to_internal(truth), np.linalg.inv(P0i))[half:]
    trace = np.broadcast_to(position_crlb_trace(model.cov_to_si(bounds)), err.shape)
    rmse = float(np.sqrt(np.mean(err ** 2)))
    rmse_tracked = float(np.sqrt(np.mean(err[tracked] ** 2))) if tracked.any() else float("nan")
    bound = float(np.sqrt(np.mean(trace[tracked]))) if tracked.any() else float("nan")
    thetas = model.to_internal(truth[:check_passages, 0])
    verdict = check_array(model, thetas, sc.steps, starts=8)
    return Evaluation(passages, convergence_rate(est, truth), float(trmse(est, truth).mean()), rmse, rmse_tracked,
                      float(tracked.mean()), bound, rmse_tracked / bound if bound > 0 else float("inf"),
                      verdict.verdict, float(verdict.min_chi2))
