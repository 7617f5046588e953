"""The sweep file: layouts x site conditions x Monte Carlo passages, typed and validated.

A sweep is read from TOML (``shipsense sweep SWEEP.toml``)::

    name = "envelope-layouts"
    scenario = "S1-P2"        # base scenario: medium, noise, prior, period, steps, tracker options
    template = "E1"           # the base sensor that generated layouts copy (default: its first sensor)
    seed = 0
    passages = 16             # Monte Carlo passages per cell
    chunk = 8                 # passages per task (a task is the unit of scheduling and of resumption)
    method = "tracker"        # tracker | bank
    metrics = ["convergence", "rmse", "rmse_over_crlb", "nees_coverage", "ambiguity", "time"]
    combine = "product"       # product | list: how the [conditions] lists combine

    [[layouts]]
    name = "line"
    generator = "line"        # line | triangle | grid; or file = "layout.toml" (any scenario file)
    n = 3
    spacing = 10.0

    [conditions]              # every key a list of values
    water_depth = [15.0, 30.0]
    noise_scale = [1.0, 2.0]

Paths in the file (layout files, a base scenario file) are relative to the
sweep file.  Every cell's scenario is built and validated when the sweep is
loaded, so a bad cell is refused before any work starts.  Errors raise
:class:`SweepError` with one message naming the field.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from shipsense.errors import ShipsenseError

__all__ = ["CONDITION_KEYS", "METRICS", "LayoutSpec", "SweepError", "SweepSpec", "load_sweep", "parse_sweep"]

METRICS = ("convergence", "rmse", "rmse_over_crlb", "nees_coverage", "ambiguity", "time")
"""Metrics a sweep can compute (see :mod:`shipsense.sweep.evaluate` for their definitions)."""

CONDITION_KEYS = {
    "water_depth": "water depth D, m (sensors on the seabed follow it)",
    "sigma_water": "sea-water conductivity, S/m",
    "sigma_seabed": "seabed conductivity, S/m",
    "noise_scale": "factor on every sensor's noise standard deviation",
    "source_scale": "factor on the source strength (magnetic moment and electric dipole, nominal and prior)",
    "prior_range": "[min, max] start range of the passages from the array centroid, m",
    "prior_speed": "[min, max] speed of the passages, m/s",
    "prior_cpa": "[min, max] closest approach of the passages to the centroid, m",
    "dropout": "probability that a measurement component is missing",
    "outlier_eps": "share of outliers (contaminated noise at the scenario's outlier scale)",
    "manoeuvre_probability": "share of passages that make one random manoeuvre (a turn or a speed change, the "
                             "scenario's [manoeuvres.random] ranges or their defaults)",
}
"""Site conditions a sweep can vary, with their meaning and units."""

MAX_CELLS = 100_000
MAX_TASKS = 1_000_000


class SweepError(ShipsenseError):
    """A sweep file, its output folder or its scheduler is unusable; the message names the field or path."""


def _finite(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class LayoutSpec(_Strict):
    """One candidate array: a generated shape or a layout file."""

    name: str = Field(min_length=1, max_length=80)
    generator: Literal["line", "triangle", "grid"] | None = None
    file: str | None = None
    n: Annotated[int, Field(ge=2, le=64)] = 3
    spacing: Annotated[float, Field(gt=0, le=10_000)] = 10.0
    side: Annotated[float, Field(gt=0, le=10_000)] = 10.0
    shape: tuple[Annotated[int, Field(ge=1, le=16)], Annotated[int, Field(ge=1, le=16)]] = (2, 2)
    angle_deg: Annotated[float, Field(ge=-360, le=360)] = 90.0
    center: tuple[float, float] = (0.0, 0.0)

    @model_validator(mode="after")
    def _one_source(self):
        if (self.generator is None) == (self.file is None):
            raise ValueError("give exactly one of generator (line, triangle, grid) or file")
        if not all(_finite(c) and abs(c) <= 1e5 for c in self.center):
            raise ValueError("center: must be two finite coordinates within 100 km")
        if self.generator == "grid" and self.shape[0] * self.shape[1] < 2:
            raise ValueError("shape: a grid needs at least 2 sensors")
        return self


class SweepSpec(_Strict):
    """A validated sweep (see the module docstring for the file format)."""

    name: str = Field(min_length=1, max_length=80)
    scenario: str = Field(min_length=1)
    template: str | None = None
    seed: Annotated[int, Field(ge=0, le=2**63 - 1)] = 0
    passages: Annotated[int, Field(ge=1, le=100_000)] = 16
    chunk: Annotated[int, Field(ge=1, le=10_000)] = 8
    method: Literal["tracker", "bank"] = "tracker"
    metrics: list[Literal[METRICS]] = Field(default_factory=lambda: list(METRICS), min_length=1)
    combine: Literal["product", "list"] = "product"
    ambiguity_passages: Annotated[int, Field(ge=1, le=64)] = 4
    layouts: list[LayoutSpec] = Field(min_length=1)
    conditions: dict[str, list] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _check(self):
        names = [lay.name for lay in self.layouts]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"layouts: names must be unique, repeated: {', '.join(dup)}")
        if len(set(self.metrics)) != len(self.metrics):
            raise ValueError("metrics: a metric is listed twice")
        for key, values in self.conditions.items():
            if key not in CONDITION_KEYS:
                raise ValueError(f"conditions.{key}: unknown condition (expected one of: {', '.join(CONDITION_KEYS)})")
            if not values:
                raise ValueError(f"conditions.{key}: an empty list leaves the sweep with no cells")
            for v in values:
                _check_condition_value(key, v)
        if self.combine == "list" and len({len(v) for v in self.conditions.values()}) > 1:
            lengths = ", ".join(f"{k}: {len(v)}" for k, v in self.conditions.items())
            raise ValueError(f"conditions: combine = 'list' needs lists of one length, got {lengths}")
        return self

    def condition_sets(self) -> list[dict]:
        """The site conditions, one dict per combination (``[{}]`` when there are none)."""
        keys = list(self.conditions)
        if not keys:
            return [{}]
        if self.combine == "list":
            return [dict(zip(keys, vals)) for vals in zip(*self.conditions.values())]
        out = [{}]
        for k in keys:
            out = [{**c, k: v} for c in out for v in self.conditions[k]]
        return out


def _check_condition_value(key, v):
    where = f"conditions.{key}"
    if key.startswith("prior_"):
        if not (isinstance(v, list) and len(v) == 2 and all(_finite(x) for x in v)):
            raise ValueError(f"{where}: each value must be [min, max] of two finite numbers, got {v!r}")
        lo, hi = v
        if lo > hi:
            raise ValueError(f"{where}: [min, max] with min <= max, got {v!r}")
        if key != "prior_cpa" and lo <= 0:
            raise ValueError(f"{where}: values must be > 0, got {v!r}")
        if max(abs(lo), abs(hi)) > 1e5:
            raise ValueError(f"{where}: values must be within 1e5, got {v!r}")
        return
    if not _finite(v):
        raise ValueError(f"{where}: each value must be a finite number, got {v!r}")
    limits = {"dropout": (0.0, 0.95), "outlier_eps": (0.0, 0.5), "manoeuvre_probability": (0.0, 1.0),
              "noise_scale": (1e-3, 1e3),
              "source_scale": (1e-3, 1e3), "water_depth": (1.0, 1e4), "sigma_water": (1e-3, 100.0),
              "sigma_seabed": (1e-6, 100.0)}
    lo, hi = limits[key]
    if not lo <= v <= hi:
        raise ValueError(f"{where}: {v!r} is outside the allowed range [{lo:g}, {hi:g}]")


def _message(err: ValidationError) -> str:
    e = err.errors()[0]
    loc = ".".join(str(p) for p in e["loc"])
    msg = e["msg"].removeprefix("Value error, ")
    if e["type"] in ("int_type", "float_type", "string_type", "bool_type", "list_type", "tuple_type", "dict_type"):
        msg = f"expected {e['type'].removesuffix('_type')}, got {type(e.get('input')).__name__} {e.get('input')!r}"
    elif e["type"] == "extra_forbidden":
        msg = "unknown key (typo?)"
    elif e["type"] == "missing":
        msg = "required"
    return f"{loc}: {msg}" if loc else msg


def parse_sweep(data: dict, source: str = "sweep") -> SweepSpec:
    """A validated :class:`SweepSpec` from a parsed TOML table (``source`` names it in errors)."""
    try:   # through JSON: strict types, with TOML arrays accepted where a field is a tuple
        return SweepSpec.model_validate_json(json.dumps(data, default=str))
    except ValidationError as err:
        raise SweepError(f"{source}: {_message(err)}") from None


def load_sweep(path) -> tuple[SweepSpec, Path]:
    """Read and validate a sweep file; returns the spec and the folder its relative paths are taken from."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as err:
        reason = err.strerror if isinstance(err, OSError) else "not UTF-8 text"
        raise SweepError(f"{path}: cannot read the sweep file ({reason})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise SweepError(f"{path}: not valid TOML ({err})") from None
    return parse_sweep(data, str(path)), path.resolve().parent
