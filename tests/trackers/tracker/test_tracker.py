"""The project's tracker: streaming = batch, causal, honest covariances, statuses, timestamps, robustness."""

import numpy as np
import pytest
from scaled import close as _close

from shipsense import load_scenario, simulate
from shipsense.trackers import Tracker
from shipsense.trackers.tracker.results import INCONSISTENT, INITIALISING, NO_DATA, RESTARTED, TRACKING


@pytest.fixture(scope="module")
def s2():
    sc = load_scenario("S2")
    sim = simulate(sc, runs=4, seed=5, random=True)
    tr = Tracker(sc, passages=4, sensors=["M1", "M2"])
    return sc, sim.times, sim.measurements[..., :6], tr.model.state_from_truth(sim.truth), tr.track(
        sim.times, sim.measurements[..., :6])


def test_it_tracks_every_passage_with_honest_finite_covariances(s2):
    sc, t, y, truth, res = s2
    err = np.hypot(*(res.estimates[:, -1, :2] - truth[:, -1, :2]).T)
    assert np.all(err < 1.0), err
    assert np.isfinite(res.covs).all()
    np.testing.assert_array_equal(res.covs, np.swapaxes(res.covs, -1, -2))
    assert np.all(np.linalg.eigvalsh(res.covs) > 0)
    # statuses: initialising until the window is fitted, then tracking with restarts, never "no data"
    assert set(np.unique(res.status)) <= {INITIALISING, TRACKING, RESTARTED}
    assert np.all(res.status[:, 0] == INITIALISING) and np.all((res.status[:, -5:] == TRACKING)
                                                                | (res.status[:, -5:] == RESTARTED))
    assert np.all(np.diff((res.status == INITIALISING).astype(int), axis=1) <= 0)   # initialising comes first
    # the truth lies inside the reported 95 % ellipse about as often as it should once tracking
    d = res.estimates[..., :2] - truth[..., :2]
    q = np.einsum("pki,pkij,pkj->pk", d, np.linalg.inv(res.position_cov), d)
    cover = np.mean(q[res.status != INITIALISING] <= 5.991)
    assert 0.85 <= cover <= 1.0, cover
    # before the first fit the belief is the prior's: centred on the array, wide enough to hold the passage
    assert np.all(q[res.status == INITIALISING] <= 5.991)


def test_streaming_equals_batch_and_is_causal(s2):
    sc, t, y, truth, res = s2
    tr = Tracker(sc, passages=4, sensors=["M1", "M2"])
    for k in range(y.shape[1]):
        s = tr.update(t[k], y[:, k])
        assert _close(s.estimate, res.estimates[:, k], 1e-9) and _close(s.cov, res.covs[:, k], 1e-9)
        np.testing.assert_array_equal(s.status, res.status[:, k])
    # causal: changing the samples after k changes nothing up to k (exactly: the same computations)
    k = y.shape[1] // 2
    y2 = y.copy()
    y2[:, k + 1:] *= 1.5
    res2 = Tracker(sc, passages=4, sensors=["M1", "M2"]).track(t, y2)
    np.testing.assert_array_equal(res2.estimates[:, :k + 1], res.estimates[:, :k + 1])
    np.testing.assert_array_equal(res2.covs[:, :k + 1], res.covs[:, :k + 1])
    assert not np.allclose(res2.estimates[:, k + 2:], res.estimates[:, k + 2:])


@pytest.mark.parametrize("scenario, runs", [("S2", 8), ("demo", 6)])
def test_deferred_window_fits_are_the_fits_update_makes(scenario, runs):
    """``update(..., defer_fits=True)`` leaves a passage whose window completes pending and ``fit_pending`` fits
    every pending window in one batch: passages fed sample by sample at their own pace (pending ones wait,
    then catch up) get exactly ``track``'s estimates, covariances and statuses, though their windows, of
    different lengths (the demo's end early past their peak), complete at different samples and are fitted
    together.  A pending passage refuses another sample.  The passages' different paces also put their later
    refits in other batches than ``track``'s, which changes nothing (the demo's moved at 1e-9 while the global
    starts were fitted over the padded windows)."""
    sim = simulate(scenario, runs=runs, seed=7, random=True)
    t, y = np.broadcast_to(sim.times, sim.measurements.shape[:2]), sim.measurements
    ref = Tracker(scenario, passages=runs).track(sim.times, y)
    tr = Tracker(scenario, passages=runs)
    P, K = y.shape[:2]
    est, cov, status = np.full((P, K, tr.model.n), np.nan), np.full((P, K, tr.model.n, tr.model.n), np.nan), \
        np.full((P, K), -1)
    nk = np.zeros(P, dtype=int)
    batches = []
    for step in range(10 * K):
        act = np.flatnonzero(~tr.pending() & (nk < K))
        if step % 6 == 5 or act.size == 0:
            done, s = tr.fit_pending()
            batches.append(done.size)
            est[done, nk[done] - 1], cov[done, nk[done] - 1], status[done, nk[done] - 1] = s.estimate, s.cov, s.status
            act = np.flatnonzero(~tr.pending() & (nk < K))
        if act.size == 0:
            break
        act = act[nk[act] <= nk[act].min() + 3]                 # the passages drift apart by a few samples
        s = tr.update(t[act, nk[act]], y[act, nk[act]], passages=act, defer_fits=True)
        est[act, nk[act]], cov[act, nk[act]], status[act, nk[act]] = s.estimate, s.cov, s.status
        if step == 0:
            assert not tr.pending().any()
        nk[act] += 1
        if tr.pending().any() and not tr.pending()[act].all():
            p = int(np.flatnonzero(tr.pending())[0])
            with pytest.raises(ValueError, match="fit_pending"):
                tr.update(t[p, nk[p]], y[p, nk[p]][None], passages=[p], defer_fits=True)
    assert (nk == K).all() and max(batches) > 1                   # several windows in one batch
    np.testing.assert_array_equal(status, ref.status)
    np.testing.assert_array_equal(est, ref.estimates)
    np.testing.assert_array_equal(cov, ref.covs)


@pytest.mark.parametrize("history", [1000, 12])
def test_passage_states_carried_into_a_sibling_go_on_as_they_would_have(s2, history):
    """A passage's state taken mid-track (``passage_states``) and set into other rows of a sibling tracker
    (``set_passage_states``) goes on exactly as it would have: estimates, covariances and statuses equal to the
    bit those of tracking it without a break, and its gap is carried (renumbered).  With a 12-sample history
    the history has wrapped at the break and is carried whole; a fresh row of the sibling is left alone.
    States move only between a tracker and its siblings, one per distinct passage in range."""
    sc, t, y, truth, _ = s2
    P, K = y.shape[:2]
    times = np.repeat(t[None], P, axis=0)
    times[1, 20:] += 8.0                                # a gap longer than S2's 5 s limit, before the break
    opts = {"sensors": ["M1", "M2"], "history": history}
    ref = Tracker(sc, passages=P, **opts).track(times, y)
    first = Tracker(sc, passages=P, **opts)
    k = 40
    for j in range(k):
        first.update(times[:, j], y[:, j])
    states = first.passage_states(range(P))
    other = first.sibling(P + 1)
    rows = np.array([3, 0, 4, 1])                       # passage p goes on as row rows[p]; row 2 stays fresh
    other.set_passage_states(rows, states)
    assert [(g.passage, g.start_s) for g in other.gaps] == [(0, times[1, 19])]
    for j in range(k, K):
        s = other.update(times[:, j], y[:, j], passages=rows)
        np.testing.assert_array_equal(s.estimate, ref.estimates[:, j])
        np.testing.assert_array_equal(s.cov, ref.covs[:, j])
        np.testing.assert_array_equal(s.status, ref.status[:, j])
    assert other.state.n[2] == 0 and other.state.phase[2] == Tracker(sc, passages=1, **opts).state.phase[0]
    assert set(np.unique(ref.status[:, k:])) - {INITIALISING, NO_DATA}       # it was tracking by then
    with pytest.raises(ValueError, match="sibling"):
        Tracker(sc, passages=P, **opts).set_passage_states([0], states[:1])
    with pytest.raises(ValueError, match="distinct"):
        other.set_passage_states([0, 0], states[:2])
    with pytest.raises(IndexError, match="out of range"):
        other.set_passage_states([P + 1], states[:1])
    for bad in ([-1], [P + 1]):
        with pytest.raises(IndexError, match="out of range"):
            first.passage_states(bad)
    for bad in ([True, False], [0.9]):
        with pytest.raises(ValueError, match="integers"):
            first.passage_states(bad)
    assert first.passage_states([]) == [] and first.passage_states(np.array([1], dtype=np.int32))[0].gaps
    other.set_passage_states([0], states[:1])            # row 0's gap (passage 1's) goes with its occupant
    assert other.gaps == []


def test_a_passage_is_tracked_as_alone_whatever_is_refitted_beside_it():
    """Two S0 passages (one magnetometer, which rescans) refitted at the same samples with windows of
    different lengths get, each, exactly what it gets alone: the batch pads the shorter window, which the
    compiled fits skip, and the global starts are fitted per window length.  (Before, they were fitted over
    the padded window, picking other samples: passage 5 of this draw moved, tracked with passage 0 -- so a
    vector environment's sub-environment differed from a single environment with the same seed.)"""
    sim = simulate("S0", runs=6, seed=11, random=True)
    y = sim.measurements[[5, 0]]
    both = Tracker("S0", passages=2).track(sim.times, y)
    for i in range(2):
        alone = Tracker("S0", passages=1).track(sim.times, y[i:i + 1])
        np.testing.assert_array_equal(both.estimates[i], alone.estimates[0])
        np.testing.assert_array_equal(both.covs[i], alone.covs[0])
        np.testing.assert_array_equal(both.status[i], alone.status[0])


def test_robust_refits_are_batched_per_window_length():
    """A robust tracker's refits (their information numpy's over the window) are batched per window length:
    PassageHard-v1's passage 1 of this draw, refitted beside the others with windows of other lengths, gets
    exactly what it gets alone; in one padded batch it moved."""
    from shipsense.config import load_scenario
    from shipsense.envs import PASSAGE_V1_VARIANTS

    sc = load_scenario("S2").with_updates(**PASSAGE_V1_VARIANTS["shipsense/PassageHard-v1"]["overrides"])
    sim = simulate(sc, runs=6, seed=2, random=True)
    y = sim.measurements
    alone = Tracker(sc, passages=1).track(sim.times, y[1:2])
    both = Tracker(sc, passages=6)
    assert both.huber is not None and not both.pads_exactly
    res = both.track(sim.times, y)
    np.testing.assert_array_equal(res.estimates[1], alone.estimates[0])
    np.testing.assert_array_equal(res.covs[1], alone.covs[0])
    padded = Tracker(sc, passages=6)
    padded.pads_exactly = True                          # one padded batch, as the compiled fits take
    assert not np.array_equal(padded.track(sim.times, y).estimates[1], alone.estimates[0])


def test_each_passage_starts_from_its_own_data_and_nothing_raises_for_the_batch(s2):
    sc, t, y, truth, res = s2
    y2 = y.copy()
    y2[0] = np.nan                       # a passage with no data at all
    y2[1, :7] = np.nan                   # one whose first samples are missing
    for method in ("tracker", "bank"):
        r = Tracker(sc, passages=4, sensors=["M1", "M2"], method=method).track(t, y2)
        assert np.all(r.status[0] == NO_DATA) and np.all(r.status[1, :7] == NO_DATA)
        assert np.all(r.status[1, 7:] != NO_DATA)
        assert np.isfinite(r.covs).all()
    np.testing.assert_allclose(r.estimates[0], np.broadcast_to(r.estimates[0, :1], r.estimates[0].shape))


def test_time_comes_from_the_timestamps(s2):
    sc, t, y, truth, res = s2
    shifted = Tracker(sc, passages=4, sensors=["M1", "M2"]).track(t + 1234.5, y)
    assert _close(shifted.estimates, res.estimates, 1e-6)
    # irregular sampling: drop a third of the samples at random; the tracker follows the passages in time
    rng = np.random.default_rng(0)
    keep = np.sort(np.concatenate([[0], 1 + rng.choice(len(t) - 1, 2 * (len(t) - 1) // 3, replace=False)]))
    r = Tracker(sc, passages=4, sensors=["M1", "M2"]).track(t[keep], y[:, keep])
    err = np.hypot(*(r.estimates[:, -1, :2] - truth[:, keep[-1], :2]).T)
    assert np.all(err < 2.0), err
    # a gap longer than the limit is predicted through and reported once, naming it
    hole = np.r_[0:40, 60:len(t)]
    tr = Tracker(sc, passages=4, sensors=["M1", "M2"], gap_limit_s=5.0)
    r = tr.track(t[hole], y[:, hole])
    assert [(g.passage, g.start_s, g.end_s) for g in r.gaps] == [(p, t[39], t[60]) for p in range(4)]
    assert "predicted through" in str(r.gaps[0])
    with pytest.raises(ValueError, match="time must increase: passage 0"):
        tr.update(np.full(4, t[0]), y[:, 0])


@pytest.mark.parametrize("initial_fits_too", [False, True])
def test_a_bank_knocked_off_its_track_is_restarted_by_its_alarm(s2, initial_fits_too):
    """The bank's hypotheses moved 30 m off with a covariance of centimetres: the innovations raise the
    divergence alarm and a refit brings the track back.  Also when the bank and the initial window's fits
    are all 150 m off and sailing the other way, beyond the reach of a local refit: the restart after an
    alarm runs the global initialiser again on everything since the detection."""
    sc, t, y, truth, res = s2
    tr = Tracker(sc, passages=4, sensors=["M1", "M2"], refit_every=None, through_peak=None, collapse=None)
    K = y.shape[1]
    for k in range(K // 2):
        tr.update(t[k], y[:, k])
    assert np.all(tr.state.phase == 2)
    if initial_fits_too:
        tr.bank.belief.mean[:, 0] += 150.0
        tr.bank.belief.mean[:, 2:4] *= -1.0
        tr.state.win[..., 0] += 150.0 / tr.model.x_scale[0]
        tr.state.win[..., 2:4] *= -1.0
    else:
        tr.bank.belief.mean[:, 0] += 30.0
    tr.bank.belief = type(tr.bank.belief).from_cov(tr.bank.belief.mean, np.broadcast_to(
        np.eye(tr.model.n) * 1e-4, tr.bank.belief.chol.shape))
    for k in range(K // 2, K):
        s = tr.update(t[k], y[:, k])
    assert np.all(tr.state.alarms >= 1)
    err = np.hypot(*(s.estimate[:, :2] - truth[:, -1, :2]).T)
    assert np.all(err < 1.0), err


def test_robust_mode_with_outliers_and_dropouts_stays_consistent():
    sc = load_scenario("S2").with_updates(noise={"model": "contaminated", "eps": 0.2, "outlier_scale": 10.0,
                                                 "dropout": 0.3})
    sim = simulate(sc, runs=4, seed=3, random=True)
    tr = Tracker(sc, passages=4, sensors=["M1", "M2"])
    assert tr.settings.robust and tr.unit.name == "huber_ukf" and 1.9 < tr.kappa < 2.1
    res = tr.track(sim.times, sim.measurements[..., :6])
    truth = tr.model.state_from_truth(sim.truth)
    err = np.hypot(*(res.estimates[:, -1, :2] - truth[:, -1, :2]).T)
    assert np.all(err < 2.0), err
    assert np.isfinite(res.covs).all() and np.all(np.linalg.eigvalsh(res.covs) > 0)
    d = res.estimates[..., :2] - truth[..., :2]
    q = np.einsum("pki,pkij,pkj->pk", d, np.linalg.inv(res.position_cov), d)
    assert np.mean(q[res.status >= TRACKING] <= 5.991) >= 0.85
    assert set(np.unique(res.status)) <= {INITIALISING, TRACKING, RESTARTED, INCONSISTENT}


def test_passages_step_and_start_over_on_their_own(s2):
    """The environments' use: passages advance (``update(..., passages=)``) and restart
    (``reset_passages``) independently; a passage's track does not depend on when the others run."""
    sc, t, y, truth, res = s2
    K = y.shape[1]
    tr = Tracker(sc, passages=2, sensors=["M1", "M2"])
    for k in range(10):
        tr.update(t[k:k + 1], y[0:1, k], passages=[0])
    for k in range(10, K):
        s = tr.update(np.array([t[k], t[k - 10]]), np.stack([y[0, k], y[1, k - 10]]))
    assert _close(s.estimate[0], res.estimates[0, -1], 1e-6) and _close(s.cov[0], res.covs[0, -1], 1e-6)
    tr.reset_passages([0])
    assert tr.state.n.tolist() == [0, K - 10]
    s = tr.update(t[:1], y[0:1, 0], passages=[0])
    assert s.status[0] == INITIALISING and _close(s.estimate, res.estimates[0:1, 0], 1e-12)


def test_a_weak_window_fit_does_not_start_a_bank_wider_than_the_prior():
    """A one-magnetometer passage of the wide-prior study whose window fit hardly tells range from moment: its
    covariance was kilometres wide, the SRCDKF's sigma points left the model's domain and the track went to
    1e23 m.  The bank now starts from the fit's information plus the passage prior's, so the estimate stays
    within the prior's reach and the passage is tracked to the end."""
    from shipsense.reproduce import wide

    sc, model, unit, y, truth, ends = wide.family_passages("one_magnetometer", 500, 0)
    tr = Tracker(sc, passages=1, sensors=list(model.array.ids), unit=unit.name,
                 **wide.init_options("one_magnetometer", sc))
    res = tr.track(sc.times[: y.shape[1]], y[394:395])
    err = np.hypot(*(res.estimates[0, : ends[394], :2] - truth[394, : ends[394], :2]).T)
    assert err.max() < 500.0 and err[-10:].max() < 1.0, (err.max(), err[-10:])
    assert np.isfinite(res.covs).all()


def test_an_inconsistent_track_reports_no_more_than_the_prior_knows():
    """Wide-prior one-magnetometer passage 29: the early window fits are wrong (one magnetometer before the
    closest approach), the refits fail their test for several samples (15 before the ambiguity restart, 7
    with it) and the track is 120-150 m off while its own covariance shrinks to metres.  The status says
    `inconsistent`; the covariance must say it too: the truth stays inside the reported 99.9 % ellipse at
    every such sample."""
    from shipsense.reproduce import wide

    sc, model, unit, y, truth, ends = wide.family_passages("one_magnetometer", 100, 0)
    tr = Tracker(sc, passages=1, sensors=list(model.array.ids), **wide.init_options("one_magnetometer", sc))
    res = tr.track(sc.times[: y.shape[1]], y[29:30])
    bad = res.status[0] == INCONSISTENT
    d = res.estimates[0, :, :2] - truth[29, :, :2]
    err = np.hypot(*d.T)
    assert bad.sum() >= 5 and err[bad].max() > 20.0       # the case: a stretch far off
    q = np.einsum("ki,kij,kj->k", d, np.linalg.inv(res.position_cov[0]), d)
    assert q[bad].max() < 13.8, q[bad].max()
    assert err[ends[29] - 10: ends[29]].max() < 1.0       # and it recovers


def test_huber_variance_factor_at_a_threshold_matches_quadrature():
    from scipy import integrate, stats

    from shipsense.trackers.fit.robust import Huber

    h = Huber(eps=0.2, scale=10.0)

    def expect(f, c):   # E[f(e)] under the contaminated noise, by quadrature split at the kinks +-c
        return sum(share * integrate.quad(lambda e, sd=sd: f(e) * stats.norm(scale=sd).pdf(e), lo, hi, epsabs=1e-12)[0]
                   for share, sd in ((0.8, 1.0), (0.2, 10.0)) for lo, hi in ((-np.inf, -c), (-c, c), (c, np.inf)))

    for c in (0.5, 1.345, 3.0, 20.0):
        psi2 = expect(lambda e, c=c: min(e * e, c * c), c)
        slope = expect(lambda e, c=c: float(abs(e) <= c), c)
        assert abs(h.variance_factor_at(c) / (psi2 / slope**2) - 1.0) < 1e-8   # quadrature's accuracy
    assert abs(h.variance_factor_at(h.gamma) / h.variance_factor - 1.0) < 1e-8
    assert abs(h.variance_factor_at(np.inf) - (0.8 + 0.2 * 100.0)) < 1e-9   # no clip: the noise's variance


def test_a_huber_fit_dominated_by_one_sample_reports_the_variance_of_its_masked_outliers():
    """One sample carrying most of the information (an inverse-cube field at the closest approach) is fitted
    so closely that an outlier on it goes undetected: the asymptotic ``kappa (J^T J)^-1`` is then several times
    too small (8x here); the leverage-aware information comes within 1.3x of the Monte Carlo variance of the
    Huber fit (linear model; the clip at ``gamma / (1 - h)`` ignores the other samples' share of the residual)."""
    from shipsense.trackers.fit.robust import Huber, leverage_information

    rng = np.random.default_rng(0)
    h, n_rows, draws = Huber(eps=0.2, scale=10.0), 60, 4000
    J = np.column_stack([np.ones(n_rows), np.linspace(-1.0, 1.0, n_rows)])
    J[n_rows // 2] = [0.0, 12.0]                      # the dominant sample: leverage 0.87
    e = rng.standard_normal((draws, n_rows)) * np.where(rng.random((draws, n_rows)) < h.eps, h.scale, 1.0)
    theta = np.zeros((draws, 2))
    for _ in range(60):                                # the Huber M-estimate of every draw (IRLS, batched)
        r = e - theta @ J.T
        w = np.minimum(1.0, h.gamma / np.maximum(np.abs(r), 1e-300))
        rhs = np.einsum("ri,dr->di", J, w * e)[..., None]
        theta = np.linalg.solve(np.einsum("ri,dr,rj->dij", J, w, J), rhs)[..., 0]
    var = theta[:, 1].var()
    JtJ = J.T @ J
    asymptotic = h.variance_factor * np.linalg.inv(JtJ)[1, 1]
    leverage = h.variance_factor * np.linalg.inv(leverage_information(J[None], JtJ[None], h, n_rows)[0])[1, 1]
    assert var > 4.0 * asymptotic, (var, asymptotic)
    assert 0.8 < var / leverage < 1.6, (var, leverage)


def test_faulty_passages_are_inside_their_ellipses_as_often_as_they_say():
    """20 % outliers of 10 std and 30 % dropouts on two magnetometers: after convergence the truth lies inside
    the reported 95 % ellipse in 0.85-0.99 of the samples (issue 16's target).  Measured on these passages: 0.873
    with the refits' covariance accounting for leverage, 0.765 with the asymptotic ``kappa (J^T J)^-1`` (seed 11:
    0.925 and 0.858)."""
    from shipsense.trackers.metrics import converged_until, passage_ends

    sc = load_scenario("S2").with_updates(noise={"model": "contaminated", "eps": 0.2, "outlier_scale": 10.0,
                                                 "dropout": 0.3})
    sim = simulate(sc, runs=16, seed=12, random=True)
    tr = Tracker(sc, passages=16, sensors=["M1", "M2"])
    res = tr.track(sim.times, sim.measurements[..., :6])
    truth = tr.model.state_from_truth(sim.truth)
    conv, err, valid = converged_until(res.estimates, truth, passage_ends(truth, tr.model.array.positions[
        :, :2].mean(axis=0), sc.period))
    assert conv.mean() >= 0.9
    k = np.arange(truth.shape[1])
    above = np.where(valid, err >= 10.0, False)
    settled = np.where(above.any(axis=1), truth.shape[1] - np.argmax(above[:, ::-1], axis=1), 0)
    post = valid & conv[:, None] & (k >= settled[:, None]) & (res.status >= TRACKING)
    d = res.estimates[..., :2] - truth[..., :2]
    q = np.einsum("pki,pkij,pkj->pk", d, np.linalg.inv(res.position_cov), d)
    assert 0.85 <= np.mean(q[post] <= 5.991) <= 0.99, np.mean(q[post] <= 5.991)


def test_leverage_information_of_a_fit_that_cannot_separate_two_components_does_not_raise():
    """A refit's Jacobian with two equal columns (a combination of the state no sample tells apart) made the
    sandwich's solve raise for the whole batch (seen on 1,000 faulty two-magnetometer passages); it is now the
    pseudo-inverse's: finite, blind to that combination, and the batch's other fits are as before."""
    from shipsense.trackers.fit.robust import Huber, leverage_information

    rng = np.random.default_rng(2)
    J = rng.standard_normal((2, 12, 3))
    J[1, :, 2] = J[1, :, 1]
    JtJ = np.swapaxes(J, -1, -2) @ J
    h = Huber(eps=0.2, scale=10.0)
    info = leverage_information(J, JtJ, h, 12)
    assert np.isfinite(info).all()
    np.testing.assert_allclose(info[0], leverage_information(J[:1], JtJ[:1], h, 12)[0], rtol=1e-12)
    assert np.linalg.norm(info[1] @ np.array([0.0, 1.0, -1.0])) < 1e-9 * np.linalg.norm(info[1])


def test_one_magnetometer_rescans_and_leaves_a_wrong_basin():
    """S0 passage 79 (300 random passages, seed 0) is seen from 190 m: early on two tracks, the true one and
    one 400 m off, explain its samples equally well (chi-square 338 against 338 at sample 110), and the bank
    took the wrong one.  Refits started from the bank's hypotheses stayed there -- 128 m off with a reported
    sd of 8 m at sample 200, where the true track's chi-square is lower by 19 -- until the consistency test
    fired at sample 246, too late to converge.  One magnetometer's tracker therefore also runs the global
    initialiser on its samples every ``refit_every`` samples before the closest approach (``rescan``, on by
    default for that family only)."""
    sc = load_scenario("S0")
    sim = simulate(sc, runs=300, seed=0, random=True)
    tr = Tracker(sc, passages=1)
    assert tr.settings.rescan and not Tracker("S2", sensors=["M1", "M2"]).settings.rescan
    res = tr.track(sim.times, sim.measurements[79:80])
    truth = tr.model.state_from_truth(sim.truth[79:80])
    err = np.hypot(*(res.estimates[0, :, :2] - truth[0, :, :2]).T)
    assert err[200] < 10.0 and err[-30:].max() < 10.0, (err[200], err[-30:].max())


@pytest.mark.parametrize("bad, match", [({"window_s": 0.0}, "window_s: must be > 0"),
                                        ({"grid_samples": 0}, "grid_samples: must be greater than or equal to 1"),
                                        ({"grid_samples": 7.5}, "grid_samples: expected a whole number"),
                                        ({"grid_samples": True}, "grid_samples: expected a whole number"),
                                        ({"consistency_window": 1}, "consistency_window: must be greater than or "
                                                                    "equal to 2"),
                                        ({"keep": 6}, "keep: cannot exceed keep_init \\(5\\), got 6")])
def test_bad_options_raise_one_error_naming_the_option(bad, match):
    with pytest.raises(ValueError, match=match):
        Tracker("S2", **bad)


def test_the_grid_search_samples_follow_the_array_family():
    """Several magnetometers search their grid on every second sample of S2's 30-sample window (15); one
    magnetometer and the electrodes keep at least 16 (docs: Results: 15 of S0's 75 lost two of 1,000 faulty
    passages); an explicit value wins, and window_fits is called with it."""
    from shipsense.trackers.tracker import bank_starts

    assert Tracker("S2").settings.grid_samples == 15
    assert Tracker("S0").settings.grid_samples == 16
    assert Tracker("S1-P2").settings.grid_samples == 16
    sc = load_scenario("S2")
    sim = simulate(sc, runs=1, seed=2, random=True)
    seen = []
    window_fits = bank_starts.window_fits

    def spy(model, yw, **kw):
        seen.append(kw["grid_samples"])
        return window_fits(model, yw, **kw)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(bank_starts, "window_fits", spy)
        Tracker(sc, grid_samples=10).track(sim.times, sim.measurements)
    assert seen and set(seen) == {10}
