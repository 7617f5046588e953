"""Filter units: the Kalman filter as the linear limit, FilterPy agreement, equivalences, masking, robustness."""

import numpy as np
import pytest
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
from reference import kalman_reference
from scaled import assert_cov_close, assert_factor_close, assert_loglik_close

from shipsense import load_scenario, simulate
from shipsense.models.field_model import LinearModel, model_from_scenario
from shipsense.trackers.filters import FILTER_NAMES, Belief, get_filter, predict
from shipsense.trackers.filters.run import run_filter
from shipsense.trackers.metrics import position_error

ALL = {name: get_filter(name) for name in FILTER_NAMES}
ALL["huber_ukf"] = get_filter("huber_ukf", gamma=1e12)   # the KF limit needs gamma -> infinity
ALL["puekf"] = get_filter("puekf", n_pu=4)               # linear: N_pu sub-updates with R N_pu = one update




@pytest.fixture(scope="module")
def linear_case():
    rng = np.random.default_rng(0)
    T = 0.5
    A = np.eye(4)
    A[0, 2] = A[1, 3] = T
    Q = 0.05 * np.eye(4)
    C = rng.standard_normal((3, 4))
    R = np.array([0.5, 1.0, 2.0])
    model = LinearModel(A, Q, C, R)
    x = np.array([0.0, 0.0, 1.0, -1.0])
    ys = []
    for _ in range(30):
        x = A @ x + rng.multivariate_normal(np.zeros(4), Q)
        ys.append(C @ x + rng.standard_normal(3) * np.sqrt(R))
    y = np.array(ys)[None].repeat(3, axis=0) + rng.standard_normal((3, 30, 3))  # 3 runs
    x0 = np.array([1.0, -1.0, 0.0, 0.0])
    P0 = np.diag([4.0, 4.0, 1.0, 1.0])
    refs = [kalman_reference(A, Q, C, np.diag(R), y[r], x0, P0) for r in range(3)]
    return model, y, x0, P0, refs


@pytest.mark.parametrize("name", FILTER_NAMES)
def test_every_filter_reproduces_the_kalman_filter(name, linear_case):
    model, y, x0, P0, refs = linear_case
    run = run_filter(ALL[name], model, y, x0, P0)
    for r, (xs, Ps, ll) in enumerate(refs):
        np.testing.assert_allclose(run.means[r], xs, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(run.covs[r], Ps, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(run.loglik[r], ll, rtol=1e-9)


@pytest.fixture(scope="module")
def s0():
    sim = simulate("S0", runs=3, seed=11)
    model = model_from_scenario("S0")
    truth = sim.truth[..., [0, 1, 2, 3, 5, 6, 7]]
    x0 = truth[:, 0].copy()
    x0[:, 0] += 15.0
    x0[:, 1] -= 10.0
    x0[:, 4:] = 0.0
    P0 = np.diag([400.0, 400.0, 4.0, 4.0, 1e14, 1e14, 1e14])
    return sim, model, truth, x0, P0


def test_ukf_matches_filterpy_on_the_s0_passage(s0):
    sim, model, _, x0, P0 = s0
    steps = 120
    y = sim.measurements[0, :steps] / model.y_scale
    xi, Pi = model.to_internal(x0[0]), P0 / np.outer(model.x_scale, model.x_scale)
    points = MerweScaledSigmaPoints(model.n, alpha=1.0, beta=2.0, kappa=0.0)
    ukf = UnscentedKalmanFilter(model.n, model.m, model.period, hx=model.h, fx=lambda x, dt: model.A @ x,
                                points=points)
    ukf.x, ukf.P, ukf.Q, ukf.R = xi.copy(), Pi.copy(), model.Q.copy(), np.diag(model.R)
    ref = []
    for k in range(steps):
        if k:
            ukf.predict()
        else:  # FilterPy's update draws its points in predict: draw them from the prior at step 0
            ukf.sigmas_f = points.sigma_points(ukf.x, ukf.P)
        ukf.update(y[k])
        ref.append(ukf.x.copy())
    ref = np.array(ref) * model.x_scale
    ours = run_filter("ukf", model, sim.measurements[0, :steps], x0[0], P0).means
    scale = np.abs(ref).max(axis=0)
    np.testing.assert_allclose(ours / scale, ref / scale, rtol=0, atol=1e-6)


def test_srcdkf_covariance_equals_cdkf(s0):
    sim, model, _, x0, P0 = s0
    a = run_filter("cdkf", model, sim.measurements, x0, P0)
    b = run_filter("srcdkf", model, sim.measurements, x0, P0)
    d = np.sqrt(np.diagonal(a.covs, axis1=-2, axis2=-1))
    rel = np.abs(b.covs - a.covs) / (d[..., :, None] * d[..., None, :])   # in correlation units
    assert rel.max() < 1e-8, rel.max()
    np.testing.assert_allclose(b.means, a.means, rtol=0, atol=1e-6 * np.abs(a.means).max())


def test_puekf_with_one_sub_update_is_the_ekf(s0):
    sim, model, _, x0, P0 = s0
    a = run_filter("ekf", model, sim.measurements, x0, P0)
    b = run_filter(get_filter("puekf", n_pu=1), model, sim.measurements, x0, P0)
    # the same update computed in another order: over 300 steps with S0's Q (0.1 (A·m²)² on moments of 1e7,
    # a nearly singular moment block) rounding grows with the conditioning and differs between BLAS kernels
    # (3.5e-7 nats on an AVX-512 machine, 0 on AVX2); a wrong update differs by whole nats
    np.testing.assert_allclose(b.means, a.means, rtol=1e-9, atol=1e-9)
    assert_loglik_close(b.loglik, a.loglik, nats=1e-5)
    c = run_filter(get_filter("puekf", n_pu=5), model, sim.measurements, x0, P0)
    assert not np.allclose(c.means, a.means)  # the sub-updates do something on a nonlinear model


def test_huber_ukf_tends_to_ukf_and_suppresses_outliers():
    sc = load_scenario("S2")
    model = model_from_scenario(sc, sensors=["M1", "M2"])
    truth_cols = [0, 1, 2, 3, 5, 6, 7]
    sim = simulate(sc, runs=1)
    x0 = sim.truth[0, 0, truth_cols].copy()
    x0[:2] += [3.0, -3.0]
    x0[4:] = 0.0
    P0 = np.diag([25.0, 25.0, 2.0, 2.0, 1e8, 1e8, 1e8])
    cols = ~sim.array.axial
    a = run_filter("ukf", model, sim.measurements[..., cols], x0, P0)
    b = run_filter(get_filter("huber_ukf", gamma=1e9), model, sim.measurements[..., cols], x0, P0)
    np.testing.assert_allclose(b.means, a.means, rtol=1e-12, atol=1e-9)
    dirty = simulate(sc.with_updates(noise={"model": "contaminated", "eps": 0.2}), runs=40, seed=3)
    y = dirty.measurements[..., cols]
    truth = dirty.truth[..., truth_cols]
    err_ukf = position_error(run_filter("ukf", model, y, x0, P0).means, truth)[:, 20:].mean()
    err_hub = position_error(run_filter("huber_ukf", model, y, x0, P0).means, truth)[:, 20:].mean()
    assert err_hub < 0.8 * err_ukf, (err_hub, err_ukf)


@pytest.mark.parametrize("name", FILTER_NAMES)
def test_a_batch_element_equals_the_filter_run_alone(name, s0):
    sim, model, _, x0, P0 = s0
    batch = run_filter(name, model, sim.measurements[:, :60], x0, P0)
    alone = run_filter(name, model, sim.measurements[1, :60], x0[1], P0)
    np.testing.assert_allclose(batch.means[1], alone.means, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(batch.loglik[1], alone.loglik, rtol=1e-10)


@pytest.mark.parametrize("name", FILTER_NAMES)
def test_large_batches_give_the_small_batch_results(name, s0):
    """Above a few hundred elements the factorisations take vectorised paths; results must not change."""
    sim, model, _, x0, P0 = s0
    small = run_filter(name, model, sim.measurements[:, :40], x0, P0, store=("means", "chols"))
    big = run_filter(name, model, np.repeat(sim.measurements[:, :40], 200, axis=0), np.repeat(x0, 200, axis=0), P0,
                     store=("means", "chols"))
    np.testing.assert_allclose(big.means[::200], small.means, rtol=1e-9, atol=1e-7)
    assert_loglik_close(big.loglik[::200], small.loglik, nats=1e-6)
    assert_factor_close(big.chols[::200], small.chols, 1e-7)


@pytest.mark.parametrize("name", FILTER_NAMES)
def test_masked_update_equals_the_model_without_those_rows(name):
    sc = load_scenario("S2")
    full = model_from_scenario(sc, sensors=["M1", "M2"])
    part = model_from_scenario(sc, sensors=["M1"])
    sim = simulate(sc, runs=2, seed=5)
    cols = ~sim.array.axial
    y = sim.measurements[..., cols]
    x0 = sim.truth[:, 0, [0, 1, 2, 3, 5, 6, 7]].copy()
    x0[:, 4:] = 0.0
    P0 = np.diag([25.0, 25.0, 2.0, 2.0, 1e8, 1e8, 1e8])
    y_nan = y.copy()
    y_nan[:, 10:40, 3:] = np.nan        # M2 silent for 30 steps
    masked = run_filter(name, full, y_nan, x0, P0, store=("means", "chols"))
    # from the same belief at step 9, each masked step equals the one-sensor model's step
    b = Belief(masked.means[:, 9] / full.x_scale, masked.chols[:, 9] / full.x_scale[:, None], np.ones(2, bool))
    unit = get_filter(name)
    for k in range(10, 40):
        b_full, inn_full = unit.update(predict(b, full), y_nan[:, k] / full.y_scale, full)
        b_part, inn_part = unit.update(predict(b, part), y[:, k, :3] / part.y_scale, part)
        np.testing.assert_allclose(b_full.mean, b_part.mean, rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(b_full.cov, b_part.cov, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(inn_full.loglik, inn_part.loglik, rtol=1e-10)
        assert (inn_full.m == 3).all()
        b = b_full
    np.testing.assert_allclose(masked.means[:, 39], b.mean * full.x_scale, rtol=1e-12)


def test_bearing_update_is_invariant_to_adding_pi():
    model = model_from_scenario("S2", sensors=["A1"])
    belief = Belief.from_cov(np.array([30.0, 40.0, -2.0, 1.0]), np.diag([25.0, 25.0, 1.0, 1.0]))
    y = np.array([np.arctan2(41.0, 31.0)])
    for name in ("ekf", "ukf", "cdkf", "srcdkf"):
        a, ia = get_filter(name).update(belief, y, model)
        b, ib = get_filter(name).update(belief, y + np.pi, model)
        c, ic = get_filter(name).update(belief, y - np.pi, model)
        np.testing.assert_allclose(a.mean, b.mean, atol=1e-9)
        np.testing.assert_allclose(a.mean, c.mean, atol=1e-9)
        assert abs(ia.eps[0]) < 0.1


@pytest.mark.parametrize("name", FILTER_NAMES)
def test_loss_of_positive_definiteness_is_flagged_per_element(name, s0):
    sim, model, _, x0, P0 = s0
    xi = model.to_internal(x0)
    Pi = P0 / np.outer(model.x_scale, model.x_scale)
    good = Belief.from_cov(xi, np.broadcast_to(Pi, (3, 7, 7)))
    chol = good.chol.copy()
    chol[1] = np.nan                                   # element 1 is broken
    bad = Belief(xi, chol, good.ok)
    y = sim.measurements[:, 0] / model.y_scale
    unit = get_filter(name)
    out, _ = unit.update(unit.predict(bad, model), y, model)
    ref, _ = unit.update(unit.predict(good, model), y, model)
    assert out.ok.tolist() == [True, False, True]
    assert np.isfinite(out.mean).all() and np.isfinite(out.chol).all()
    np.testing.assert_allclose(out.mean[[0, 2]], ref.mean[[0, 2]])


def test_run_filter_stores_what_it_is_asked_for(s0):
    sim, model, _, x0, P0 = s0
    y = sim.measurements[:, :30]
    default = run_filter("ukf", model, y, x0, P0)
    assert default.chols is None and default.means.shape == y.shape[:-1] + (model.n,)
    full = run_filter("ukf", model, y, x0, P0, store=("means", "covs", "chols"))
    only = run_filter("ukf", model, y, x0, P0, store="means")
    assert only.covs is None and only.chols is None
    np.testing.assert_array_equal(only.means, default.means)
    np.testing.assert_array_equal(full.covs, default.covs)
    # the factors are the covariances' (scaled to SI like them)
    assert_cov_close(full.chols @ np.swapaxes(full.chols, -1, -2), full.covs, 1e-10)
    with pytest.raises(ValueError, match="store: unknown 'factors'"):
        run_filter("ukf", model, y, x0, P0, store=("means", "factors"))
