"""The several-ship tracker's settings (:class:`ShipsSettings`), validated once when made."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields


@dataclass(frozen=True)
class ShipsSettings:
    """How :class:`~shipsense.trackers.ships.tracker.ShipsTracker` counts ships.

    Parameters
    ----------
    max_ships : int
        Most ships tracked at once: 1 (the one-ship tracker alone) or 2.
    window_s : float
        Window of the birth test, s: the residual of the current model over the last ``window_s`` seconds is
        searched for a second source, and the one- and two-ship filters are compared over it.
    every_s : float
        How often the birth test runs while a passage has one ship, s.
    penalty : float
        Multiplier of the BIC penalty :math:`\\tfrac12 n_1 \\ln N` (``n_1`` the one-ship state's dimension, ``N``
        the measurements in the window) that the two-ship model's windowed predictive log-likelihood must beat.
    min_separation_m : float
        A second source fitted nearer than this to the first ship (at the window's middle), m, is the first
        ship's own model error, not a ship.
    inflate : float
        Factor on the joint fit's covariance (the inverse of its Gauss-Newton information plus the passage
        prior's) when the joint filter starts from it at a birth.
    refit_sd_m : float
        The joint state is refitted on the recent window (every ``every_s`` seconds) while both ships' one-sample
        position standard deviations (as for ``death_sd_m``) are at most this, m; after that the joint filter
        carries the lines on (a window refit of a fading ship wanders).
    death_sd_m : float
        A ship has left the array's reach when the position standard deviation that one sample of its own
        field gives (its information contribution, :math:`\\sqrt{\\mathrm{tr}(I_s^{-1}) / 2}`) exceeds this, m.
        Loose by default: a ship located to a few metres by the samples it has left behind still counts as
        present, and only one whose own field no longer tells where it is, at the edge of the array's reach,
        ends.
    death_samples : int
        Consecutive samples out of reach, after having been within it, before a ship dies.
    """

    max_ships: int = 2
    window_s: float = 10.0
    every_s: float = 2.5
    penalty: float = 1.0
    min_separation_m: float = 10.0
    inflate: float = 2.0
    refit_sd_m: float = 5.0
    death_sd_m: float = 200.0
    death_samples: int = 6

    def __post_init__(self):
        checks = {
            "max_ships": lambda v: isinstance(v, int) and v in (1, 2),
            "window_s": lambda v: 0 < v <= 1e4, "every_s": lambda v: 0 < v <= 1e4,
            "penalty": lambda v: 0 <= v <= 1e3, "min_separation_m": lambda v: 0 <= v <= 1e4,
            "inflate": lambda v: 1 <= v <= 1e6, "refit_sd_m": lambda v: 0 < v <= 1e6,
            "death_sd_m": lambda v: 0 < v <= 1e6,
            "death_samples": lambda v: isinstance(v, int) and 1 <= v <= 10 ** 6,
        }
        bounds = {"max_ships": "1 or 2", "window_s": "in (0, 1e4] s", "every_s": "in (0, 1e4] s",
                  "penalty": "in [0, 1000]", "min_separation_m": "in [0, 1e4] m", "inflate": "in [1, 1e6]",
                  "refit_sd_m": "in (0, 1e6] m",
                  "death_sd_m": "in (0, 1e6] m", "death_samples": "an integer in [1, 1e6]"}
        for f in fields(self):
            v = getattr(self, f.name)
            ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and checks[f.name](v)
            if not ok:
                raise ValueError(f"ships.{f.name}: must be {bounds[f.name]}, got {v!r}")
