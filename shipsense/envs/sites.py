"""Sites for ``shipsense/ArrayDesign-v1``: a passage-geometry prior and a candidate region, drawn under a seed.

A :class:`Site` is where an array is to be laid: the traffic it must watch (a lane heading with a spread, the
lane's closest-approach offsets from the region's centre, speeds, the ship's electric source strength), the
water depth (sensors stand on the seabed) and circular exclusion zones inside the square candidate region.
:func:`sample_site` draws one from the documented distribution (:data:`SITE_DISTRIBUTION`);
:meth:`Site.scenario` turns it into a scenario of the base scenario's sensor type whose ``[prior]`` is the site's
traffic, so the project's tools (Fisher matrices, the designer, the ambiguity check) work on it unchanged.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

SITE_DISTRIBUTION = {
    "heading_deg": "uniform(0, 360): the lane's mean heading (from +x, counter-clockwise)",
    "heading_spread_deg": "uniform(0, 30): headings are uniform within +-spread of the mean",
    "cpa_centre_m": "uniform(-0.6, 0.6) x half_width: the lane's mean closest approach to the centre (signed)",
    "cpa_half_width_m": "uniform(0.15, 1.0) x half_width: closest approaches uniform within +- this of the centre",
    "speed_mps": "low uniform(4, 8), high = low + uniform(1, 4)",
    "p_Am": "low log-uniform(50, 150), high = low x uniform(1.5, 3) (log-uniform in between)",
    "water_depth_m": "one of DEPTHS_M, equally likely; the sensors stand on the seabed (few depths: the electric "
                     "field's kernel is tabulated per medium, about a second each, once per process)",
    "exclusions": "0, 1 or 2 circles (equally likely), centres uniform in the region, radius uniform(0.15, 0.4) x "
                  "half_width; redrawn (up to 20 times, then none) until at least 2 k candidates stay free",
}
"""The distribution :func:`sample_site` draws from (each entry independent, in this order)."""

DEPTHS_M = (10.0, 15.0, 20.0, 25.0, 30.0)
"""The water depths a drawn site can have (m)."""

RANGE_M = (100.0, 150.0)
"""Start distance of the site's passages from the region's centre (m): at 4 m/s a passage of S1-P2 (40 s) still
reaches its closest approach."""


@dataclass(frozen=True)
class Site:
    """A site (see the module docstring); lengths in metres, angles in degrees, ``p`` in A m."""

    heading_deg: float
    heading_spread_deg: float
    cpa_m: tuple
    speed_mps: tuple
    p_Am: tuple
    water_depth_m: float
    exclusions: tuple = ()      # ((x, y, radius), ...) relative to the region's centre

    @classmethod
    def from_dict(cls, d):
        """A site from a dict of its fields (the env's ``site`` argument); a ValueError naming ``site`` and the
        field for anything missing, unknown or out of range."""
        if not isinstance(d, dict):
            raise ValueError(f"site must be a dict of {', '.join(cls.__dataclass_fields__)}, got {d!r}")
        unknown = set(d) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"site: unknown field(s) {', '.join(sorted(unknown))}")
        try:
            site = cls(**{k: (tuple(tuple(e) for e in v) if k == "exclusions" else
                              tuple(v) if isinstance(v, (list, tuple)) else v) for k, v in d.items()})
        except TypeError as err:
            raise ValueError(f"site: {err}") from None
        site.validate()
        return site

    def validate(self):
        def pair(name, v, lo, hi):
            if (len(v) != 2 or not all(isinstance(x, (int, float)) and math.isfinite(x) for x in v)
                    or not lo <= v[0] <= v[1] <= hi):
                raise ValueError(f"site.{name} must be [low, high] with {lo:g} <= low <= high <= {hi:g}, got {v!r}")

        for name, v, lo, hi in (("heading_deg", self.heading_deg, -360.0, 720.0),
                                ("heading_spread_deg", self.heading_spread_deg, 0.0, 90.0),
                                ("water_depth_m", self.water_depth_m, 8.0, 11_000.0)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"site.{name} must be a number in [{lo:g}, {hi:g}], got {v!r}")
        pair("cpa_m", self.cpa_m, -RANGE_M[0], RANGE_M[0])
        pair("speed_mps", self.speed_mps, 0.1, 30.0)
        pair("p_Am", self.p_Am, 1e-3, 1e6)
        for e in self.exclusions:
            if len(e) != 3 or not all(math.isfinite(x) for x in e) or e[2] <= 0:
                raise ValueError(f"site.exclusions: each must be (x, y, radius > 0), got {e!r}")

    def to_json(self):
        return {k: (list(map(list, v)) if k == "exclusions" else list(v) if isinstance(v, tuple) else v)
                for k, v in asdict(self).items()}

    def scenario(self, base):
        """The base scenario with the site's water depth, its sensors on the seabed and the site's traffic as
        its ``[prior]`` (the base passage's source depth is kept)."""
        prior = base.prior.model_copy(update={
            "range": RANGE_M,
            "bearing_deg": (self.heading_deg + 180.0 - self.heading_spread_deg,
                            self.heading_deg + 180.0 + self.heading_spread_deg),
            "cpa": tuple(map(float, self.cpa_m)), "speed": tuple(map(float, self.speed_mps)),
            "p": tuple(map(float, self.p_Am))})
        medium = base.medium.model_copy(update={"water_depth": float(self.water_depth_m)})
        sensors = [s.model_copy(update={"position": (0.0, 0.0, -float(self.water_depth_m))}) for s in base.sensors]
        return base.model_copy(update={"prior": prior, "medium": medium, "sensors": sensors,
                                       "name": f"{base.name}-site"})

    def free(self, xy):
        """Which of the points ``xy`` (N, 2) (relative to the centre) lie outside every exclusion."""
        ok = np.ones(len(xy), dtype=bool)
        for x, y, r in self.exclusions:
            ok &= np.hypot(xy[:, 0] - x, xy[:, 1] - y) > r
        return ok

    def features(self, half_width):
        """The site as 10 numbers of order one (the observation's site block, see the env's index table)."""
        h = math.radians(self.heading_deg)
        return np.array([math.cos(h), math.sin(h), self.heading_spread_deg / 30.0,
                         self.cpa_m[0] / half_width, self.cpa_m[1] / half_width,
                         self.speed_mps[0] / 10.0, self.speed_mps[1] / 10.0,
                         math.log10(self.p_Am[0]) / 3.0, math.log10(self.p_Am[1]) / 3.0,
                         self.water_depth_m / 30.0], dtype=np.float32)


SITE_FEATURES = 10


def sample_site(rng, half_width, xy, k):
    """A site from :data:`SITE_DISTRIBUTION` drawn with ``rng``, for a square region of ``half_width`` whose
    candidates are ``xy`` (N, 2, relative to the centre) and ``k`` sensors."""
    heading = rng.uniform(0.0, 360.0)
    spread = rng.uniform(0.0, 30.0)
    centre = rng.uniform(-0.6, 0.6) * half_width
    width = rng.uniform(0.15, 1.0) * half_width
    v0 = rng.uniform(4.0, 8.0)
    v1 = v0 + rng.uniform(1.0, 4.0)
    p0 = math.exp(rng.uniform(math.log(50.0), math.log(150.0)))
    p1 = p0 * rng.uniform(1.5, 3.0)
    depth = float(DEPTHS_M[int(rng.integers(len(DEPTHS_M)))])
    site = dict(heading_deg=heading, heading_spread_deg=spread, cpa_m=(centre - width, centre + width),
                speed_mps=(v0, v1), p_Am=(p0, p1), water_depth_m=depth)
    for _ in range(20):
        count = int(rng.integers(0, 3))
        ex = tuple((float(x), float(y), float(r)) for x, y, r in zip(
            rng.uniform(-half_width, half_width, count), rng.uniform(-half_width, half_width, count),
            rng.uniform(0.15, 0.4, count) * half_width))
        s = Site(**site, exclusions=ex)
        if s.free(xy).sum() >= 2 * k:
            return s
    return Site(**site)
