"""S0's seeding against the study's Table 2: the seed ranges from the first sample."""

import numpy as np
import pytest

from shipsense import load_scenario, simulate
from shipsense.models.field_model import model_from_scenario
from shipsense.reproduce.s0 import STUDY_SEED_RANGES_M, STUDY_TRUE_RANGE_M
from shipsense.trackers.bank.seeding import seed_ranges
from shipsense.trackers.tracker.settings import resolve_settings


def test_the_seed_ranges_are_within_3_percent_of_the_studys_table_2_at_its_factor_0975():
    """True range 157.8 m; the levels 1e6, 1e7, 1e8 A·m² seed at 37.7, 81.2 and 174.9 m in the study: the
    project's ranges (the study's first sample: run 0, seed 0, as `reproduce S0` takes it) are within 3 % of
    them, each 0.975 of the study's (one factor for every level: a field or moment scale, not the formula)."""
    sc = load_scenario("S0")
    sim = simulate(sc, runs=1, seed=0)
    model = model_from_scenario(sc)
    levels = resolve_settings(sc).bank.levels
    _, slant, _ = seed_ranges(model, sim.measurements[:, 0], levels)
    true_range = float(np.linalg.norm(sim.positions[0, 0] - model.array.positions[0]))
    assert true_range == pytest.approx(STUDY_TRUE_RANGE_M, abs=0.05)
    ratio = slant[0] / np.array(STUDY_SEED_RANGES_M)
    assert np.all(np.abs(ratio - 1) <= 0.03), ratio
    assert ratio == pytest.approx(0.975, abs=0.003)
    deviations = np.abs(true_range - slant[0])
    study = np.abs(STUDY_TRUE_RANGE_M - np.array(STUDY_SEED_RANGES_M))
    assert study == pytest.approx([120.1, 76.6, 17.1], abs=0.05)           # the study's own deviations
    assert np.argmin(deviations) == 2                                       # the largest level seeds nearest
