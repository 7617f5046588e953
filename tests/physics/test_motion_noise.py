"""Motion and noise models."""

import numpy as np

from shipsense.physics.motion import cv_positions, cv_transition, q_dwna, q_identity
from shipsense.physics.noise import contaminated, dropout_mask


def test_transition_matches_constant_velocity_positions():
    A = cv_transition(0.5, 3)
    x = np.array([10.0, -5.0, 2.0, 1.0, 1e6, 2e6, 3e6])
    xs = [x]
    for _ in range(9):
        xs.append(A @ xs[-1])
    pos = cv_positions(x[:2], x[2:4], 0.5 * np.arange(10))
    np.testing.assert_allclose(np.array(xs)[:, :2], pos)
    np.testing.assert_allclose(np.array(xs)[:, 4:], np.broadcast_to(x[4:], (10, 3)))


def test_dwna_is_the_textbook_block_and_psd():
    T, sa = 0.4, 0.3
    Q = q_dwna(T, (sa, 2 * sa), [0.0, 1e-3])
    np.testing.assert_allclose(Q[np.ix_([0, 2], [0, 2])], sa**2 * np.array([[T**4 / 4, T**3 / 2], [T**3 / 2, T**2]]))
    np.testing.assert_allclose(Q[1, 3], (2 * sa) ** 2 * T**3 / 2)
    assert Q[0, 1] == 0 and Q[4, 4] == 0 and Q[5, 5] == 1e-3
    assert np.linalg.eigvalsh(Q).min() >= -1e-15
    np.testing.assert_allclose(q_identity(3, 0.1), 0.1 * np.eye(7))


def test_contaminated_noise_variance_and_dropout_rate():
    rng = np.random.default_rng(0)
    eps = 0.1
    x = contaminated(rng, 2.0, (400_000,), eps)
    expected = 4.0 * ((1 - eps) + eps * 100)
    assert abs(x.var() / expected - 1) < 0.03
    m = dropout_mask(rng, (200_000,), 0.2)
    assert abs((~m).mean() - 0.2) < 0.005
    assert dropout_mask(rng, (5,), 0.0).all()
