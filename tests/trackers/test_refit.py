"""Batch refits and the tracker that restarts its bank from them."""

import numpy as np
import pytest

from shipsense import load_scenario, simulate
from shipsense.trackers.filters import get_filter
from shipsense.trackers.initialiser import global_init
from shipsense.trackers.models import model_from_scenario
from shipsense.trackers.restarts import collapse_alarm, divergence_alarm, refit_at
from shipsense.trackers.studies import track_with_global_init, track_with_restarts


def test_divergence_alarm_fires_after_the_first_window_above_the_limit():
    K, w = 40, 5
    nis = np.ones((4, K))
    nis[0, 20:25] = 4.0               # the window 19..23 is the first to average above 3 (3.4): restart at 24
    nis[1, 20:25] = 2.9               # below the limit of 3
    nis[2, 5:10] = 10.0               # before the bank's start (12): not its innovations
    nis[3, K - 1] = 20.0              # only the window ending on the last sample: nothing left to restart
    start = np.array([0, 0, 12, 0])
    np.testing.assert_array_equal(divergence_alarm(nis, start, w, 3.0), [24, K, K, K])
    # missing samples: a window counts when at least half of it (2 of 5) is measured
    gappy = np.full((2, K), np.nan)
    gappy[:, 30] = 9.0
    gappy[0, 32] = 9.0
    np.testing.assert_array_equal(divergence_alarm(gappy, [0, 0], w, 3.0), [33, K])


def _s2(runs=4, seed=5):
    sc = load_scenario("S2")
    model = model_from_scenario(sc, sensors=["M1", "M2"]).without_process_noise()
    sim = simulate(sc, runs=runs, seed=seed, random=True)
    y, truth = sim.measurements[..., :6], model.state_from_truth(sim.truth)
    gi = global_init(model, y, ranges=np.geomspace(20, 150, 8), speeds=np.linspace(3, 7, 3))
    return model, y, truth, gi


def test_without_triggers_it_is_the_bank_and_with_them_it_is_causal():
    model, y, truth, gi = _s2()
    ukf = get_filter("ukf")
    est0, bank = track_with_global_init(ukf, model, y, gi)
    est, cov, restarts = track_with_restarts(ukf, model, y, gi, through_peak=None, nis_limit=np.inf,
                                             refit_every=None, collapse=None)
    np.testing.assert_array_equal(est, est0)
    assert not restarts.any()
    est, cov, restarts = track_with_restarts(ukf, model, y, gi)
    assert restarts.min() >= 1                          # the refit after the closest approach
    err = np.hypot(*(est[:, -1, :2] - truth[:, -1, :2]).T)
    assert np.all(err < 0.5), err
    # causal: changing the samples after k leaves every estimate up to k (from the bank's start on) alone
    K = y.shape[1]
    k = int(gi.start.max()) + (K - int(gi.start.max())) // 2
    y2 = y.copy()
    y2[:, k + 1:] += 3e-8
    est2, cov2, _ = track_with_restarts(ukf, model, y2, gi)
    mine = (np.arange(K)[None, :] >= gi.start[:, None]) & (np.arange(K)[None, :] <= k)
    # (to rounding: the passages refitted together form one batch, and later ones join it)
    np.testing.assert_allclose(est2[mine], est[mine], rtol=1e-6)
    # covariances against their own scale, |dP_ij| <= 1e-4 sqrt(P_ii P_jj): an off-diagonal of 1e-10 beside
    # variances of ~7 is zero to rounding, BLAS rounding differs between machines, and a refit batch of another
    # composition stops its Levenberg-Marquardt iterations elsewhere within their tolerance (seen: 2e-6)
    sd = np.sqrt(np.einsum("...ii->...i", cov[mine]))
    assert np.all(np.abs(cov2[mine] - cov[mine]) <= 1e-4 * sd[..., :, None] * sd[..., None, :])
    assert not np.allclose(cov2[:, k + 1:], cov[:, k + 1:], rtol=1e-2)
    assert not np.allclose(est2[:, k + 1:], est[:, k + 1:], rtol=1e-3)


def test_a_diverged_bank_is_restarted_from_a_refit():
    """Seeds moved 30 m off with a covariance of centimetres: the bank without restarts stays off; the
    divergence alarm restarts it from a multistart refit that finds the passage."""
    from dataclasses import replace

    model, y, truth, gi = _s2()
    bad = gi.seeds.copy()
    bad[..., 0] += 30.0
    P0 = np.broadcast_to(np.diag([1e-4, 1e-4, 1e-4, 1e-4, 1e-12, 1e-12, 1e-12]), gi.P0.shape).copy()
    wrong = replace(gi, seeds=bad, P0=P0)
    ukf = get_filter("ukf")
    K = y.shape[1]
    est0, _, _ = track_with_restarts(ukf, model, y, wrong, through_peak=None, nis_limit=np.inf, refit_every=None,
                                     collapse=None)
    est, _, restarts = track_with_restarts(ukf, model, y, wrong, through_peak=None, refit_every=None, collapse=None)
    k = np.arange(K)
    late = k >= K - 10
    err0 = np.hypot(*(est0[:, late, :2] - truth[:, late, :2]).transpose(2, 0, 1))
    err = np.hypot(*(est[:, late, :2] - truth[:, late, :2]).transpose(2, 0, 1))
    assert np.all(err0.max(axis=1) > 5.0), err0.max(axis=1)
    assert np.all(restarts >= 1) and np.all(err.max(axis=1) < 1.0), (restarts, err.max(axis=1))


def test_multistart_refit_leaves_a_wrong_basin():
    model, y, truth, gi = _s2()
    R, K = y.shape[:2]
    at = np.full(R, K - 5)
    wrong = truth.copy()
    wrong[..., 0] = -wrong[..., 0]                      # a track mirrored across the array's y axis
    one = refit_at(model, y, gi, wrong, at)
    many = refit_at(model, y, gi, wrong, at, multistart=np.ones(R, dtype=bool))
    assert np.all(many.loglik <= 0) and np.all(many.loglik >= one.loglik)
    err = np.hypot(*(many.seeds[:, 0, :2] - truth[np.arange(R), at, :2]).T)
    assert np.all(err < 0.5) and many.fit_ok.all(), err
    with pytest.raises(ValueError, match="refit samples"):
        refit_at(model, y, gi, wrong, np.full(R, K))


def test_a_bank_from_a_fit_that_failed_the_test_claims_no_covariance_until_a_refit_passes():
    from dataclasses import replace

    model, y, truth, gi = _s2()
    assert gi.fit_ok.all()
    failed = replace(gi, fit_ok=np.array([False, True, True, True]))
    est, cov, restarts = track_with_restarts(get_filter("ukf"), model, y, failed, through_peak=None,
                                             refit_every=None, collapse=None)
    s, w = int(gi.start[0]), 10
    # retried after one window: the passing refit of samples up to s + w - 1 is the estimate there
    assert np.isnan(cov[0, s:s + w - 1]).all() and np.isfinite(cov[0, s + w - 1:]).all()
    assert restarts.tolist() == [1, 0, 0, 0]
    np.testing.assert_array_equal(np.isfinite(cov[1:, :, 0, 0]), np.arange(y.shape[1])[None] >= gi.start[1:, None])


def test_collapse_alarm_fires_on_the_sample_after_a_collapse_within_the_window():
    K, w = 30, 5
    spread = np.ones((4, K))
    spread[0, 12] = 0.2            # below 0.25 of the fit's trace (1) two samples after the start (10)
    spread[1, 12] = 0.3            # not below
    spread[2, 16] = 0.1            # after the window (10..14)
    spread[3, 5] = 0.1             # before the start
    start = np.array([10, 10, 10, 10])
    np.testing.assert_array_equal(collapse_alarm(spread, start, np.ones(4), 0.25, w), [13, K, K, K])


def test_refit_keeps_distinct_fits_weighted_by_their_likelihoods():
    model, y, truth, gi = _s2()
    R, K = y.shape[:2]
    at = np.full(R, K - 5)
    mirrored = truth.copy()
    mirrored[..., 0] = -mirrored[..., 0]
    hyps = np.stack([truth[np.arange(R), at - 1], mirrored[np.arange(R), at - 1]], axis=1)
    two = refit_at(model, y, gi, mirrored, at, hypotheses=hyps, keep=3)
    assert two.seeds.shape == (R, 3, model.n)
    # the best first (the passage); a second only where a start ended more than 15 m away (else it repeats
    # the best at no weight); never a third: the two mirrored starts are one fit
    assert np.all(two.loglik[:, 0] > two.loglik[:, 1]) and np.all(np.isneginf(two.loglik[:, 2]))
    err = np.hypot(*(two.seeds[:, 0, :2] - truth[np.arange(R), at, :2]).T)
    assert np.all(err < 0.5), err
    second = np.isfinite(two.loglik[:, 1])
    apart = np.hypot(*(two.seeds[:, 1, :2] - two.seeds[:, 0, :2]).T)
    assert second.sum() >= 2 and np.all(apart[second] > 14.0) and np.all(apart[~second] == 0.0), (second, apart)
    # the same fits as one start at a time
    one = refit_at(model, y, gi, truth, at)
    np.testing.assert_allclose(two.seeds[:, 0], one.seeds[:, 0], rtol=1e-6, atol=1e-9)


def test_the_filter_collapses_after_a_refit_where_the_batch_fit_does_not_and_the_tracker_refits():
    """S0 passage 85 (a single magnetometer): refitted at sample 224, the fit's position standard
    deviation is about 6 m, as is the fit of one more sample; one UKF step from the fit reports under 1 m.
    With the collapse alarm the tracker re-fits instead, and claims no such accuracy there."""
    from shipsense.reproduce.common import prior_grid
    from shipsense.trackers.bank import run_bank

    sc = load_scenario("S0")
    model = model_from_scenario(sc).without_process_noise()
    sim = simulate(sc, runs=86, seed=0, random=True)     # prefix-stable: the consistency study's passages
    y = sim.measurements[85:86]
    gi = global_init(model, y, **prior_grid(sc), snr_start=400.0, refine=(20, 60), explore_samples=15)
    est, _ = track_with_global_init(get_filter("ukf"), model, y, gi)

    def sd(P):
        return float(np.sqrt(P[..., 0, 0] + P[..., 1, 1]))

    fit, more = (refit_at(model, y, gi, est, np.array([a])) for a in (224, 225))
    assert 4.0 < sd(fit.P0[0, 0]) < 9.0 and sd(more.P0[0, 0]) > 0.8 * sd(fit.P0[0, 0])
    step = run_bank(get_filter("ukf"), model, y[:, 224:225], fit.seeds, fit.P0)
    assert sd(step.pos_cov[0, 0, 0]) < 0.25 * sd(fit.P0[0, 0])
    _, cov0, n0 = track_with_restarts(get_filter("ukf"), model, y, gi, collapse=None)
    _, cov1, n1 = track_with_restarts(get_filter("ukf"), model, y, gi)
    assert n1[0] > n0[0] + 5
    k = slice(235, 245)   # after the first scheduled refit (234): the filter alone is down to 1 m there
    assert np.sqrt(cov1[0, k, 0, 0] + cov1[0, k, 1, 1]).min() > 2 * np.sqrt(cov0[0, k, 0, 0] + cov0[0, k, 1, 1]).max()
