"""Metrics of several ships: GOSPA against Stone Soup's independent implementation and its own properties, the
share of samples with the right number of ships, per-ship RMSE and coverage by labelled tracks."""

import datetime
import itertools

import numpy as np
import pytest

from shipsense.trackers.metrics import (
    CHI2_2DOF_95,
    cardinality_rate,
    gospa,
    label_assignment,
    ship_coverage,
    ship_rmse,
)


def padded(points, n):
    """``points`` (m, 2) as n rows, NaN-padded."""
    out = np.full((n, 2), np.nan)
    out[: len(points)] = points
    return out


def random_sets(rng, n_sets, most=4, box=60.0):
    for _ in range(n_sets):
        i, j = rng.integers(0, most + 1, size=2)
        yield box * rng.random((i, 2)), box * rng.random((j, 2))


@pytest.mark.parametrize("c", [5.0, 20.0])
def test_gospa_agrees_with_stone_soup(c):
    ospametric = pytest.importorskip("stonesoup.metricgenerator.ospametric")
    from stonesoup.types.state import State

    metric = ospametric.GOSPAMetric(p=2, c=c)
    t = datetime.datetime(2024, 1, 1)
    rng = np.random.default_rng(0)
    sets = list(random_sets(rng, 120))
    assert sum(len(e) + len(y) == 0 for e, y in sets) > 0
    sets += [(np.zeros((0, 2)), np.ones((3, 2))), (np.ones((2, 2)), np.zeros((0, 2)))]     # empty sets
    est = np.stack([padded(e, 4) for e, _ in sets])
    tru = np.stack([padded(y, 4) for _, y in sets])
    got = gospa(est, tru, c=c)
    for b, (e, y) in enumerate(sets):
        if len(e) + len(y) == 0:                            # Stone Soup needs a state to date the metric
            assert got.total[b] == 0
            continue
        ref = metric.compute_gospa_metric([State(x[:, None], timestamp=t) for x in e],
                                          [State(x[:, None], timestamp=t) for x in y])[0].value
        assert got.total[b] == pytest.approx(ref["distance"], rel=1e-9, abs=1e-12)
        assert got.localisation[b] == pytest.approx(ref["localisation"], rel=1e-9, abs=1e-12)
        assert got.missed[b] == pytest.approx(ref["missed"], rel=1e-9, abs=1e-12)
        assert got.false[b] == pytest.approx(ref["false"], rel=1e-9, abs=1e-12)


def test_gospa_equals_brute_force_over_every_assignment():
    rng = np.random.default_rng(1)
    c = 20.0
    for e, y in random_sets(rng, 60, most=3):
        best = np.inf
        for k in range(min(len(e), len(y)) + 1):
            for rows in itertools.combinations(range(len(y)), k):
                for cols in itertools.permutations(range(len(e)), k):
                    d2 = [np.sum((y[r] - e[q]) ** 2) for r, q in zip(rows, cols)]
                    if all(v < c * c for v in d2):
                        best = min(best, sum(d2) + c * c / 2 * (len(e) + len(y) - 2 * k))
        assert gospa(padded(e, 3), padded(y, 3), c=c).total ** 2 == pytest.approx(best, rel=1e-12, abs=1e-12)


def test_gospa_of_identical_sets_is_zero_and_each_missed_ship_costs_half_c_squared():
    rng = np.random.default_rng(2)
    y = 100 * rng.random((6, 3, 2))
    g = gospa(y, y, c=20.0)
    np.testing.assert_array_equal(g.total, 0.0)
    np.testing.assert_array_equal(g.assignment, np.broadcast_to(np.arange(3), (6, 3)))
    for missed in range(4):
        est = y.copy()
        est[:, :missed] = np.nan
        g = gospa(est, y, c=20.0)
        np.testing.assert_allclose(g.missed, 200.0 * missed)
        np.testing.assert_allclose(g.total, np.sqrt(200.0 * missed))
        np.testing.assert_array_equal(g.false, 0.0)
        np.testing.assert_array_equal(g.localisation, 0.0)


def test_gospa_is_symmetric_but_for_missed_and_false():
    rng = np.random.default_rng(3)
    sets = list(random_sets(rng, 50))
    a = np.stack([padded(e, 4) for e, _ in sets])
    b = np.stack([padded(y, 4) for _, y in sets])
    ab, ba = gospa(a, b), gospa(b, a)
    np.testing.assert_allclose(ab.total, ba.total, rtol=1e-12)
    np.testing.assert_allclose(ab.localisation, ba.localisation, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(ab.missed, ba.false)
    np.testing.assert_array_equal(ab.false, ba.missed)


def test_an_estimate_beyond_the_cut_off_is_a_missed_and_a_false_ship():
    y = np.array([[[0.0, 0.0]]])
    g = gospa(y + [[[30.0, 0.0]]], y, c=20.0)
    assert g.missed[0] == g.false[0] == 200.0 and g.localisation[0] == 0 and g.assignment[0, 0] == -1
    g = gospa(y + [[[3.0, 4.0]]], y, c=20.0)
    assert g.total[0] == pytest.approx(5.0) and g.assignment[0, 0] == 0


def test_cardinality_rate_counts_the_samples_with_the_right_number_of_ships():
    truth = np.zeros((4, 2, 2))
    truth[2:, 1] = np.nan                                   # one ship at samples 2, 3
    est = np.zeros((4, 3, 2))
    est[:, 1:] = np.nan                                     # one track throughout
    assert cardinality_rate(est, truth) == 0.5
    assert cardinality_rate(est, truth, where=np.array([False, False, True, True])) == 1.0


def test_ship_rmse_and_coverage_follow_the_labelled_tracks():
    K = 400
    rng = np.random.default_rng(4)
    truth = np.stack([np.stack([np.linspace(0, 100, K), np.zeros(K)], -1),
                      np.stack([np.zeros(K), np.linspace(0, 100, K)], -1)], axis=1)      # (K, 2 ships, 2)
    sd = np.array([1.0, 3.0])
    err = sd[None, :, None] * rng.standard_normal((K, 2, 2))
    tracks = (truth + err)[:, ::-1]                         # track 0 follows ship 1 and track 1 ship 0
    assignment = label_assignment(tracks, truth)
    np.testing.assert_array_equal(assignment, [1, 0])
    rmse = ship_rmse(tracks, truth, assignment)
    np.testing.assert_allclose(rmse, np.sqrt(np.mean(np.sum(err ** 2, -1), 0)), rtol=1e-12)
    covs = (sd[::-1, None, None] ** 2 * np.eye(2))[None].repeat(K, 0)                    # each track's own sd
    cov = ship_coverage(tracks, covs, truth, assignment)
    assert np.all(np.abs(cov - 0.95) < 0.04), cov
    q = np.sum(err ** 2, -1) / sd ** 2
    np.testing.assert_allclose(cov, np.mean(q <= CHI2_2DOF_95, 0), rtol=1e-12)
    # a ship without a track: no error to average, never covered
    lone = ship_rmse(tracks[:, :1], truth, np.array([-1, 0]))
    assert np.isnan(lone[0]) and lone[1] == pytest.approx(rmse[1])
    assert ship_coverage(tracks[:, :1], covs[:, :1], truth, np.array([-1, 0]))[0] == 0.0
