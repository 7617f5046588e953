"""The tracker's windowed innovation consistency test: its null distribution, its power, what it does on failure."""

import numpy as np
import pytest
from reference import statistic, terms
from scipy import stats

from shipsense import load_scenario, simulate
from shipsense.trackers import Tracker
from shipsense.trackers.fit.robust import Huber
from shipsense.trackers.tracker.consistency import psi_variance, threshold
from shipsense.trackers.tracker.results import INCONSISTENT, TRACKING

FAULTY = {"model": "contaminated", "eps": 0.2, "outlier_scale": 10.0, "dropout": 0.3}


@pytest.mark.parametrize("state_var", [0.0, 0.3, 4.0])
def test_psi_variance_matches_quadrature_of_the_noise_model(state_var):
    """``v = E[psi(z)^2]`` in closed form against Huber.expect's quadrature of the same mixture: a clean share
    of variance 1 and outliers of variance ``(state_var + scale^2) / (state_var + 1)``."""
    gamma, eps, scale = 1.345, 0.2, 10.0
    v = psi_variance(np.array(state_var), np.array(1.0), gamma, eps, scale)
    h = Huber(gamma=gamma, eps=eps, scale=np.sqrt((state_var + scale ** 2) / (state_var + 1.0)))
    assert v == pytest.approx(h.expect(lambda e: np.clip(e, -gamma, gamma) ** 2), rel=1e-8)
    assert psi_variance(np.array(state_var), np.array(1.0)) == 1.0   # Gaussian and no clip: z itself


def test_honest_innovations_fail_the_test_at_its_level_and_biased_ones_fail_it_often():
    """White innovations of the declared noise (Gaussian, unclipped, 30 % missing): T is chi-square with one
    degree per channel with data, so a test at level 0.01 fails in 1 % of windows (within 3 sd of the
    binomial); with 20 % outliers of 10 sd and Huber's clip, the normal approximation fails in 0.5-2 %.  A
    persistent error of 8 times the state's share of the innovation variance fails it in most windows, an
    outlier of any size in one of them moves it by a bounded amount."""
    rng = np.random.default_rng(0)
    n_win, N, m = 20000, 20, 3
    state_var, noise_var = np.full((n_win, N, m), 0.5), np.ones((n_win, N, m))
    present = rng.random((n_win, N, m)) > 0.3
    eps = rng.standard_normal((n_win, N, m)) * np.sqrt(state_var + noise_var)
    T, dof = statistic(terms(eps, state_var, noise_var, present).sum(axis=1))
    assert np.all(dof == present.any(axis=1).sum(axis=-1))
    rate = np.mean(T > threshold(dof, 0.01))
    assert abs(rate - 0.01) < 3 * np.sqrt(0.01 * 0.99 / n_win), rate
    # contaminated noise, Huber's clip
    out = rng.random((n_win, N, m)) < 0.2
    noisy = np.sqrt(state_var) * rng.standard_normal(eps.shape) + np.where(
        out, 10.0, 1.0) * rng.standard_normal(eps.shape)
    robust = (1.345, 0.2, 10.0)
    T, dof = statistic(terms(noisy, state_var, noise_var, present, *robust).sum(axis=1))
    assert 0.005 < np.mean(T > threshold(dof, 0.01)) < 0.02
    # one huge outlier per window: bounded by the clip
    huge = noisy.copy()
    huge[:, 0, 0] = 1e6
    T2, _ = statistic(terms(huge, state_var, noise_var, present, *robust).sum(axis=1))
    assert np.mean(T2 > threshold(dof, 0.01)) < 0.05
    # a persistent error of covariance 8 x state_var on top of the honest innovations
    bias = np.sqrt(8.0 * state_var[:, :1]) * rng.standard_normal((n_win, 1, m))
    T, dof = statistic(terms(eps + bias, state_var, noise_var, present).sum(axis=1))
    assert np.mean(T > threshold(dof, 0.01)) > 0.5


def _s2(noise_factor, runs, seed):
    """S2 passages tracked with the declared noise, their measurements carrying ``noise_factor`` times it."""
    sc = load_scenario("S2")
    sim = simulate(sc, runs=runs, seed=seed, random=True)
    tr = Tracker(sc, passages=runs, sensors=["M1", "M2"])
    y = sim.measurements[..., :6]
    sd = np.sqrt(tr.model.R) * tr.model.y_scale
    y = y + np.sqrt(noise_factor ** 2 - 1.0) * sd * np.random.default_rng(seed).standard_normal(y.shape)
    return tr, tr.track(sim.times, y)


def test_the_tracker_flags_an_optimistic_filter_and_not_an_honest_one():
    """Passages whose noise is 3 times the declared: the test fails, those samples are ``inconsistent`` and
    their covariance is inflated (finite, symmetric, positive definite).  At the declared noise it fails on
    no more samples than its level allows (binomial, 1e-3 one-sided)."""
    tr, res = _s2(1, 8, 21)
    tests, fails = int(tr.state.cons_tests.sum()), int(tr.state.cons_fails.sum())
    assert tests > 100
    assert fails <= stats.binom.isf(1e-3, tests, tr.settings.consistency_level), (fails, tests)
    tr3, res3 = _s2(3, 8, 21)
    assert tr3.state.cons_fails.sum() > 5 * max(fails, 1), (tr3.state.cons_fails.sum(), fails)
    assert (res3.status == INCONSISTENT).sum() >= tr3.state.cons_fails.sum() // 2
    assert np.isfinite(res3.covs).all()
    assert_positive_definite(res3.covs)
    assert set(np.unique(res.status)) >= {TRACKING}


def test_faulty_passages_keep_finite_symmetric_positive_definite_covariances():
    """Issue 16 item 3 over faulty passages (20 % outliers of 10 sd, 30 % dropouts) of one magnetometer, where
    restarts, failed fits and the consistency test's inflation all happen: every covariance of every sample is
    finite, symmetric and positive definite, and no estimate is NaN."""
    sc = load_scenario("S0").with_updates(noise=FAULTY)
    sim = simulate(sc, runs=6, seed=4, random=True)
    tr = Tracker(sc, passages=6)
    res = tr.track(sim.times, sim.measurements)
    assert np.isfinite(res.covs).all() and np.isfinite(res.estimates).all()
    assert_positive_definite(res.covs)
    assert tr.state.restarts.sum() > 0 and tr.state.cons_fails.sum() > 0 and (res.status == INCONSISTENT).any()


def assert_positive_definite(c):
    """Symmetric, and positive definite against its own scale: the entries span 1e-9 (m/s)^2 to 1e16 (A m^2)^2,
    so the eigenvalues of the raw matrix are rounding at 1e-17 of the largest; those of the correlation matrix
    ``D^-1/2 C D^-1/2`` are not.  The position block is checked as it is."""
    np.testing.assert_array_equal(c, np.swapaxes(c, -1, -2))
    d = np.sqrt(np.diagonal(c, axis1=-2, axis2=-1))
    assert np.all(d > 0)
    assert np.all(np.linalg.eigvalsh(c / d[..., :, None] / d[..., None, :]) > 0)
    assert np.all(np.linalg.eigvalsh(c[..., :2, :2]) > 0)


def test_quantiles_from_scipy_special_equal_scipy_stats_and_the_tracker_leaves_scipy_stats_unloaded():
    """The tests' chi-square and normal quantiles come from scipy.special (scipy.stats costs 40 MB and 0.3 s to
    import): equal to scipy.stats' (the same special functions underneath); a tracked passage, its window fits'
    goodness-of-fit limits and the bank's divergence flags load no scipy.stats."""
    import subprocess
    import sys

    from shipsense.models.field_model import model_from_scenario
    from shipsense.trackers.fit.robust import _normal_pdf
    from shipsense.trackers.init.window_fits import chi2_limit
    from shipsense.trackers.tracker.consistency import _quantiles

    np.testing.assert_array_equal(_quantiles(0.01, 9)[1:], stats.chi2.isf(0.01, np.arange(1, 16)))
    model = model_from_scenario("S2")
    yfit = np.ones((3, 7, model.m))
    yfit[1, :2] = np.nan
    dof = np.isfinite(yfit).reshape(3, -1).sum(axis=1) - model.n        # no prior: data less the state
    np.testing.assert_array_equal(chi2_limit(model, yfit, None, 0.01), stats.chi2.isf(0.01, dof))
    h = Huber(eps=0.1)
    mu, var = h.moments
    assert h.limit(30, 0.01) == pytest.approx(30 * mu + stats.norm.isf(0.01) * np.sqrt(30 * var), rel=1e-15)
    e = np.linspace(-40.0, 40.0, 81)
    np.testing.assert_allclose(_normal_pdf(e, 10.0), stats.norm(scale=10.0).pdf(e), rtol=1e-15)
    code = ("import sys; from shipsense import load_scenario, simulate; from shipsense.trackers import Tracker; "
            "from shipsense.trackers.bank import run_bank; sc = load_scenario('S2'); s = simulate(sc, runs=1, seed=1); "
            "t = Tracker(sc, passages=1); t.track(sc.times, s.measurements); "
            "b = run_bank('ukf', t.model, s.measurements, s.truth[:, :1, :7], 100.0 * np.eye(7), "
            "store=('nis', 'm', 'ok')); b.diverged(); assert 'scipy.stats' not in sys.modules, 'scipy.stats loaded'")
    subprocess.run([sys.executable, "-c", "import numpy as np; " + code], check=True)


@pytest.mark.parametrize("shared", [False, True])
@pytest.mark.parametrize("huber", [None, (1.345, 0.2, 10.0)])
def test_the_trackers_one_pass_is_the_definitions(huber, shared):
    """``window_test`` (the tracker's compiled pass) against :func:`terms`, :func:`statistic` and
    :func:`threshold` over a stream of samples: the same windows (to rounding), the same tests, the same
    failures and resets; the selected hypothesis's innovations are the ones tested, a NaN covariance stays NaN
    (as np.maximum and np.clip leave it) and the noise removed is the filter's (one row for every element, as the
    tracker passes its model's) or a reweighted one per element (the Huber UKF's ``R``)."""
    from shipsense.trackers.tracker.consistency import quantile_table, window_test

    rng = np.random.default_rng(2)
    P, H, m, N, level = 5, 3, 4, 6, 0.2
    gamma, out_eps, scale = huber if huber else (np.inf, 0.0, 1.0)
    R_declared = np.array([1.0, 2.0, 0.5, 3.0])
    window, count = np.zeros((P, N, 2, m)), np.zeros(P, dtype=np.int64)
    tests, fails, now = np.zeros(P, dtype=np.int64), np.zeros(P, dtype=np.int64), np.zeros(P, dtype=bool)
    ref_window, ref_count = window.copy(), count.copy()
    ref_tests, ref_fails = tests.copy(), fails.copy()
    runs = np.array([0, 1, 3, 4])
    failures = 0
    for k in range(40):
        sel = rng.integers(0, H, runs.size)
        R_used = R_declared * rng.uniform(1.0, 2.0, (1 if shared else runs.size * H, m))
        S = np.zeros((runs.size * H, m, m))
        S[:, np.arange(m), np.arange(m)] = R_used + rng.uniform(0.0, 0.5, (runs.size * H, m))
        eps = rng.standard_normal((runs.size * H, m)) * (1.0 + 2.0 * (k % 10 > 6))   # bursts fail the test
        present = rng.random((runs.size, m)) > 0.25
        if k == 7:
            S[sel[0], 1, 1] = np.nan                                         # (passage 0, selected)
        failed = np.empty(runs.size, dtype=bool)
        now[:] = False
        window_test(runs, sel, H, eps, S, R_used, R_declared, present, gamma, out_eps, scale,
                    quantile_table(level, m), window, count, tests, fails, now, failed)
        # the definitions, as the tracker applied them before
        pick = np.arange(runs.size)
        e = eps.reshape(runs.size, H, m)[pick, sel]
        Sd = np.diagonal(S, axis1=-2, axis2=-1).reshape(runs.size, H, m)[pick, sel]
        noise = R_used if shared else R_used.reshape(runs.size, H, m)[pick, sel]
        t = terms(e, np.maximum(Sd - noise, 0.0), R_declared, present, gamma, out_eps, scale)
        ref_window[runs, ref_count[runs] % N] = t
        ref_count[runs] += 1
        T, dof = statistic(ref_window[runs].sum(axis=1))
        tested = ref_count[runs] >= N
        ref_tests[runs] += tested
        ref_failed = tested & (T > threshold(dof, level))
        gone = runs[ref_failed]
        ref_window[gone], ref_count[gone] = 0.0, 0
        ref_fails[gone] += 1
        np.testing.assert_array_equal(failed, ref_failed)
        np.testing.assert_allclose(window, ref_window, rtol=1e-13, atol=0)   # (NaN where the reference has NaN)
        np.testing.assert_array_equal(now, np.isin(np.arange(P), gone))
        np.testing.assert_array_equal(count, ref_count)
        np.testing.assert_array_equal(tests, ref_tests)
        np.testing.assert_array_equal(fails, ref_fails)
        failures += ref_failed.sum()
    assert failures > 0 and (count[2], tests[2]) == (0, 0)                       # tests fail; passage 2 never ran
