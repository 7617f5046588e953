"""`check` and `design` see manoeuvres: their prior passages are the simulator's draws with the scenario's
manoeuvres, and the Fisher information follows each passage's true motion (finite differences of the
simulator's truth as the reference); without a ``[manoeuvres]`` table nothing changes."""

import numpy as np
import pytest

from shipsense import load_scenario, simulate
from shipsense.design.designer import design_array, summary_lines
from shipsense.design.fisher import PassageMotion, passage_fim, trajectory
from shipsense.design.manoeuvre_bound import passage_motion
from shipsense.design.observability import check_array, scenario_passages
from shipsense.models.field_model import candidate_model, model_from_scenario
from shipsense.models.transitions import powers
from shipsense.simulator import manoeuvring_truth, sample_manoeuvring_passages, sample_passages


def straight(sc):
    """The scenario without its ``[manoeuvres]`` table."""
    return sc.with_updates(manoeuvres=None)


def test_the_prior_passages_are_the_simulators_draws_with_their_manoeuvres():
    sc = load_scenario("S2-turn")
    x0, m = sample_manoeuvring_passages(sc, 12, seed=3)
    sim = simulate(sc, runs=12, seed=3, random=True)
    np.testing.assert_array_equal(x0, sim.truth[:, 0])
    for a, b in zip((m.kind, m.start, m.duration, m.rate, m.acceleration),
                    (sim.manoeuvres.kind, sim.manoeuvres.start, sim.manoeuvres.duration, sim.manoeuvres.rate,
                     sim.manoeuvres.acceleration)):
        np.testing.assert_array_equal(a, b)
    assert 0 < np.any(m.kind != 0, axis=1).sum() < 12                 # some passages manoeuvre, some do not
    # the manoeuvres have their own stream: the initial states are those of the scenario without the table
    np.testing.assert_array_equal(x0, sample_passages(straight(sc), 12, seed=3))
    x1, m1 = sample_manoeuvring_passages(sc, 12, seed=3)              # same seed, same draws
    np.testing.assert_array_equal(x1, x0)
    np.testing.assert_array_equal(m1.start, m.start)
    assert not np.array_equal(sample_manoeuvring_passages(sc, 12, seed=4)[1].start, m.start)


def test_the_motion_is_the_simulators_truth_and_its_jacobian_matches_finite_differences():
    sc = load_scenario("S2-turn")
    model = model_from_scenario(sc)
    x0, m = sample_manoeuvring_passages(sc, 1, seed=0, random=False)  # the nominal turn and slow-down
    motion = passage_motion(model, x0, m, sc.times)
    truth = simulate(sc, runs=1, seed=0).truth
    np.testing.assert_allclose(motion.states, model.to_internal(model.state_from_truth(truth)), rtol=1e-12)
    assert motion.manoeuvring.tolist() == [True]

    def states(x):
        return model.to_internal(model.state_from_truth(manoeuvring_truth(x, m, sc.times)[0]))

    labels = model.labels
    columns = {"x": 0, "y": 1, "vx": 2, "vy": 3, "mx": 5, "my": 6, "mz": 7}
    for label, col in columns.items():
        j = labels.index(label)
        h = 1e-4 * max(1.0, abs(x0[0, col]))
        up, down = x0.copy(), x0.copy()
        up[0, col] += h
        down[0, col] -= h
        fd = (states(up) - states(down))[0] / (2 * h / model.x_scale[j])         # d x_k / d theta_j
        np.testing.assert_allclose(motion.jacobians[0, :, :, j], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


@pytest.mark.parametrize("per_sensor", [False, True])
@pytest.mark.parametrize("block", [10_000, 5])       # whole passages at once, and blocks of samples
def test_straight_motion_gives_the_constant_velocity_information(per_sensor, block):
    sc = load_scenario("S2")
    model = model_from_scenario(sc)
    thetas = model.to_internal(model.state_from_truth(sample_passages(sc, 3, seed=2)))
    K = 60
    motion = PassageMotion(trajectory(model, thetas, K), np.broadcast_to(powers(model.A, K), (3, K) + model.A.shape),
                           np.zeros(3, bool))
    for stride in (1, 2):
        np.testing.assert_allclose(
            passage_fim(model, thetas, K, per_sensor, stride, block, motion=motion),
            passage_fim(model, thetas, K, per_sensor, stride, block), rtol=1e-10)


def test_a_motion_of_the_wrong_shape_is_refused():
    model = model_from_scenario("S2")
    thetas = np.ones((2, model.n))
    bad = PassageMotion(np.zeros((2, 9, model.n)), np.zeros((2, 9, model.n, model.n)), np.zeros(2, bool))
    with pytest.raises(ValueError, match="motion"):
        passage_fim(model, thetas, 10, motion=bad)


def test_check_passages_manoeuvre_and_only_the_manoeuvring_ones_change_their_information():
    sc = load_scenario("S2-turn")
    _, model, thetas, motion = scenario_passages(sc, 8, seed=1)
    _, _, thetas0, motion0 = scenario_passages(straight(sc), 8, seed=1)
    assert motion0 is None                                             # no table: straight, as before
    np.testing.assert_array_equal(thetas, thetas0)                    # the same initial states
    J = passage_fim(model, thetas, sc.steps, stride=2, motion=motion)
    J0 = passage_fim(model, thetas, sc.steps, stride=2)
    moved = motion.manoeuvring
    assert 0 < moved.sum() < 8
    np.testing.assert_allclose(J[~moved], J0[~moved], rtol=1e-8)
    change = np.linalg.norm(J - J0, axis=(-1, -2)) / np.linalg.norm(J0, axis=(-1, -2))
    assert np.all(change[~moved] < 1e-9) and np.all(change[moved] > 1e-6)   # (a late turn changes little)
    assert change.max() > 0.1


def test_a_turn_away_from_the_array_before_it_is_reached_leaves_a_larger_bound():
    # the nominal passage heads for the array; turning away 20 s before it gets there, it never comes near
    sc = load_scenario("S2-turn")
    sc = sc.with_updates(prior=None, manoeuvres={"body_fixed_share": 0.0, "turns": [
        {"start": 4.0, "duration": 30.0, "rate_deg_s": 3.0}]})
    _, model, thetas, motion = scenario_passages(sc)
    _, _, thetas0, motion0 = scenario_passages(straight(sc))
    assert motion0 is None and motion.manoeuvring.tolist() == [True]
    c = check_array(model, thetas, sc.steps, starts=0, motion=motion)
    c0 = check_array(model, thetas0, sc.steps, starts=0)
    assert c.fim_rank == c0.fim_rank == model.n
    assert (c.manoeuvring, c0.manoeuvring) == (1, 0)

    def position_bound(J):
        return np.sqrt(np.trace(np.linalg.inv(J[0])[:2, :2]))

    bound = position_bound(passage_fim(model, thetas, sc.steps, motion=motion))
    bound0 = position_bound(passage_fim(model, thetas0, sc.steps))
    assert bound > 3 * bound0


def test_design_draws_the_manoeuvres_and_reports_them():
    sc = load_scenario("S2-turn")
    cands = np.array([[x, y, -2.0] for x in (-20.0, 0.0, 20.0) for y in (-20.0, 0.0, 20.0)])
    kw = dict(candidates=cands, passages=6, seed=2, random_layouts=20, cuts=False, check=False, bb_work=0)
    res = design_array(sc, 2, **kw)
    res0 = design_array(straight(sc), 2, **kw)
    assert res0.motion is None and "manoeuvring_passages" not in res0.report()
    assert res.report()["manoeuvring_passages"] == int(res.motion.manoeuvring.sum()) > 0
    assert any("prior passages manoeuvre" in line for line in summary_lines(res))
    np.testing.assert_array_equal(res.thetas, res0.thetas)
    model = candidate_model(sc, cands)
    expected = passage_fim(model, res.thetas, sc.steps, per_sensor=True, stride=2, motion=res.motion)
    straight_info = passage_fim(model, res.thetas, sc.steps, per_sensor=True, stride=2)
    assert not np.allclose(expected, straight_info)
    # the design's objective is valued on the manoeuvring passages' information
    assert res.placement.value != pytest.approx(res0.placement.value, rel=1e-9)
