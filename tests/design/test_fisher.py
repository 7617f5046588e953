"""Fisher information and bounds against independent computations."""

import numpy as np
import pytest
from reference import linear_gaussian

from shipsense import load_scenario
from shipsense.design.fisher import bound_map, crlb, passage_fim, pcrlb, trajectory
from shipsense.design.observability import fit_passages
from shipsense.models.field_model import model_from_scenario


def test_fim_matches_the_covariance_of_maximum_likelihood_estimates():
    """Well-conditioned case (two vector magnetometers, a close passage): Cov(theta_ML) ~ J^-1."""
    sc = load_scenario("S2")
    model = model_from_scenario(sc, sensors=["M1", "M2"])
    steps = 40
    theta = model.to_internal(np.array([30.0, 25.0, -2.0, -2.0, 1e4, 1e4, 1e4]))
    J = passage_fim(model, theta, steps)
    C = crlb(J)
    rng = np.random.default_rng(0)
    B = 400
    clean = model.h(trajectory(model, theta, steps))
    y = clean + rng.standard_normal((B,) + clean.shape) * np.sqrt(model.R)
    est, chi2 = fit_passages(model, y, np.repeat(theta[None], B, axis=0), steps)
    assert np.median(chi2) == pytest.approx(steps * model.m - model.n, rel=0.15)
    emp = np.cov(est.T)
    d = np.sqrt(np.diag(C))
    # variances within 25 % and correlations within 0.1 (400 samples)
    np.testing.assert_allclose(np.diag(emp), np.diag(C), rtol=0.25)
    np.testing.assert_allclose(emp / np.outer(d, d), C / np.outer(d, d), atol=0.1)


def test_fim_is_additive_over_sensors():
    model = model_from_scenario("S1-P2")
    theta = model.to_internal(np.array([-120.0, -60.0, 8.0, 5.0, -6.8, 100.0]))
    per = passage_fim(model, theta, 101, per_sensor=True)
    assert per.shape == (3, 6, 6)
    np.testing.assert_allclose(per.sum(axis=0), passage_fim(model, theta, 101), rtol=1e-12)


def test_pcrlb_equals_the_kalman_covariance_for_a_linear_gaussian_model():
    rng = np.random.default_rng(1)
    (A, Q, C, R), model = linear_gaussian(rng)
    P0 = np.diag([4.0, 4.0, 1.0, 1.0])
    bounds = pcrlb(model, rng.standard_normal((5, 25, 4)), np.linalg.inv(P0))
    P = P0.copy()
    for k in range(25):
        if k:
            P = A @ P @ A.T + Q
        S = C @ P @ C.T + np.diag(R)
        P = P - P @ C.T @ np.linalg.solve(S, C @ P)
        np.testing.assert_allclose(bounds[k], P, rtol=1e-9, atol=1e-12)


def test_per_passage_bounds_and_the_deterministic_limit():
    """Per run: each run's own Kalman covariance; their mean is at least the pooled bound (Jensen);
    with Q = 0 the information form equals the covariance recursion with a vanishing Q."""
    model = model_from_scenario("S0")
    states = model.to_internal(np.array([[[40.0 + 5 * k, -60.0 + 2 * k, 5.0, 2.0, 1e6, 2e6, -1e6] for k in range(30)],
                                         [[-200.0 + 6 * k, 35.0, 6.0, 0.0, 5e6, 0.0, 3e6] for k in range(30)]]))
    J0 = np.linalg.inv(np.diag([400.0, 400.0, 4.0, 4.0, 10.0, 10.0, 10.0]))
    each = pcrlb(model, states, J0, per_run=True)
    assert each.shape == (2, 30, 7, 7)
    for r in range(2):
        np.testing.assert_allclose(each[r], pcrlb(model, states[r:r + 1], J0), rtol=1e-10)
    pooled = pcrlb(model, states, J0)
    assert np.all(each[:, :, 0, 0].mean(axis=0) >= pooled[:, 0, 0] * (1 - 1e-9))
    det = pcrlb(model, states, J0, per_run=True, Q=np.zeros((7, 7)))
    tiny = pcrlb(model, states, J0, per_run=True, Q=1e-12 * np.eye(7))
    np.testing.assert_allclose(det, tiny, rtol=1e-4, atol=1e-12)
    assert np.all(det[:, -1, 0, 0] <= each[:, -1, 0, 0])     # no process noise: never a larger bound


def test_bound_map_is_smaller_inside_the_array_than_far_out():
    model = model_from_scenario("S1-P2")
    xs = np.array([0.0, 150.0])
    bound, per = bound_map(model, xs, [0.0], velocity=[5.0, 0.0], params=[-6.8, 100.0])
    assert bound.shape == (1, 2) and per.shape == (3, 1, 2)
    assert np.isfinite(bound).all() and bound[0, 0] < bound[0, 1]
    assert np.all(per >= bound[None] - 1e-12)   # one sensor alone is never better than all three
