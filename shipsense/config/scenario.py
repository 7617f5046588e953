"""A scenario: the array of sensors, the medium, the nominal passage and its prior, the traffic (the
``[traffic]`` table, :mod:`shipsense.config.traffic`), the noise, the signal chains and the tracker (the
``[tracker]`` table, :mod:`shipsense.config.tracker`), and its TOML form."""

from __future__ import annotations

import json
import math
from typing import Annotated, Literal

import numpy as np
from pydantic import (
    Field,
    ValidationError,
    model_validator,
)

from shipsense.config.fields import (
    Conductivity,
    ConfigModel,
    Coord2,
    Coord3,
    Finite,
    Moment3,
    Positive,
    PositiveRange,
    Range,
    ScenarioError,
    Speed2,
    Std,
    Var,
    Vec3,
    check_source_plane,
    format_error,
    within,
)
from shipsense.config.manoeuvres import ManoeuvreConfig, check_manoeuvres
from shipsense.config.tracker import TrackerConfig
from shipsense.config.traffic import TrafficConfig, check_traffic
from shipsense.physics.array import CHANNELS, KINDS, SensorArray
from shipsense.physics.electric import CONDUCTIVITY_RATIO, Medium
from shipsense.physics.magnetic import earth_field_direction

MIN_SENSOR_SPACING = 0.01
"""Sensors closer than this (m) are taken to coincide."""
MIN_SOURCE_DISTANCE = 1.0
"""A passage may not come closer than this (m) to a sensor: the point-dipole fields are singular there."""


class SensorConfig(ConfigModel):
    """One seabed sensor.

    Measurement kinds (``kind``; :data:`shipsense.physics.array.KINDS`), with their components:

    * magnetometer: ``vector`` (``R^T B``, 3), ``magnitude`` (``|B|``, 1), ``tmi`` (``B . b_E``, 1);
    * electrode: ``vector`` (``R^T E``, signed, 3), ``envelope`` (``(|E_x|, |E_y|, |E_z|)``, the shaft-rate
      envelope of each channel, 3), ``magnitude`` (``|E|``, the envelope of the field's magnitude, 1;
      independent of ``orientation``);
    * accelerometer: ``bearing`` (axial, rad, 1).

    ``noise_std`` / ``noise_var`` lists have one value per component.
    """

    id: str = Field(min_length=1, description="Unique sensor name.")
    type: Literal["magnetometer", "electrode", "accelerometer"]
    kind: str = Field(description="Measurement kind: magnetometer vector | magnitude | tmi; electrode vector | "
                                  "envelope | magnitude; accelerometer bearing (shipsense.physics.array.KINDS).")
    position: Coord3 = Field(description="World position (x east, y north, z up; z = 0 at the surface), m.")
    noise_std: Std | list[Std] | None = Field(
        default=None, description="Per-component noise std, SI units (T, V/m, rad); scalar or one per component.")
    noise_var: Var | list[Var] | None = Field(
        default=None, description="Per-component noise variance, SI units squared (alternative to noise_std).")
    orientation: tuple[Vec3, Vec3, Vec3] | None = Field(
        default=None, description="Rotation matrix whose columns are the sensor axes in world coordinates.")

    @model_validator(mode="after")
    def _check(self):
        if self.kind not in KINDS[self.type]:
            raise ValueError(f"kind: unknown measurement kind {self.kind!r} for a {self.type} "
                             f"(expected one of: {', '.join(KINDS[self.type])})")
        if (self.noise_std is None) == (self.noise_var is None):
            raise ValueError("give exactly one of noise_std or noise_var")
        n = len(CHANNELS[(self.type, self.kind)])
        given = self.noise_std if self.noise_std is not None else self.noise_var
        if isinstance(given, list) and len(given) != n:
            name = "noise_std" if self.noise_std is not None else "noise_var"
            raise ValueError(f"{name}: a {self.kind} {self.type} has {n} components, got {len(given)} values")
        if self.orientation is not None:
            R = np.array(self.orientation)
            if not (np.allclose(R.T @ R, np.eye(3), atol=1e-6) and np.linalg.det(R) > 0):
                raise ValueError("orientation: must be a rotation matrix (orthonormal, det +1)")
        return self

    @property
    def channel_std(self) -> tuple[float, ...]:
        """Noise standard deviation of each component (SI)."""
        n = len(CHANNELS[(self.type, self.kind)])
        if self.noise_std is not None:
            v = self.noise_std if isinstance(self.noise_std, list) else [self.noise_std] * n
            return tuple(float(x) for x in v)
        v = self.noise_var if isinstance(self.noise_var, list) else [self.noise_var] * n
        return tuple(math.sqrt(x) for x in v)


class MediumConfig(ConfigModel):
    """Sea water of conductivity ``sigma_water`` (S/m) and depth ``water_depth`` (m) over a seabed half-space of
    conductivity ``sigma_seabed`` (S/m), under insulating air (:class:`shipsense.physics.electric.Medium`)."""

    sigma_water: Conductivity = 4.0
    sigma_seabed: Conductivity = 0.04
    water_depth: Annotated[Positive, within(11_000.0, "m")] = 15.0

    @model_validator(mode="after")
    def _check(self):
        lo, hi = CONDUCTIVITY_RATIO
        ratio = self.sigma_seabed / self.sigma_water
        if not lo <= ratio <= hi:
            raise ValueError(f"sigma_seabed: the seabed-to-water conductivity ratio must be within [{lo:g}, {hi:g}] "
                             f"(the image series' range: shipsense.physics.electric.CONDUCTIVITY_RATIO), got "
                             f"{self.sigma_seabed:g} / {self.sigma_water:g} = {ratio:.3g}")
        return self

    def physics(self) -> Medium:
        return Medium(self.sigma_water, self.sigma_seabed, self.water_depth)


class EarthConfig(ConfigModel):
    """Direction of the Earth's field, for ``tmi`` magnetometers."""

    inclination_deg: Annotated[Finite, Field(ge=-90, le=90)] = 60.0
    declination_deg: Annotated[Finite, Field(ge=-180, le=360)] = 0.0


class PassageConfig(ConfigModel):
    """The nominal passage: a straight, constant-velocity track."""

    start: Coord2 = Field(description="Source (x, y) at t = 0, m.")
    velocity: Speed2 = Field(description="(v_x, v_y), m/s.")
    z: Annotated[Finite, Field(le=0), within(11_000.0, "m")] = Field(
        0.0, description="Source height (world z, <= 0), m.")
    moment: Moment3 | None = Field(None, description="Magnetic moment, A·m² (needed by magnetometers).")
    p: Annotated[Positive, within(1e9, "A·m")] | None = Field(
        None, description="Electric dipole moment along the keel, A·m (needed by electrodes).")


class PriorConfig(ConfigModel):
    """A prior over random passages past the array (used with ``random=True``).

    The start is drawn at a range and bearing from the array centroid; the
    course is the heading towards the centroid plus an offset; the moment
    magnitude (and ``p``) is log-uniform, the moment direction uniform.
    """

    range: Annotated[PositiveRange, within(1e6, "m")] = (150.0, 400.0)
    bearing_deg: Annotated[Range, within(720.0, "deg")] = (0.0, 360.0)
    course_offset_deg: Annotated[Range, within(180.0, "deg")] = (-20.0, 20.0)
    cpa: Annotated[Range, within(1e6, "m")] | None = Field(
        None, description="If given, the course is set so that the closest approach to the centroid is uniform "
        "in this range (m), instead of course_offset_deg.")
    speed: Annotated[PositiveRange, within(100.0, "m/s")] = (3.0, 10.0)
    moment: Annotated[PositiveRange, within(1e12, "A·m²")] | None = None
    p: Annotated[PositiveRange, within(1e9, "A·m")] | None = None


class NoiseConfig(ConfigModel):
    """Measurement noise model (:mod:`shipsense.physics.noise`).

    ``gaussian``: ``N(0, R)`` per component; ``contaminated`` (outliers): ``(1 - eps) N(0, R) + eps N(0,
    outlier_scale^2 R)`` (Huber 1964).  Either way each component is missing with probability ``dropout``.
    """

    model: Literal["gaussian", "contaminated"] = "gaussian"
    eps: Annotated[Finite, Field(ge=0, lt=1)] = 0.1
    outlier_scale: Positive = 10.0
    dropout: Annotated[Finite, Field(ge=0, lt=1)] = 0.0


class EnvelopeChainConfig(ConfigModel):
    """How electrode envelopes (``envelope`` and ``magnitude`` kinds) are made: ideal ``|E| + noise``, or the raw
    shaft-rate chain."""

    mode: Literal["ideal", "raw"] = "ideal"
    raw_rate_hz: Positive = 100.0
    shaft_hz: Positive = 3.0
    lowpass_hz: Positive = 0.5
    raw_noise_std: Annotated[Finite, Field(ge=0)] = 1e-7
    pad_s: Annotated[Finite, Field(ge=0)] = 10.0

    @model_validator(mode="after")
    def _check(self):
        if not self.shaft_hz < self.raw_rate_hz / 2:
            raise ValueError(f"shaft_hz: must be below the Nyquist rate raw_rate_hz/2 = {self.raw_rate_hz / 2:g}")
        if not self.lowpass_hz < self.shaft_hz:
            raise ValueError("lowpass_hz: must be below shaft_hz")
        return self


class SeismicConfig(ConfigModel):
    """Bearing from accelerometers: the shortcut (bearing + error) or the eigenvector chain."""

    mode: Literal["shortcut", "chain"] = "shortcut"
    bias_deg: Finite = 0.0
    sample_rate_hz: Positive = 200.0
    amplitude: Positive = 1.0
    range_ref: Positive = 100.0
    range_exponent: Annotated[Finite, Field(ge=0)] = 1.0
    sensor_noise: Annotated[Finite, Field(ge=0)] = 0.05
    multipath_gain: Annotated[Finite, Field(ge=0)] = 0.0
    multipath_bias_deg: Finite = 0.0
    noise_dof: Annotated[Finite, Field(gt=2)] | None = None


class Scenario(ConfigModel):
    """A complete scenario: array, medium, passage, traffic, noise, chains, tracker."""

    name: str = "scenario"
    description: str = ""
    period: Annotated[Positive, within(3600.0, "s")] = Field(description="Tracker period T, s.")
    steps: Annotated[int, Field(ge=2, le=1_000_000)]
    runs: Annotated[int, Field(ge=1, le=1_000_000)] = 1
    seed: Annotated[int, Field(ge=0, le=2**63 - 1)] = 0
    sensors: list[SensorConfig] = Field(min_length=1)
    medium: MediumConfig | None = None
    earth: EarthConfig = EarthConfig()
    passage: PassageConfig
    prior: PriorConfig | None = None
    manoeuvres: ManoeuvreConfig | None = None
    traffic: TrafficConfig | None = None
    noise: NoiseConfig = NoiseConfig()
    envelope_chain: EnvelopeChainConfig = EnvelopeChainConfig()
    seismic: SeismicConfig = SeismicConfig()
    tracker: TrackerConfig | None = None

    @model_validator(mode="after")
    def _check(self):
        ids = [s.id for s in self.sensors]
        for i, sid in enumerate(ids):
            if sid in ids[:i]:
                raise ValueError(f"sensors[{i}].id: duplicate sensor id {sid!r}")
        pos = np.array([s.position for s in self.sensors])
        d = np.linalg.norm(pos[:, None, :] - pos[None, :, :], axis=-1)
        for i in range(len(ids)):
            for j in range(i):
                # a node may carry sensors of different types at one point
                if d[i, j] < MIN_SENSOR_SPACING and self.sensors[i].type == self.sensors[j].type:
                    raise ValueError(f"sensors[{i}].position: {self.sensors[i].type} {ids[i]!r} coincides with "
                                     f"{ids[j]!r} at {list(pos[i])} (closer than {MIN_SENSOR_SPACING} m)")
        types = {s.type for s in self.sensors}
        depth = self.medium.water_depth if self.medium is not None else math.inf
        for i, s in enumerate(self.sensors):
            z = s.position[2]
            if z > 0 or z < -depth:
                where = ("above the sea surface (z > 0)" if z > 0 else
                         f"below the seabed (z < -{depth:g}, the medium's water_depth)")
                raise ValueError(f"sensors[{i}].position: sensor {s.id!r} is outside the water: {where}")
        if "electrode" in types and self.medium is None:
            raise ValueError("medium: electrode sensors need a [medium] section")
        zt = self.passage.z
        if zt < -depth:
            raise ValueError(f"passage.z: the source is below the seabed (z < -{depth:g}, the medium's water_depth)")
        if "electrode" in types and not -depth < zt < 0:
            raise ValueError(f"passage.z: an electric source must be strictly inside the water (-{depth:g} < z < 0; "
                             "the medium's water_depth)")
        if "magnetometer" in types and self.passage.moment is None:
            raise ValueError("passage.moment: magnetometers need the source's magnetic moment [mx, my, mz]")
        if "electrode" in types and self.passage.p is None:
            raise ValueError("passage.p: electrode sensors need the source's dipole moment p (A·m)")
        if math.hypot(*self.passage.velocity) == 0 and "electrode" in types:
            raise ValueError("passage.velocity: the electric dipole lies along the keel, so the speed must be > 0")
        # closest approach of the nominal passage to every sensor (a manoeuvring one: check_manoeuvres)
        start = np.array([*self.passage.start, zt])
        vel = np.array([*self.passage.velocity, 0.0])
        duration = self.period * (self.steps - 1)
        vv = vel @ vel
        for s in self.sensors if self.manoeuvres is None or not self.manoeuvres.scheduled else ():
            rel = np.array(s.position) - start
            t = 0.0 if vv == 0 else float(np.clip(rel @ vel / vv, 0.0, duration))
            gap = np.linalg.norm(rel - t * vel)
            if gap < MIN_SOURCE_DISTANCE:
                raise ValueError(f"passage: the source passes {gap:.3g} m from sensor {s.id!r} (closer than "
                                 f"{MIN_SOURCE_DISTANCE} m: the source would be inside the sensor)")
        if self.prior is not None:
            check_source_plane(self.sensors, zt, MIN_SOURCE_DISTANCE, "prior", "random passages")
            if "magnetometer" in types and self.prior.moment is None:
                raise ValueError("prior.moment: magnetometers need a moment magnitude range [min, max]")
            if "electrode" in types and self.prior.p is None:
                raise ValueError("prior.p: electrode sensors need a dipole moment range [min, max]")
        if self.manoeuvres is not None:
            check_manoeuvres(self, MIN_SOURCE_DISTANCE)
        if self.traffic is not None:
            check_traffic(self, MIN_SOURCE_DISTANCE)
        if self.tracker is not None:
            pn = self.tracker.process_noise
            n = self.n_params
            if pn.param_var is not None and len(pn.param_var) != n:
                raise ValueError(f"tracker.process_noise.param_var: the state has {n} parameters, "
                                 f"got {len(pn.param_var)} values")
            if pn.model == "diagonal" and (pn.q_diag is None or len(pn.q_diag) != 4 + n):
                raise ValueError(f"tracker.process_noise.q_diag: the diagonal model needs {4 + n} values "
                                 f"(x, y, vx, vy and {n} parameters)")
        return self

    # -- derived -----------------------------------------------------------
    @property
    def times(self) -> np.ndarray:
        """Sample times ``k T``, k = 0..steps-1, s."""
        return self.period * np.arange(self.steps)

    @property
    def sensor_types(self) -> set[str]:
        return {s.type for s in self.sensors}

    @property
    def n_params(self) -> int:
        """Parameters after (x, y, vx, vy) in the tracker state: moment (3) and/or (z, p) (2)."""
        types = self.sensor_types
        return 3 * ("magnetometer" in types) + 2 * ("electrode" in types)

    def array(self, electric_method: str = "fast") -> SensorArray:
        """The physics-level :class:`~shipsense.physics.array.SensorArray` of this scenario."""
        return SensorArray(
            ids=[s.id for s in self.sensors],
            types=[s.type for s in self.sensors],
            kinds=[s.kind for s in self.sensors],
            positions=np.array([s.position for s in self.sensors], dtype=float),
            orientations=np.array([s.orientation if s.orientation is not None else np.eye(3)
                                   for s in self.sensors], dtype=float),
            medium=self.medium.physics() if self.medium is not None else None,
            earth_direction=earth_field_direction(self.earth.inclination_deg, self.earth.declination_deg),
            electric_method=electric_method,
        )

    @property
    def channel_std(self) -> np.ndarray:
        """Noise standard deviation of every channel, in the array's channel order, shape (m,)."""
        return np.array([v for s in self.sensors for v in s.channel_std])

    def with_updates(self, **changes) -> Scenario:
        """A validated copy with top-level fields replaced (e.g. ``runs=10``)."""
        return validate_scenario({**self.model_dump(), **changes}, source=f"scenario {self.name!r}")


def to_toml(scenario: Scenario) -> str:
    """The scenario as a TOML document that :func:`load_scenario` reads back to an equal scenario."""
    import json

    data = scenario.model_dump(mode="json", exclude_none=True)

    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, (int, float)):
            return repr(v)
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        raise TypeError(f"cannot write {type(v).__name__} to TOML")

    lines = []

    def table(name, d, array=False):
        if name:
            lines.append("")
            lines.append(f"[[{name}]]" if array else f"[{name}]")
        subs = []
        for k, v in d.items():
            if isinstance(v, dict):
                subs.append((k, v, False))
            elif isinstance(v, list) and v and isinstance(v[0], dict):
                subs.append((k, v, True))
            else:
                lines.append(f"{k} = {value(v)}")
        for k, v, is_array in subs:
            full = f"{name}.{k}" if name else k
            if is_array:
                for item in v:
                    table(full, item, array=True)
            else:
                table(full, v)

    table("", data)
    return "\n".join(lines) + "\n"


def validate_scenario(data: dict, source: str, strict: bool = False) -> Scenario:
    """A validated scenario from ``data``; ``strict`` (a TOML file, whose values carry their own types): no
    coercion -- a string is not a number, a boolean not a count, a float not an integer."""
    try:
        if strict:
            try:
                text = json.dumps(data, allow_nan=True)
            except TypeError as err:   # a TOML date or time: no scenario value is one
                raise ScenarioError(f"{source}: a value of an unsupported type ({err})") from None
            return Scenario.model_validate_json(text, strict=True)
        return Scenario.model_validate(data)
    except ValidationError as err:
        raise ScenarioError(format_error(err, source)) from None
