"""Several ships in one recording: ship 0 and the noise unmoved by companions, fields that superpose, the named
encounters' geometry, the counts, the truth file and the [traffic] table's validation."""

import csv

import numpy as np
import pytest

from shipsense import load_scenario, simulate
from shipsense.config import ScenarioError
from shipsense.physics.magnetic import dipole_field
from shipsense.recording.tidy_csv import TRUTH_KEYS, write_truth
from shipsense.simulator import STATE_LABELS


def with_traffic(name, **traffic):
    return load_scenario(name).with_updates(traffic=traffic)


def test_one_ship_or_no_table_simulates_exactly_as_before():
    plain = simulate("S2", runs=3, seed=4, random=True)
    one = simulate(with_traffic("S2", count=1, geometry="crossing"), runs=3, seed=4, random=True)
    assert plain.companions is None and one.companions is None
    for a, b in ((plain.truth, one.truth), (plain.measurements, one.measurements), (plain.clean, one.clean)):
        np.testing.assert_array_equal(a, b)
    assert plain.ships.shape == (3, 1, 80, 9) and plain.ships_present.all()


@pytest.mark.parametrize("geometry", ["prior", "crossing", "head_on", "overtaking", "following"])
def test_companions_leave_ship_0_and_the_noise_where_they_were(geometry):
    plain = simulate("S2", runs=3, seed=4, random=True)
    two = simulate(with_traffic("S2", count=2, geometry=geometry), runs=3, seed=4, random=True)
    np.testing.assert_array_equal(two.truth, plain.truth)
    mag = ~two.array.axial                               # the same noise (to rounding; bearings wrap)
    np.testing.assert_allclose((two.measurements - two.clean)[..., mag], (plain.measurements - plain.clean)[..., mag],
                               rtol=0, atol=1e-6 * two.scenario.channel_std[mag].min())
    assert not np.allclose(two.clean[..., :6], plain.clean[..., :6])


def test_the_magnetometers_read_the_sum_and_the_accelerometer_the_nearer_ship():
    sim = simulate(with_traffic("S2", count=3, geometry=["crossing", "prior"]), runs=2, seed=1, random=True)
    arr = sim.array
    ships = sim.ships
    for r in range(2):
        for s in arr.group("magnetometer"):
            B = sum(dipole_field(arr.positions[s], ships[r, j, :, [0, 1, 4]].T, ships[r, j, 0, 5:8]) for j in range(3))
            np.testing.assert_allclose(sim.clean[r][:, arr.channel_sensor == s], B, rtol=1e-12, atol=1e-25)
        acc = arr.group("accelerometer")[0]
        d = ships[r, :, :, :2] - arr.positions[acc, :2]                      # (3, K, 2)
        near = np.argmin(np.linalg.norm(d, axis=-1), axis=0)
        dn = d[near, np.arange(d.shape[1])]
        col = arr.channel_sensor == acc
        np.testing.assert_allclose(np.cos(2 * sim.clean[r][:, col][:, 0]),
                                   np.cos(2 * np.arctan2(dn[:, 1], dn[:, 0])), atol=1e-12)


def test_the_seismic_chain_hears_the_nearer_ship():
    sc = load_scenario("S2")
    sc = sc.with_updates(seismic={**sc.seismic.model_dump(), "mode": "chain", "sensor_noise": 1e-6},
                         traffic={"count": 2, "geometry": "head_on", "separation": 15.0})
    sim = simulate(sc, runs=3, seed=2, random=True)
    ax = sim.array.axial
    d = sim.measurements[..., ax] - sim.clean[..., ax]      # the clean bearing: the nearer ship's (tested above)
    assert np.abs((d + np.pi / 2) % np.pi - np.pi / 2).max() < 1e-5
    alone = simulate(sc.with_updates(traffic=None), runs=3, seed=2, random=True)
    assert np.abs(sim.measurements[..., ax] - alone.measurements[..., ax]).max() > 0.1   # ship 1 is heard


def closest_approach(sim, run):
    """Time and distance of the closest approach of ships 0 and 1 (straight tracks), analytically."""
    a, b = sim.ships[run, 0, 0], sim.ships[run, 1, 0]
    dp, dv = b[:2] - a[:2], b[2:4] - a[2:4]
    t = -dp @ dv / (dv @ dv)
    return t, np.linalg.norm(dp + t * dv)


@pytest.mark.parametrize("geometry", ["crossing", "head_on", "overtaking"])
def test_named_encounters_meet_at_the_separation_after_the_offset(geometry):
    sim = simulate(with_traffic("S2", count=2, geometry=geometry, separation=[20.0, 50.0], time_offset=[-5.0, 5.0],
                                crossing_angle_deg=[45.0, 135.0]), runs=20, seed=2, random=True)
    lead = sim.truth[:, 0]
    t0 = -np.sum(lead[:, :2] * lead[:, 2:4], axis=-1) / np.sum(lead[:, 2:4] ** 2, axis=-1)   # centroid at 0
    v0, v1 = sim.truth[:, 0, 2:4], sim.companions[:, 0, 0, 2:4]
    turn = np.degrees(np.abs(np.arctan2(v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0], np.sum(v0 * v1, axis=-1))))
    for r in range(20):
        t, d = closest_approach(sim, r)
        assert 20.0 - 1e-9 <= d <= 50.0 + 1e-9
        assert -5.0 - 1e-9 <= t - t0[r] <= 5.0 + 1e-9
    ratio = np.linalg.norm(v1, axis=-1) / np.linalg.norm(v0, axis=-1)
    if geometry == "crossing":
        assert np.all((turn >= 45 - 1e-9) & (turn <= 135 + 1e-9)) and np.allclose(ratio, 1.0)
    elif geometry == "head_on":
        np.testing.assert_allclose(turn, 180.0)
        np.testing.assert_allclose(ratio, 1.0)
    else:
        np.testing.assert_allclose(turn, 0.0, atol=1e-6)
        np.testing.assert_allclose(ratio, 1.5)


def test_a_follower_keeps_its_distance_astern():
    sim = simulate(with_traffic("S2", count=2, geometry="following", separation=25.0), runs=4, seed=3, random=True)
    rel = sim.companions[:, 0, :, :2] - sim.truth[..., :2]
    heading = sim.truth[..., 2:4] / np.linalg.norm(sim.truth[..., 2:4], axis=-1, keepdims=True)
    np.testing.assert_allclose(rel, -25.0 * heading, atol=1e-9)


def test_counts_are_drawn_in_their_range_and_absent_ships_read_nothing():
    base = simulate("S2", runs=40, seed=5, random=True)
    sim = simulate(with_traffic("S2", count=[1, 3], geometry="prior"), runs=40, seed=5, random=True)
    assert set(sim.ship_count) == {1, 2, 3}
    assert np.array_equal(sim.ships_present.sum(axis=1), sim.ship_count)
    alone = sim.ship_count == 1
    np.testing.assert_array_equal(sim.clean[alone], base.clean[alone])
    assert np.isnan(sim.ships[~sim.ships_present]).all() and np.isfinite(sim.ships[sim.ships_present]).all()


def test_a_prefix_of_a_batch_equals_the_smaller_batch():
    sc = with_traffic("S2", count=[1, 3], geometry=["head_on", "prior"])
    big, small = simulate(sc, runs=6, seed=3, random=True), simulate(sc, runs=2, seed=3, random=True)
    np.testing.assert_array_equal(big.ships[:2], small.ships)
    np.testing.assert_array_equal(big.measurements[:2], small.measurements)


def test_random_manoeuvres_are_drawn_for_every_ship():
    sc = load_scenario("S2-turn")
    sim = simulate(sc.with_updates(traffic={"count": 2, "geometry": "prior"}), runs=8, seed=1, random=True)
    v = sim.companions[:, 0, :, 2:4]
    changed = ~np.all(np.isclose(v, v[:, :1]), axis=(1, 2))
    assert changed.any()


def test_the_shipped_crossing_is_the_sum_of_its_two_single_ship_passages():
    crossing = load_scenario("S2-crossing")
    sim = simulate(crossing, runs=1, seed=0)
    first = crossing.with_updates(traffic=None)
    ship1 = sim.companions[0, 0, 0]
    second = first.with_updates(passage={**first.passage.model_dump(), "start": tuple(ship1[:2]),
                                         "velocity": tuple(ship1[2:4])})
    a, b = simulate(first, runs=1, seed=0), simulate(second, runs=1, seed=0)
    mag = ~sim.array.axial
    np.testing.assert_allclose(sim.clean[..., mag], a.clean[..., mag] + b.clean[..., mag], rtol=1e-12, atol=1e-24)
    t, d = closest_approach(sim, 0)
    assert abs(d - 30.0) < 1e-9
    v0, v1 = sim.truth[0, 0, 2:4], ship1[2:4]
    assert abs(v0 @ v1) < 1e-9 * (v0 @ v0)                                  # at right angles


def test_truth_csv_has_a_row_per_run_ship_and_sample(tmp_path):
    sim = simulate(with_traffic("S2", count=[1, 3], geometry="crossing"), runs=5, seed=2, random=True)
    path = tmp_path / "truth.csv"
    write_truth(sim, path)
    with open(path) as fh:
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == (*TRUTH_KEYS, *STATE_LABELS)
    body = np.array(rows[1:], dtype=float)
    assert len(body) == sim.ship_count.sum() * sim.times.size
    run, ship, step = body[:, :3].astype(int).T
    np.testing.assert_array_equal(body[:, 4:], sim.ships[run, ship, step])
    np.testing.assert_allclose(body[:, 3], sim.times[step], rtol=1e-5)


@pytest.mark.parametrize("traffic, field", [
    ({"count": 9}, "traffic.count"),
    ({"count": [3, 2]}, "traffic.count"),
    ({"count": 3, "geometry": ["crossing"]}, "traffic.geometry"),
    ({"count": 2, "geometry": "overtaking", "speed_ratio": 0.9}, "traffic.speed_ratio"),
    ({"count": 2, "crossing_angle_deg": 180.0}, "traffic.crossing_angle_deg"),
    ({"count": 2, "separation": -1.0}, "traffic.separation"),
    ({"count": 2, "separation": [30.0, 20.0]}, "traffic.separation"),
    ({"count": 2, "time_offset": [5.0, -5.0]}, "traffic.time_offset"),
    ({"count": 2, "crossing_angle_deg": [100.0, 80.0]}, "traffic.crossing_angle_deg"),
    ({"count": 2, "speed_ratio": [1.2, 1.1]}, "traffic.speed_ratio"),
])
def test_bad_traffic_names_the_field(traffic, field):
    with pytest.raises(ScenarioError, match=rf"{field}[:.]"):
        load_scenario("S2").with_updates(traffic=traffic)


def test_traffic_needs_what_it_uses():
    sc = load_scenario("S0")
    with pytest.raises(ScenarioError, match="traffic.geometry: prior companions"):
        sc.with_updates(prior=None, traffic={"count": 2})
    demo = load_scenario("demo")
    with pytest.raises(ScenarioError, match="traffic.count: the raw envelope chain"):
        demo.with_updates(envelope_chain={"mode": "raw"}, traffic={"count": 2, "geometry": "crossing"})
    flat = sc.with_updates(prior=None, passage={**sc.passage.model_dump(), "z": -19.5})
    with pytest.raises(ScenarioError, match="traffic: ships at z = -19.5"):
        flat.with_updates(traffic={"count": 2, "geometry": "head_on"})


def test_simulate_writes_the_truth_of_every_ship(tmp_path, capsys):
    from shipsense.cli import main

    truth, rec = tmp_path / "truth.csv", tmp_path / "rec.npz"
    assert main(["simulate", "S2-crossing", "--runs", "2", "--out", str(rec), "--truth", str(truth)]) == 0
    rows = list(csv.DictReader(truth.open()))
    assert len(rows) == 2 * 2 * 80 and {r["ship"] for r in rows} == {"0", "1"}
    data = np.load(rec)
    assert data["ships"].shape == (2, 2, 80, 9) and list(data["ship_count"]) == [2, 2]
    assert "ships in run 0: 2" in capsys.readouterr().out
    assert main(["simulate", "S2", "--truth", str(tmp_path / "t.txt")]) == 2
    assert "--truth must end in .csv" in capsys.readouterr().err
    assert [p.name for p in sorted(tmp_path.iterdir())] == ["rec.npz", "truth.csv"]
