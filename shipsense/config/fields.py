"""The value types of the configuration: finite, positive, ranges and physical limits in SI units, each a
pydantic annotation whose message names the field's problem in the project's words."""

from __future__ import annotations

import math
import re
from typing import Annotated

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    Strict,
    ValidationError,
)

from shipsense.errors import ShipsenseError


class ScenarioError(ShipsenseError):
    """A scenario file or value is invalid; the message names the field and the reason."""


def check_finite(x: float) -> float:
    if not math.isfinite(x):
        raise ValueError(f"must be a finite number, got {x}")
    return x


def check_positive(x: float) -> float:
    if not x > 0:
        raise ValueError(f"must be > 0, got {x}")
    return x


def check_range(r: tuple[float, float]) -> tuple[float, float]:
    if r[0] > r[1]:
        raise ValueError(f"must be [min, max] with min <= max, got {list(r)}")
    return r


Finite = Annotated[float, AfterValidator(check_finite)]
Positive = Annotated[float, AfterValidator(check_finite), AfterValidator(check_positive)]
Vec2 = tuple[Finite, Finite]
Vec3 = tuple[Finite, Finite, Finite]


def within(limit, unit):
    """A validator: every component's magnitude at most ``limit`` (a physical range, stated in the message)."""
    def check(v):
        values = v if isinstance(v, (tuple, list)) else (v,)
        if any(abs(x) > limit for x in values):
            raise ValueError(f"outside the physical range: at most {limit:g} {unit} in magnitude, got {v!r}")
        return v
    return AfterValidator(check)


def at_least(limit, unit):
    """A validator: every component at least ``limit`` (the small end of a physical range, stated in the
    message: a value below it overflows the computations that divide by it)."""
    def check(v):
        values = v if isinstance(v, (tuple, list)) else (v,)
        if any(x < limit for x in values):
            raise ValueError(f"outside the physical range: at least {limit:g} {unit}, got {v!r}")
        return v
    return AfterValidator(check)


Coord2 = Annotated[Vec2, within(1e6, "m")]
Coord3 = Annotated[Vec3, within(1e6, "m")]
Speed2 = Annotated[Vec2, within(100.0, "m/s")]
Speed = Annotated[Positive, within(100.0, "m/s")]
Distance = Annotated[Positive, within(1e6, "m")]
Moment3 = Annotated[Vec3, within(1e12, "A·m²")]
Moment = Annotated[Positive, within(1e12, "A·m²")]
ElectricMoment = Annotated[Positive, within(1e9, "A·m")]
MIN_NOISE_STD = 1e-15
"""Smallest noise standard deviation (SI: T, V/m, rad) a sensor may have: a femtotesla, far below any seabed
sensor's floor; below it the whitened residuals and the Fisher information overflow."""
Std = Annotated[Positive, within(1e3, "(SI)"), at_least(MIN_NOISE_STD, "(SI)")]
Var = Annotated[Positive, within(1e6, "(SI²)"), at_least(MIN_NOISE_STD ** 2, "(SI²)")]
Conductivity = Annotated[Positive, within(100.0, "S/m")]


def range_of(kind):
    """The type ``[min, max]`` of two values of type ``kind``, ``min <= max`` (:func:`check_range`)."""
    return Annotated[tuple[kind, kind], AfterValidator(check_range)]


Range = range_of(Finite)
PositiveRange = range_of(Positive)


def check_source_plane(sensors, z, min_distance, field, ships):
    """Raise ``ValueError`` naming ``field`` when sources sailing anywhere in the plane at depth ``z`` (m) can
    pass through a sensor of ``sensors`` (closer than ``min_distance`` m in z); ``ships`` says which sources
    (for the message: "random passages", "ships")."""
    for s in sensors:
        if abs(s.position[2] - z) < min_distance:
            raise ValueError(f"{field}: {ships} at z = {z:g} can pass through sensor {s.id!r} "
                             f"(z = {s.position[2]:g}); keep the source plane {min_distance} m away")


class ConfigModel(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
Fraction = Annotated[Finite, Field(gt=0, lt=1)]
Count = Annotated[int, Strict(), Field(ge=1, le=1_000_000)]
Flag = Annotated[bool, Strict()]


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
            if isinstance(part, str) and ("[" in part or "-" in part or part in ("list", "tuple")):
                continue   # a union branch's name (constrained-int, function-after[...]), not a field
            loc += f"[{part}]" if isinstance(part, int) else (f".{part}" if loc else str(part))
        msg = e["msg"]
        msg = msg[len("Value error, "):] if msg.startswith("Value error, ") else msg
        field = re.match(r"([A-Za-z_]\w*): ", msg)
        if field and loc:   # a table's own check names its field: one path, "medium.sigma_seabed: ..."
            loc, msg = f"{loc}.{field[1]}", msg[field.end():]
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
