"""Simulator: reproducibility, batch consistency against direct kernel calls, noise statistics."""

import numpy as np
import pytest

from shipsense import load_scenario, simulate
from shipsense.physics.electric import hed_field
from shipsense.physics.magnetic import dipole_field


@pytest.mark.parametrize("name", ["S0", "S1-P2", "S2", "demo"])
def test_reproducible_under_a_seed(name):
    a = simulate(name, runs=3, seed=5, random=True)
    b = simulate(name, runs=3, seed=5, random=True)
    np.testing.assert_array_equal(a.measurements, b.measurements)
    np.testing.assert_array_equal(a.truth, b.truth)
    c = simulate(name, runs=3, seed=6, random=True)
    assert not np.allclose(a.truth, c.truth)


@pytest.mark.parametrize("name", ["S0", "S1-P1", "S2"])
def test_a_prefix_of_a_batch_equals_the_smaller_batch(name):
    big = simulate(name, runs=6, seed=3, random=True)
    small = simulate(name, runs=2, seed=3, random=True)
    np.testing.assert_array_equal(big.measurements[:2], small.measurements)
    np.testing.assert_array_equal(big.truth[:2], small.truth)


def test_clean_measurements_equal_direct_kernel_calls_per_run():
    sim = simulate("S2", runs=4, seed=0, random=True)
    arr = sim.array
    for r in range(sim.runs):
        for s in arr.group("magnetometer"):
            B = dipole_field(arr.positions[s], sim.positions[r], sim.truth[r, 0, 5:8])
            cols = arr.channel_sensor == s
            np.testing.assert_allclose(sim.clean[r][:, cols], B, rtol=1e-12)
        acc = arr.group("accelerometer")[0]
        d = sim.positions[r] - arr.positions[acc]
        brg = np.arctan2(d[:, 1], d[:, 0])
        col = arr.channel_sensor == acc
        np.testing.assert_allclose(np.cos(2 * sim.clean[r][:, col][:, 0]), np.cos(2 * brg), atol=1e-12)


def test_envelopes_equal_series_field_of_the_keel_dipole():
    sc = load_scenario("S1-P2")
    sim = simulate(sc, runs=2, seed=1, random=True)
    medium = sc.medium.physics()
    for r in range(2):
        v = sim.truth[r, 0, 2:4]
        p = sim.truth[r, 0, 8] * np.array([*v, 0.0]) / np.linalg.norm(v)
        for s in range(3):
            E = hed_field(sim.array.positions[s], sim.positions[r], p, medium, rtol=1e-12)
            cols = sim.array.channel_sensor == s
            np.testing.assert_allclose(sim.clean[r][:, cols], np.abs(E), rtol=1e-6, atol=1e-6 * np.abs(E).max())


def test_raw_chain_of_magnitude_electrodes_follows_the_field_magnitude():
    base = load_scenario("S1-P2")
    kinds = ["magnitude", "envelope", "magnitude"]
    sc = base.model_copy(update={"sensors": [s.model_copy(update={"kind": k}) for s, k in zip(base.sensors, kinds)]})
    ideal = simulate(sc, runs=2, seed=0)
    assert ideal.measurements.shape[-1] == 5
    env = simulate(base, runs=2, seed=0)                  # the same passages with envelope triads
    np.testing.assert_allclose(ideal.clean[..., 0], np.linalg.norm(env.clean[..., 0:3], axis=-1), rtol=1e-12)
    raw = simulate(sc.with_updates(envelope_chain={"mode": "raw", "raw_noise_std": 1e-8}), runs=2, seed=0)
    rms = np.sqrt(np.mean((raw.measurements - raw.clean) ** 2, axis=1)) / np.abs(raw.clean).max(axis=1)
    assert rms.shape == (2, 5) and rms.max() < 0.1, rms   # as for envelope triads (the low-pass smooths the peak)


def test_noise_statistics_and_dropouts():
    sc = load_scenario("S0").with_updates(noise={"dropout": 0.1})
    sim = simulate(sc, runs=50, seed=2)
    assert abs((~sim.mask).mean() - 0.1) < 0.01
    assert np.isnan(sim.measurements[~sim.mask]).all() and np.isfinite(sim.measurements[sim.mask]).all()
    z = ((sim.measurements - sim.clean) / sc.channel_std)[sim.mask]
    assert abs(z.std() - 1) < 0.02 and abs(z.mean()) < 0.02


def test_contaminated_noise_has_outliers():
    base = load_scenario("S2")
    clean = simulate(base, runs=40, seed=1)
    dirty = simulate(base.with_updates(noise={"model": "contaminated", "eps": 0.2}), runs=40, seed=1)
    mag = ~clean.array.axial
    z0 = np.abs((clean.measurements - clean.clean)[..., mag] / base.channel_std[mag])
    z1 = np.abs((dirty.measurements - dirty.clean)[..., mag] / base.channel_std[mag])
    assert (z0 > 5).mean() < 1e-4 and 0.1 < (z1 > 5).mean() < 0.2


def test_random_passages_follow_the_prior():
    sc = load_scenario("S0")
    sim = simulate(sc, runs=300, seed=4, random=True)
    r = np.linalg.norm(sim.truth[:, 0, :2], axis=-1)  # the array centroid is the origin
    speed = np.linalg.norm(sim.truth[:, 0, 2:4], axis=-1)
    mom = np.linalg.norm(sim.truth[:, 0, 5:8], axis=-1)
    assert sc.prior.range[0] <= r.min() and r.max() <= sc.prior.range[1]
    assert sc.prior.speed[0] <= speed.min() and speed.max() <= sc.prior.speed[1]
    assert sc.prior.moment[0] <= mom.min() and mom.max() <= sc.prior.moment[1]
    # heading towards the array within the course offset
    to_centre = -sim.truth[:, 0, :2] / r[:, None]
    cos = np.sum(to_centre * sim.truth[:, 0, 2:4], axis=-1) / speed
    assert cos.min() >= np.cos(np.deg2rad(20)) - 1e-9


def test_nominal_passage_is_the_scenario_passage():
    sim = simulate("S0", runs=2)
    np.testing.assert_allclose(sim.truth[:, 0, :4], [[-140, -70, 6, 6]] * 2)
    np.testing.assert_allclose(sim.truth[0, -1, :2], [-140 + 6 * 29.9, -70 + 6 * 29.9])


def test_raw_envelope_chain_and_seismic_chain_run_and_stay_close():
    sc = load_scenario("S1-P2").with_updates(envelope_chain={"mode": "raw", "raw_noise_std": 1e-8})
    sim = simulate(sc, runs=2, seed=0)
    # the 0.5 Hz low-pass smooths the ~1 s closest approach of a 10 m/s ship (the loss S1 experiment 3
    # measures), so only the record-wide RMS error is bounded here
    rms = np.sqrt(np.mean((sim.measurements - sim.clean) ** 2, axis=1)) / np.abs(sim.clean).max(axis=1)
    assert rms.max() < 0.1, rms.max()
    sc2 = load_scenario("S2").with_updates(seismic={"mode": "chain"})
    sim2 = simulate(sc2, runs=3, seed=0)
    ax = sim2.array.axial
    err = np.rad2deg(np.abs(np.angle(np.exp(2j * (sim2.measurements[..., ax] - sim2.clean[..., ax]))) / 2))
    assert np.median(err) < 2.0


def test_prior_closest_approach_range():
    sc = load_scenario("S2").with_updates(prior={**load_scenario("S2").prior.model_dump(), "cpa": (-10.0, 10.0)})
    sim = simulate(sc, runs=200, seed=2, random=True)
    p0, v = sim.truth[:, 0, :2], sim.truth[:, 0, 2:4]          # the array centroid is the origin
    cpa = np.abs(p0[:, 0] * v[:, 1] - p0[:, 1] * v[:, 0]) / np.linalg.norm(v, axis=-1)
    assert cpa.max() <= 10.0 + 1e-9 and cpa.max() > 8.0


def test_default_moment_walk_is_relative_to_the_ship():
    from shipsense.config import ProcessNoiseConfig
    from shipsense.models.field_model import model_from_scenario

    small = model_from_scenario(load_scenario("S2").with_updates(prior=None), process_noise=ProcessNoiseConfig())
    big = model_from_scenario(load_scenario("S0").with_updates(prior=None), process_noise=ProcessNoiseConfig())
    assert np.diag(big.Q)[4] == pytest.approx(0.6069, rel=1e-3)      # the setting measured consistent on S0
    ratio = np.sqrt(np.diag(small.Q)[4] / np.diag(big.Q)[4])
    assert ratio == pytest.approx(np.linalg.norm([1e4] * 3) / np.linalg.norm([8e7, 2e7, 4e7]), rel=1e-9)


def test_raw_chain_in_chunks_of_runs_equals_one_batch(monkeypatch):
    """The raw shaft-rate chain simulates runs in chunks to bound its memory: each run's chain is its own and the
    noise is drawn run after run, so the chunks give the one batch's envelopes bit for bit (envelope and magnitude
    electrodes in one array)."""
    import shipsense.simulator as simulator

    sc = load_scenario("S1-P2")
    kinds = ["envelope", "magnitude", "envelope"]
    sc = sc.model_copy(update={"sensors": [s.model_copy(update={"kind": k}) for s, k in zip(sc.sensors, kinds)]})
    sc = sc.with_updates(envelope_chain={"mode": "raw", "raw_noise_std": 1e-8})
    whole = simulate(sc, runs=5, seed=3).measurements
    monkeypatch.setattr(simulator, "RAW_CHUNK_BYTES", 1)           # one run at a time
    np.testing.assert_array_equal(simulate(sc, runs=5, seed=3).measurements, whole)
