"""Metrics against direct computations on synthetic tracks."""

import numpy as np
import pytest

from shipsense.trackers.metrics import (
    CHI2_2DOF_95,
    converged,
    convergence_rate,
    coverage,
    mrmse,
    nees,
    position_crlb_trace,
    position_error,
    position_nees,
    rmse_k,
    selection_accuracy,
    trmse,
)


def test_error_metrics_on_a_constant_offset():
    truth = np.zeros((5, 20, 4))
    est = truth.copy()
    est[..., 0] = 3.0
    est[..., 1] = 4.0
    np.testing.assert_allclose(position_error(est, truth), 5.0)
    np.testing.assert_allclose(rmse_k(est, truth), 5.0)
    np.testing.assert_allclose(trmse(est, truth), 5.0)
    assert mrmse(est, truth) == pytest.approx({"x": 3.0, "y": 4.0, "r": 5.0})


def test_rmse_is_root_mean_square_over_runs():
    truth = np.zeros((2, 3, 2))
    est = truth.copy()
    est[0, :, 0] = 3.0
    est[1, :, 0] = 4.0
    np.testing.assert_allclose(rmse_k(est, truth), np.sqrt((9 + 16) / 2))


def test_convergence_needs_the_error_to_stay_small():
    truth = np.zeros((3, 100, 2))
    est = truth.copy()
    est[0, :, 0] = 50.0                        # never converges
    est[1, -5:, 0] = 20.0                      # was fine, diverges at the end
    est[2, :50, 0] = 80.0                      # converges halfway
    np.testing.assert_array_equal(converged(est, truth), [False, False, True])
    assert convergence_rate(est, truth) == pytest.approx(1 / 3)


def test_nees_of_consistent_gaussian_errors_averages_the_dimension():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((2, 2))
    P = A @ A.T + np.eye(2)
    e = rng.multivariate_normal(np.zeros(2), P, size=(20000, 1))
    value = nees(e, np.broadcast_to(P, (20000, 1, 2, 2)), np.zeros_like(e))
    assert value.mean() == pytest.approx(2.0, rel=0.03)


def test_selection_accuracy():
    tr = np.array([[5.0, 1.0], [2.0, 9.0], [3.0, 4.0]])
    assert selection_accuracy([1, 0, 1], tr) == pytest.approx(2 / 3)


def test_position_error_is_the_norm_of_the_horizontal_difference_under_broadcasting():
    """The in-place form gives the textbook ``sqrt(sum(d * d))`` bit for bit, for a bank of hypotheses against
    one truth per run (broadcast), and for integer inputs."""
    rng = np.random.default_rng(0)
    means, truth = rng.normal(size=(5, 4, 30, 7)) * 100, rng.normal(size=(5, 1, 30, 7)) * 100
    d = means[..., :2] - truth[..., :2]
    np.testing.assert_array_equal(position_error(means, truth), np.sqrt(np.sum(d * d, axis=-1)))
    assert position_error(means, truth).shape == (5, 4, 30)
    np.testing.assert_array_equal(position_error(np.array([[3, 0]]), np.array([[0, 4]])), [5.0])
    assert position_error([3.0, 0.0], [0.0, 4.0]) == 5.0                    # one state
    assert position_error(means.astype(np.float32), truth.astype(np.float32)).dtype == np.float32


def _covariances(rng, shape, n):
    """Random symmetric positive-definite matrices (*shape, n, n), metres-sized."""
    A = rng.normal(size=shape + (n, n)) * 5.0
    return A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(n)


def test_position_nees_is_the_quadratic_form_of_the_inverse_block_and_nan_without_a_valid_covariance():
    """Against a dense ``d @ inv(P) @ d`` sample by sample, for position covariances and for whole state
    covariances (their (x, y) block); NaN where the block is not finite and positive definite."""
    rng = np.random.default_rng(1)
    R, K = 3, 7
    truth, est = rng.normal(size=(R, K, 4)) * 50, rng.normal(size=(R, K, 4)) * 50
    full = _covariances(rng, (R, K), 4)
    want = np.empty((R, K))
    for r in range(R):
        for k in range(K):
            d = est[r, k, :2] - truth[r, k, :2]
            want[r, k] = d @ np.linalg.inv(full[r, k, :2, :2]) @ d
    np.testing.assert_allclose(position_nees(est, full, truth), want, rtol=1e-10)
    np.testing.assert_allclose(position_nees(est, full[..., :2, :2], truth), want, rtol=1e-10)
    np.testing.assert_array_equal(nees(est, full, truth), position_nees(est, full, truth))  # the one position NEES
    bad = full[..., :2, :2].copy()
    bad[0, 0] = np.nan                                    # no covariance reported
    bad[0, 1] = [[1.0, 2.0], [2.0, 1.0]]                  # indefinite
    bad[0, 2] = [[1.0, 1.0], [1.0, 1.0]]                  # singular
    bad[0, 3] = -np.eye(2)                                # negative definite (its determinant is positive)
    q = position_nees(est, bad, truth)
    assert np.isnan(q[0, :4]).all()
    np.testing.assert_allclose(q[0, 4:], want[0, 4:], rtol=1e-10)
    np.testing.assert_allclose(q[1:], want[1:], rtol=1e-10)


def test_nees_of_other_components_is_still_the_dense_quadratic_form():
    rng = np.random.default_rng(2)
    truth, est = rng.normal(size=(4, 5, 4)), rng.normal(size=(4, 5, 4))
    P = _covariances(rng, (4, 5), 4)
    d = est[..., 2:] - truth[..., 2:]
    want = [[d[r, k] @ np.linalg.inv(P[r, k, 2:, 2:]) @ d[r, k] for k in range(5)] for r in range(4)]
    np.testing.assert_allclose(nees(est, P, truth, components=(2, 3)), want, rtol=1e-10)


def test_coverage_counts_the_samples_inside_the_95_percent_ellipse():
    """Against a count sample by sample: NEES at most the quantile, over the masked samples, per row and over
    all; NaN (no covariance) is outside; the quantile is chi-square's with 2 degrees of freedom."""
    assert CHI2_2DOF_95 == pytest.approx(-2.0 * np.log(0.05), rel=1e-15)
    rng = np.random.default_rng(3)
    q = rng.chisquare(2, size=(6, 40))
    q[rng.random(q.shape) < 0.1] = np.nan
    q[0, :3] = CHI2_2DOF_95                               # on the limit: inside
    where = rng.random(q.shape) < 0.7
    rows = [sum(1 for k in range(40) if where[r, k] and q[r, k] <= CHI2_2DOF_95) / where[r].sum() for r in range(6)]
    np.testing.assert_allclose(coverage(q, where, axis=1), rows, rtol=1e-15)
    total = sum(1 for v, w in zip(q.ravel(), where.ravel()) if w and v <= CHI2_2DOF_95) / where.sum()
    assert coverage(q, where) == pytest.approx(total, rel=1e-15)
    assert coverage(q) == pytest.approx(np.sum(q <= CHI2_2DOF_95) / q.size, rel=1e-15)
    assert coverage(np.array([1.0, 3.0, 7.0]), limit=2.0) == pytest.approx(1 / 3)


def test_position_crlb_trace_is_the_si_trace_of_the_position_block():
    """Against ``np.trace`` of the (x, y) block, and of bounds in a model's internal units brought to SI
    (``S B S``, S the internal units' SI values: the model's ``cov_to_si``)."""
    from shipsense.models import model_from_scenario

    rng = np.random.default_rng(4)
    B = _covariances(rng, (3, 5), 5)
    np.testing.assert_allclose(position_crlb_trace(B), np.trace(B[..., :2, :2], axis1=-2, axis2=-1), rtol=1e-14)
    model = model_from_scenario("S0")                      # moment in 1e6 A m^2: x_scale not all ones
    Bi = _covariances(rng, (4,), model.n)
    S = np.diag(model.x_scale)
    np.testing.assert_allclose(model.cov_to_si(Bi), S @ Bi @ S, rtol=1e-14)
    np.testing.assert_allclose(model.cov_to_internal(model.cov_to_si(Bi)), Bi, rtol=1e-14)
    assert position_crlb_trace(B).shape == (3, 5)


def test_the_crlb_limit_is_where_an_efficient_estimate_is_within_10_m_in_95_percent_of_cases():
    """4.08 m = 10 / sqrt(2 ln 20): an equal-axes Gaussian error of that sd lies within 10 m with probability
    0.95 (Rayleigh, and by sampling); of any shape whose larger axis has that sd, with at least 0.95."""
    from shipsense.trackers.metrics import CONVERGENCE_THRESHOLD_M, CRLB_SD_LIMIT_M, convergence_allowed, crlb_sd

    s = CRLB_SD_LIMIT_M
    assert s == pytest.approx(10.0 / np.sqrt(2 * np.log(20.0)), rel=1e-12) and 4.08 < s < 4.09
    assert 1 - np.exp(-CONVERGENCE_THRESHOLD_M**2 / (2 * s**2)) == pytest.approx(0.95, abs=1e-12)
    rng = np.random.default_rng(0)
    for ratio, angle in ((1.0, 0.0), (0.3, 0.7), (0.0, 2.0)):                # the smaller axis' share, rotation
        R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        C = R @ np.diag([s**2, ratio * s**2]) @ R.T
        assert crlb_sd(C) == pytest.approx(np.sqrt(np.linalg.eigvalsh(C).max()), rel=1e-12)
        assert convergence_allowed(C * (1 - 1e-9)) and not convergence_allowed(C * (1 + 1e-6))
        e = rng.multivariate_normal([0.0, 0.0], C, size=200_000)
        inside = np.mean(np.hypot(e[:, 0], e[:, 1]) <= CONVERGENCE_THRESHOLD_M)
        assert inside >= 0.95 - 0.002 and (ratio < 1 or inside == pytest.approx(0.95, abs=0.002))
    full = np.zeros((3, 5, 5))
    full[:, :2, :2] = np.diag([4.0, 1.0])
    assert crlb_sd(full) == pytest.approx([2.0] * 3)                       # a whole state's bound: its (x, y) block


def test_convergence_is_judged_over_the_passages_whose_data_allow_it_beside_the_unrestricted_rate():
    from shipsense.trackers.metrics import converged_until, convergence_rates, judged_sample

    conv = np.array([True, False, True, False])
    allowed = np.array([True, True, True, False])
    r = convergence_rates(conv, allowed)
    assert r == {"convergence": 0.5, "convergence_bounded": pytest.approx(2 / 3), "bounded": 3}
    assert np.isnan(convergence_rates(conv, np.zeros(4, bool))["convergence_bounded"])
    truth = np.zeros((2, 50, 4))
    ends = np.array([49, 19])
    first = judged_sample(ends)
    assert list(first) == [45, 18]                                         # the last 10 % (at least one sample)
    means = truth.copy()
    means[0, first[0] - 1, 0] = 50.0                                       # just before the judged samples
    means[1, first[1], 0] = 50.0                                           # the first judged sample
    assert list(converged_until(means, truth, ends)[0]) == [True, False]
