"""State-space models: the physics kernels bound to tracker states.

A model exposes what every filter needs, batched over leading axes:

* ``n``, ``m``: state and measurement dimensions;
* ``A`` (n, n) and ``Q`` (n, n): the linear (constant-velocity) transition;
* ``h(x)`` (..., n) -> (..., m) and its Jacobian ``H(x)`` (..., m, n);
* ``R`` (m,): measurement noise variances (diagonal);
* ``residual(a, b)``: ``a - b`` with axial channels (bearings) wrapped modulo pi.

Internal units.  Filters see scaled quantities so that covariances stay well
conditioned: positions in m, velocities in m/s, magnetic moments in units of
``moment_unit`` (1e6 A·m² by default), the electric source height in m and
``p`` in A·m; magnetic fields in nT, electric fields in nV/m, bearings in rad.
:meth:`FieldModel.to_internal` / :meth:`FieldModel.to_si` convert states, and
:attr:`FieldModel.y_scale` measurements; users see SI.

State layout (:mod:`shipsense.physics.motion`): ``(x, y, v_x, v_y)``, then the magnetic moment
``(m_x, m_y, m_z)`` if the array has magnetometers, then ``(z, p)`` if it has
electrodes (the source height and the scalar dipole along the keel).  A model
over several sensor types is the fused (stacked) model: its channels are the
array's channels.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from shipsense.physics.array import CHANNELS, SensorArray, as_slice
from shipsense.physics.motion import cv_transition, q_dwna, q_identity
from shipsense.physics.seismic import wrap_axial

DEPTH_MARGIN = 0.5
"""Closest a source may come to the sea surface or the seabed in fits (m)."""

CHANNEL_UNIT = {"magnetometer": 1e-9, "electrode": 1e-9, "accelerometer": 1.0}
"""SI value of one internal measurement unit per sensor type (nT, nV/m, rad)."""


@dataclass(frozen=True, eq=False)
class FieldModel:
    """A passage seen by a sensor array: constant-velocity motion, field measurements.

    Parameters
    ----------
    array : SensorArray
    period : float
        Sampling period T, s.
    Q : array_like, shape (n, n)
        Process noise in internal units.
    R : array_like, shape (m,)
        Measurement noise variances in internal units.
    source_z : float
        Source height (m) when the state has no ``z`` (no electrodes).
    moment_unit : float
        A·m² per internal moment unit.
    """

    array: SensorArray
    period: float
    Q: np.ndarray
    R: np.ndarray
    source_z: float = 0.0
    moment_unit: float = 1e6
    _d: dict = field(init=False, repr=False)

    def __post_init__(self):
        types = set(self.array.types)
        labels = ["x", "y", "vx", "vy"]
        if "magnetometer" in types:
            labels += ["mx", "my", "mz"]
        if "electrode" in types:
            labels += ["z", "p"]
        n = len(labels)
        x_scale = np.ones(n)
        if "mx" in labels:
            x_scale[labels.index("mx"):labels.index("mx") + 3] = self.moment_unit
        y_scale = np.array([CHANNEL_UNIT[self.array.types[s]] for s in self.array.channel_sensor])
        Q = np.asarray(self.Q, dtype=float)
        R = np.asarray(self.R, dtype=float).reshape(-1)
        if Q.shape != (n, n):
            raise ValueError(f"Q must be ({n}, {n}) for state {labels}, got {Q.shape}")
        if R.shape != (self.array.n_channels,):
            raise ValueError(f"R must have one variance per channel ({self.array.n_channels}), got {R.shape}")
        object.__setattr__(self, "Q", Q)
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "_d", {
            "labels": tuple(labels), "x_scale": x_scale, "y_scale": y_scale,
            "A": cv_transition(self.period, n - 4), "axial": self.array.axial,
            "axial_cols": as_slice(np.flatnonzero(self.array.axial)),
            "mom": labels.index("mx") if "mx" in labels else None,
            "z": labels.index("z") if "z" in labels else None,
        })

    # -- dimensions and constants ---------------------------------------------
    labels = property(lambda self: self._d["labels"], doc="State component names.")
    n = property(lambda self: len(self._d["labels"]), doc="State dimension.")
    m = property(lambda self: self.array.n_channels, doc="Measurement dimension.")
    A = property(lambda self: self._d["A"], doc="Transition matrix (n, n).")
    axial = property(lambda self: self._d["axial"], doc="Boolean (m,): bearing channels.")
    axial_cols = property(lambda self: self._d["axial_cols"],
                          doc="The bearing channels as a slice or indices (None if there are none).")
    x_scale = property(lambda self: self._d["x_scale"], doc="SI value of one internal unit per state component.")
    y_scale = property(lambda self: self._d["y_scale"], doc="SI value of one internal unit per channel.")

    def stepped(self, dt):
        """This model with the transition of time steps ``dt`` (E,) s, one per batch element.

        ``A(dt) = I + (dt / T)(A - I)`` (constant velocity) and ``Q(dt) = (dt / T) Q``: exact for the
        random walks of the parameters and for no process noise, first order in ``dt / T`` for the
        white-acceleration block.  Filters' predictions take it as is (irregular sampling).
        """
        from shipsense.models.transitions import transitions

        dt = np.asarray(dt, dtype=float)
        return Transitioned(self, transitions(self, dt), self.Q * (dt / self.period)[..., None, None], dt)

    def without_process_noise(self) -> FieldModel:
        """The same model with Q = 0: a straight, constant-velocity passage with a constant source."""
        return replace(self, Q=np.zeros_like(self.Q))

    @property
    def state_bounds(self):
        """Physical bounds ``(lo, hi)`` of the internal state (n,) each; infinite where there are none.

        The source depth lies in the water (``-water_depth < z < 0``, with
        :data:`DEPTH_MARGIN` from the surface and the seabed) and the keel
        dipole ``p`` is non-negative (the envelope cannot see its sign).
        ``None`` for a state with no bounded component (no electrodes).
        """
        d = self._d
        if d["z"] is None:
            return None
        lo, hi = np.full(self.n, -np.inf), np.full(self.n, np.inf)
        lo[d["z"]] = -self.array.medium.water_depth + DEPTH_MARGIN
        hi[d["z"]] = -DEPTH_MARGIN
        lo[d["z"] + 1] = 0.0
        return lo, hi

    def state_from_truth(self, truth):
        """This model's state (SI) from simulation truth columns ``x, y, vx, vy, z, mx, my, mz, p`` (..., 9)."""
        cols = {"x": 0, "y": 1, "vx": 2, "vy": 3, "z": 4, "mx": 5, "my": 6, "mz": 7, "p": 8}
        return np.asarray(truth)[..., [cols[c] for c in self.labels]]

    def to_internal(self, x_si):
        return np.asarray(x_si, dtype=float) / self.x_scale

    def to_si(self, x):
        return np.asarray(x) * self.x_scale

    def cov_to_internal(self, P_si):
        """A covariance (..., n, n) in SI units in this model's internal units (``P / (s s^T)``, ``s`` the
        :attr:`x_scale`)."""
        return np.asarray(P_si, dtype=float) / np.outer(self.x_scale, self.x_scale)

    def cov_to_si(self, P):
        """A covariance (or a bound) (..., n, n) in internal units in SI units (``P s s^T``)."""
        return np.asarray(P) * np.outer(self.x_scale, self.x_scale)

    def residual(self, a, b):
        """``a - b`` with bearing channels wrapped modulo pi."""
        d = np.asarray(a) - np.asarray(b)
        cols = self._d["axial_cols"]
        if cols is not None:
            d[..., cols] = wrap_axial(d[..., cols])
        return d

    # -- measurement function ---------------------------------------------------
    def _source(self, x, moment_scale=None, dipole_scale=1.0):
        """Source position (m), moment and dipole of internal states (..., n).

        Moment and dipole are SI unless scales are given: the moment is then
        ``x_m * moment_scale`` and the dipole ``p * dipole_scale`` (times the
        course direction).
        """
        d = self._d
        q = np.empty(x.shape[:-1] + (3,), dtype=x.dtype)
        q[..., 0] = x[..., 0]
        q[..., 1] = x[..., 1]
        q[..., 2] = x[..., d["z"]] if d["z"] is not None else self.source_z
        moment = None
        if d["mom"] is not None:
            moment = x[..., d["mom"]:d["mom"] + 3] * (self.moment_unit if moment_scale is None else moment_scale)
        dipole = None
        if d["z"] is not None:
            v = x[..., 2:4]
            speed = np.sqrt(np.sum(v * v, axis=-1, keepdims=True))
            vhat = v / np.where(speed > 0, speed, 1.0)
            p = x[..., d["z"] + 1, None] * dipole_scale
            dipole = np.concatenate([p * vhat, np.zeros(x.shape[:-1] + (1,))], axis=-1)
        return q, moment, dipole

    def h(self, x):
        """Predicted measurements (internal units), (..., n) -> (..., m).

        Every reading is homogeneous of degree one in the moment and in the
        electric dipole (vector, magnitude and tmi fields; the field and its
        envelope) or independent of them (bearings, in radians already), so
        the channel units are folded into the sources: no pass over the output.
        Real states on the fast HED path run the compiled kernel
        (:func:`shipsense.models.measurement.readings`); complex states and the series HED path the numpy
        kernels.
        """
        from shipsense.models.measurement import readings

        compiled = readings(self, x)
        return compiled if compiled is not None else self._h_numpy(x)

    def _h_numpy(self, x):
        """:meth:`h` through the numpy kernels of :mod:`shipsense.physics` (every sensor type, complex states)."""
        x = np.asarray(x)
        x = x.astype(np.result_type(x, float), copy=False)
        q, moment, dipole = self._source(x, self.moment_unit / CHANNEL_UNIT["magnetometer"],
                                         1.0 / CHANNEL_UNIT["electrode"])
        return self.array.measure(q, moment, dipole)

    def H(self, x):
        """Analytic Jacobian ``dh/dx`` (internal units), (..., n) -> (..., m, n)."""
        return self.h_and_H(x)[1]

    def h_and_H(self, x):
        """``(h(x), H(x))`` from one pass of the kernels (the Jacobian's pass yields the readings too), for
        callers that need both at the same states (least-squares fits).  With the series electric path
        (``electric_method="series"``) the readings are :meth:`h`'s, evaluated apart."""
        from shipsense.models.measurement import h_and_jacobian

        compiled = h_and_jacobian(self, x)     # the filters' compiled kernel (not the series HED path)
        return compiled if compiled is not None else self._h_and_H_numpy(x)

    def kernel_spec(self):
        """The compiled measurement kernel's description of this model (:mod:`shipsense.models.measurement`):
        every sensor type (magnetometers, seismic bearings, electrodes on the fast HED path); None for the
        series HED path (``electric_method="series"``), which only the numpy kernels evaluate."""
        from shipsense.models.measurement import FIELD, sensor_codes
        from shipsense.physics.electric import fast_hed

        a = self.array
        if a.electric_method != "fast" and "electrode" in a.types:
            return None
        code = sensor_codes(a.types, a.kinds)
        width = np.array([len(CHANNELS[(t, k)]) for t, k in zip(a.types, a.kinds)])
        offs = np.concatenate([[0], np.cumsum(width)[:-1]]).astype(np.int64)
        earth = np.zeros(3) if a.earth_direction is None else np.asarray(a.earth_direction, dtype=float)
        d = self._d
        cols = np.array([-1 if d["mom"] is None else d["mom"], -1 if d["z"] is None else d["z"], 1, 1], np.int64)
        hed, table = np.zeros(9), np.zeros((1, 3))
        if "electrode" in a.types:     # the medium's table, grid (ints) and constants (floats), in nV/m
            table, nx, nw, *consts = fast_hed(a.medium).point_parameters(CHANNEL_UNIT["electrode"])
            cols[2:] = nx, nw
            hed = np.array(consts, dtype=float)
        return (FIELD, np.array(a.positions, dtype=float), np.array(a.orientations, dtype=float),
                code, earth, offs, np.zeros((1, 1)), self.moment_unit / CHANNEL_UNIT["magnetometer"],
                float(self.source_z), np.array(a.axial, dtype=np.int64), cols, hed, table)

    def _h_and_H_numpy(self, x):
        """:meth:`h_and_H` through the numpy kernels of :mod:`shipsense.physics` (every sensor type)."""
        x = np.asarray(x, dtype=float)
        d = self._d
        q, moment, dipole = self._source(x)
        val, Jq, Jm, Jp = self.array.measure_jacobian(q, moment, dipole)
        y = val / self.y_scale if self.array.electric_method == "fast" else self.h(x)
        J = np.zeros(x.shape[:-1] + (self.m, self.n))
        J[..., 0:2] = Jq[..., 0:2]
        if d["mom"] is not None:
            J[..., d["mom"]:d["mom"] + 3] = Jm * self.moment_unit
        if d["z"] is not None:
            iz = d["z"]
            J[..., iz] = Jq[..., 2]
            v = x[..., 2:4]
            speed = np.sqrt(np.sum(v * v, axis=-1))
            safe = np.where(speed > 0, speed, 1.0)
            vhat = v / safe[..., None]
            # 2-vector products written out (einsum over a trailing axis of 2 cost more than the kernels' rest)
            ux, uy = vhat[..., 0, None], vhat[..., 1, None]
            px, py = Jp[..., 0], Jp[..., 1]
            J[..., iz + 1] = px * ux + py * uy
            # d(p v/|v|)/dv = p (I - vhat vhat^T) / |v|
            s = (x[..., iz + 1] / safe)[..., None]
            J[..., 2] = s * (px * (1.0 - ux * ux) - py * (ux * uy))
            J[..., 3] = s * (py * (1.0 - uy * uy) - px * (ux * uy))
        return y, J / self.y_scale[:, None]


class Transitioned:
    """A model (a :class:`FieldModel` or a :class:`LinearModel`) with other transitions: ``A`` and ``Q`` per batch
    element (..., n, n) (:meth:`FieldModel.stepped`, the motion modes of an IMM); it measures as ``model``.
    ``tau``: the time steps (...) s the transitions are of, where known (None: the model's period)."""

    def __init__(self, model, A, Q, tau=None):
        self._model, self.A, self.Q, self.tau = model, A, Q, tau

    def __getattr__(self, name):
        return getattr(self._model, name)


@dataclass(frozen=True, eq=False)
class LinearModel:
    """Linear-Gaussian model ``x_k = A x_{k-1} + w``, ``y = C x + v``: the Kalman filter's own case.

    Used to check that every filter reproduces the Kalman filter.
    """

    A: np.ndarray
    Q: np.ndarray
    C: np.ndarray
    R: np.ndarray

    n = property(lambda self: self.A.shape[0])
    m = property(lambda self: self.C.shape[0])
    axial = property(lambda self: np.zeros(self.C.shape[0], dtype=bool))
    axial_cols = None

    def h(self, x):
        return np.asarray(x) @ self.C.T

    def H(self, x):
        return np.broadcast_to(self.C, np.shape(x)[:-1] + self.C.shape)

    def residual(self, a, b):
        return np.asarray(a) - np.asarray(b)

    def kernel_spec(self):
        """The compiled measurement kernel's description of ``y = C x`` (:mod:`shipsense.models.measurement`)."""
        from shipsense.models.measurement import LINEAR

        C = np.array(self.C, dtype=float)
        return (LINEAR, np.zeros((1, 3)), np.zeros((1, 3, 3)), np.zeros(1, np.int64), np.zeros(3),
                np.zeros(1, np.int64), C, 0.0, 0.0, np.zeros(C.shape[0], np.int64), np.array([-1, -1, 1, 1], np.int64),
                np.zeros(9), np.zeros((1, 3)))


def subset_array(array: SensorArray, keep) -> SensorArray:
    """The sensors ``keep`` (indices) of an array, in that order."""
    keep = np.asarray(keep, dtype=int)
    return SensorArray(
        ids=[array.ids[i] for i in keep], types=[array.types[i] for i in keep],
        kinds=[array.kinds[i] for i in keep], positions=array.positions[keep],
        orientations=array.orientations[keep], medium=array.medium, earth_direction=array.earth_direction,
        electric_method=array.electric_method,
    )


def channel_columns(array: SensorArray, keep):
    return np.concatenate([np.flatnonzero(array.channel_sensor == i) for i in keep])


def subset_model(model: FieldModel, keep) -> FieldModel:
    """The model of the sensors ``keep`` (indices) of ``model``'s array (same motion model and units)."""
    keep = np.asarray(keep, dtype=int)
    array = subset_array(model.array, keep)
    types = set(array.types)
    labels = ["x", "y", "vx", "vy"] + ["mx", "my", "mz"] * ("magnetometer" in types)
    labels += ["z", "p"] * ("electrode" in types)
    idx = [model.labels.index(c) for c in labels]       # a fused model's subset keeps its own state's block of Q
    return FieldModel(array, model.period, model.Q[np.ix_(idx, idx)], model.R[channel_columns(model.array, keep)],
                      source_z=model.source_z, moment_unit=model.moment_unit)


MOMENT_WALK = 0.0085
"""Default per-step random walk of the magnetic moment, relative to the scenario's moment magnitude."""


def _process_noise(sc, pn, types, period, moment_unit=1e6):
    """Q of a scenario's process noise in SI units of the state (m, m/s, A·m², m, A·m)."""
    n_params = 3 * ("magnetometer" in types) + 2 * ("electrode" in types)
    if pn.model == "identity":
        return q_identity(n_params, pn.sigma_q)
    if pn.model == "diagonal":
        return np.diag(np.asarray(pn.q_diag, dtype=float)[: 4 + n_params])
    scale = float(np.linalg.norm(sc.passage.moment)) if sc.passage.moment is not None else moment_unit
    if sc.prior is not None and sc.prior.moment is not None:
        scale = float(np.sqrt(sc.prior.moment[0] * sc.prior.moment[1]))
    walk = (MOMENT_WALK * scale) ** 2
    default = [walk] * (3 * ("magnetometer" in types)) + [0.0, 1e-3] * ("electrode" in types)
    param_var = pn.param_var if pn.param_var is not None and len(pn.param_var) == n_params else default
    return q_dwna(period, pn.sigma_a, param_var)


def model_from_scenario(scenario, sensors=None, *, moment_unit=1e6, process_noise=None):
    """The tracker model of a scenario (all sensors, or the ids in ``sensors``).

    Process noise comes from ``[tracker.process_noise]`` (or ``process_noise``,
    a ProcessNoiseConfig), in SI units of the state (m², (m/s)², (A·m²)², m², (A·m)²), and is
    rescaled once here to the model's internal state (moment in ``moment_unit`` A·m²).  Defaults when the scenario has
    no tracker section, or ``param_var`` is not given: DWNA with sigma_a = 1
    m/s² and per-step random walks with standard deviation 0.85 % of the
    moment magnitude (the nominal passage's, or the geometric mean of the
    prior's range when there is one), 0 on z and 1e-3 (A·m)² on p -- the
    setting ``experiments/filter_consistency.py`` found consistent on S0 (docs: Results).
    """
    from shipsense.config import ProcessNoiseConfig, load_scenario

    sc = load_scenario(scenario)
    array = sc.array()
    keep = np.arange(len(array.ids)) if sensors is None else np.array([array.ids.index(s) for s in sensors])
    sub = subset_array(array, keep)
    y_scale = np.array([CHANNEL_UNIT[sub.types[s]] for s in sub.channel_sensor])
    R = (sc.channel_std[channel_columns(array, keep)] / y_scale) ** 2
    pn = process_noise or (sc.tracker.process_noise if sc.tracker is not None else ProcessNoiseConfig())
    Q = _process_noise(sc, pn, set(sub.types), sc.period, moment_unit)
    model = FieldModel(sub, sc.period, Q, R, source_z=sc.passage.z, moment_unit=moment_unit)
    # Q is in SI units of the state; the model's state is scaled (moment in moment_unit A·m²): rescale it once
    return replace(model, Q=Q / np.outer(model.x_scale, model.x_scale))


def candidate_model(scenario, positions, template: int = 0) -> FieldModel:
    """A model whose sensors are copies of the scenario's sensor ``template`` at ``positions`` (N, 3).

    Used by placement: one candidate per sensor, so per-sensor Fisher
    information is per-candidate information.
    """
    from shipsense.config import load_scenario

    sc = load_scenario(scenario)
    base = model_from_scenario(sc, sensors=[sc.sensors[template].id])
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    N = len(positions)
    a = base.array
    array = SensorArray(ids=[f"C{i}" for i in range(N)], types=[a.types[0]] * N, kinds=[a.kinds[0]] * N,
                        positions=positions, orientations=np.repeat(a.orientations[:1], N, axis=0),
                        medium=a.medium, earth_direction=a.earth_direction)
    return FieldModel(array, base.period, base.Q, np.tile(base.R, N), source_z=base.source_z,
                      moment_unit=base.moment_unit)
