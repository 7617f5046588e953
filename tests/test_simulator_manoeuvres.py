"""Manoeuvring passages in the simulator: straight scenarios unchanged to the bit, the truth of turns and speed
changes, the moment's body-fixed share, random manoeuvres' reproducibility and the written schedule."""

import json
from pathlib import Path

import numpy as np
import pytest

from shipsense import load_scenario, simulate
from shipsense.config import shipped_scenarios
from shipsense.physics.manoeuvre import SPEED_CHANGE, STRAIGHT, TURN
from shipsense.simulator import keel_dipole

# fingerprints (sums, sums of squares, NaN counts and five values of times, truth, clean, measurements and mask)
# of simulate(name, runs=3, seed=5, random=...) made by the simulator before manoeuvres existed (commit 6df8b14),
# on the straight scenarios, and of the seismic and raw envelope chains (runs=2, seed=3, random); compared to
# 1e-9 so that another machine's last bits (BLAS, libm) do not fail it while any change of a draw or a formula does
FROZEN = json.loads((Path(__file__).parent / "data" / "straight_simulations.json").read_text())


def fingerprint(sim):
    out = []
    for a in (sim.times, sim.truth, sim.clean, sim.measurements, sim.mask):
        a = np.asarray(a, dtype=float).ravel()
        fin = np.where(np.isfinite(a), a, 0.0)
        idx = np.linspace(0, a.size - 1, 5).astype(int)
        out += [float(np.sum(fin)), float(np.sum(fin * fin)), float(np.isnan(a).sum())] + [float(fin[i]) for i in idx]
    return out


def test_scenarios_without_manoeuvres_simulate_as_before():
    got = {}
    straight = [n for n in shipped_scenarios() if load_scenario(n).manoeuvres is None]
    assert set(straight) >= {"S0", "S1-P1", "S1-P2", "S2", "S2-field-trial", "demo"}
    for name in straight:
        for random in (False, True):
            key = f"{name}/{'random' if random else 'nominal'}"
            if key in FROZEN:
                got[key] = fingerprint(simulate(name, runs=3, seed=5, random=random))
    sc = load_scenario("S2")
    got["S2/seismic-chain/random"] = fingerprint(simulate(sc.with_updates(
        seismic={**sc.seismic.model_dump(), "mode": "chain"}), runs=2, seed=3, random=True))
    sc = load_scenario("demo")
    got["demo/raw-envelope/random"] = fingerprint(simulate(sc.with_updates(
        envelope_chain={**sc.envelope_chain.model_dump(), "mode": "raw"}, steps=40), runs=2, seed=3, random=True))
    assert set(got) == set(FROZEN)
    for key in FROZEN:
        np.testing.assert_allclose(got[key], FROZEN[key], rtol=1e-9, atol=1e-300, err_msg=key)


def test_straight_truth_carries_heading_speed_and_no_manoeuvre():
    sim = simulate("S0", runs=2, seed=1, random=True)
    v = sim.truth[..., 2:4]
    np.testing.assert_array_equal(sim.speed, np.hypot(v[..., 0], v[..., 1]))
    np.testing.assert_array_equal(sim.heading, np.arctan2(v[..., 1], v[..., 0]))
    assert not sim.manoeuvre.any() and not sim.manoeuvres.any


def test_the_nominal_turn_and_slow_down_of_s2_turn():
    sc = load_scenario("S2-turn")
    sim = simulate(sc, runs=1, seed=0)
    t = sim.times
    turn, change = sc.manoeuvres.turns[0], sc.manoeuvres.speed_changes[0]
    in_turn = (t >= turn.start) & (t < turn.start + turn.duration)
    in_change = (t >= change.start) & (t < change.start + change.duration)
    assert np.array_equal(sim.manoeuvre[0] == TURN, in_turn)
    assert np.array_equal(sim.manoeuvre[0] == SPEED_CHANGE, in_change)
    assert np.all(sim.manoeuvre[0][~in_turn & ~in_change] == STRAIGHT)
    psi0 = np.arctan2(*sc.passage.velocity[::-1])
    turned = np.angle(np.exp(1j * (sim.heading[0] - psi0)))
    np.testing.assert_allclose(turned[t >= turn.start + turn.duration], np.deg2rad(turn.rate_deg_s * turn.duration))
    np.testing.assert_allclose(turned[in_turn], np.deg2rad(turn.rate_deg_s) * (t[in_turn] - turn.start), atol=1e-12)
    s0 = np.hypot(*sc.passage.velocity)
    np.testing.assert_allclose(sim.speed[0][t < change.start], s0)
    np.testing.assert_allclose(sim.speed[0][t >= change.start + change.duration], change.factor * s0)
    # the path: the distance covered between samples is the speed's integral (trapezoid exact for constant a)
    step = np.linalg.norm(np.diff(sim.positions[0][:, :2], axis=0), axis=-1)
    straight = ~(in_turn[:-1] | in_turn[1:])
    np.testing.assert_allclose(step[straight], 0.5 * (sim.speed[0][:-1] + sim.speed[0][1:])[straight] * sc.period,
                               rtol=1e-12)


def test_the_body_fixed_share_of_the_moment_turns_with_the_hull_and_the_fields_follow():
    sc = load_scenario("S2-turn")
    m0 = np.array(sc.passage.moment)
    for share in (0.0, 0.6, 1.0):
        s = sc.with_updates(manoeuvres={**sc.manoeuvres.model_dump(), "body_fixed_share": share})
        sim = simulate(s, runs=1, seed=0)
        turn = sim.heading[0] - sim.heading[0, 0]
        c, sn = np.cos(turn), np.sin(turn)
        rotated = np.stack([c * m0[0] - sn * m0[1], sn * m0[0] + c * m0[1], np.full_like(c, m0[2])], axis=-1)
        np.testing.assert_allclose(sim.truth[0, :, 5:8], (1 - share) * m0 + share * rotated, rtol=1e-12, atol=1e-8)
        sources = sim.positions
        clean = sim.array.measure(sources, sim.truth[..., 5:8], keel_dipole(sim.truth[..., 2:4], sim.truth[..., 8]))
        np.testing.assert_array_equal(sim.clean, clean)


def test_manoeuvres_draw_from_their_own_stream():
    """Random manoeuvres move no other draw: with and without them, the same passages start alike and the
    noise is the same; the draws are prefix-stable and follow the prior's ranges."""
    sc = load_scenario("S2-turn")
    plain = sc.with_updates(manoeuvres=None)
    a = simulate(sc, runs=40, seed=2, random=True)
    b = simulate(plain, runs=40, seed=2, random=True)
    before = a.times[None, :] < a.manoeuvres.start[:, :1]     # every sample before a run's manoeuvre (if any)
    assert before.all(axis=1).any() and not before.all()
    np.testing.assert_array_equal(a.truth[before], b.truth[before])
    np.testing.assert_array_equal(a.measurements[before], b.measurements[before])
    np.testing.assert_array_equal(a.mask, b.mask)
    small = simulate(sc, runs=5, seed=2, random=True)
    np.testing.assert_array_equal(small.truth, a.truth[:5])
    rnd = sc.manoeuvres.random
    records = a.manoeuvres.to_records()
    made = [r[0] for r in records if r]
    assert 0 < len(made) < 40 and all(len(r) <= 1 for r in records)
    for r, rec in enumerate(records):
        if rec and rec[0]["kind"] == "turn":
            assert rnd.turn_rate_deg_s[0] <= abs(rec[0]["rate_deg_s"]) <= rnd.turn_rate_deg_s[1]
            total = abs(rec[0]["rate_deg_s"]) * rec[0]["duration"]
            assert rnd.turn_deg[0] - 1e-9 <= total <= rnd.turn_deg[1] + 1e-9
        elif rec:
            factor = 1 + rec[0]["acceleration"] * rec[0]["duration"] / np.hypot(*a.truth[r, 0, 2:4])
            assert rnd.speed_factor[0] - 1e-9 <= factor <= rnd.speed_factor[1] + 1e-9
        if rec:
            assert rnd.start[0] <= rec[0]["start"] <= rnd.start[1]
    never = sc.with_updates(manoeuvres={**sc.manoeuvres.model_dump(),
                                        "random": {**rnd.model_dump(), "probability": 0.0}})
    np.testing.assert_array_equal(simulate(never, runs=40, seed=2, random=True).truth, b.truth)


def test_raw_envelope_chain_of_a_turning_passage_follows_the_field():
    sc = load_scenario("demo")
    sc = sc.with_updates(steps=60, envelope_chain={**sc.envelope_chain.model_dump(), "mode": "raw",
                                                   "raw_noise_std": 1e-9},
                         manoeuvres={"turns": [{"start": 5.0, "duration": 15.0, "rate_deg_s": -3.0}]})
    sim = simulate(sc, runs=1, seed=0)
    cols = np.flatnonzero([sim.array.types[s] == "electrode" for s in sim.array.channel_sensor])
    straight = simulate(sc.with_updates(manoeuvres=None), runs=1, seed=0)
    err = np.abs(sim.measurements[..., cols] - sim.clean[..., cols]).mean()
    moved = np.abs(straight.clean[..., cols] - sim.clean[..., cols]).mean()
    assert err < 0.25 * moved, (err, moved)


def test_save_npz_writes_the_truth_and_the_schedule(tmp_path):
    sim = simulate("S2-turn", runs=2, seed=0)
    sim.save_npz(tmp_path / "s.npz")
    data = np.load(tmp_path / "s.npz")
    np.testing.assert_array_equal(data["heading"], sim.heading)
    np.testing.assert_array_equal(data["speed"], sim.speed)
    np.testing.assert_array_equal(data["manoeuvre"], sim.manoeuvre)
    assert list(data["manoeuvre_labels"]) == ["straight", "turn", "speed_change"]
    schedule = json.loads(str(data["manoeuvre_schedule"]))
    assert schedule["body_fixed_share"] == pytest.approx(0.6)
    assert [m["kind"] for m in schedule["runs"][1]] == ["turn", "speed_change"]
    assert schedule["runs"][0][0]["rate_deg_s"] == pytest.approx(3.0)
