"""The IMM filter: FilterPy's IMMEstimator as the independent reference, and the limits of the recursion."""

import math

import numpy as np
import pytest
from filterpy.kalman import IMMEstimator, KalmanFilter

from shipsense.models.field_model import LinearModel
from shipsense.models.motion_modes import MODES, MotionModes, motion_modes
from shipsense.trackers.filters import get_filter
from shipsense.trackers.filters.core import Belief
from shipsense.trackers.filters.imm import IMM, ModeBelief, combine


def _kinematic_model(rng, T=2.0):
    """A linear model over (x, y, v_x, v_y) measured by a drawn C: every filter unit is the Kalman filter on it."""
    A = np.eye(4)
    A[0, 2] = A[1, 3] = T
    Q = np.diag([0.01, 0.01, 0.001, 0.001])
    C = rng.standard_normal((3, 4))
    R = np.array([0.5, 1.0, 2.0])
    return LinearModel(A, Q, C, R), T


def _turning_truth(T, steps, rng, C, R):
    x = np.array([-50.0, 10.0, 5.0, 0.0])
    truth, ys = [], []
    for k in range(steps):
        w = math.radians(2.5) if 20 <= k < 40 else 0.0
        if w:
            s, c = math.sin(w * T), math.cos(w * T)
            vx, vy = x[2], x[3]
            x = np.array([x[0] + (s * vx + (c - 1) * vy) / w, x[1] + ((1 - c) * vx + s * vy) / w,
                          c * vx - s * vy, s * vx + c * vy])
        else:
            x = np.array([x[0] + T * x[2], x[1] + T * x[3], x[2], x[3]])
        truth.append(x)
        ys.append(C @ x + rng.standard_normal(len(R)) * np.sqrt(R))
    return np.array(truth), np.array(ys)


@pytest.mark.parametrize("unit", ["ekf", "ukf", "cdkf"])
def test_imm_equals_filterpy_on_a_linear_model(unit):
    """Every Gaussian unit on a linear model is the Kalman filter, so the IMM over it is FilterPy's IMMEstimator
    over Kalman filters with the same modes (state-independent: no speed mode noise along a course, no moment):
    means, covariances, mode probabilities and log-likelihoods agree at every step of a turning passage."""
    rng = np.random.default_rng(3)
    model, T = _kinematic_model(rng)
    modes = MotionModes(n=4, period=T, Q=model.Q, speed_accel=0.0, initial=(0.7, 0.1, 0.1, 0.1))
    truth, ys = _turning_truth(T, 60, rng, model.C, model.R)
    x0, P0 = truth[0] + np.array([3.0, -2.0, 0.5, 0.2]), np.diag([25.0, 25.0, 1.0, 1.0])

    A, Q = modes.transitions(np.zeros((modes.M, 4)), T)
    filters = []
    for j in range(modes.M):
        kf = KalmanFilter(dim_x=4, dim_z=3)
        kf.F, kf.Q, kf.H, kf.R = A[j], Q[j], model.C, np.diag(model.R)
        kf.x, kf.P = x0.copy(), P0.copy()
        filters.append(kf)
    ref = IMMEstimator(filters, modes.prior.copy(), modes.switching(T))

    imm = IMM(get_filter(unit), modes)
    belief = imm.start(Belief.from_cov(x0, P0))
    for k in range(1, len(ys)):
        ref.predict()
        cbar = ref.cbar.copy()            # (update replaces it by the next step's)
        ref.update(ys[k])
        lik = np.dot(cbar, [f.likelihood for f in ref.filters])
        belief, inn = imm.step(belief, ys[k], model)
        x, P = combine(belief)
        np.testing.assert_allclose(belief.prob, ref.mu, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(x, ref.x, rtol=1e-7, atol=1e-7)
        np.testing.assert_allclose(P, ref.P, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(inn.loglik, np.log(lik), rtol=1e-7, atol=1e-7)
    assert belief.mean.shape == (modes.M, 4)


def test_one_mode_is_the_unit_itself():
    """An IMM whose modes never switch and start certain in ``cv`` is the unit's own filter on the model."""
    rng = np.random.default_rng(5)
    model, T = _kinematic_model(rng)
    modes = MotionModes(n=4, period=T, Q=model.Q, initial=(1.0, 0.0, 0.0, 0.0), sojourn_cv=1e300)
    _, ys = _turning_truth(T, 30, rng, model.C, model.R)
    unit = get_filter("ukf")
    imm = IMM(unit, modes)
    start = Belief.from_cov(np.array([-50.0, 10.0, 5.0, 0.0]), np.diag([25.0, 25.0, 1.0, 1.0]))
    belief, plain = imm.start(start), start
    for y in ys[1:]:
        belief, inn = imm.step(belief, y, model)
        plain, ref = unit.step(plain, y, model)
        x, P = combine(belief)
        np.testing.assert_allclose(x, plain.mean, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(P, plain.cov, rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(inn.loglik, ref.loglik, rtol=1e-9)


def test_the_turn_modes_move_a_ship_on_its_circle():
    """A turn mode's transition is the exact motion at its rate: the speed is kept, the course turns by
    ``omega tau`` and the position stays on the circle of radius ``v / omega``."""
    modes = MotionModes(n=4, period=2.0, Q=np.zeros((4, 4)))
    x = np.array([0.0, 0.0, 6.0, 0.0])
    A, _ = modes.transitions(np.broadcast_to(x, (modes.M, 4)), 3.0)
    w = modes.turn_rate
    centre = np.array([0.0, 6.0 / w])                     # (a left turn from the course +x)
    for j, sign in ((MODES.index("turn_left"), 1.0), (MODES.index("turn_right"), -1.0)):
        y = A[j] @ x
        assert np.hypot(*y[2:]) == pytest.approx(6.0)
        assert math.atan2(y[3], y[2]) == pytest.approx(sign * w * 3.0)
        c = centre * sign
        assert np.hypot(*(y[:2] - c)) == pytest.approx(6.0 / w)


def test_the_speed_mode_accelerates_along_the_course_only():
    """The speed mode's extra process noise lies along the mixed mean's course: none across it."""
    modes = MotionModes(n=4, period=1.0, Q=np.zeros((4, 4)))
    course = np.array([3.0, 4.0]) / 5.0
    x = np.broadcast_to(np.array([0.0, 0.0, *(5.0 * course)]), (modes.M, 4))
    _, Q = modes.transitions(x, 1.0)
    Qs = Q[MODES.index("speed")]
    across = np.array([-course[1], course[0]])
    assert across @ Qs[2:, 2:] @ across == pytest.approx(0.0, abs=1e-15)
    assert course @ Qs[2:, 2:] @ course == pytest.approx(modes.speed_accel ** 2)


def test_a_turn_is_followed_by_the_turn_mode():
    """On a passage measured in position (sd 2 m) that turns left at 2.5 deg/s for a third of its length, the
    ``turn_left`` mode's probability rises during the turn and the IMM's error during and after the turn is smaller
    than the constant-velocity filter's, which lags the turn."""
    rng = np.random.default_rng(11)
    T = 2.0
    A = np.eye(4)
    A[0, 2] = A[1, 3] = T
    model = LinearModel(A, np.diag([1e-4, 1e-4, 1e-4, 1e-4]), np.eye(4)[:2], np.array([4.0, 4.0]))
    truth, ys = _turning_truth(T, 60, rng, model.C, model.R)
    modes = motion_modes(model)
    unit = get_filter("ukf")
    imm = IMM(unit, modes)
    start = Belief.from_cov(truth[0], np.diag([4.0, 4.0, 0.25, 0.25]))
    belief, plain = imm.start(start), start
    turn_prob, err_imm, err_cv = [], [], []
    for k in range(1, len(ys)):
        belief, _ = imm.step(belief, ys[k], model)
        plain, _ = unit.step(plain, ys[k], model)
        turn_prob.append(belief.prob[MODES.index("turn_left")])
        err_imm.append(np.hypot(*(combine(belief)[0][:2] - truth[k, :2])))
        err_cv.append(np.hypot(*(plain.mean[:2] - truth[k, :2])))
    turn_prob = np.array(turn_prob)
    assert turn_prob[25:39].mean() > 0.5 > turn_prob[:18].mean()
    assert np.mean(err_imm[25:50]) < 0.5 * np.mean(err_cv[25:50])


def test_mode_beliefs_batch_over_passages():
    """A batch of passages steps as each passage alone (the modes are one more batch axis)."""
    rng = np.random.default_rng(2)
    model, T = _kinematic_model(rng)
    modes = motion_modes(model)
    imm = IMM(get_filter("ckf"), modes)
    starts = np.array([[-50.0, 10.0, 5.0, 0.0], [20.0, -5.0, -3.0, 1.0], [0.0, 0.0, 0.0, 4.0]])
    P0 = np.diag([25.0, 25.0, 1.0, 1.0])
    ys = rng.standard_normal((3, 8, 3))
    batch = imm.start(Belief.from_cov(starts, np.broadcast_to(P0, (3, 4, 4))))
    alone = [imm.start(Belief.from_cov(s, P0)) for s in starts]
    for k in range(8):
        batch, _ = imm.step(batch, ys[:, k], model)
        for i in range(3):
            alone[i], _ = imm.step(alone[i], ys[i, k], model)
    for i in range(3):
        np.testing.assert_allclose(batch.mean[i], alone[i].mean, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(batch.prob[i], alone[i].prob, rtol=1e-10, atol=1e-14)
    assert isinstance(batch, ModeBelief)
