"""HED in a layered sea: image limits, potential, tolerance, tail bound, fast path."""

import numpy as np
import pytest

from shipsense.physics.electric import FastHED, Medium, hed_field, hed_potential, magnitude_jacobian, magnitude_reading

SIG1 = 4.0


def fullspace(s, q, p, sigma):
    """Textbook dipole in a homogeneous full space, written independently of the kernel."""
    r = np.asarray(s, float) - np.asarray(q, float)
    R = np.linalg.norm(r, axis=-1, keepdims=True)
    pr = np.sum(p * r, axis=-1, keepdims=True)
    return (3 * pr * r - R**2 * p) / (4 * np.pi * sigma * R**5)


def _geometry(rng, n, depth=15.0):
    rho = np.exp(rng.uniform(np.log(1.0), np.log(2000.0), n))
    az = rng.uniform(0, 2 * np.pi, n)
    sens = np.stack([rho * np.cos(az), rho * np.sin(az), rng.uniform(-depth, 0, n)], axis=-1)
    src = np.stack([np.zeros(n), np.zeros(n), rng.uniform(-depth + 0.2, -0.2, n)], axis=-1)
    th = rng.uniform(0, 2 * np.pi, n)
    p = np.stack([100 * np.cos(th), 100 * np.sin(th), np.zeros(n)], axis=-1)
    return sens, src, p


def test_equal_conductivities_leave_source_and_surface_image():
    rng = np.random.default_rng(0)
    medium = Medium(SIG1, SIG1, 15.0)
    assert medium.eta == 0
    s, q, p = _geometry(rng, 200)
    image = q * np.array([1, 1, -1])
    expected = fullspace(s, q, p, SIG1) + fullspace(s, image, p, SIG1)
    np.testing.assert_allclose(hed_field(s, q, p, medium), expected, rtol=1e-12, atol=1e-25)
    np.testing.assert_allclose(hed_field(s, q, p, medium, method="fast"), expected, rtol=1e-12, atol=1e-25)


def test_deep_water_tends_to_the_full_space_dipole():
    # far from the surface and the seabed, every image is far away: the full-space dipole remains
    medium = Medium(SIG1, 0.04, 20_000.0)
    q = np.array([0.0, 0.0, -10_000.0])
    s = q + np.array([[3.0, 4.0, 1.0], [-2.0, 0.5, -3.0]])
    p = np.array([50.0, -20.0, 0.0])
    E0 = fullspace(s, q, p, SIG1)
    np.testing.assert_allclose(hed_field(s, q, p, medium), E0, rtol=0, atol=1e-9 * np.abs(E0).max())


def test_conductive_seabed_reflects_with_negative_eta():
    # seabed more conductive than the water: eta < 0 and the series still converges to its tolerance
    medium = Medium(1.0, 10.0, 15.0)
    assert medium.eta < 0
    s = np.array([40.0, 10.0, -15.0])
    q = np.array([0.0, 0.0, -5.0])
    p = np.array([100.0, 0.0, 0.0])
    a = hed_field(s, q, p, medium, rtol=1e-6)
    b = hed_field(s, q, p, medium, rtol=1e-13)
    scale = 100.0 / (4 * np.pi * 1.0 * np.linalg.norm(s - q) ** 3)
    assert np.abs(a - b).max() <= 1e-6 * scale


@pytest.mark.parametrize("sigma2", [0.04, 1.0])
def test_field_is_minus_gradient_of_potential(sigma2):
    medium = Medium(SIG1, sigma2, 15.0)
    rng = np.random.default_rng(1)
    q = np.array([0.0, 0.0, -6.8])
    p = np.array([70.0, 70.0, 0.0])
    for _ in range(4):
        s = np.array([*rng.uniform(-120, 120, 2), rng.uniform(-14.5, -0.5)])
        h = 1e-3
        grad = np.array([(hed_potential(s + h * e, q, p, medium, rtol=1e-14)
                          - hed_potential(s - h * e, q, p, medium, rtol=1e-14)) / (2 * h) for e in np.eye(3)])
        E = hed_field(s, q, p, medium, rtol=1e-14)
        np.testing.assert_allclose(E, -grad, rtol=1e-5, atol=1e-6 * np.abs(E).max())


@pytest.mark.parametrize("sigma2", [0.04, 1.0])
def test_tolerance_is_a_proven_bound(sigma2):
    """Stopping at rtol leaves an error below rtol times the direct-field scale, everywhere."""
    medium = Medium(SIG1, sigma2, 15.0)
    s, q, p = _geometry(np.random.default_rng(2), 400)
    ref, n_ref = hed_field(s, q, p, medium, rtol=1e-14, return_shells=True)
    scale = np.linalg.norm(p, axis=-1) / (4 * np.pi * SIG1 * np.linalg.norm(s - q, axis=-1) ** 3)
    previous = 0
    for rtol in (1e-2, 1e-4, 1e-6, 1e-9):
        E, n = hed_field(s, q, p, medium, rtol=rtol, return_shells=True)
        err = np.linalg.norm(E - ref, axis=-1)
        assert np.all(err <= rtol * scale), (rtol, (err / scale).max())
        assert previous <= n <= n_ref
        previous = n


def test_tightening_the_tolerance_changes_the_field_by_less_than_it():
    medium = Medium(SIG1, 0.04, 15.0)
    s, q, p = _geometry(np.random.default_rng(3), 300)
    a = hed_field(s, q, p, medium, rtol=1e-7)
    b = hed_field(s, q, p, medium, rtol=1e-8)
    scale = 100.0 / (4 * np.pi * SIG1 * np.linalg.norm(s - q, axis=-1) ** 3)
    assert np.all(np.linalg.norm(a - b, axis=-1) <= 1e-7 * scale)


def test_resistive_seabed_needs_many_shells_and_typical_magnitudes():
    # physics.md: p = 100 A m, seabed sensor, sigma2 = 0.04: ~1e-4 V/m at 50 m and ~3e-6 V/m at 300 m
    medium = Medium(SIG1, 0.04, 15.0)
    q = np.array([0.0, 0.0, -6.8])
    p = np.array([100.0, 0.0, 0.0])
    E50, n = hed_field([50.0, 0, -15], q, p, medium, rtol=1e-13, return_shells=True)
    E300 = hed_field([300.0, 0, -15], q, p, medium, rtol=1e-13)
    assert 3e-5 < np.linalg.norm(E50) < 3e-4
    assert 1e-6 < np.linalg.norm(E300) < 1e-5
    assert n > 300  # eta = 0.98: hundreds of shells, as the spec warns
    ten = hed_field([300.0, 0, -15], q, p, medium, rtol=1e-13, max_shells=10_000)
    assert np.allclose(ten, E300)


def test_linear_in_the_moment_and_vertical_moment_ignored():
    medium = Medium(SIG1, 0.04, 15.0)
    s, q, _ = _geometry(np.random.default_rng(4), 50)
    p1 = np.array([30.0, -10.0, 0.0])
    p2 = np.array([-5.0, 80.0, 0.0])
    for method in ("series", "fast"):
        def f(p, method=method):
            return hed_field(s, q, p, medium, method=method)

        np.testing.assert_allclose(f(p1 + 2 * p2), f(p1) + 2 * f(p2), rtol=1e-9, atol=1e-22)
        np.testing.assert_allclose(f(p1 + [0, 0, 5.0]), f(p1), rtol=0, atol=0)


@pytest.mark.parametrize("sigma2", [0.04, 1.0])
def test_fast_path_matches_series_on_a_grid(sigma2):
    """The fast path's error is below 1e-6 relative for offsets from 1 m to 2 km."""
    medium = Medium(SIG1, sigma2, 15.0)
    rho = np.geomspace(1.0, 2000.0, 60)
    az = np.linspace(0, 2 * np.pi, 7, endpoint=False)
    zs = np.array([-15.0, -10.0, -0.5])
    zt = np.array([-14.0, -6.8, -1.0])
    R, A, Zs, Zt = np.meshgrid(rho, az, zs, zt, indexing="ij")
    s = np.stack([R * np.cos(A), R * np.sin(A), Zs], axis=-1)
    q = np.stack([0 * R, 0 * R, Zt], axis=-1)
    p = np.array([60.0, 80.0, 0.0])
    ref = hed_field(s, q, p, medium, rtol=1e-13)
    fast = hed_field(s, q, p, medium, method="fast")
    rel = np.linalg.norm(fast - ref, axis=-1) / np.linalg.norm(ref, axis=-1)
    assert rel.max() <= 1e-6, rel.max()


def test_fast_path_beyond_its_table_follows_the_asymptote():
    medium = Medium(SIG1, 0.3, 15.0)
    kernel = FastHED(medium, rho_max=2000.0)
    s = np.array([[50.0, 0, -15], [6000.0, 1000.0, -15], [30_000.0, 0.0, -15]])
    q = np.array([0.0, 0.0, -6.8])
    p = np.array([100.0, 0.0, 0.0])
    ref = hed_field(s, q, p, medium, rtol=1e-12)
    rel = np.linalg.norm(kernel(s, q, p) - ref, axis=-1) / np.linalg.norm(ref, axis=-1)
    assert rel[0] < 1e-6 and rel[1:].max() < 0.5   # extrapolated: the right order, not exact
    E, dE, G = kernel.field_jacobian(s, q, p)
    assert np.isfinite(dE).all() and np.isfinite(G).all()


def test_medium_rejects_non_positive_values():
    with pytest.raises(ValueError, match="sigma_seabed"):
        Medium(4.0, -0.1, 15.0)
    with pytest.raises(ValueError, match="water_depth"):
        Medium(4.0, 0.1, float("nan"))


@pytest.mark.parametrize("sigma2", [0.04, 1.0])
def test_fast_jacobian_matches_complex_step_of_the_series(sigma2):
    from shipsense.physics.electric import _series

    medium = Medium(SIG1, sigma2, 15.0)
    s, q, _ = _geometry(np.random.default_rng(6), 300)
    p = np.array([60.0, 80.0, 0.0])
    E, dE, G = FastHED(medium).field_jacobian(s, q, p)
    np.testing.assert_allclose(np.einsum("...ij,j->...i", G, p[:2]), E, rtol=1e-12)
    h = 1e-20
    for j in range(3):
        qc = q.astype(complex)
        qc[:, j] += 1j * h
        rx, ry = s[:, 0] - qc[:, 0], s[:, 1] - qc[:, 1]
        total, _ = _series(rx, ry, s[:, 2] + 0j, qc[:, 2], p[0] + 0 * rx, p[1] + 0 * rx, medium, 1e-13,
                           200_000, potential=False)
        cs = (total.T / (4 * np.pi * SIG1)).imag / h
        rel = np.linalg.norm(cs - dE[..., j], axis=-1) / np.linalg.norm(dE, axis=(-1, -2))
        assert rel.max() < 1e-5, (j, rel.max())


def test_magnitude_reading_limits_and_symmetry():
    """``|E|`` of the equal-conductivity medium is the length of the textbook source-plus-surface-image field;
    it is the same for every sensor orientation, and the same at a sensor and at its mirror image across
    the dipole's vertical plane (where the signed cross-keel component flips)."""
    rng = np.random.default_rng(3)
    medium = Medium(SIG1, SIG1, 15.0)
    s, q, p = _geometry(rng, 200)
    image = q * np.array([1, 1, -1])
    expected = np.linalg.norm(fullspace(s, q, p, SIG1) + fullspace(s, image, p, SIG1), axis=-1)
    np.testing.assert_allclose(magnitude_reading(hed_field(s, q, p, medium)), expected, rtol=1e-12)
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    E = hed_field(s, q, p, Medium(SIG1, 0.04, 15.0), method="fast")
    np.testing.assert_allclose(magnitude_reading(E @ R), magnitude_reading(E), rtol=1e-12)
    # mirror across the vertical plane through the source along the dipole (the keel)
    u = p[:, :2] / np.linalg.norm(p[:, :2], axis=-1, keepdims=True)
    M = 2 * u[:, :, None] * u[:, None, :] - np.eye(2)
    s_m = s.copy()
    s_m[:, :2] = q[:, :2] + np.einsum("nij,nj->ni", M, s[:, :2] - q[:, :2])
    E_m = hed_field(s_m, q, p, Medium(SIG1, 0.04, 15.0), method="fast")
    np.testing.assert_allclose(magnitude_reading(E_m), magnitude_reading(E), rtol=1e-9)
    cross = np.stack([-u[:, 1], u[:, 0]], -1)
    np.testing.assert_allclose(np.sum(E_m[:, :2] * cross, -1), -np.sum(E[:, :2] * cross, -1),
                               rtol=1e-9, atol=1e-12 * np.abs(E).max())


def test_magnitude_jacobian_matches_finite_differences_and_is_zero_at_a_null():
    medium = Medium(SIG1, 0.04, 15.0)
    s, q, _ = _geometry(np.random.default_rng(7), 100)
    p = np.array([60.0, 80.0, 0.0])
    E, dE, _ = FastHED(medium).field_jacobian(s, q, p)
    e, de = magnitude_jacobian(E, dE)
    np.testing.assert_allclose(e, np.linalg.norm(E, axis=-1), rtol=1e-14)
    h = 1e-4
    for j in range(3):
        dq = np.zeros(3)
        dq[j] = h
        fd = (magnitude_reading(FastHED(medium)(s, q + dq, p)) - magnitude_reading(FastHED(medium)(s, q - dq, p)))
        np.testing.assert_allclose(de[:, j], fd / (2 * h), rtol=1e-5, atol=1e-6 * np.abs(de).max())
    # at a null of the field the magnitude has a cone: the derivative is the zero subgradient, not NaN
    e0, de0 = magnitude_jacobian(np.zeros((2, 3)), dE[:2])
    assert np.all(e0 == 0) and np.all(de0 == 0)


def test_fast_path_split_across_threads_equals_one_thread_bit_for_bit(monkeypatch):
    """A batch of SPLIT_MIN points or more runs as chunks in threads (every point is independent)."""
    from shipsense import parallel

    medium = Medium(SIG1, 0.04, 15.0)
    rng = np.random.default_rng(8)
    n = parallel.SPLIT_MIN + 101
    s = np.column_stack([rng.uniform(-300, 300, (n, 2)), np.full(n, -15.0)])
    q = np.column_stack([np.zeros((n, 2)), rng.uniform(-10, -1, n)])
    p = np.column_stack([rng.uniform(-100, 100, (n, 2)), np.zeros(n)])
    kernel = FastHED(medium)
    out = {}
    for threads in ("1", "3"):
        monkeypatch.setenv("SHIPSENSE_THREADS", threads)
        out[threads] = (kernel(s, q, p), *kernel.field_jacobian(s, q, p))
    for a, b in zip(out["1"], out["3"]):
        assert a.shape == b.shape
        np.testing.assert_array_equal(a, b)


def _series_table(kernel, rho, w, rtol):
    """The fast path's remainder table written as the plain series: shell after shell over the whole grid,
    stopping after the first shell whose tail bound (two images per shell per family) is within ``rtol`` of
    the scale at every point."""
    from shipsense.physics.electric import _integral_tail

    D, eta = kernel.medium.water_depth, kernel.medium.eta
    K = np.zeros(rho.shape + (3,))
    s2 = rho * rho + kernel._a**2
    for n in range(2, 1_000_000):
        c = eta**n
        for dz in (w + 2 * n * D, w - 2 * n * D):
            R2 = rho * rho + dz * dz
            inv_R3 = R2**-1.5
            K[..., 0] += c * inv_R3
            K[..., 1] += c * (inv_R3 / R2)
            K[..., 2] += c * dz * (inv_R3 / R2)
        if np.all(2.0 * _integral_tail(abs(eta), n, D, np.abs(rho), 3) <= rtol / s2**1.5):
            break
    return K * np.stack([s2**1.5, s2**2.5, s2**2.5 / kernel._a], axis=-1)


@pytest.mark.parametrize("sigma2", [0.04, 40.0])
def test_the_fast_paths_table_is_the_plain_series_bit_for_bit(monkeypatch, sigma2):
    """The table is built from the offsets that decide the stopping shell, point by point on contiguous
    scratch and in chunks on the CPUs: each number is still the plain series' (the same terms, added in the
    same order), on one thread or several."""
    medium = Medium(SIG1, sigma2, 15.0)
    kernels = {}
    for threads in ("1", "2"):
        monkeypatch.setenv("SHIPSENSE_THREADS", threads)
        kernels[threads] = FastHED(medium, rho_max=3000.0)
    kernel = kernels["1"]
    x = kernel._x0 + kernel._hx * np.arange(kernel._nx)
    w = kernel._w0 + kernel._hw * np.arange(kernel._nw)
    rho = kernel._a * np.sinh(x)[:, None] * np.ones((1, kernel._nw))
    want = _series_table(kernel, rho, np.ones((kernel._nx, 1)) * w[None, :], 1e-13).reshape(-1, 3)
    assert kernel._table.shape[0] > 8192     # (more points than a chunk: the build is split)
    np.testing.assert_array_equal(kernels["1"]._table, want)
    np.testing.assert_array_equal(kernels["2"]._table, want)


def test_a_conductivity_ratio_outside_the_series_range_is_refused_and_the_stopping_shell_is_bounded():
    """At |eta| = 1 (sigma_seabed = 1e-308 rounds eta to 1) the tail falls like 1/n^2 and no tolerance is reached in
    a bounded number of shells: the Medium refuses the ratio; at the range's ends the stopping shell is found
    within MAX_SHELLS."""
    from shipsense.physics.electric import CONDUCTIVITY_RATIO, MAX_SHELLS, _last_shell

    with pytest.raises(ValueError, match="CONDUCTIVITY_RATIO"):
        Medium(4.0, 1e-308, 15.0)
    with pytest.raises(ValueError, match="CONDUCTIVITY_RATIO"):
        Medium(1e-6, 100.0, 15.0)
    rho = np.array([0.0, 30.0, 2000.0])
    for ratio in CONDUCTIVITY_RATIO:
        eta = Medium(1.0, ratio, 15.0).eta
        assert 2 <= _last_shell(eta, 15.0, rho, 1e-13 / (rho**2 + 900.0) ** 1.5) <= MAX_SHELLS
    with pytest.raises(RuntimeError, match="CONDUCTIVITY_RATIO"):
        _last_shell(1.0, 15.0, rho, 1e-13 / (rho**2 + 900.0) ** 1.5)
