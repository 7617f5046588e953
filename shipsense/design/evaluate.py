"""Judge a layout by the tracker itself on held-out passages (every placement method uses this).

For passages drawn from the scenario's prior (a seed separate from design),
the scenario's bank tracks each one; reported are the convergence rate, the
mean TRMSE of the selected estimate, its RMSE over the second half of the
passage against the posterior CRLB there (the ratio), and the ambiguity
verdict of the array.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from shipsense.design.fisher import pcrlb
from shipsense.design.observability import check_array
from shipsense.trackers.bank import run_bank
from shipsense.trackers.metrics import convergence_rate, position_error, trmse
from shipsense.trackers.models import model_from_scenario
from shipsense.trackers.seeding import seed_hypotheses

HELD_OUT_SEED = 10_000


@dataclass(frozen=True)
class Evaluation:
    """Tracking quality of a layout on held-out passages."""

    passages: int
    convergence_rate: float
    trmse_m: float
    rmse_second_half_m: float
    bound_m: float
    ratio_to_bound: float
    verdict: str
    min_chi2: float

    def to_json(self):
        return {k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in asdict(self).items()}


def evaluate_layout(scenario, passages=50, seed=HELD_OUT_SEED, filter_name=None, check_passages=3):
    """Evaluate a scenario's array with its tracker on ``passages`` random passages from its prior."""
    from shipsense.config import load_scenario
    from shipsense.simulator import simulate
    from shipsense.trackers.bank import study_bank

    sc = load_scenario(scenario)
    if sc.prior is None:
        raise ValueError(f"scenario {sc.name!r} has no [prior]: held-out passages need one")
    model = model_from_scenario(sc)
    sim = simulate(sc, runs=passages, seed=seed, random=True)
    truth = model.state_from_truth(sim.truth)
    unit, bank_cfg = study_bank(sc, filter_name)
    seeds, P0 = seed_hypotheses(model, sim.measurements[:, 0], bank_cfg)
    bank = run_bank(unit, model, sim.measurements, seeds, P0, prune_nats=bank_cfg.prune_nats)
    est = bank.selected_means
    half = sc.steps // 2
    err = position_error(est, truth)
    rmse = float(np.sqrt(np.mean(err[:, half:] ** 2)))
    P0i = P0 / np.outer(model.x_scale, model.x_scale)
    bounds = pcrlb(model, model.to_internal(truth), np.linalg.inv(P0i))
    bound = float(np.sqrt(np.mean(bounds[half:, 0, 0] + bounds[half:, 1, 1])))
    thetas = model.to_internal(truth[:check_passages, 0])
    verdict = check_array(model, thetas, sc.steps, starts=8)
    return Evaluation(passages, convergence_rate(est, truth), float(trmse(est, truth).mean()), rmse, bound,
                      rmse / bound if bound > 0 else float("inf"), verdict.verdict, float(verdict.min_chi2))
