"""Tracker models: analytic Jacobians against complex-step and finite differences; scaling."""

import numpy as np
import pytest

from shipsense import load_scenario
from shipsense.models.field_model import model_from_scenario


def complex_step(f, x, h=1e-20):
    return np.stack([f(x + 1j * h * e).imag / h for e in np.eye(x.size)], axis=-1)


def central(f, x, h):
    return np.stack([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(x.size)], axis=-1)


@pytest.mark.parametrize("kind", ["vector", "vector_world_axes", "magnitude", "tmi"])
def test_magnetic_jacobian_matches_complex_step(kind, tmp_path):
    # "vector" rotates its first sensor; "vector_world_axes" keeps them on the world axes (the kernel's
    # shortcut without orientation products)
    rotate = kind == "vector"
    kind = kind.removesuffix("_world_axes")
    sc = load_scenario("S2")
    sensors = [s.model_copy(update={"kind": kind, "orientation": None}) if s.type == "magnetometer" else s
               for s in sc.sensors if s.type == "magnetometer"]
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # a rotated first sensor
    if rotate:
        sensors[0] = sensors[0].model_copy(update={"orientation": tuple(map(tuple, R))})
    model = model_from_scenario(sc.model_copy(update={"sensors": sensors}))
    rng = np.random.default_rng(0)
    for _ in range(5):
        x = np.array([*rng.uniform(-60, 60, 2), *rng.uniform(-5, 5, 2), *rng.uniform(-0.05, 0.05, 3)])
        H = model.H(x)
        np.testing.assert_allclose(H, complex_step(model.h, x), rtol=1e-9, atol=1e-12 * np.abs(H).max())


def test_electric_jacobian_chain_rule_matches_finite_differences():
    # the kernel derivative itself is checked against complex-step of the series in
    # tests/physics/test_electric.py; here the chain rule through z, p and the keel direction
    model = model_from_scenario("S1-P2")
    assert model.labels == ("x", "y", "vx", "vy", "z", "p")
    rng = np.random.default_rng(1)
    for _ in range(4):
        x = np.array([*rng.uniform(-80, 80, 2), *rng.uniform(-8, 8, 2), rng.uniform(-10, -3), rng.uniform(50, 200)])
        H = model.H(x)
        fd = central(model.h, x, 1e-4)
        np.testing.assert_allclose(H, fd, rtol=1e-4, atol=1e-5 * np.abs(H).max())


@pytest.mark.parametrize("kinds", [("magnitude",) * 3, ("magnitude", "vector", "envelope")])
def test_electric_magnitude_jacobian_matches_finite_differences(kinds):
    sc = load_scenario("S1-P2")
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])   # a rotated first sensor: |E| ignores it
    sensors = [s.model_copy(update={"kind": k, "orientation": tuple(map(tuple, R)) if i == 0 else None})
               for i, (s, k) in enumerate(zip(sc.sensors, kinds))]
    model = model_from_scenario(sc.model_copy(update={"sensors": sensors}))
    assert model.m == sum(1 if k == "magnitude" else 3 for k in kinds)
    rng = np.random.default_rng(2)
    for _ in range(4):
        x = np.array([*rng.uniform(-80, 80, 2), *rng.uniform(-8, 8, 2), rng.uniform(-10, -3), rng.uniform(50, 200)])
        H = model.H(x)
        np.testing.assert_allclose(H, central(model.h, x, 1e-4), rtol=1e-4, atol=1e-5 * np.abs(H).max())
        e = np.linalg.norm(model_from_scenario("S1-P2").h(x)[:3])   # the first sensor's envelope triad
        assert model.h(x)[0] == pytest.approx(e, rel=1e-12)


def test_electric_magnitude_at_a_null_field_has_a_finite_jacobian():
    sc = load_scenario("S1-P2")
    sensors = [s.model_copy(update={"kind": "magnitude"}) for s in sc.sensors]
    model = model_from_scenario(sc.model_copy(update={"sensors": sensors}))
    x = np.array([30.0, -20.0, 5.0, 2.0, -6.8, 0.0])   # no dipole: |E| = 0 at every sensor
    assert np.all(model.h(x) == 0)
    H = model.H(x)
    assert np.all(np.isfinite(H)) and np.all(H == 0)   # the zero subgradient of the cone, explicitly


def test_candidate_model_copies_an_electric_magnitude_template():
    from shipsense.models.field_model import candidate_model

    sc = load_scenario("S1-P2")
    sc = sc.model_copy(update={"sensors": [s.model_copy(update={"kind": "magnitude"}) for s in sc.sensors]})
    pos = np.array([[10.0, 0.0, -15.0], [0.0, 30.0, -15.0]])
    cand = candidate_model(sc, pos)
    assert cand.m == 2 and cand.array.kinds == ("magnitude",) * 2 and cand.R.shape == (2,)
    moved = [s.model_copy(update={"position": tuple(p)}) for s, p in zip(sc.sensors, pos)]
    x = np.array([-40.0, 25.0, 6.0, -2.0, -6.8, 120.0])
    np.testing.assert_allclose(cand.h(x), model_from_scenario(sc.model_copy(update={"sensors": moved})).h(x),
                               rtol=1e-12)


@pytest.mark.parametrize("name", ["demo", "S1-P1"])
def test_h_and_H_in_one_pass_equal_h_and_H(name):
    """The fits' fused pass (readings from the Jacobian's kernels) gives the readings of the measurement path."""
    model = model_from_scenario(name)
    rng = np.random.default_rng(4)
    x = model.to_internal(model.state_from_truth(np.column_stack([
        rng.uniform(-150, 150, (6, 2)), rng.uniform(-8, 8, (6, 2)), np.full(6, -6.0),
        rng.uniform(-1e6, 1e6, (6, 3)), rng.uniform(50, 200, 6)])))
    y, H = model.h_and_H(x)
    np.testing.assert_allclose(y, model.h(x), rtol=1e-10, atol=1e-12 * np.abs(y).max())
    np.testing.assert_array_equal(H, model.H(x))


def test_bearing_jacobian_and_residual_wrap():
    model = model_from_scenario("S2", sensors=["A1"])
    x = np.array([30.0, 40.0, -2.0, 1.0])
    # complex step of the axial bearing written as atan(dy/dx) (analytic, equal modulo pi)
    s = model.array.positions[0]
    H_cs = complex_step(lambda v: np.arctan((v[1] - s[1]) / (v[0] - s[0]))[None], x)
    np.testing.assert_allclose(model.H(x), H_cs, rtol=1e-12)
    a, b = np.pi / 2 - 0.01, -np.pi / 2 + 0.01
    assert model.residual(np.array([a]), np.array([b]))[0] == pytest.approx(-0.02)
    assert model.residual(np.array([b]), np.array([a]))[0] == pytest.approx(0.02)


def test_internal_units_are_well_scaled_and_round_trip():
    model = model_from_scenario("S0")
    x_si = np.array([-140.0, -70.0, 6.0, 6.0, 8e7, 2e7, 4e7])
    x = model.to_internal(x_si)
    np.testing.assert_allclose(x[4:], [80, 20, 40])
    np.testing.assert_allclose(model.to_si(x), x_si)
    np.testing.assert_allclose(model.R, 8.0)  # R = 8 nT^2
    y = model.h(x)
    assert 1 < np.abs(y).max() < 1e5  # nT


@pytest.mark.parametrize("name, unit", [("S0", "srcdkf"), ("S2", "ukf")])
def test_process_noise_is_si_so_the_internal_scale_does_not_change_the_estimates(name, unit):
    """Q, P0 and R are SI in the scenario and rescaled once by the model: the moment kept in 1e6 or in 1e7
    A·m² internally gives the same estimates to 1e-9 (relative), and S0's Q = 0.1 I is 0.1 (A·m²)² on the
    moment, 1e-13 in (1e6 A·m²)² (scenarios.md)."""
    from shipsense import simulate
    from shipsense.trackers.filters.run import run_filter

    sc = load_scenario(name)
    sensors = ["M1", "M2"] if name == "S2" else None
    a, b = (model_from_scenario(sc, sensors=sensors, moment_unit=u) for u in (1e6, 1e7))
    np.testing.assert_allclose(a.Q * np.outer(a.x_scale, a.x_scale), b.Q * np.outer(b.x_scale, b.x_scale),
                               rtol=1e-12)
    if name == "S0":
        np.testing.assert_allclose(np.diag(a.Q), [0.1] * 4 + [0.1e-12] * 3, rtol=1e-12)
    sim = simulate(sc, runs=3, seed=2)
    cols = np.isin([c[0] for c in sim.channels], a.array.ids)
    truth = a.state_from_truth(sim.truth)
    x0 = truth[:, 0] + np.array([5.0, -5.0, 0.5, 0.5] + [0.0] * (a.n - 4))
    x0[:, 4:7] *= 0.5
    P0 = np.diag([100.0, 100.0, 4.0, 4.0] + [(0.5 * np.abs(truth[0, 0, 4:7]).max()) ** 2] * 3
                 + [1.0] * (a.n - 7))
    ra, rb = (run_filter(unit, m, sim.measurements[..., cols], x0, P0) for m in (a, b))
    scale = np.abs(ra.means).max(axis=(0, 1))          # each state component against its own magnitude
    assert np.isfinite(ra.means).all()
    np.testing.assert_allclose(rb.means / scale, ra.means / scale, rtol=0, atol=1e-9)


def _every_kind_model():
    """One model over every sensor type and measurement kind, vector and envelope sensors on rotated axes."""
    from shipsense.models.field_model import FieldModel
    from shipsense.physics.array import SensorArray
    from shipsense.physics.electric import Medium

    c, s = np.cos(0.7), np.sin(0.7)
    tilt = np.array([[c, -s, 0.0], [s * 0.8, c * 0.8, -0.6], [s * 0.6, c * 0.6, 0.8]])     # orthonormal columns
    kinds = [("magnetometer", "vector"), ("magnetometer", "magnitude"), ("magnetometer", "tmi"),
             ("electrode", "vector"), ("electrode", "envelope"), ("electrode", "magnitude"),
             ("accelerometer", "bearing")]
    pos = np.array([[-60.0, 10.0, -15.0], [0.0, -40.0, -15.0], [50.0, 30.0, -14.0], [-20.0, 60.0, -15.0],
                    [35.0, -25.0, -15.0], [90.0, 5.0, -13.0], [-80.0, -50.0, -15.0]])
    array = SensorArray(ids=[f"s{i}" for i in range(7)], types=[t for t, _ in kinds], kinds=[k for _, k in kinds],
                        positions=pos, orientations=np.stack([tilt if i in (0, 3, 4) else np.eye(3) for i in range(7)]),
                        medium=Medium(4.0, 0.3, 15.0), earth_direction=np.array([0.2, 0.4, -0.894427191]))
    return FieldModel(array, 1.0, np.eye(9), np.ones(array.n_channels), moment_unit=1e6)


@pytest.mark.parametrize("name", ["S0", "S2", "S1-P1", "every kind"])
def test_compiled_readings_and_jacobian_equal_the_numpy_kernels(name):
    """Every model on the fast HED path fits and filters through the compiled kernel; the numpy kernels of
    physics/ are the independent reference (and the path of complex states and the series HED)."""
    from shipsense.models.measurement import kernel_of

    model = _every_kind_model() if name == "every kind" else model_from_scenario(name)
    assert kernel_of(model) is not None
    rng = np.random.default_rng(6)
    truth = np.column_stack([rng.uniform(-150, 150, (12, 2)), rng.uniform(-8, 8, (12, 2)), rng.uniform(-12, -2, 12),
                             rng.uniform(-1e6, 1e6, (12, 3)), rng.uniform(50, 900, 12)])
    truth[0, 2:4] = 0.0               # at rest: no keel direction, no dipole
    x = model.to_internal(model.state_from_truth(truth)).reshape(4, 3, model.n)     # two batch axes
    y, H = model.h_and_H(x)
    y_np, H_np = model._h_and_H_numpy(x)
    assert y.shape == y_np.shape and H.shape == H_np.shape
    np.testing.assert_allclose(y, y_np, rtol=1e-12, atol=1e-13 * np.abs(y_np).max())
    np.testing.assert_allclose(H, H_np, rtol=1e-12, atol=1e-13 * np.abs(H_np).max())
    np.testing.assert_allclose(model.h(x), model._h_numpy(x), rtol=1e-12, atol=1e-13 * np.abs(y_np).max())


def test_series_hed_models_have_no_compiled_kernel():
    """The series HED path is evaluated by the numpy kernels only (the compiled kernel is the fast path's)."""
    from dataclasses import replace

    from shipsense.models.field_model import FieldModel
    from shipsense.models.measurement import kernel_of

    model = model_from_scenario("S1-P1")
    series = FieldModel(replace(model.array, electric_method="series"), model.period, model.Q, model.R)
    assert kernel_of(model) is not None and kernel_of(series) is None


def test_transitions_are_the_constant_velocity_formula():
    """``transitions(model, tau)`` is ``I + (tau / T)(A - I)`` to the bit (its ``I`` and ``A - I`` are kept per
    transition, by value: models with other transitions get theirs), ``A`` itself at ``tau = T`` and ``I`` at 0,
    a fresh writeable array every call."""
    from shipsense.models.transitions import transitions

    taus = np.array([[0.0, 0.5, -1.25], [3.0, 7.5, 2.0]])
    for name in ("S0", "S1-P1", "S2", "S0"):             # (S0 and S2: the same shape, other periods)
        model = model_from_scenario(load_scenario(name))
        n = model.A.shape[0]
        want = np.eye(n) + (taus[..., None, None] / model.period) * (model.A - np.eye(n))
        got = transitions(model, taus)
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(transitions(model, model.period), model.A)
        np.testing.assert_array_equal(transitions(model, 0.0), np.eye(n))
        got[...] = 0.0                                   # (the caller's to write)
        np.testing.assert_array_equal(transitions(model, taus), want)
