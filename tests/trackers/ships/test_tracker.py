"""The several-ship tracker: two ships crossing give two tracks whose labels do not swap; a one-ship passage
gives no second track; its settings are checked."""

import numpy as np
import pytest

import shipsense
from shipsense.trackers import metrics
from shipsense.trackers.ships import ShipsSettings, ShipsTracker


@pytest.fixture(scope="module")
def crossing():
    sim = shipsense.simulate("S2-crossing", runs=1, seed=0)        # the nominal crossing: 30 m apart at the meeting
    result = ShipsTracker("S2-crossing", sensors=["M1", "M2"]).track(sim.times, sim.measurements[..., :6])
    return sim, result


def test_a_crossing_gives_two_tracks_whose_labels_do_not_swap(crossing):
    sim, r = crossing
    truth = np.moveaxis(sim.ships, 1, 2)                           # (runs, K, ships, 9)
    K = truth.shape[1]
    assert r.estimates.shape == (1, K, 2, 7)
    assert (r.born >= 0).all()                                     # both tracks born
    both = r.present[0].all(axis=1)
    assert both[K // 2:].mean() >= 0.9                             # two ships over most of the second half
    np.testing.assert_array_equal(metrics.label_assignment(r.estimates, truth)[0], [0, 1])
    # wherever both tracks say they are located (position sd <= 5 m each), each is nearer its own ship than the
    # other ship: no swap (a track just born, still tens of metres wide, is between the ships, and says so)
    d = np.hypot(*(r.estimates[0][both][:, :, None, :2] - truth[0][both][:, None, :, :2]).transpose(3, 0, 1, 2))
    own = (d[:, 0, 0] < d[:, 0, 1]) & (d[:, 1, 1] < d[:, 1, 0])
    sd = np.sqrt(np.trace(r.covs[0][both][..., :2, :2], axis1=-2, axis2=-1) / 2)      # (samples, 2) m
    located = (sd <= 5.0).all(axis=1)
    assert located[len(located) // 2:].mean() >= 0.9 and own[located].all()
    assert np.median(d[located][:, [0, 1], [0, 1]]) < 2.0           # and near it (m)
    assert (r.ship_count[0] == r.present[0].sum(axis=1)).all()


def test_a_one_ship_passage_gives_no_second_track():
    sim = shipsense.simulate("S2", runs=6, seed=11, random=True)
    tr = ShipsTracker("S2", passages=6, sensors=["M1", "M2"], settings=ShipsSettings(death_sd_m=20.0))
    r = tr.track(sim.times, sim.measurements[..., :6])
    assert r.present[..., 1].mean() <= 0.05
    # the one ship is tracked at the end where its own field still locates it, and has died where it does not
    reach = tr.reach_sd(tr.base.state_from_truth(sim.truth))          # (runs, K) m
    near = (reach[:, -10:] <= 10.0).all(axis=1)
    assert near.any() and r.present[near, -10:, 0].all()
    far = reach[np.arange(6), np.maximum(r.died[:, 0], 0)] > 0.5 * tr.settings.death_sd_m
    assert (r.died[:, 0] >= 0).any() and (far | (r.died[:, 0] < 0)).all()
    ended = r.died[:, 0] >= 0
    assert not r.present[ended, -1, 0].any()                        # an ended track is not reported


def test_with_one_ship_at_most_the_tracker_is_the_one_ship_trackers_output(crossing):
    sim, _ = crossing
    tr = ShipsTracker("S2-crossing", sensors=["M1", "M2"], settings=ShipsSettings(max_ships=1, death_sd_m=1e6))
    r = tr.track(sim.times, sim.measurements[..., :6])
    one = tr.one.track(sim.times, sim.measurements[..., :6])
    shown = r.present[0, :, 0]
    assert not r.present[..., 1].any()
    np.testing.assert_array_equal(r.estimates[0, shown, 0], one.estimates[0, shown])


@pytest.mark.parametrize("field, value", [("max_ships", 3), ("window_s", 0.0), ("penalty", -1.0),
                                          ("death_samples", 1.5), ("death_sd_m", float("nan")), ("inflate", True)])
def test_a_bad_setting_is_one_error_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"ships.{field}: must be"):
        ShipsSettings(**{field: value})
