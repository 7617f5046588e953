"""The tracker with motion modes (``[tracker.motion] model = "imm"``) on passages that turn and change speed."""

import numpy as np
import pytest

from shipsense import load_scenario, simulate
from shipsense.models.motion_modes import MODES
from shipsense.trackers import Tracker
from shipsense.trackers.tracker.results import STATUSES


@pytest.fixture(scope="module")
def turning():
    """S2-turn's nominal passage, its turn (60 degrees at 3 deg/s) starting as the ship passes the array, then a
    slow-down, with S2's two magnetometers, tracked with the constant-velocity filter and with the motion
    modes."""
    sc = load_scenario("S2-turn")
    sc = sc.with_updates(manoeuvres={**sc.manoeuvres.model_dump(), "turns": [
        {"start": 20.0, "duration": 20.0, "rate_deg_s": 3.0}], "speed_changes": [
        {"start": 45.0, "duration": 10.0, "factor": 0.6}]})
    sim = simulate(sc, runs=4, seed=2)
    out = {}
    for model in ("cv", "imm"):
        tr = Tracker(sc, passages=4, sensors=["M1", "M2"], motion={"model": model})
        cols = np.isin([c[0] for c in sim.channels], tr.model.array.ids)
        out[model] = tr, tr.track(sim.times, sim.measurements[..., cols])
    return sc, sim, out


def test_the_motion_modes_hold_a_turning_ship_the_constant_velocity_filter_loses(turning):
    """After the turn and the speed change, the IMM tracker's error is a fraction of the constant-velocity
    tracker's, which can only report the track inconsistent."""
    sc, sim, out = turning
    K = sim.times.shape[-1]
    done = np.flatnonzero(sim.manoeuvre[0]).max() + 1
    err = {m: np.hypot(*(r.estimates[:, done:, :2] - sim.truth[:, done:, :2]).transpose(2, 0, 1))
           for m, (_, r) in out.items()}
    assert done < K - 10
    assert np.median(err["imm"]) < 0.2 * np.median(err["cv"])


def test_the_modes_are_reported_and_say_when_the_ship_manoeuvres(turning):
    """Every sample carries the selected hypothesis's mode probabilities (summing to one once tracking), and
    the status ``manoeuvring`` is reported during the manoeuvres, not on the straight legs before them."""
    sc, sim, out = turning
    tr, res = out["imm"]
    assert res.mode_names == MODES == tr.mode_names
    assert res.modes.shape == sim.times.shape[:0] + (4, sim.times.shape[-1], len(MODES))
    names = res.status_names()
    tracked = np.isin(names, ["tracking", "manoeuvring", "restarted", "inconsistent"])
    np.testing.assert_allclose(res.modes[tracked].sum(-1), 1.0, rtol=1e-9)
    moving = sim.manoeuvre != 0
    assert (names[moving] == "manoeuvring").mean() > 0.3
    first = np.flatnonzero(moving[0]).min()
    assert (names[:, :first] == "manoeuvring").mean() < 0.05
    assert "manoeuvring" in STATUSES


def test_the_constant_velocity_tracker_reports_no_modes(turning):
    _, _, out = turning
    tr, res = out["cv"]
    assert tr.modes is None and res.mode_names == () and res.modes.shape[-1] == 0
    assert not (res.status_names() == "manoeuvring").any()


def test_a_passage_state_carries_its_modes_to_a_sibling(turning):
    """A passage carried to a sibling tracker with its mode beliefs steps on as it would have at home."""
    sc, sim, _ = turning
    tr = Tracker(sc, passages=2, sensors=["M1", "M2"], motion={"model": "imm"})
    cols = np.isin([c[0] for c in sim.channels], tr.model.array.ids)
    y = sim.measurements[:2][..., cols]
    for k in range(40):
        tr.update(sim.times[k], y[:, k])
    other = tr.sibling(2)
    other.set_passage_states([1, 0], tr.passage_states([0, 1]))
    for k in range(40, 48):
        a = tr.update(sim.times[k], y[:, k])
        b = other.update(sim.times[k], y[::-1, k])
        np.testing.assert_array_equal(a.estimate, b.estimate[::-1])
        np.testing.assert_array_equal(a.modes, b.modes[::-1])


@pytest.mark.parametrize("field, value", [("threshold", 1.5), ("turn_rate_deg_s", 0.0), ("model", "ct"),
                                          ("sojourn_manoeuvre_s", -1.0), ("hull_share", 2.0)])
def test_a_bad_motion_option_is_refused_naming_it(field, value):
    from shipsense.errors import ShipsenseError
    from shipsense.trackers.tracker.settings import resolve_settings

    with pytest.raises(ShipsenseError, match=f"motion.{field}"):
        resolve_settings("S2", motion={field: value})


@pytest.fixture(scope="module")
def started_across_a_turn():
    """A passage of S1-P2's electrode envelopes (a random passage with a random manoeuvre, as
    ``experiments/manoeuvres.py`` draws them) whose turn ends as its bank starts: the initialisation window's
    fit spans the turn, so it fails, and the bank starts untrusted."""
    sc = load_scenario("S1-P2")
    end = sc.period * (sc.steps - 1)
    sc = sc.with_updates(manoeuvres={"body_fixed_share": 0.0, "random": {
        "probability": 0.5, "turn_share": 0.5, "turn_rate_deg_s": [1.0, 3.0], "turn_deg": [20.0, 90.0],
        "speed_factor": [0.5, 2.0], "acceleration": [0.05, 0.3], "start": [0.1 * end, 0.5 * end]}})
    sim = simulate(sc, runs=30, seed=0, random=True)
    p = 13
    tr = Tracker(sc, passages=1, motion={"model": "imm"})
    cols = np.isin([c[0] for c in sim.channels], tr.model.array.ids)
    res = tr.track(sim.times, sim.measurements[p:p + 1][..., cols])
    return sim.manoeuvre[p], sim.truth[p], tr, res


def test_a_bank_started_across_a_turn_is_refitted_after_it(started_across_a_turn):
    """The bank whose start spans the turn reports it inconsistent, then is refitted on the samples after its
    start (its manoeuvre modes explained the failed fit, not a manoeuvre: they do not hold its refits back a
    window after them), and tracks the straight leg after it: consistent and within 2 m at the end (at over 100 m)."""
    moving, truth, tr, res = started_across_a_turn
    names = res.status_names()[0]
    started = np.flatnonzero(~np.isin(names, ["initialising", "no data"])).min()
    assert moving.any() and np.flatnonzero(moving).max() <= started + 1      # (the case: a start across a turn)
    assert names[started] == "inconsistent"
    assert tr.state.restarts[0] >= 1
    last = slice(-8, None)
    assert not (names[last] == "inconsistent").any()
    assert np.hypot(*(res.estimates[0, last, :2] - truth[last, :2]).T).max() < 2.0
