"""The joint model of two ships: the summed readings are the one-ship model's, added; bearings the nearer ship's;
the Jacobian matches finite differences; a far second ship leaves the first ship's filter as it is alone."""

import numpy as np
import pytest

from shipsense.models.field_model import model_from_scenario
from shipsense.trackers.filters.run import run_filter
from shipsense.trackers.ships import JointModel


@pytest.fixture(scope="module")
def base():
    return model_from_scenario("S2-crossing")          # two magnetometers and a seismic bearing node


def _states(base, rng, count):
    x = np.zeros((count, base.n))
    x[:, :2] = rng.uniform(-80, 80, (count, 2))
    x[:, 2:4] = rng.uniform(-5, 5, (count, 2))
    x[:, 4:7] = rng.uniform(-3e4, 3e4, (count, 3)) / base.moment_unit
    return x


def test_the_summed_reading_is_the_sum_of_the_ships_readings_and_bearings_are_the_nearer_ships(base):
    rng = np.random.default_rng(0)
    x1, x2 = _states(base, rng, 50), _states(base, rng, 50)
    joint = JointModel(base, 2)
    y = joint.h(np.concatenate([x1, x2], axis=1))
    h1, h2 = base.h(x1), base.h(x2)
    field = ~base.axial
    np.testing.assert_allclose(y[:, field], h1[:, field] + h2[:, field], rtol=1e-12, atol=1e-12)
    node = base.array.positions[base.array.channel_sensor[base.axial][0], :2]
    nearer_1 = np.hypot(*(x1[:, :2] - node).T) < np.hypot(*(x2[:, :2] - node).T)
    np.testing.assert_array_equal(y[:, base.axial][:, 0], np.where(nearer_1, h1[:, base.axial][:, 0],
                                                                    h2[:, base.axial][:, 0]))
    y2, H = joint.h_and_H(np.concatenate([x1, x2], axis=1))
    np.testing.assert_allclose(y2, y, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(H[:, field, :base.n], base.H(x1)[:, field], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(H[:, field, base.n:], base.H(x2)[:, field], rtol=1e-12, atol=1e-15)


def test_the_joint_jacobian_matches_central_differences(base):
    rng = np.random.default_rng(1)
    joint = JointModel(base, 2)
    x = np.concatenate([_states(base, rng, 3), _states(base, rng, 3)], axis=1)
    H = joint.H(x)
    step = 1e-6 * np.maximum(1.0, np.abs(x))
    for j in range(joint.n):
        e = np.zeros(joint.n)
        e[j] = step[0, j]
        d = joint.residual(joint.h(x + e), joint.h(x - e)) / (2 * e[j])
        np.testing.assert_allclose(H[:, :, j], d, rtol=1e-5, atol=1e-6 * np.abs(H).max())


def test_a_far_second_ship_leaves_the_first_ships_filter_as_it_is_alone(base):
    """With the second ship out of reach its columns of H vanish; the joint UKF with kappa = n_1 - n (the
    one-ship spread sqrt(n_1)) then has the one-ship UKF's points for ship 1 and its ship-2 points read as the
    centre, whose net weights (mean -1 + n_1 / n_1 = 0, covariance 1 + 1 = 2) are the one-ship UKF's: the same
    filter to rounding."""
    import shipsense
    from shipsense.trackers.filters import get_filter

    sim = shipsense.simulate("S2", runs=2, seed=3, random=True)
    model = model_from_scenario("S2")
    x0 = model.state_from_truth(sim.truth[:, 0]) + np.array([3.0, -2.0, 0.2, 0.1, 500.0, -500.0, 300.0])
    P0 = np.diag([25.0, 25.0, 0.5, 0.5, 1e7, 1e7, 1e7])
    alone = run_filter("ukf", model, sim.measurements, x0, P0)
    far = np.array([1e5, 1e5, 0.0, 0.0, 1e3, 1e3, 1e3])                  # 141 km off: its field is ~1e-12 nT
    joint = JointModel(model, 2)
    P0j = np.zeros((14, 14))
    P0j[:7, :7], P0j[7:, 7:] = P0, np.diag([1.0, 1.0, 0.01, 0.01, 1e2, 1e2, 1e2])
    x0j = np.concatenate([x0, np.broadcast_to(far, x0.shape)], axis=1)
    both = run_filter(get_filter("ukf", kappa=-7.0), joint, sim.measurements, x0j, P0j)
    np.testing.assert_allclose(both.means[..., :7], alone.means, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(both.covs[..., :7, :7], alone.covs, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(both.loglik, alone.loglik, rtol=1e-8, atol=1e-6)


def test_a_joint_model_needs_a_ship(base):
    with pytest.raises(ValueError, match="ships must be at least 1"):
        JointModel(base, 0)
