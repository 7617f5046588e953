"""Metrics against direct computations on synthetic tracks."""

import numpy as np
import pytest

from shipsense.trackers.metrics import (
    converged,
    convergence_rate,
    mrmse,
    nees,
    position_error,
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
