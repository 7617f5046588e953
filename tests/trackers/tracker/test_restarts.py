"""Batch refits (trackers.restarts): multistart, distinct fits, and why the tracker re-fits a collapsed filter."""

import numpy as np
import pytest

from shipsense import load_scenario, simulate
from shipsense.models.field_model import model_from_scenario
from shipsense.reproduce.studies import track_with_global_init
from shipsense.trackers import Tracker
from shipsense.trackers.filters import get_filter
from shipsense.trackers.init.global_init import global_init
from shipsense.trackers.tracker.restarts import refit_at


def _s2(runs=4, seed=5):
    sc = load_scenario("S2")
    model = model_from_scenario(sc, sensors=["M1", "M2"]).without_process_noise()
    sim = simulate(sc, runs=runs, seed=seed, random=True)
    y, truth = sim.measurements[..., :6], model.state_from_truth(sim.truth)
    gi = global_init(model, y, ranges=np.geomspace(20, 150, 8), speeds=np.linspace(3, 7, 3))
    return model, y, truth, gi

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
    With the collapse alarm the tracker re-fits instead, and claims no such accuracy."""
    from shipsense.reproduce.common import prior_grid
    from shipsense.trackers.bank.bank import run_bank

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
    # the tracker: with the collapse alarm it re-fits more often, and reports more than the collapsed filter
    tr0, tr1 = Tracker(sc, collapse=None), Tracker(sc)
    res0, res1 = tr0.track(sim.times, y), tr1.track(sim.times, y)
    assert tr1.state.restarts[0] > tr0.state.restarts[0]
    ok = (res0.status[0] >= 2) & (res1.status[0] >= 2)
    spread0 = np.sqrt(np.trace(res0.position_cov[0, ok], axis1=-2, axis2=-1))
    spread1 = np.sqrt(np.trace(res1.position_cov[0, ok], axis1=-2, axis2=-1))
    assert np.median(spread1 / spread0) > 1.0


_RESTART_OPTIONS = {
    "default": dict(through_peak=0.5, refit_every=20, rescan=True, collapse=0.25, max_restarts=4),
    "none": dict(through_peak=None, refit_every=None, rescan=False, collapse=None, max_restarts=4),
    "fractional": dict(through_peak=0.5, refit_every=12.5, rescan=True, collapse=0.25, max_restarts=1.5),
    "never": dict(through_peak=0.0, refit_every=np.inf, rescan=True, collapse=None, max_restarts=0),
    "always": dict(through_peak=0.5, refit_every=-1, rescan=False, collapse=0.25, max_restarts=4),
}


@pytest.mark.parametrize("robust", [False, True])
@pytest.mark.parametrize("which", list(_RESTART_OPTIONS))
def test_the_compiled_restart_test_is_the_trackers_rules(robust, which):
    """``restarts.due``, given the options as the tracker hands them over, against the tracker's restart rules
    written in numpy (as they were): alarms (mean or median NIS over a window with gaps and an infinity, an
    untrusted fit, restarts left), the peak passed, the schedule, a rescan, a collapse, a failed consistency
    test; stuck passages reported inconsistent with their covariance scaled by the level (np.nanmean's or
    np.nanmedian's, to the bit); the peak updated; passages not asked about untouched.  Options None, False,
    fractional, infinite and negative, as a user may give them."""
    from shipsense.config import TrackerOptions
    from shipsense.trackers.tracker.bank_starts import restart_options as _restart_options
    from shipsense.trackers.tracker.restarts import due

    o = _RESTART_OPTIONS[which]
    # (model_construct: the values a user may hand the compiled rule directly, outside the options' ranges)
    options = TrackerOptions.model_construct(robust=robust, nis_window=10, nis_limit=3.0, **o)
    rng = np.random.default_rng(11)
    P, Nw, n = 40, 10, 3
    nis = rng.exponential(2.5, (P, Nw))
    nis[rng.random((P, Nw)) < 0.3] = np.nan
    nis[3] = np.nan
    nis[4, 2] = np.inf
    state = dict(n=rng.integers(0, 60, P), start=rng.integers(0, 30, P), trusted=rng.random(P) > 0.3,
                 alarms=rng.integers(0, 6, P), peak=rng.uniform(0, 50, P), peak_done=rng.random(P) > 0.5,
                 scan=rng.integers(0, 40, P), own=rng.uniform(0, 10, P), ref=rng.uniform(0, 20, P),
                 cons_now=rng.random(P) > 0.8)
    snr = rng.uniform(0, 60, P)
    runs = np.sort(rng.choice(P, 30, replace=False))
    for r, (n_, start, scan) in zip(runs[:2], ((25, 5, 25), (25, 20, 5))):   # due on the boundary only: the
        state["n"][r], state["start"][r], state["scan"][r] = n_, start, scan  # schedule, then the rescan
        state["peak_done"][r], state["cons_now"][r], state["trusted"][r], state["own"][r] = False, False, True, 1e9
        nis[r], snr[r] = np.nan, 99.0
    # the rules in numpy, as Tracker._restart had them
    s = {k: v.copy() for k, v in state.items()}
    since = s["n"][runs] - s["start"][runs]
    window = nis[runs]
    present = np.isfinite(window).sum(axis=1)
    level = np.zeros(runs.size)
    some = present > 0
    level[some] = (np.nanmedian if robust else np.nanmean)(window[some], axis=1)
    diverged = (present >= max(1, Nw // 2)) & (level > 3.0)
    alarm = (diverged | (~s["trusted"][runs] & (since >= Nw))) & (s["alarms"][runs] < o["max_restarts"])
    peak = s["peak"].copy()
    peak[runs] = np.maximum(peak[runs], snr[runs])
    after_peak = (o["through_peak"] is not None) & ~s["peak_done"][runs] & (since > 0) & (
        snr[runs] < (o["through_peak"] or 0.0) * peak[runs])
    scheduled = (o["refit_every"] is not None) & ~s["peak_done"][runs] & (since >= (o["refit_every"] or 0))
    rescan = o["rescan"] & (o["refit_every"] is not None) & ~s["peak_done"][runs] & (
        s["n"][runs] - s["scan"][runs] >= (o["refit_every"] or 0))
    collapse = np.zeros(runs.size, dtype=bool)
    if o["collapse"] is not None:
        collapse = (since < Nw) & (since > 0) & (s["own"][runs] < o["collapse"] * s["ref"][runs])
    want_due = alarm | after_peak | scheduled | rescan | collapse | s["cons_now"][runs]
    stuck = diverged & ~alarm
    status, cov = np.zeros(P, np.int8), rng.uniform(1, 2, (P, n, n))
    want_status, want_cov = status.copy(), cov.copy()
    want_status[runs[stuck]] = 4
    want_cov[runs[stuck]] *= np.maximum(1.0, level[stuck])[:, None, None]

    flags = np.empty((runs.size, 4), dtype=bool)
    got = {k: v.copy() for k, v in state.items()}
    due(runs, got["n"], got["start"], nis, got["trusted"], got["alarms"], got["peak"], got["peak_done"], snr,
        got["scan"], got["own"], got["ref"], got["cons_now"], *_restart_options(options), status, cov, 4, flags)
    np.testing.assert_array_equal(flags, np.stack([want_due, alarm, after_peak, rescan], axis=1))
    np.testing.assert_array_equal(got["peak"], peak)
    np.testing.assert_array_equal(status, want_status)
    np.testing.assert_array_equal(cov, want_cov)
    assert stuck.any() and diverged.any() and not want_due.all()
    if which == "default":
        assert alarm.any() and after_peak.any() and collapse.any()
        assert want_due[:2].all() and not (alarm | after_peak | collapse)[:2].any()
    for k in state:
        if k != "peak":
            np.testing.assert_array_equal(got[k], state[k])


def test_the_restart_level_is_numpys_mean_to_the_bit():
    """The kernel's mean NIS adds the window as numpy does (a pairwise sum from eight values): the same level as
    ``np.nanmean`` for windows of 1 to 128 samples with gaps, and the alarm decision at a level of exactly
    3.0 (a window whose in-order sum is one ulp above it)."""
    from numba import njit

    from shipsense.trackers.tracker.restarts import _numpy_sum

    mean = njit(lambda a: _numpy_sum(a))
    rng = np.random.default_rng(3)
    for N in list(range(1, 33)) + [64, 100, 128]:
        for _ in range(50):
            w = rng.exponential(2.0, N) * 10 ** rng.uniform(-3, 3, N)
            w[rng.random(N) < 0.3] = np.nan
            seen = ~np.isnan(w)
            if seen.any():
                assert mean(np.where(seen, w, 0.0)) / seen.sum() == np.nanmean(w)
    w = np.array([10.902861646966068, 0.3712825742238698, 0.9636660270059065, 1.0247034332995926,
                  2.6322048152020954, 3.225788492468857, 1.8475521326435036, 0.4293743039459304, 6.88766248480456,
                  1.7149040894396208])
    assert np.nanmean(w) == 3.0 and mean(w) / 10 == 3.0 and sum(w) / 10 > 3.0
