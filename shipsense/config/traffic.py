"""The ``[traffic]`` table: several ships in one recording (:mod:`shipsense.physics.traffic`).

Ship 0 is the scenario's own passage (the nominal one or a draw from ``[prior]``); ``count`` ships sail in all,
the others (companions) each drawn from ``[prior]`` or placed by a named encounter with ship 0 (``crossing``,
``head_on``, ``overtaking``, ``following``).  A value given as ``[min, max]`` is drawn uniformly per run and
ship; a single number is fixed.  A scenario without the table (or with ``count = 1``) has one ship.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, Strict, model_validator

from shipsense.config.fields import ConfigModel, Finite, check_source_plane, range_of, within
from shipsense.physics.traffic import GEOMETRIES

MAX_SHIPS = 8
"""Most ships a recording may hold."""

ShipCount = Annotated[int, Strict(), Field(ge=1, le=MAX_SHIPS)]
Geometry = Literal[GEOMETRIES]
Separation = Annotated[Finite, Field(ge=0), within(1e5, "m")]
Offset = Annotated[Finite, within(1e7, "s")]
Angle = Annotated[Finite, Field(gt=0, lt=180)]
Ratio = Annotated[Finite, Field(gt=0, le=10)]


def span(value) -> tuple[float, float]:
    """``(min, max)`` of a value given as one number or as ``[min, max]``."""
    return (value, value) if isinstance(value, (int, float)) else (value[0], value[1])


class TrafficConfig(ConfigModel):
    """Several ships: how many, and where the companions of ship 0 sail.

    A named encounter meets ship 0 abeam at ``separation`` (their closest approach) ``time_offset`` after
    ship 0's closest approach to the array centre; a follower keeps ``separation`` astern of ship 0.  Each
    companion carries its own source: drawn from ``[prior]`` like ship 0's for random passages, ship 0's
    moment and dipole for the nominal one.
    """

    count: ShipCount | range_of(ShipCount) = Field(
        1, description="Number of ships in a run, or [min, max] drawn uniformly per run.")
    geometry: Geometry | list[Geometry] = Field(
        "prior", description="How the companions sail: prior | crossing | head_on | overtaking | following; one "
                             "for every companion, or a list with one per companion (ships 1, 2, ...).")
    separation: Separation | range_of(Separation) = Field(
        (20.0, 60.0), description="Closest approach of a named encounter to ship 0 (a follower: its distance "
                                  "astern), or [min, max], m.")
    time_offset: Offset | range_of(Offset) = Field(
        0.0, description="Time of a named encounter after ship 0's closest approach to the array centre; for a "
                         "prior companion, how much later it starts its passage; or [min, max], s.")
    crossing_angle_deg: Angle | range_of(Angle) = Field(
        (60.0, 120.0), description="Angle between a crossing companion's course and ship 0's, or [min, max]; "
                                   "the side is drawn, deg.")
    speed_ratio: Ratio | range_of(Ratio) | None = Field(
        None, description="A named companion's speed over ship 0's, or [min, max] (default 1, overtaking 1.5; a "
                          "follower keeps ship 0's speed).")

    @model_validator(mode="after")
    def _check(self):
        hi = span(self.count)[1]
        if isinstance(self.geometry, list) and len(self.geometry) != hi - 1:
            raise ValueError(f"geometry: a list needs one entry per companion ({hi - 1} for up to {hi} ships), "
                             f"got {len(self.geometry)}")
        if "overtaking" in self.geometries and span(self.speed_ratio or 1.5)[0] <= 1:
            raise ValueError(f"speed_ratio: an overtaking companion must be faster than ship 0 (> 1), got "
                             f"{self.speed_ratio}")
        return self

    @property
    def max_ships(self) -> int:
        """The most ships a run can hold."""
        return span(self.count)[1]

    @property
    def geometries(self) -> tuple[str, ...]:
        """The geometry of each companion, ships 1 .. max_ships - 1."""
        if isinstance(self.geometry, list):
            return tuple(self.geometry)
        return (self.geometry,) * (self.max_ships - 1)

    def ratio_span(self, geometry: str) -> tuple[float, float]:
        """The speed ratio's ``(min, max)`` for a named ``geometry`` (its default if not given)."""
        if geometry == "following":
            return (1.0, 1.0)
        if self.speed_ratio is None:
            return (1.5, 1.5) if geometry == "overtaking" else (1.0, 1.0)
        return span(self.speed_ratio)


def check_traffic(sc, min_distance: float) -> None:
    """The checks of a scenario's traffic that need the rest of it (raises ``ValueError`` naming the field):
    prior companions need ``[prior]``; named ones a moving ship 0; the source plane keeps ``min_distance``
    (m) from every sensor (any companion may pass over one); the raw envelope chain holds one ship."""
    cfg = sc.traffic
    if cfg.max_ships < 2:
        return
    if "prior" in cfg.geometries and sc.prior is None:
        raise ValueError("traffic.geometry: prior companions are drawn from [prior], which this scenario lacks")
    named = [g for g in cfg.geometries if g != "prior"]
    if named and sc.passage.velocity[0] == 0 and sc.passage.velocity[1] == 0:
        raise ValueError(f"traffic.geometry: a {named[0]} companion sails relative to ship 0's course, but "
                         "passage.velocity is 0")
    check_source_plane(sc.sensors, sc.passage.z, min_distance, "traffic", "ships")
    if sc.envelope_chain.mode == "raw":
        raise ValueError("traffic.count: the raw envelope chain simulates one ship; use envelope_chain.mode = "
                         "\"ideal\" with several ships")
