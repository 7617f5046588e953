"""The tracker's options, the global initialiser's settings per array family, and the
belief before a passage is initialised.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TrackerOptions:
    """Options of :class:`Tracker` (defaults: the project's measured settings, EXPERIMENTS.md).

    ``window_s``, ``snr_start``, ``refine``, ``explore_samples``, ``grid_samples``,
    ``z_std`` and ``rescan`` default to the global initialiser's settings for
    the array's family (:func:`family_options`).
    """

    method: str = "tracker"
    unit: str | None = None
    robust: bool | None = None
    window_s: float | None = None
    snr_start: float | None = None
    refine: tuple | int | None = None
    explore_samples: int | None = None
    grid_samples: int | None = None
    z_std: float | None = None
    keep_init: int = 5
    keep: int = 3
    refit_every: int | None = 20
    through_peak: float | None = 0.5
    nis_window: int = 10
    nis_limit: float = 3.0
    max_restarts: int = 4
    collapse: float | None = 0.25
    ambiguity_nats: float = 10.0
    report_nats: float = 3.0
    report_distance_m: float = 20.0
    distinct_m: float = 15.0
    gof: float = 0.01
    inflate: float = 2.0
    history: int = 1000
    gap_limit_s: float | None = None
    consistency_window: int | None = 20
    consistency_level: float = 0.01
    rescan: bool | None = None

    def __post_init__(self):
        if self.method not in ("tracker", "bank"):
            raise ValueError(f"method must be 'tracker' or 'bank', got {self.method!r}")
        for name in ("window_s", "nis_window", "keep_init", "keep", "history", "max_restarts"):
            v = getattr(self, name)
            if v is None and name == "window_s":
                continue
            if not (np.isfinite(v) and v > 0) and not (name == "max_restarts" and v == 0):
                raise ValueError(f"{name} must be a positive number, got {v!r}")
        if self.consistency_window is not None and not (
                isinstance(self.consistency_window, int | np.integer) and self.consistency_window >= 2):
            raise ValueError(f"consistency_window must be an integer of at least 2 or None, "
                             f"got {self.consistency_window!r}")
        if not (np.isfinite(self.consistency_level) and 0.0 < self.consistency_level < 1.0):
            raise ValueError(f"consistency_level must lie strictly between 0 and 1, got {self.consistency_level!r}")
        if self.grid_samples is not None and (isinstance(self.grid_samples, bool) or not (
                isinstance(self.grid_samples, int | np.integer) and self.grid_samples >= 1)):
            raise ValueError(f"grid_samples must be a positive integer or None, got {self.grid_samples!r}")
        if self.keep > self.keep_init:
            raise ValueError(f"keep ({self.keep}) cannot exceed keep_init ({self.keep_init})")


def family_options(model, scenario):
    """The global initialiser's settings for an array's family, as measured on the wide-prior study
    (EXPERIMENTS.md): envelope electrodes start at SNR 50 with the bank's depth prior and refine (10, 30, 60)
    grid minima; one magnetometer starts at SNR 50 and explores (20, 60) minima on 15 samples; several
    magnetometers start at SNR 5 and refine (5, 20), their grid searched on every second sample of the
    15 s window (``grid_samples`` 15 of S2's 30; the others at least 16: 19 of S0's 75, where 15 lost two of
    1,000 faulty passages, and 19 of S1's 38; EXPERIMENTS.md).  The window lasts 15 s, 7.5 s for one magnetometer:
    at SNR 400 a 15 s window left 5 of 60 S0 passages (seed 100) still initialising when they ended, and
    7.5 s converged on 98 % of them (87 % with 15 s) with the refits correcting the early fits; on the wide
    study's one-magnetometer passages 7.5 s converged on 98 of 100, 15 s on 97.  The single magnetometer's
    start was SNR 400 (the wide study's setting, where an early window's wrong fit stuck with the bank); with
    the tracker's refits an earlier start is corrected, and S0 passages that end before their closest
    approach -- whose CRLB at the end is still 0.2-5 m -- get a track: on 300 S0 passages (seeds 0 and 1)
    convergence 0.917 / 0.950 at SNR 400, 0.987 / 0.987 at SNR 50, with the approaching passages at 1.000
    either way (EXPERIMENTS.md).  One magnetometer also rescans (see :class:`Tracker`): on 300 S0 passages
    (seed 0) convergence 0.987 -> 0.990; with it the tracker converges on every one of 975 S0 passages (of
    1,000) whose position CRLB where convergence is judged allows it, the failures all ending 100-140 m out
    with a CRLB sd of 4.1-42 m there.  It costs 5.3 times the CPU time (200 S0 passages, idle machine: 0.243
    -> 1.293 s per passage; EXPERIMENTS.md); ``rescan=False`` for speed.  The other families converge on
    0.999-1.000 without it."""
    types = list(model.array.types)
    if "electrode" in types:
        z_std = scenario.tracker.bank.z_std if scenario.tracker is not None and scenario.tracker.bank else 1.0
        return {"snr_start": 50.0, "refine": (10, 30, 60), "explore_samples": None, "z_std": z_std, "window_s": 15.0,
                "rescan": False, "grid_samples": 16}
    if types.count("magnetometer") == 1:
        return {"snr_start": 50.0, "refine": (20, 60), "explore_samples": 15, "z_std": None, "window_s": 7.5,
                "rescan": True, "grid_samples": 16}
    return {"snr_start": 5.0, "refine": (5, 20), "explore_samples": None, "z_std": None, "window_s": 15.0,
            "rescan": False, "grid_samples": 15}


def initial_grid(sc):
    """The initialiser's grid of start ranges and speeds from the scenario's passage prior (or defaults)."""
    if sc.prior is not None:
        return {"ranges": np.geomspace(20.0, 1.2 * sc.prior.range[1], 8), "speeds": np.linspace(*sc.prior.speed, 3)}
    return {"ranges": np.geomspace(20.0, 500.0, 8), "speeds": np.array([2.0, 6.0, 10.0])}


def prior_belief(model, sc, bank):
    """The belief before a passage is initialised (SI): the array centroid, at rest, with a spread whose 95 %
    ellipse reaches the passage prior's farthest start (500 m without a prior) and velocities of its top speed."""
    labels = model.labels
    mean, std = np.zeros(model.n), np.zeros(model.n)
    mean[:2] = model.array.positions[:, :2].mean(axis=0)
    r_max = sc.prior.range[1] if sc.prior is not None else 500.0
    v_max = sc.prior.speed[1] if sc.prior is not None else 12.0
    std[:2] = r_max / np.sqrt(-2.0 * np.log(0.05))
    std[2:4] = v_max / 1.96
    if "mx" in labels:
        m_max = sc.prior.moment[1] if sc.prior is not None and sc.prior.moment else bank.moment_std
        std[labels.index("mx"):labels.index("mx") + 3] = m_max
    if "z" in labels:
        iz = labels.index("z")
        mean[iz], std[iz] = model.source_z, bank.z_std
        p_max = sc.prior.p[1] if sc.prior is not None and sc.prior.p else bank.p_std
        mean[iz + 1], std[iz + 1] = 0.5 * p_max, p_max
    return mean, np.diag(std * std)
