"""Typed, validated scenario configuration (pydantic v2, loaded from TOML).

A scenario file describes an array of seabed sensors, the medium, a nominal
ship passage, optionally a prior over random passages, the noise model, the
signal chains and the tracker.  Everything is checked once, here; the physics
kernels below trust their inputs.  A bad file raises :class:`ScenarioError`
with one message that names the field and the reason.

Units are SI throughout (m, s, T, V/m, A·m², A·m, S/m, rad) except where a
field name ends in ``_deg`` or ``_hz``.  The file format is documented in
the docs: "Scenario files" (the guide) and the scenario reference generated
from these models.
"""

from __future__ import annotations

import json
import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    Strict,
    ValidationError,
    model_validator,
)

from shipsense.defaults import HUBER_GAMMA, N_PU
from shipsense.errors import ShipsenseError
from shipsense.physics.array import CHANNELS, KINDS, SensorArray
from shipsense.physics.electric import Medium
from shipsense.physics.magnetic import earth_field_direction

__all__ = ["Scenario", "ScenarioError", "load_scenario", "shipped_scenarios"]

MIN_SENSOR_SPACING = 0.01
"""Sensors closer than this (m) are taken to coincide."""
MIN_SOURCE_DISTANCE = 1.0
"""A passage may not come closer than this (m) to a sensor: the point-dipole fields are singular there."""


class ScenarioError(ShipsenseError):
    """A scenario file or value is invalid; the message names the field and the reason."""


def _finite(x: float) -> float:
    if not math.isfinite(x):
        raise ValueError(f"must be a finite number, got {x}")
    return x


def _positive(x: float) -> float:
    if not x > 0:
        raise ValueError(f"must be > 0, got {x}")
    return x


def _range(r: tuple[float, float]) -> tuple[float, float]:
    if r[0] > r[1]:
        raise ValueError(f"must be [min, max] with min <= max, got {list(r)}")
    return r


Finite = Annotated[float, AfterValidator(_finite)]
Positive = Annotated[float, AfterValidator(_finite), AfterValidator(_positive)]
Vec2 = tuple[Finite, Finite]
Vec3 = tuple[Finite, Finite, Finite]


def _within(limit, unit):
    """A validator: every component's magnitude at most ``limit`` (a physical range, stated in the message)."""
    def check(v):
        values = v if isinstance(v, (tuple, list)) else (v,)
        if any(abs(x) > limit for x in values):
            raise ValueError(f"outside the physical range: at most {limit:g} {unit} in magnitude, got {v!r}")
        return v
    return AfterValidator(check)


Coord2 = Annotated[Vec2, _within(1e6, "m")]
Coord3 = Annotated[Vec3, _within(1e6, "m")]
Speed2 = Annotated[Vec2, _within(100.0, "m/s")]
Moment3 = Annotated[Vec3, _within(1e12, "A·m²")]
Std = Annotated[Positive, _within(1e3, "(SI)")]
Var = Annotated[Positive, _within(1e6, "(SI²)")]
Conductivity = Annotated[Positive, _within(100.0, "S/m")]
Range = Annotated[tuple[Finite, Finite], AfterValidator(_range)]
PositiveRange = Annotated[tuple[Positive, Positive], AfterValidator(_range)]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class SensorConfig(_Model):
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


class MediumConfig(_Model):
    """Sea water of conductivity ``sigma_water`` (S/m) and depth ``water_depth`` (m) over a seabed half-space of
    conductivity ``sigma_seabed`` (S/m), under insulating air (:class:`shipsense.physics.electric.Medium`)."""

    sigma_water: Conductivity = 4.0
    sigma_seabed: Conductivity = 0.04
    water_depth: Annotated[Positive, _within(11_000.0, "m")] = 15.0

    def physics(self) -> Medium:
        return Medium(self.sigma_water, self.sigma_seabed, self.water_depth)


class EarthConfig(_Model):
    """Direction of the Earth's field, for ``tmi`` magnetometers."""

    inclination_deg: Annotated[Finite, Field(ge=-90, le=90)] = 60.0
    declination_deg: Annotated[Finite, Field(ge=-180, le=360)] = 0.0


class PassageConfig(_Model):
    """The nominal passage: a straight, constant-velocity track."""

    start: Coord2 = Field(description="Source (x, y) at t = 0, m.")
    velocity: Speed2 = Field(description="(v_x, v_y), m/s.")
    z: Annotated[Finite, Field(le=0), _within(11_000.0, "m")] = Field(
        0.0, description="Source height (world z, <= 0), m.")
    moment: Moment3 | None = Field(None, description="Magnetic moment, A·m² (needed by magnetometers).")
    p: Annotated[Positive, _within(1e9, "A·m")] | None = Field(
        None, description="Electric dipole moment along the keel, A·m (needed by electrodes).")


class PriorConfig(_Model):
    """A prior over random passages past the array (used with ``random=True``).

    The start is drawn at a range and bearing from the array centroid; the
    course is the heading towards the centroid plus an offset; the moment
    magnitude (and ``p``) is log-uniform, the moment direction uniform.
    """

    range: PositiveRange = (150.0, 400.0)
    bearing_deg: Range = (0.0, 360.0)
    course_offset_deg: Range = (-20.0, 20.0)
    cpa: Range | None = Field(None, description="If given, the course is set so that the closest approach to "
                              "the centroid is uniform in this range (m), instead of course_offset_deg.")
    speed: PositiveRange = (3.0, 10.0)
    moment: PositiveRange | None = None
    p: PositiveRange | None = None


class NoiseConfig(_Model):
    """Measurement noise model (:mod:`shipsense.physics.noise`).

    ``gaussian``: ``N(0, R)`` per component; ``contaminated`` (outliers): ``(1 - eps) N(0, R) + eps N(0,
    outlier_scale^2 R)`` (Huber 1964).  Either way each component is missing with probability ``dropout``.
    """

    model: Literal["gaussian", "contaminated"] = "gaussian"
    eps: Annotated[Finite, Field(ge=0, lt=1)] = 0.1
    outlier_scale: Positive = 10.0
    dropout: Annotated[Finite, Field(ge=0, lt=1)] = 0.0


class EnvelopeChainConfig(_Model):
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


class SeismicConfig(_Model):
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


class ProcessNoiseConfig(_Model):
    """Process noise of the tracker's constant-velocity motion model (:mod:`shipsense.physics.motion`), in **SI
    units of the state**.

    ``identity``: ``sigma_q I``; ``dwna``: white acceleration ``sigma_a`` (m/s²) plus a per-step
    random-walk variance ``param_var`` on each parameter (moment in (A·m²)², z in m², p in
    (A·m)²); ``diagonal``: ``diag(q_diag)`` (m², (m/s)², then the parameters as for ``param_var``).
    A model that scales its state (the trackers keep the moment in 1e6 A·m²) rescales Q with it:
    ``sigma_q = 0.1`` is 0.1 (A·m²)² on the moment, 1e-13 in (1e6 A·m²)².  The defaults (DWNA,
    sigma_a = 1 m/s², a moment walk of 0.85 % of the scenario's moment magnitude per step) are the
    setting ``experiments/filter_consistency.py`` found consistent on S0 (docs: Results), made relative
    so that it transfers to ships of other sizes.
    """

    model: Literal["identity", "dwna", "diagonal"] = "dwna"
    sigma_q: Positive = 0.1
    q_diag: list[Annotated[Finite, Field(ge=0)]] | None = None
    sigma_a: tuple[Positive, Positive] = (1.0, 1.0)
    param_var: list[Annotated[Finite, Field(ge=0)]] | None = None


class BankConfig(_Model):
    """Multiple-initial-value bank: K moment (or p) levels times l bearings, run side by side, the hypothesis
    of largest cumulative innovation log-likelihood selected (the source studies' method).

    Seeds are placed at the range implied by the first measured field for each
    level, on each bearing, around the sensor that measured the strongest
    field.  Every hypothesis starts with ``initial_velocity``, a zero moment
    (magnetic) or ``p`` = its level (electric), and the initial standard
    deviations below.
    """

    levels: list[Positive] = Field(min_length=1, description="Moment magnitudes (A·m²) or p levels (A·m).")
    bearings_deg: list[Finite] = Field(min_length=1)
    bearing_convention: Literal["east", "north"] = Field(
        "east", description="east: bearings counter-clockwise from +x, seed = (r cos phi, r sin phi); north: "
        "clockwise from north (+y), seed = (r sin phi, r cos phi) (the magnetic source study's S0 bank).")
    initial_velocity: Vec2 = (6.0, 6.0)
    initial_course: Literal["fixed", "towards_array"] = Field(
        "fixed", description="fixed: every hypothesis gets initial_velocity; towards_array: the speed "
        "|initial_velocity| on the course from the seed towards the array centroid (a passing ship).")
    position_std: Positive = 30.0
    velocity_std: Positive = 2.0
    moment_std: Positive = 1e8
    z_std: Positive = 1.0
    p_std: Positive = 50.0
    p_initial: Positive = Field(100.0, description="Initial p (A·m) when the levels are magnetic (fused model).")
    range_correction: Positive = Field(2.0, description="Image correction c of the electric range formula.")
    prune_nats: Positive | None = Field(None, description="Drop hypotheses this far below the best (None: keep all).")
    ambiguity_nats: Positive = Field(3.0, description="Near-tie threshold on the normalised log-likelihood.")
    ambiguity_distance: Positive = Field(20.0, description="Near-ties farther apart than this (m) are ambiguous.")
    divergence_window: Annotated[int, Field(ge=2)] = 10

    def state_std(self, labels):
        """The hypotheses' initial standard deviations (SI) of the state components named ``labels``."""
        std = {"x": self.position_std, "y": self.position_std, "vx": self.velocity_std, "vy": self.velocity_std,
               "mx": self.moment_std, "my": self.moment_std, "mz": self.moment_std, "z": self.z_std,
               "p": self.p_std}
        return np.array([std[c] for c in labels])


FILTERS = ("ekf", "ukf", "ckf", "cdkf", "srcdkf", "puekf", "huber_ukf")
"""The filter units (:mod:`shipsense.trackers.filters`)."""
Fraction = Annotated[Finite, Field(gt=0, lt=1)]
Count = Annotated[int, Strict(), Field(ge=1, le=1_000_000)]
Flag = Annotated[bool, Strict()]


def _stages(v):
    """Refinement stages as a tuple: one stage given as a whole number, or a list (a TOML array)."""
    if isinstance(v, int) and not isinstance(v, bool):
        return (v,)
    return tuple(v) if isinstance(v, list) else v


class TrackerOptions(_Model):
    """Options of the project's tracker (:class:`shipsense.trackers.Tracker`), the ``[tracker]`` table's
    own keys.  ``None`` on ``unit``, ``robust``, ``gap_limit_s`` and the initialiser's settings (``window_s``,
    ``snr_start``, ``refine``, ``explore_samples``, ``grid_samples``, ``z_std``, ``rescan``) means the default
    for the scenario and the array's family (resolved once, by
    :func:`shipsense.trackers.tracker.settings.resolve_settings`); on ``refit_every``, ``through_peak``,
    ``collapse`` and ``consistency_window`` it turns that restart rule or alarm off."""

    method: Literal["tracker", "bank"] = Field(
        "tracker", description="tracker: the project's tracker; bank: the source studies' bank of hypotheses "
        "seeded from the first sample (the scenario's filter, process noise and [tracker.bank]).")
    unit: Literal[FILTERS] | None = Field(
        None, description="The tracker's filter unit (default: ukf, huber_ukf when robust; with method = "
        "'bank': the scenario's filter).")
    robust: Flag | None = Field(None, description="Huber updates and robust refits (default: on when the "
                                "scenario's noise model is 'contaminated').")
    huber_gamma: Annotated[Positive, _within(100.0, "")] = Field(
        HUBER_GAMMA, description="Huber threshold on a whitened residual (robust updates and fits).")
    window_s: Annotated[Positive, _within(3600.0, "s")] | None = Field(
        None, description="Length of the initialisation window after the detection, s.")
    snr_start: Annotated[Positive, _within(1e9, "")] | None = Field(
        None, description="Detection: the strongest field channel's signal-to-noise ratio that starts a window.")
    refine: Annotated[tuple[Count, ...], BeforeValidator(_stages), Field(min_length=1)] | None = Field(
        None, description="Grid minima refined per stage (later stages only for passages whose fit fails).")
    explore_samples: Count | None = Field(
        None, description="Samples of the window the refinement explores on first (None: all).")
    grid_samples: Count | None = Field(None, description="Samples of the window the grid search uses.")
    z_std: Annotated[Positive, _within(1e3, "m")] | None = Field(
        None, description="Prior standard deviation of the source depth in the fits, m (None: no prior).")
    keep_init: Annotated[int, Strict(), Field(ge=1, le=64)] = Field(5, description="Hypotheses a bank starts with.")
    keep: Annotated[int, Strict(), Field(ge=1, le=64)] = Field(3, description="Distinct fits a refit keeps.")
    refit_every: Count | None = Field(20, description="Refit every this many samples until the closest "
                                      "approach (None: never).")
    through_peak: Fraction | None = Field(0.5, description="Refit once when the signal has fallen to this "
                                          "fraction of its peak (None: never).")
    nis_window: Annotated[int, Strict(), Field(ge=1, le=10_000)] = Field(
        10, description="Samples of the divergence alarm's NIS window.")
    nis_limit: Annotated[Positive, _within(1e6, "")] = Field(
        3.0, description="Mean (median when robust) normalised NIS above which the bank has diverged.")
    max_restarts: Annotated[int, Strict(), Field(ge=0, le=1_000_000)] = Field(
        4, description="Alarms a passage may restart from.")
    collapse: Annotated[Finite, Field(gt=0, le=1)] | None = Field(
        0.25, description="Refit when the position covariance has shrunk below this fraction of the start's "
        "without the innovations agreeing (None: never).")
    ambiguity_nats: Positive = Field(10.0, description="Hypotheses within this many nats of the best "
                                     "restart a refit.")
    report_nats: Positive = Field(3.0, description="Near-ties within this many nats are reported ambiguous.")
    report_distance_m: Annotated[Positive, _within(1e6, "m")] = Field(
        20.0, description="... when farther apart than this, m.")
    distinct_m: Annotated[Positive, _within(1e6, "m")] = Field(
        15.0, description="Fits closer than this (m) are one.")
    gof: Fraction = Field(0.01, description="Level of the fits' chi-square goodness-of-fit test.")
    inflate: Annotated[Positive, _within(1e6, "")] = Field(
        2.0, description="Inflation of a window fit's covariance when a bank starts from it.")
    history: Annotated[int, Strict(), Field(ge=2, le=1_000_000)] = Field(
        1000, description="Samples a refit may use (the cost per sample is bounded).")
    gap_limit_s: Annotated[Positive, _within(1e9, "s")] | None = Field(
        None, description="A gap between samples longer than this (s) is reported (default: 10 periods).")
    consistency_window: Annotated[int, Strict(), Field(ge=2, le=1_000_000)] | None = Field(
        20, description="Samples of the windowed innovation consistency test (None: off).")
    consistency_level: Fraction = Field(0.01, description="Level of the consistency test.")
    rescan: Flag | None = Field(None, description="Rerun the global initialiser on the schedule until the "
                                "closest approach (default: one magnetometer).")

    @model_validator(mode="after")
    def _check_options(self):
        if self.keep > self.keep_init:
            raise ValueError(f"keep: cannot exceed keep_init ({self.keep_init}), got {self.keep}")
        if self.refine is not None and any(b <= a for a, b in zip(self.refine, self.refine[1:])):
            raise ValueError(f"refine: the stages' counts must increase, got {list(self.refine)}")
        return self


class TrackerConfig(TrackerOptions):
    """The ``[tracker]`` table: the options of the project's tracker (:class:`TrackerOptions`) and the source
    studies' filter, process noise and bank (``method = "bank"``, ``shipsense track --method bank``)."""

    filter: Literal[FILTERS] = Field("ukf", description="The source studies' filter unit.")
    n_pu: Annotated[int, Strict(), Field(ge=1, le=1000)] = Field(N_PU, description="PU-EKF sub-updates.")
    process_noise: ProcessNoiseConfig = ProcessNoiseConfig()
    bank: BankConfig | None = None


class Scenario(_Model):
    """A complete scenario: array, medium, passage, noise, chains, tracker."""

    name: str = "scenario"
    description: str = ""
    period: Annotated[Positive, _within(3600.0, "s")] = Field(description="Tracker period T, s.")
    steps: Annotated[int, Field(ge=2, le=1_000_000)]
    runs: Annotated[int, Field(ge=1, le=1_000_000)] = 1
    seed: Annotated[int, Field(ge=0, le=2**63 - 1)] = 0
    sensors: list[SensorConfig] = Field(min_length=1)
    medium: MediumConfig | None = None
    earth: EarthConfig = EarthConfig()
    passage: PassageConfig
    prior: PriorConfig | None = None
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
        # closest approach of the nominal passage to every sensor
        start = np.array([*self.passage.start, zt])
        vel = np.array([*self.passage.velocity, 0.0])
        duration = self.period * (self.steps - 1)
        vv = vel @ vel
        for s in self.sensors:
            rel = np.array(s.position) - start
            t = 0.0 if vv == 0 else float(np.clip(rel @ vel / vv, 0.0, duration))
            gap = np.linalg.norm(rel - t * vel)
            if gap < MIN_SOURCE_DISTANCE:
                raise ValueError(f"passage: the source passes {gap:.3g} m from sensor {s.id!r} (closer than "
                                 f"{MIN_SOURCE_DISTANCE} m: the source would be inside the sensor)")
        if self.prior is not None:
            for s in self.sensors:
                if abs(s.position[2] - zt) < MIN_SOURCE_DISTANCE:
                    raise ValueError(f"prior: random passages at z = {zt:g} can pass through sensor {s.id!r} "
                                     f"(z = {s.position[2]:g}); keep the source plane {MIN_SOURCE_DISTANCE} m away")
            if "magnetometer" in types and self.prior.moment is None:
                raise ValueError("prior.moment: magnetometers need a moment magnitude range [min, max]")
            if "electrode" in types and self.prior.p is None:
                raise ValueError("prior.p: electrode sensors need a dipole moment range [min, max]")
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


_TYPE_WORDS = {"int_type": "a whole number", "int_from_float": "a whole number", "int_parsing": "a whole number",
               "float_type": "a number", "float_parsing": "a number", "string_type": "text",
               "bool_type": "true or false", "list_type": "a list", "tuple_type": "a list",
               "dict_type": "a table", "model_type": "a table", "literal_error": None}


def format_error(err: ValidationError, source: str) -> str:
    """One line naming the file, each field path and what is wrong, in the project's words (pydantic's union
    branch names and type jargon removed; of a union's failed branches, the value's own complaint is kept)."""
    by_loc = {}
    for e in err.errors():
        loc = ""
        for part in e["loc"]:
            if isinstance(part, str) and ("[" in part or part in ("list", "tuple")):
                continue   # a union branch's name, not a field
            loc += f"[{part}]" if isinstance(part, int) else (f".{part}" if loc else str(part))
        msg = e["msg"]
        msg = msg[len("Value error, "):] if msg.startswith("Value error, ") else msg
        kind = e["type"]
        if kind == "missing":
            msg = "required field is missing"
        elif kind == "extra_forbidden":
            msg = "unknown field (check the spelling)"
        elif _TYPE_WORDS.get(kind):
            got = e.get("input")
            msg = f"expected {_TYPE_WORDS[kind]}, got {type(got).__name__} {got!r}"
        elif msg.startswith("Input should be "):   # a range or a choice: "must be ..., got ..."
            got = e.get("input")
            msg = f"must be {msg[len('Input should be '):]}, got {got!r}"
        by_loc.setdefault(loc, []).append((kind.endswith("_type") or kind.endswith("_parsing"), msg))
    lines = []
    for loc, msgs in by_loc.items():
        own = [m for is_type, m in msgs if not is_type] or [m for _, m in msgs]
        for m in dict.fromkeys(own):
            lines.append(f"{loc}: {m}" if loc else m)
    return f"{source}: " + "; ".join(lines)


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


def _shipped_dir():
    return resources.files("shipsense") / "scenarios"


def shipped_scenarios() -> dict[str, str]:
    """Names of the scenarios shipped with the package and their one-line descriptions."""
    out = {}
    for entry in sorted(_shipped_dir().iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".toml"):
            desc = tomllib.loads(entry.read_text()).get("description", "").strip()
            out[entry.name[:-5]] = desc.splitlines()[0] if desc else ""
    return out


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load and validate a scenario: a shipped name (``S0``, ``S1-P2``, ...) or a TOML path.

    Raises
    ------
    ScenarioError
        With one message naming the file, the field and the reason.
    """
    if isinstance(name_or_path, Scenario):
        return name_or_path
    text = None
    path = Path(name_or_path)
    lookup = {n.lower(): n for n in shipped_scenarios()}
    if str(name_or_path).lower() in lookup and not path.is_file():
        name = lookup[str(name_or_path).lower()]
        text = (_shipped_dir() / f"{name}.toml").read_text()
        source = f"shipped scenario {name!r}"
    elif path.is_file():
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as err:
            raise ScenarioError(f"{path}: cannot read the file ({err})") from None
        source = str(path)
    else:
        raise ScenarioError(f"{name_or_path}: no such file, and not a shipped scenario "
                            f"(shipped: {', '.join(shipped_scenarios())})")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{source}: not valid TOML ({err})") from None
    return validate_scenario(data, source, strict=True)
