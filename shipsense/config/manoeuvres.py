"""The ``[manoeuvres]`` table: scheduled turns and speed changes of the nominal passage, a prior over random
manoeuvres of random passages, and the share of the magnetic moment that turns with the hull
(:mod:`shipsense.physics.manoeuvre`).

A scenario without the table has straight, constant-velocity passages.  Scheduled manoeuvres
(``[[manoeuvres.turns]]``, ``[[manoeuvres.speed_changes]]``) belong to the nominal passage, as ``[passage]``
does; ``[manoeuvres.random]`` belongs to the random passages drawn from ``[prior]``.
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from pydantic import AfterValidator, Field, model_validator

from shipsense.config.fields import ConfigModel, Finite, Positive, PositiveRange, Range, within
from shipsense.physics.manoeuvre import SPEED_CHANGE, TURN, Manoeuvres, manoeuvring_motion

MAX_SPEED = 100.0
"""Fastest a manoeuvre may make a ship, m/s (the passage velocity's physical range)."""
MAX_TURN_RATE_DEG_S = 20.0
"""Fastest turn, deg/s."""

Seconds = Annotated[Finite, Field(ge=0), within(1e7, "s")]
Duration = Annotated[Positive, within(1e7, "s")]
Share = Annotated[Finite, Field(ge=0, le=1)]


def _nonzero(x: float) -> float:
    if x == 0:
        raise ValueError("a turn needs a nonzero rate")
    return x


class TurnConfig(ConfigModel):
    """A coordinated turn of the nominal passage: the course turns at a constant rate, the speed holds."""

    start: Seconds = Field(description="Time the turn begins, from the passage start, s.")
    duration: Duration = Field(description="Length of the turn, s.")
    rate_deg_s: Annotated[Finite, within(MAX_TURN_RATE_DEG_S, "deg/s"), AfterValidator(_nonzero)] = Field(
        description="Turn rate (positive: counter-clockwise, to port), deg/s.")


class SpeedChangeConfig(ConfigModel):
    """A speed change of the nominal passage: a constant acceleration along the course, given as the factor
    on the speed or as the acceleration itself (exactly one of them)."""

    start: Seconds = Field(description="Time the speed change begins, from the passage start, s.")
    duration: Duration = Field(description="Length of the speed change, s.")
    factor: Annotated[Finite, Field(gt=0, le=10)] | None = Field(
        None, description="Speed at the end over the speed at the start.")
    acceleration: Annotated[Finite, within(10.0, "m/s²")] | None = Field(
        None, description="Acceleration along the course (negative: slowing down), m/s².")

    @model_validator(mode="after")
    def _check(self):
        if (self.factor is None) == (self.acceleration is None):
            raise ValueError("give exactly one of factor or acceleration")
        return self


class RandomManoeuvreConfig(ConfigModel):
    """Random manoeuvres of random passages: with ``probability`` a passage makes one manoeuvre, a turn (with
    probability ``turn_share``) or else a speed change, starting uniformly in ``start``.  A turn's rate and
    total turn are uniform in their ranges, its direction port or starboard with equal odds; a speed
    change's factor is log-uniform and its acceleration's magnitude uniform."""

    probability: Share = Field(0.5, description="Probability that a passage manoeuvres.")
    turn_share: Share = Field(0.5, description="Share of the manoeuvres that are turns (the rest: speed changes).")
    turn_rate_deg_s: Annotated[PositiveRange, within(MAX_TURN_RATE_DEG_S, "deg/s")] = Field(
        (0.5, 3.0), description="Range of the turn rate's magnitude, deg/s.")
    turn_deg: Annotated[PositiveRange, within(360.0, "degrees")] = Field(
        (10.0, 90.0), description="Range of the total turn's magnitude, degrees.")
    speed_factor: Annotated[PositiveRange, within(10.0, "- (factor)")] = Field(
        (0.5, 2.0), description="Range of the speed at the end over the speed at the start (log-uniform).")
    acceleration: Annotated[PositiveRange, within(10.0, "m/s²")] = Field(
        (0.05, 0.5), description="Range of the along-track acceleration's magnitude, m/s².")
    start: Annotated[Range, within(1e7, "s")] | None = Field(
        None, description="Window of the manoeuvre's start, from the passage start (default: the whole "
                          "passage), s.")


class ManoeuvreConfig(ConfigModel):
    """Manoeuvres: scheduled turns and speed changes of the nominal passage (they may not overlap), random
    ones of random passages, and how the magnetic moment turns with the hull."""

    body_fixed_share: Share = Field(
        0.0, description="Share of the magnetic moment that turns with the hull (the permanent moment; the "
                         "rest, induced, stays with the Earth's field).")
    turns: list[TurnConfig] = Field(default_factory=list, description="Scheduled coordinated turns.")
    speed_changes: list[SpeedChangeConfig] = Field(default_factory=list, description="Scheduled speed changes.")
    random: RandomManoeuvreConfig | None = Field(None, description="Random manoeuvres of random passages.")

    @property
    def scheduled(self) -> list[tuple[str, int, TurnConfig | SpeedChangeConfig]]:
        """``(field name, index, manoeuvre)`` of the scheduled manoeuvres, by start."""
        items = [("turns", i, t) for i, t in enumerate(self.turns)]
        items += [("speed_changes", i, c) for i, c in enumerate(self.speed_changes)]
        return sorted(items, key=lambda it: it[2].start)


def nominal_manoeuvres(cfg: ManoeuvreConfig | None, velocity, runs: int) -> Manoeuvres:
    """The schedule of ``runs`` copies of the nominal passage (initial ``velocity`` (2,), m/s): the scheduled
    manoeuvres, a speed factor turned into the acceleration that reaches it."""
    if cfg is None or not cfg.scheduled:
        return Manoeuvres.none(runs, 0.0 if cfg is None else cfg.body_fixed_share)
    speed = math.hypot(*velocity)
    rows = []
    for _, _, m in cfg.scheduled:
        if isinstance(m, TurnConfig):
            rows.append((TURN, m.start, m.duration, math.radians(m.rate_deg_s), 0.0))
        else:
            a = m.acceleration if m.acceleration is not None else speed * (m.factor - 1.0) / m.duration
            rows.append((SPEED_CHANGE, m.start, m.duration, 0.0, a))
            speed += a * m.duration
    cols = [np.tile(np.array(c, dtype=float), (runs, 1)) for c in zip(*rows)]
    return Manoeuvres.from_slots(*cols, body_fixed_share=cfg.body_fixed_share)


def check_manoeuvres(sc, min_distance: float) -> None:
    """The checks of a scenario's manoeuvres that need the rest of it (raises ``ValueError`` naming the field):
    scheduled manoeuvres start before the passage ends and do not overlap, the speed stays in (0, 100] m/s,
    the nominal manoeuvring passage keeps ``min_distance`` (m) from every sensor; random manoeuvres need a
    ``[prior]`` and a start window inside the passage."""
    cfg = sc.manoeuvres
    end = sc.period * (sc.steps - 1)
    speed = math.hypot(*sc.passage.velocity)
    prev = None
    for name, i, m in cfg.scheduled:
        where = f"manoeuvres.{name}[{i}]"
        if m.start >= end:
            raise ValueError(f"{where}.start: starts at {m.start:g} s, not before the passage ends "
                             f"(at {end:g} s: period x (steps - 1))")
        if prev is not None and m.start < prev[2].start + prev[2].duration:
            raise ValueError(f"{where}.start: at {m.start:g} s it overlaps manoeuvres.{prev[0]}[{prev[1]}] "
                             f"({prev[2].start:g} s to {prev[2].start + prev[2].duration:g} s)")
        prev = (name, i, m)
        if speed == 0:
            raise ValueError(f"{where}: the nominal passage does not move (passage.velocity is 0): a manoeuvre "
                             "needs speed > 0")
        if isinstance(m, SpeedChangeConfig):
            after = speed * m.factor if m.factor is not None else speed + m.acceleration * m.duration
            field = "factor" if m.factor is not None else "acceleration"
            if not 0 < after <= MAX_SPEED:
                raise ValueError(f"{where}.{field}: the speed would go from {speed:.3g} m/s to {after:.3g} m/s "
                                 f"(it must stay in (0, {MAX_SPEED:g}] m/s)")
            speed = after
    if cfg.scheduled:
        _check_clearance(sc, min_distance, end)
    rnd = cfg.random
    if rnd is not None:
        if sc.prior is None:
            raise ValueError("manoeuvres.random: random manoeuvres are made by random passages, which need a "
                             "[prior] section")
        if rnd.start is not None and not (rnd.start[0] >= 0 and rnd.start[0] < end):
            raise ValueError(f"manoeuvres.random.start: the window must begin in [0, {end:g}) s (the passage), "
                             f"got {list(rnd.start)}")
        fastest = sc.prior.speed[1] * rnd.speed_factor[1] if rnd.turn_share < 1 and rnd.probability > 0 else 0
        if fastest > MAX_SPEED:
            raise ValueError(f"manoeuvres.random.speed_factor: prior.speed up to {sc.prior.speed[1]:g} m/s times "
                             f"{rnd.speed_factor[1]:g} exceeds {MAX_SPEED:g} m/s")


def _check_clearance(sc, min_distance, end):
    """The nominal manoeuvring passage (sampled every 0.1 m of its path, at most 200 000 points) keeps
    ``min_distance`` from every sensor."""
    sched = nominal_manoeuvres(sc.manoeuvres, sc.passage.velocity, 1)
    top = max(math.hypot(*sc.passage.velocity), float(np.max(np.abs(
        manoeuvring_motion(np.array([sc.passage.start]), np.array([sc.passage.velocity]), sched,
                           np.linspace(0.0, end, 64))[1]))) * math.sqrt(2))
    n = int(min(200_000, max(2 * sc.steps, math.ceil(top * end / 0.1))))
    pos = manoeuvring_motion(np.array([sc.passage.start]), np.array([sc.passage.velocity]), sched,
                             np.linspace(0.0, end, n))[0][0]
    pos = np.concatenate([pos, np.full((n, 1), sc.passage.z)], axis=-1)
    for s in sc.sensors:
        gap = float(np.min(np.linalg.norm(pos - np.array(s.position), axis=-1)))
        if gap < min_distance:
            raise ValueError(f"manoeuvres: the manoeuvring passage passes {gap:.3g} m from sensor {s.id!r} "
                             f"(closer than {min_distance} m: the source would be inside the sensor)")
