"""Magnetic dipole kernel: closed forms, symmetry, potential, broadcasting."""

import numpy as np
import pytest

from shipsense.physics.magnetic import (
    dipole_field,
    dipole_field_at,
    earth_field_direction,
    magnitude_reading,
    tmi_reading,
)

MU = 1e-7


def _random_rotation(rng):
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.mark.parametrize("seed", range(5))
def test_on_axis_and_equatorial_closed_forms(seed):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-100, 100, 3)
    m = rng.standard_normal(3) * 1e7
    mhat = m / np.linalg.norm(m)
    r = rng.uniform(5, 500)
    # on axis: B = 2 mu m / r^3 along the moment
    np.testing.assert_allclose(dipole_field(q + r * mhat, q, m), MU * 2 * m / r**3, rtol=1e-12)
    # equatorial: B = -mu m / r^3
    perp = np.cross(mhat, rng.standard_normal(3))
    perp /= np.linalg.norm(perp)
    np.testing.assert_allclose(dipole_field(q + r * perp, q, m), -MU * m / r**3, rtol=1e-10,
                               atol=1e-12 * MU * np.linalg.norm(m) / r**3)


def test_rotation_and_translation_equivariance():
    rng = np.random.default_rng(1)
    s = rng.uniform(-50, 50, (20, 3))
    q = rng.uniform(-50, 50, (20, 3))
    m = rng.standard_normal((20, 3)) * 1e6
    B = dipole_field(s, q, m)
    R = _random_rotation(rng)
    np.testing.assert_allclose(dipole_field(s @ R.T, q @ R.T, m @ R.T), B @ R.T, rtol=1e-10, atol=1e-20)
    t = rng.uniform(-1e3, 1e3, 3)
    np.testing.assert_allclose(dipole_field(s + t, q + t, m), B, rtol=1e-8, atol=1e-20)


def test_field_is_minus_mu0_gradient_of_scalar_potential():
    # independent computation: B = -mu0 grad(m . r / (4 pi r^3)), by central differences
    rng = np.random.default_rng(2)
    q = np.array([3.0, -4.0, 0.0])
    m = np.array([8e7, 2e7, 4e7])

    def psi(s):
        r = s - q
        return MU * (m @ r) / np.linalg.norm(r) ** 3

    for _ in range(5):
        s = q + rng.uniform(-60, 60, 3)
        h = 1e-4 * np.linalg.norm(s - q)
        grad = np.array([(psi(s + h * e) - psi(s - h * e)) / (2 * h) for e in np.eye(3)])
        np.testing.assert_allclose(dipole_field(s, q, m), -grad, rtol=1e-6)


def test_broadcasting_over_leading_axes():
    rng = np.random.default_rng(3)
    s = rng.uniform(-50, 50, (4, 1, 3))
    q = rng.uniform(-50, 50, (1, 6, 3))
    m = rng.standard_normal(3) * 1e6
    B = dipole_field(s, q, m)
    assert B.shape == (4, 6, 3)
    np.testing.assert_allclose(B[2, 5], dipole_field(s[2, 0], q[0, 5], m))


def test_singular_point_is_nan_without_warning():
    with np.errstate(all="raise"):
        B = dipole_field(np.zeros((2, 3)), [[0, 0, 0], [0, 0, 1.0]], [1.0, 0, 0])
    assert np.isnan(B[0]).all() and np.isfinite(B[1]).all()


def test_scalar_readings():
    B = np.array([3e-9, 4e-9, 0.0])
    assert magnitude_reading(B) == pytest.approx(5e-9)
    b = earth_field_direction(90.0, 0.0)  # vertical, pointing down
    np.testing.assert_allclose(b, [0, 0, -1], atol=1e-15)
    assert tmi_reading(np.array([0, 0, -2e-9]), b) == pytest.approx(2e-9)
    b = earth_field_direction(0.0, 90.0)  # horizontal, pointing east
    np.testing.assert_allclose(b, [1, 0, 0], atol=1e-15)


def test_jacobian_matches_complex_step():
    from shipsense.physics.magnetic import dipole_field_jacobian

    rng = np.random.default_rng(4)
    s = rng.uniform(-50, 50, (10, 3))
    q = rng.uniform(-50, 50, (10, 3))
    m = rng.standard_normal((10, 3)) * 1e6
    B, dq, dm = dipole_field_jacobian(s, q, m)
    np.testing.assert_allclose(B, dipole_field(s, q, m), rtol=1e-12)
    h = 1e-20
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        np.testing.assert_allclose(dipole_field(s, q + 1j * e, m).imag / h, dq[..., j], rtol=1e-10, atol=1e-22)
        np.testing.assert_allclose(dipole_field(s, q, m + 1j * e).imag / h, dm[..., j], rtol=1e-10, atol=1e-22)


@pytest.mark.parametrize("batch", [(5, 7), (40, 30)], ids=["rows", "components"])   # both sides of _ROWS_MAX
def test_sensor_major_kernel_equals_the_broadcast_kernel_and_flags_coincidence(batch):
    rng = np.random.default_rng(4)
    sensors = rng.normal(size=(3, 3)) * 10
    q = rng.normal(size=batch + (3,)) * 50
    m = rng.normal(size=batch + (3,)) * 1e6
    np.testing.assert_allclose(dipole_field_at(sensors, q, m), dipole_field(sensors, q[..., None, :], m[..., None, :]),
                               rtol=1e-13, atol=0)
    q[2, 3] = sensors[1]                                   # a source on sensor 1
    B = dipole_field_at(sensors, q, m)
    assert np.isnan(B[2, 3, 1]).all() and np.isfinite(np.delete(B[2, 3], 1, axis=0)).all()
    assert np.isfinite(np.delete(B.reshape(-1, 3, 3), 2 * batch[1] + 3, axis=0)).all()
    # a moment shared by the batch broadcasts like the broadcast kernel
    np.testing.assert_allclose(dipole_field_at(sensors, q, m[0, 0]), dipole_field(sensors, q[..., None, :], m[0, 0]),
                               rtol=1e-13, atol=0)
