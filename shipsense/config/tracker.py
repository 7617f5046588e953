"""The ``[tracker]`` table: the project's tracker options, the source studies' filter, process noise and bank."""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import (
    BeforeValidator,
    Field,
    Strict,
    model_validator,
)

from shipsense.config.fields import ConfigModel, Count, Finite, Flag, Fraction, Positive, Vec2, within
from shipsense.defaults import HUBER_GAMMA, N_PU


class ProcessNoiseConfig(ConfigModel):
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
    sigma_q: Annotated[Positive, within(1e24, "(state units)²")] = 0.1
    q_diag: list[Annotated[Finite, Field(ge=0), within(1e24, "(state units)²")]] | None = None
    sigma_a: Annotated[tuple[Positive, Positive], within(100.0, "m/s²")] = (1.0, 1.0)
    param_var: list[Annotated[Finite, Field(ge=0), within(1e24, "(parameter units)²")]] | None = None


class BankConfig(ConfigModel):
    """Multiple-initial-value bank: K moment (or p) levels times l bearings, run side by side, the hypothesis
    of largest cumulative innovation log-likelihood selected (the source studies' method).

    Seeds are placed at the range implied by the first measured field for each
    level, on each bearing, around the sensor that measured the strongest
    field.  Every hypothesis starts with ``initial_velocity``, a zero moment
    (magnetic) or ``p`` = its level (electric), and the initial standard
    deviations below.
    """

    levels: list[Annotated[Positive, within(1e12, "A·m² or A·m")]] = Field(
        min_length=1, description="Moment magnitudes (A·m²) or p levels (A·m).")
    bearings_deg: list[Annotated[Finite, within(720.0, "deg")]] = Field(min_length=1)
    bearing_convention: Literal["east", "north"] = Field(
        "east", description="east: bearings counter-clockwise from +x, seed = (r cos phi, r sin phi); north: "
        "clockwise from north (+y), seed = (r sin phi, r cos phi) (the magnetic source study's S0 bank).")
    initial_velocity: Annotated[Vec2, within(100.0, "m/s")] = (6.0, 6.0)
    initial_course: Literal["fixed", "towards_array"] = Field(
        "fixed", description="fixed: every hypothesis gets initial_velocity; towards_array: the speed "
        "|initial_velocity| on the course from the seed towards the array centroid (a passing ship).")
    position_std: Annotated[Positive, within(1e6, "m")] = 30.0
    velocity_std: Annotated[Positive, within(100.0, "m/s")] = 2.0
    moment_std: Annotated[Positive, within(1e12, "A·m²")] = 1e8
    z_std: Annotated[Positive, within(1e4, "m")] = 1.0
    p_std: Annotated[Positive, within(1e9, "A·m")] = 50.0
    p_initial: Annotated[Positive, within(1e9, "A·m")] = Field(
        100.0, description="Initial p (A·m) when the levels are magnetic (fused model).")
    range_correction: Annotated[Positive, within(1e3, "")] = Field(
        2.0, description="Image correction c of the electric range formula.")
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


class MotionConfig(ConfigModel):
    """The ``[tracker.motion]`` table: how the project's tracker follows a ship that turns or changes speed.

    ``imm``: an interacting multiple model filter over four motion modes (:mod:`shipsense.models.motion_modes`:
    constant velocity, left and right coordinated turns at ``turn_rate_deg_s``, a speed change), every
    hypothesis of the bank carrying the modes' probabilities; a passage whose manoeuvre modes hold more than
    ``threshold`` of the probability is reported ``manoeuvring``, and its refits use only the samples after the
    manoeuvre.  ``cv``: the constant-velocity filter alone (the source studies' model).
    """

    model: Literal["imm", "cv"] = Field("cv", description="imm: motion modes mixed by an IMM filter; cv: "
                                        "constant velocity only (the default while the IMM's calibration after "
                                        "a manoeuvre is below the project's targets: docs, Results).")
    turn_rate_deg_s: Annotated[Positive, within(30.0, "deg/s")] = Field(
        3.5, description="The turn modes' rates (left and right), deg/s.")
    turn_accel: Annotated[Positive, within(10.0, "m/s²")] = Field(
        0.1, description="White acceleration of the turn modes (covers rates between them), m/s².")
    speed_accel: Annotated[Positive, within(10.0, "m/s²")] = Field(
        0.3, description="White acceleration along the course of the speed-change mode, m/s².")
    hull_share: Fraction = Field(0.5, description="Share of the horizontal magnetic moment the turn modes "
                                 "turn with the hull (the rest is a random walk of the unknown share).")
    sojourn_straight_s: Annotated[Positive, within(1e6, "s")] = Field(
        600.0, description="Mean time between manoeuvres (the constant-velocity mode's sojourn), s.")
    sojourn_manoeuvre_s: Annotated[Positive, within(1e6, "s")] = Field(
        15.0, description="Mean duration of a manoeuvre mode, s.")
    manoeuvre_prior: Annotated[Finite, Field(gt=0, lt=1)] = Field(
        0.03, description="Probability of the manoeuvre modes together at a (re)start.")
    threshold: Annotated[Finite, Field(gt=0, lt=1)] = Field(
        0.5, description="Manoeuvre modes' probability above which the ship is reported manoeuvring.")


FILTERS = ("ekf", "ukf", "ckf", "cdkf", "srcdkf", "puekf", "huber_ukf")
"""The filter units (:mod:`shipsense.trackers.filters`)."""


def as_stages(v):
    """Refinement stages as a tuple: one stage given as a whole number, or a list (a TOML array)."""
    if isinstance(v, int) and not isinstance(v, bool):
        return (v,)
    return tuple(v) if isinstance(v, list) else v


class TrackerOptions(ConfigModel):
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
    huber_gamma: Annotated[Positive, within(100.0, "")] = Field(
        HUBER_GAMMA, description="Huber threshold on a whitened residual (robust updates and fits).")
    window_s: Annotated[Positive, within(3600.0, "s")] | None = Field(
        None, description="Length of the initialisation window after the detection, s.")
    early_starts: Flag = Field(True, description="Start a bank before the initialisation window is complete, "
                               "from a growing window's fit that locates the ship and beats its mirror image "
                               "(false: only from the complete window, as Passage-v1's observer).")
    snr_start: Annotated[Positive, within(1e9, "")] | None = Field(
        None, description="Detection: the strongest field channel's signal-to-noise ratio that starts a window.")
    refine: Annotated[tuple[Count, ...], BeforeValidator(as_stages), Field(min_length=1)] | None = Field(
        None, description="Grid minima refined per stage (later stages only for passages whose fit fails).")
    explore_samples: Count | None = Field(
        None, description="Samples of the window the refinement explores on first (None: all).")
    grid_samples: Count | None = Field(None, description="Samples of the window the grid search uses.")
    z_std: Annotated[Positive, within(1e3, "m")] | None = Field(
        None, description="Prior standard deviation of the source depth in the fits, m (None: no prior).")
    keep_init: Annotated[int, Strict(), Field(ge=1, le=64)] = Field(5, description="Hypotheses a bank starts with.")
    keep: Annotated[int, Strict(), Field(ge=1, le=64)] = Field(3, description="Distinct fits a refit keeps.")
    refit_every: Count | None = Field(20, description="Refit every this many samples until the closest "
                                      "approach (None: never).")
    through_peak: Fraction | None = Field(0.5, description="Refit once when the signal has fallen to this "
                                          "fraction of its peak (None: never).")
    nis_window: Annotated[int, Strict(), Field(ge=1, le=10_000)] = Field(
        10, description="Samples of the divergence alarm's NIS window.")
    nis_limit: Annotated[Positive, within(1e6, "")] = Field(
        3.0, description="Mean (median when robust) normalised NIS above which the bank has diverged.")
    max_restarts: Annotated[int, Strict(), Field(ge=0, le=1_000_000)] = Field(
        4, description="Alarms a passage may restart from.")
    collapse: Annotated[Finite, Field(gt=0, le=1)] | None = Field(
        0.25, description="Refit when the position covariance has shrunk below this fraction of the start's "
        "without the innovations agreeing (None: never).")
    ambiguity_nats: Positive = Field(10.0, description="Hypotheses within this many nats of the best "
                                     "restart a refit.")
    report_nats: Positive = Field(3.0, description="Near-ties within this many nats are reported ambiguous.")
    report_distance_m: Annotated[Positive, within(1e6, "m")] = Field(
        20.0, description="... when farther apart than this, m.")
    distinct_m: Annotated[Positive, within(1e6, "m")] = Field(
        15.0, description="Fits closer than this (m) are one.")
    gof: Fraction = Field(0.01, description="Level of the fits' chi-square goodness-of-fit test.")
    inflate: Annotated[Positive, within(1e6, "")] = Field(
        2.0, description="Inflation of a window fit's covariance when a bank starts from it.")
    history: Annotated[int, Strict(), Field(ge=2, le=1_000_000)] = Field(
        1000, description="Samples a refit may use (the cost per sample is bounded).")
    gap_limit_s: Annotated[Positive, within(1e9, "s")] | None = Field(
        None, description="A gap between samples longer than this (s) is reported (default: 10 periods).")
    consistency_window: Annotated[int, Strict(), Field(ge=2, le=1_000_000)] | None = Field(
        20, description="Samples of the windowed innovation consistency test (None: off).")
    consistency_level: Fraction = Field(0.01, description="Level of the consistency test.")
    rescan: Flag | None = Field(None, description="Rerun the global initialiser on the schedule until the "
                                "closest approach (default: one magnetometer).")
    motion: MotionConfig = MotionConfig()

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
