"""Seeding: the range formulas' closed forms and the seed layout."""

import numpy as np
import pytest

from shipsense import load_scenario
from shipsense.config import BankConfig
from shipsense.models.field_model import model_from_scenario
from shipsense.physics.electric import hed_field
from shipsense.physics.magnetic import dipole_field
from shipsense.trackers.bank.seeding import seed_hypotheses, seed_ranges


def test_magnetic_range_is_exact_on_the_dipole_axis_and_corrected_horizontally():
    model = model_from_scenario("S0")            # sensor at (0, 0, -20), source plane z = 0
    m = 5e7
    rho = 120.0
    src = np.array([rho, 0.0, 0.0])
    r = src - model.array.positions[0]
    moment = m * r / np.linalg.norm(r)          # on axis: |B| = 2e-7 m / r^3
    y = dipole_field(model.array.positions[0], src, moment)
    best, slant, horiz = seed_ranges(model, y, [m / 10, m, 10 * m])
    assert best == 0
    assert slant[1] == pytest.approx(np.linalg.norm(r), rel=1e-12)
    assert horiz[1] == pytest.approx(rho, rel=1e-12)                 # sqrt(r^2 - dz^2)
    assert slant[2] / slant[1] == pytest.approx(10 ** (1 / 3))


def test_electric_range_uses_the_image_correction():
    sc = load_scenario("S1-P2")
    model = model_from_scenario(sc)
    y = np.abs(hed_field(model.array.positions, [0.0, 120.0, -6.8], [100.0, 0, 0], sc.medium.physics())).ravel()
    _, slant, _ = seed_ranges(model, y, [100.0], range_correction=2.0)
    _, slant4, _ = seed_ranges(model, y, [100.0], range_correction=4.0)
    assert slant4[0] / slant[0] == pytest.approx(2 ** (1 / 3))
    assert 60 < slant[0] < 250   # the right order for a 120 m offset (a seed, not an estimate)


def test_seed_layout_levels_bearings_velocity_and_covariance():
    sc = load_scenario("S1-P2")
    model = model_from_scenario(sc)
    bank = sc.tracker.bank
    y = np.full(model.m, 1e-6)
    y[3:6] = 5e-6                                    # the second sensor measures the strongest field
    x0, P0 = seed_hypotheses(model, y[None], bank)
    K, L = len(bank.levels), len(bank.bearings_deg)
    assert x0.shape == (1, K * L, model.n)
    centre = model.array.positions[1, :2]
    rel = x0[0, :, :2] - centre
    ang = np.rad2deg(np.arctan2(rel[:, 1], rel[:, 0])) % 360
    np.testing.assert_allclose(ang.reshape(K, L), np.broadcast_to(bank.bearings_deg, (K, L)), atol=1e-9)
    np.testing.assert_allclose(x0[0, :, 5], np.repeat(bank.levels, L))          # p = level
    # towards_array: every seed heads for the array centroid at |initial_velocity|
    heading = model.array.positions[:, :2].mean(axis=0) - x0[0, :, :2]
    v = x0[0, :, 2:4]
    cos = np.sum(heading * v, -1) / np.linalg.norm(heading, axis=-1) / np.linalg.norm(v, axis=-1)
    np.testing.assert_allclose(cos, 1.0)
    assert np.all(np.linalg.eigvalsh(P0) > 0)
    fixed = bank.model_copy(update={"initial_course": "fixed"})
    x1, _ = seed_hypotheses(model, y[None], fixed)
    np.testing.assert_allclose(x1[0, :, 2:4], np.broadcast_to(bank.initial_velocity, (K * L, 2)))


def test_seeding_without_any_field_sample_is_an_error():
    model = model_from_scenario("S0")
    with pytest.raises(ValueError, match="no field sample"):
        seed_hypotheses(model, np.full((1, 3), np.nan), BankConfig(levels=[1e6], bearings_deg=[0.0]))
