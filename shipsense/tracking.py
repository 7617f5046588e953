"""Track one passage with the scenario's bank: the pipeline behind ``shipsense track`` and ``demo``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shipsense.config import BankConfig, Scenario
from shipsense.trackers.bank import BankRun, run_bank
from shipsense.trackers.filters import get_filter
from shipsense.trackers.models import FieldModel, model_from_scenario
from shipsense.trackers.seeding import field_strength, seed_hypotheses

DEFAULT_BANK = BankConfig(levels=[1e5, 1e6, 1e7], bearings_deg=[45.0, 135.0, 225.0, 315.0],
                          initial_velocity=(5.0, 5.0), initial_course="towards_array")
"""Bank used when a scenario has no ``[tracker.bank]`` section."""


@dataclass(frozen=True)
class Track:
    """One tracked passage: the model, the bank's output and the first step it used."""

    model: FieldModel
    bank: BankRun
    start: int
    filter: str
    config: BankConfig


def scenario_tracker(scenario: Scenario, filter_name=None):
    """The scenario's filter unit (with its options) and bank configuration, or the defaults.

    Returns ``(unit, bank_config)``: ``[tracker].filter`` (``ukf`` without a
    tracker section) unless ``filter_name`` is given, ``n_pu`` for the PUEKF,
    and ``[tracker.bank]`` or :data:`DEFAULT_BANK`.
    """
    tracker = scenario.tracker
    cfg = tracker.bank if tracker is not None and tracker.bank is not None else DEFAULT_BANK
    name = filter_name or (tracker.filter if tracker is not None else "ukf")
    options = {"n_pu": tracker.n_pu} if name == "puekf" and tracker is not None else {}
    return get_filter(name, **options), cfg


def track_passage(scenario: Scenario, measurements, filter_name=None, progress=False) -> Track:
    """Seed the bank from the first step with a field sample and run it over one passage.

    ``measurements`` is (K, m) in SI units in the scenario's channel order
    (NaN = missing).
    """
    y = np.asarray(measurements, dtype=float)
    model = model_from_scenario(scenario)
    unit, cfg = scenario_tracker(scenario, filter_name)
    primary = "magnetometer" if "magnetometer" in model.array.types else "electrode"
    use = np.array([t == primary for t in model.array.types])
    has = ~np.isnan(np.where(use, field_strength(model, y), np.nan)).all(axis=-1)
    if not has.any():
        raise ValueError(f"no {primary} sample in the recording: nothing to seed the tracker from")
    k0 = int(np.argmax(has))
    seeds, P0 = seed_hypotheses(model, y[None, k0], cfg)
    bank = run_bank(unit, model, y[None, k0:], seeds, P0, prune_nats=cfg.prune_nats, progress=progress)
    return Track(model, bank, k0, unit.name, cfg)
