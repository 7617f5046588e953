"""Manoeuvring motion against a numerical integration, analytic limits and finite-difference Jacobians."""

import numpy as np
import pytest

from shipsense.physics.manoeuvre import (
    SPEED_CHANGE,
    STRAIGHT,
    TURN,
    Manoeuvres,
    manoeuvring_motion,
    transition_jacobians,
    turned_moment,
)
from shipsense.physics.motion import cv_positions


def schedule():
    """Three passages: a turn then a speed-up; a slow-down then a starboard turn; nothing."""
    kind = [[TURN, SPEED_CHANGE], [TURN, SPEED_CHANGE], [STRAIGHT, STRAIGHT]]
    start = [[3.0, 20.0], [14.0, 2.5], [0.0, 0.0]]
    duration = [[10.0, 6.0], [9.0, 7.0], [0.0, 0.0]]
    rate = [[np.deg2rad(4.0), 0.0], [np.deg2rad(-7.0), 0.0], [0.0, 0.0]]
    acc = [[0.0, 0.4], [0.0, -0.3], [0.0, 0.0]]
    return Manoeuvres.from_slots(kind, start, duration, rate, acc, 0.5)


START = np.array([[0.0, 0.0], [50.0, -20.0], [-10.0, 5.0]])
VELOCITY = np.array([[4.0, 1.0], [-3.0, 2.0], [2.0, -2.0]])


def rk4(p, v, m: Manoeuvres, run, t_end, h):
    """Integrate psi' = w(t), s' = a(t), p' = s u(psi) with RK4 from t = 0 (independent of the closed form;
    the switching times on the grid, each step's rates those of its midpoint)."""
    def piece(t):
        for k, s, d, w, a in zip(m.kind[run], m.start[run], m.duration[run], m.rate[run], m.acceleration[run]):
            if k != STRAIGHT and s <= t < s + d:
                return w, a
        return 0.0, 0.0

    def rates(y, w, a):
        return np.array([y[2] * np.cos(y[3]), y[2] * np.sin(y[3]), a, w])

    y = np.array([p[0], p[1], np.hypot(*v), np.arctan2(v[1], v[0])])
    for i in range(int(round(t_end / h))):
        w, a = piece((i + 0.5) * h)
        k1 = rates(y, w, a)
        k2 = rates(y + h / 2 * k1, w, a)
        k3 = rates(y + h / 2 * k2, w, a)
        k4 = rates(y + h * k3, w, a)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return y


def test_closed_form_motion_equals_a_numerical_integration():
    m = schedule()
    times = np.array([0.0, 5.0, 12.5, 22.0, 30.0])
    pos, vel, course, label = manoeuvring_motion(START, VELOCITY, m, times)
    for r in range(3):
        for k, t in enumerate(times):
            y = rk4(START[r], VELOCITY[r], m, r, t, h=2.0 ** -8)
            # RK4 with the switching times on its grid (h a power of two): exact but for the step's error
            np.testing.assert_allclose(pos[r, k], y[:2], atol=1e-8)
            np.testing.assert_allclose(np.hypot(*vel[r, k]), y[2], atol=1e-9)
            np.testing.assert_allclose(course[r, k], y[3], atol=1e-9)
    assert label[0].tolist() == [STRAIGHT, TURN, TURN, SPEED_CHANGE, STRAIGHT] and not label[2].any()


def test_no_manoeuvre_is_constant_velocity_also_before_the_start():
    times = np.linspace(-5.0, 40.0, 31)
    pos, vel, _, label = manoeuvring_motion(START, VELOCITY, Manoeuvres.none(3), times)
    np.testing.assert_array_equal(pos, cv_positions(START, VELOCITY, times))     # to the bit
    np.testing.assert_array_equal(vel, np.repeat(VELOCITY[:, None], 31, axis=1))
    assert not label.any()


def test_a_full_turn_comes_back_to_where_it_began_and_a_speed_change_reaches_its_speed():
    w = np.deg2rad(3.0)
    m = Manoeuvres.from_slots([[TURN]], [[10.0]], [[2 * np.pi / w]], [[w]], [[0.0]])
    pos, vel, course, _ = manoeuvring_motion(START[:1], VELOCITY[:1], m, [10.0, 10.0 + 2 * np.pi / w])
    np.testing.assert_allclose(pos[0, 1], pos[0, 0], atol=1e-9)
    np.testing.assert_allclose(vel[0, 1], VELOCITY[0], atol=1e-12)
    assert course[0, 1] - course[0, 0] == pytest.approx(2 * np.pi)
    # radius s / w: the turn's centre is s/w to port of the ship
    half = manoeuvring_motion(START[:1], VELOCITY[:1], m, [10.0 + np.pi / w])[0][0, 0]
    assert np.linalg.norm(half - pos[0, 0]) == pytest.approx(2 * np.hypot(*VELOCITY[0]) / w)
    m = Manoeuvres.from_slots([[SPEED_CHANGE]], [[0.0]], [[4.0]], [[0.0]], [[-0.5]])
    pos, vel, _, _ = manoeuvring_motion(START[:1], VELOCITY[:1], m, [4.0, 9.0])
    s0 = np.hypot(*VELOCITY[0])
    u = VELOCITY[0] / s0
    np.testing.assert_allclose(vel[0, 0], (s0 - 2.0) * u)
    np.testing.assert_allclose(pos[0, 0], START[0] + (4 * s0 - 4.0) * u)
    np.testing.assert_allclose(pos[0, 1], pos[0, 0] + 5 * (s0 - 2.0) * u)


def test_schedule_slots_are_sorted_and_cleared():
    m = Manoeuvres.from_slots([[SPEED_CHANGE, TURN, TURN]], [[30.0, 5.0, 1.0]], [[2.0, 3.0, 0.0]],
                              [[0.0, 0.1, 0.2]], [[0.3, 0.0, 0.0]])
    assert m.kind.tolist() == [[TURN, SPEED_CHANGE, STRAIGHT]] and m.start[0, :2].tolist() == [5.0, 30.0]
    assert np.isinf(m.start[0, 2]) and m.any
    assert m.to_records()[0][0] == {"kind": "turn", "start": 5.0, "duration": 3.0,
                                    "rate_deg_s": pytest.approx(np.rad2deg(0.1)), "acceleration": 0.0}
    assert m.take([0]).kind.shape == (1, 3) and not Manoeuvres.none(2).any


def test_turned_moment_limits():
    m0 = np.array([3.0, -1.0, 2.0])
    turn = np.array([0.0, 0.7, np.pi])
    np.testing.assert_allclose(turned_moment(m0, turn, 0.0), np.tile(m0, (3, 1)))
    full = turned_moment(m0, turn, 1.0)
    np.testing.assert_allclose(np.linalg.norm(full, axis=-1), np.linalg.norm(m0))      # a rotation
    np.testing.assert_allclose(full[2], [-3.0, 1.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(turned_moment(m0, turn, 0.25), 0.75 * m0 + 0.25 * full)  # linear in the share


def _step_map(m: Manoeuvres, run, t0, t1):
    """The exact motion x(t0) -> x(t1) of one run, as a function of x(t0) (the schedule from t0 on)."""
    s0 = np.where(m.kind[run:run + 1] != STRAIGHT, m.start[run:run + 1], 0.0)     # empty slots stay empty
    start = np.clip(s0 - t0, 0.0, None)
    end = np.clip(s0 + m.duration[run:run + 1] - t0, 0.0, None)
    shifted = Manoeuvres.from_slots(m.kind[run:run + 1], start, end - start, m.rate[run:run + 1],
                                    m.acceleration[run:run + 1])

    def f(x):
        pos, vel, _, _ = manoeuvring_motion(x[None, :2], x[None, 2:], shifted, [t1 - t0])
        return np.concatenate([pos[0, 0], vel[0, 0]])
    return f


def test_jacobians_match_finite_differences_and_constant_velocity_without_manoeuvres():
    m = schedule()
    times = np.arange(0.0, 28.0, 1.5)      # steps straddle the manoeuvres' starts and ends
    F = transition_jacobians(START, VELOCITY, m, times)
    pos, vel, _, _ = manoeuvring_motion(START, VELOCITY, m, times)
    for r in range(3):
        for k in range(len(times) - 1):
            f = _step_map(m, r, times[k], times[k + 1])
            x = np.concatenate([pos[r, k], vel[r, k]])
            np.testing.assert_allclose(f(x), np.concatenate([pos[r, k + 1], vel[r, k + 1]]), atol=1e-9)
            h = 1e-5
            num = np.stack([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(4)], axis=-1)
            np.testing.assert_allclose(F[r, k], num, atol=1e-7)
    A = np.eye(4)
    A[0, 2] = A[1, 3] = 1.5
    np.testing.assert_allclose(F[2], np.broadcast_to(A, F[2].shape), atol=1e-13)
