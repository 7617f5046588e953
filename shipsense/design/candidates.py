"""Candidate positions for ``shipsense design --candidates``: a CSV of points or a TOML ``[candidates]`` region,
validated as strictly as a scenario (typed, within physical ranges, in the water, no two at one point), a bad
value one line naming the file, the row or field and the reason."""

from __future__ import annotations

import csv
import math
import tomllib
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import Field, ValidationError, model_validator

from shipsense.config.fields import (
    ConfigModel,
    Coord2,
    Finite,
    Positive,
    ScenarioError,
    format_error,
    within,
)
from shipsense.config.scenario import MIN_SENSOR_SPACING
from shipsense.design.placement import grid_candidates

MAX_GRID_POINTS = 1_000_000
"""Most grid points a ``[candidates]`` region may span (its bounding box over the spacing, before the polygon
and the exclusions thin it): a design from more candidates than this is beyond any machine's budget."""

Circle = tuple[Finite, Finite, Annotated[Positive, within(1e6, "m")]]


class CandidateRegion(ConfigModel):
    """The ``[candidates]`` table: grid points of step ``spacing`` (m) inside ``polygon`` ((x, y) vertices, m), at
    height ``z`` (m; default the template sensor's), outside the ``exclusions`` (circles ``[x, y, r]`` or
    polygons), thinned to ``min_spacing`` (m)."""

    polygon: list[Coord2] = Field(min_length=3, description="Vertices (x, y) of the deployable area, m.")
    spacing: Annotated[Positive, within(1e5, "m")] = Field(description="Grid step, m.")
    z: Annotated[Finite, Field(le=0), within(11_000.0, "m")] | None = Field(
        None, description="Sensor height (world z, <= 0), m (default: the template sensor's).")
    exclusions: list[Circle | Annotated[list[Coord2], Field(min_length=3)]] = Field(
        default_factory=list, description="Circles [x, y, r] or polygons [[x, y], ...] where no sensor may go.")
    min_spacing: Annotated[Finite, Field(ge=0), within(1e5, "m")] = Field(
        0.0, description="Drop grid points closer than this (m) to a kept one.")

    @model_validator(mode="after")
    def _check(self):
        poly = np.array(self.polygon)
        width, height = np.ptp(poly, axis=0)
        if not (width > 0 and height > 0):
            raise ValueError("polygon: the vertices span no area (all on one line or one point)")
        points = (math.floor(width / self.spacing) + 1) * (math.floor(height / self.spacing) + 1)
        if points > MAX_GRID_POINTS:
            raise ValueError(f"spacing: {self.spacing:g} m over the polygon's {width:g} x {height:g} m makes "
                             f"{points:.3g} grid points (at most {MAX_GRID_POINTS:,}); use a larger spacing")
        return self


class _Document(ConfigModel):
    candidates: CandidateRegion


def _in_the_water(pts, scenario, where):
    depth = scenario.medium.water_depth if scenario.medium is not None else math.inf
    z = pts[:, 2]
    for i in np.flatnonzero((z > 0) | (z < -depth)):
        place = ("above the sea surface (z > 0)" if z[i] > 0 else
                 f"below the seabed (z < -{depth:g}, the scenario's water_depth)")
        raise ScenarioError(f"{where(i)}: candidate at {list(map(float, pts[i]))} is outside the water: {place}")


def _coincident(pts, where):
    from scipy.spatial import cKDTree

    pairs = cKDTree(pts).query_pairs(MIN_SENSOR_SPACING, output_type="ndarray")
    if len(pairs):
        i, j = sorted(pairs[np.lexsort(pairs.T[::-1])][0])
        raise ScenarioError(f"{where(j)}: candidate at {list(map(float, pts[j]))} coincides with {where(i, bare=True)} "
                            f"(closer than {MIN_SENSOR_SPACING} m; each candidate once)")


def _read_csv(path, z_default):
    with open(path, newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        rows = list(reader)
    names = [h.strip() for h in header or []]
    if not {"x", "y"} <= set(names):
        raise ScenarioError(f"{path}: a candidate CSV needs a header with x,y (and optionally z, cost)")
    unknown = set(names) - {"x", "y", "z", "cost"}
    if unknown or len(set(names)) != len(names):
        raise ScenarioError(f"{path}: the header may name x, y, z and cost once each, got {','.join(names)}")
    if not rows:
        raise ScenarioError(f"{path}: no candidates (a header and no rows)")
    col = {name: i for i, name in enumerate(names)}
    pts = np.empty((len(rows), 3))
    costs = np.empty(len(rows)) if "cost" in col else None
    for r, row in enumerate(rows):
        line = r + 2
        if len(row) != len(names):
            raise ScenarioError(f"{path}: row {line}: expected {len(names)} values ({','.join(names)}), got {len(row)}")
        for name, i in col.items():
            text = row[i].strip()
            try:
                v = float(text)
            except ValueError:
                raise ScenarioError(f"{path}: row {line}, {name}: expected a number, got {text!r}") from None
            if not math.isfinite(v):
                raise ScenarioError(f"{path}: row {line}, {name}: must be a finite number, got {text!r}")
            if name == "cost":
                if v < 0:
                    raise ScenarioError(f"{path}: row {line}, cost: must be >= 0, got {text!r}")
                costs[r] = v
            else:
                if abs(v) > 1e6:
                    raise ScenarioError(f"{path}: row {line}, {name}: outside the physical range: at most 1e+06 m "
                                        f"in magnitude, got {text!r}")
                pts[r, "xyz".index(name)] = v
        if "z" not in col:
            pts[r, 2] = z_default
    return pts, costs, lambda i, bare=False: (f"row {i + 2}" if bare else f"{path}: row {i + 2}")


def _read_toml(path, z_default):
    import json

    try:
        data = tomllib.loads(Path(path).read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ScenarioError(f"{path}: not valid TOML ({err})") from None
    try:
        doc = _Document.model_validate_json(json.dumps(data, allow_nan=True, default=str), strict=True)
    except ValidationError as err:
        raise ScenarioError(format_error(err, str(path))) from None
    c = doc.candidates
    pts = grid_candidates(c.polygon, c.spacing, z_default if c.z is None else c.z,
                          [list(e) for e in c.exclusions], c.min_spacing)
    if len(pts) == 0:
        raise ScenarioError(f"{path}: candidates: no grid point of spacing {c.spacing:g} m lies inside the polygon "
                            "and outside the exclusions")
    return pts, None, lambda i, bare=False: (f"grid point {i}" if bare else f"{path}: candidates: grid point {i}")


def load_candidates(path, scenario):
    """Candidate positions (N, 3), m, and their costs (N,) or None, from a CSV (``x,y[,z][,cost]``, z defaulting
    to the scenario's first sensor's) or a TOML ``[candidates]`` table (:class:`CandidateRegion`).

    Every candidate is a finite position within the physical range, in the scenario's water (``-water_depth <=
    z <= 0``) and apart from every other by :data:`~shipsense.config.scenario.MIN_SENSOR_SPACING`.

    Raises
    ------
    ScenarioError
        With one message naming the file, the row or field and the reason.
    """
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"{path}: no such file")
    z_default = scenario.sensors[0].position[2]
    if path.suffix == ".csv":
        try:
            pts, costs, where = _read_csv(path, z_default)
        except (UnicodeDecodeError, csv.Error) as err:
            raise ScenarioError(f"{path}: not a readable CSV ({err})") from None
    elif path.suffix == ".toml":
        pts, costs, where = _read_toml(path, z_default)
    else:
        raise ScenarioError(f"{path}: candidates must be a .csv or .toml file")
    _in_the_water(pts, scenario, where)
    _coincident(pts, where)
    return pts, costs
