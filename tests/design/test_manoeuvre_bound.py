"""The PCRLB conditional on the true manoeuvres: the Kalman covariance of a linear model with the same
transitions, the straight passages' PCRLB, and transitions that carry the true states."""

import numpy as np
import pytest
from reference import linear_gaussian

from shipsense import load_scenario, simulate
from shipsense.design.fisher import pcrlb
from shipsense.design.manoeuvre_bound import conditional_pcrlb, manoeuvre_transitions, simulation_bound
from shipsense.models.field_model import model_from_scenario
from shipsense.physics.manoeuvre import SPEED_CHANGE, TURN, Manoeuvres, transition_jacobians


def kalman_covariances(F, Q, C, R, P0):
    """The Kalman filter's covariance with a transition per step (explicit, one run)."""
    P, out = P0.copy(), []
    for k in range(len(F) + 1):
        if k:
            P = F[k - 1] @ P @ F[k - 1].T + Q
        S = C @ P @ C.T + np.diag(R)
        P = P - P @ C.T @ np.linalg.solve(S, C @ P)
        out.append(P)
    return np.array(out)


@pytest.mark.parametrize("q", [1.0, 0.0])
def test_the_conditional_bound_of_a_linear_model_is_its_kalman_covariance(q):
    rng = np.random.default_rng(4)
    (A, Q, C, R), model = linear_gaussian(rng)
    times = 0.5 * np.arange(30)
    m = Manoeuvres.from_slots([[TURN, SPEED_CHANGE], [SPEED_CHANGE, TURN]], [[2.2, 9.0], [1.0, 6.3]],
                              [[5.0, 3.0], [2.0, 4.0]], [[0.3, 0.0], [0.0, -0.2]], [[0.0, 0.5], [-0.4, 0.0]])
    start, velocity = rng.normal(0, 10, (2, 2)), rng.normal(0, 3, (2, 2))
    F = transition_jacobians(start, velocity, m, times)
    assert not np.allclose(F, A)                      # the turns and speed changes are in the transitions
    P0 = np.diag([4.0, 4.0, 1.0, 1.0])
    bounds = conditional_pcrlb(model, rng.standard_normal((2, 30, 4)), np.linalg.inv(P0), F, Q=q * Q)
    for r in range(2):
        np.testing.assert_allclose(bounds[r], kalman_covariances(F[r], q * Q, C, R, P0), rtol=1e-8, atol=1e-12)


def test_without_manoeuvres_the_conditional_bound_is_the_pcrlb():
    sim = simulate("S2", runs=3, seed=1, random=True)
    model = model_from_scenario("S2")
    J0 = np.linalg.inv(np.diag([400.0, 400.0, 4.0, 4.0, 0.1, 0.1, 0.1]))
    states = model.to_internal(model.state_from_truth(sim.truth))
    np.testing.assert_allclose(simulation_bound(model, sim, J0), pcrlb(model, states, J0, per_run=True),
                               rtol=1e-10, atol=1e-14)


def test_the_transitions_carry_the_true_states_through_turns_and_the_moment_turns_with_the_hull():
    sc = load_scenario("S2-turn")
    sc = sc.with_updates(manoeuvres={**sc.manoeuvres.model_dump(), "speed_changes": []})
    sim = simulate(sc, runs=1, seed=0)
    model = model_from_scenario(sc)
    x = model.to_internal(model.state_from_truth(sim.truth))
    F = manoeuvre_transitions(model, sim.truth[:, 0, :2], sim.truth[:, 0, 2:4], sim.manoeuvres, sim.times)
    assert not np.allclose(x[0, -1, 4:7], x[0, 0, 4:7])          # the moment did turn
    # a coordinated turn at a known rate is linear, and so is the moment's turn: F_k x_k = x_{k+1}
    np.testing.assert_allclose(np.einsum("rkij,rkj->rki", F, x[:, :-1]), x[:, 1:], rtol=1e-9, atol=1e-9)


def test_the_true_transitions_change_the_bound_from_the_first_manoeuvre_on():
    """The turning passages' bound with the straight motion's transitions and with the true ones: the same up
    to the first manoeuvre, different after it, and a proper covariance throughout."""
    sc = load_scenario("S2-turn")
    sim = simulate(sc, runs=2, seed=0)
    model = model_from_scenario(sc)
    J0 = np.linalg.inv(np.diag([400.0, 400.0, 4.0, 4.0, 0.1, 0.1, 0.1]))
    states = model.to_internal(model.state_from_truth(sim.truth))
    true = simulation_bound(model, sim, J0)
    straight = pcrlb(model, states, J0, per_run=True)
    first = int(np.argmax(sim.manoeuvre[0] != 0))
    np.testing.assert_allclose(true[:, :first + 1], straight[:, :first + 1], rtol=1e-10, atol=1e-14)
    assert not np.allclose(true[:, first + 2:], straight[:, first + 2:])
    assert np.all(np.isfinite(true)) and np.all(np.linalg.eigvalsh(true) > 0)
