"""The tracker's settings, resolved once: the scenario's ``[tracker]`` table, explicit overrides, and the
defaults of the scenario and of the array's family, in one frozen object (:class:`TrackerSettings`, built by
:func:`resolve_settings`); the initialiser's grid and the belief before a passage is initialised.

The tracker, the environments, the studies, ``check``, ``design`` and ``sweep`` all run on a
:class:`TrackerSettings`; nothing below them reads the scenario's tracker table again.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import ValidationError

from shipsense.config import TrackerConfig, format_error, load_scenario
from shipsense.errors import ShipsenseError
from shipsense.models.motion_modes import MotionModes, motion_modes
from shipsense.trackers.bank.bank import default_bank
from shipsense.trackers.filters import FilterUnit, get_filter
from shipsense.trackers.fit.robust import Huber

FAMILY_SETTINGS = {
    # the global initialiser's settings per array family, chosen on the wide-prior study and the tracker
    # consistency experiment (docs: Results): electrodes also take the bank's depth prior (z_std)
    "electrodes": {"snr_start": 50.0, "refine": (10, 30, 60), "explore_samples": None, "window_s": 15.0,
                   "rescan": False, "grid_samples": 16},
    "one magnetometer": {"snr_start": 50.0, "refine": (20, 60), "explore_samples": 15, "z_std": None,
                         "window_s": 7.5, "rescan": True, "grid_samples": 16},
    "magnetometers": {"snr_start": 5.0, "refine": (5, 20), "explore_samples": None, "z_std": None,
                      "window_s": 15.0, "rescan": False, "grid_samples": 15},
}
"""The tuned per-family values of :class:`~shipsense.config.TrackerOptions` that default to ``None``: the one
table of them (:func:`family_of` names an array's family)."""


def family_of(types):
    """The family of an array with sensor ``types`` (a sequence of ``magnetometer``, ``electrode``,
    ``accelerometer``): ``electrodes`` if it has any, ``one magnetometer``, or ``magnetometers``."""
    types = list(types)
    if "electrode" in types:
        return "electrodes"
    return "one magnetometer" if types.count("magnetometer") == 1 else "magnetometers"


class TrackerSettings(TrackerConfig):
    """Everything a tracker runs with (the fields of :class:`~shipsense.config.TrackerConfig`), resolved: the
    filter unit, robustness, gap limit, initialiser settings and the studies' bank are filled in, so a
    ``None`` left means "off".  Built by :func:`resolve_settings`; frozen."""

    def filter_unit(self) -> FilterUnit:
        """The tracker's filter unit with its options (the Huber threshold, ``n_pu``)."""
        return unit_of(self.unit, self)

    def study_unit(self) -> FilterUnit:
        """The source studies' filter unit (``filter``) with its options."""
        return unit_of(self.filter, self)

    def motion_modes(self, model) -> MotionModes | None:
        """The IMM's motion modes on ``model`` (:mod:`shipsense.models.motion_modes`) from ``[tracker.motion]``,
        or None for the constant-velocity filter alone (``model = "cv"``, and the studies' bank)."""
        m = self.motion
        if m.model == "cv" or self.method == "bank":
            return None
        share = m.manoeuvre_prior / 3.0
        return motion_modes(model, turn_rate=math.radians(m.turn_rate_deg_s), turn_accel=m.turn_accel,
                            speed_accel=m.speed_accel, body_fixed=m.hull_share, sojourn_cv=m.sojourn_straight_s,
                            sojourn_manoeuvre=m.sojourn_manoeuvre_s, initial=(1.0 - m.manoeuvre_prior, share, share,
                                                                              share))

    def huber(self, noise) -> Huber | None:
        """The robust fits' noise model (None unless ``robust``): Huber's cost at ``huber_gamma`` under the
        scenario's contaminated noise ``noise`` (a :class:`~shipsense.config.NoiseConfig`), or Gaussian."""
        if not self.robust:
            return None
        if noise.model == "contaminated":
            return Huber(gamma=self.huber_gamma, eps=noise.eps, scale=noise.outlier_scale)
        return Huber(gamma=self.huber_gamma)


def unit_of(name, settings) -> FilterUnit:
    """Filter unit ``name`` with the options ``settings`` holds for it."""
    options = {"puekf": {"n_pu": settings.n_pu}, "huber_ukf": {"gamma": settings.huber_gamma}}.get(name, {})
    return get_filter(name, **options)


def resolve_settings(scenario, sensors=None, **overrides) -> TrackerSettings:
    """The tracker's settings for ``scenario`` (a :class:`~shipsense.config.Scenario` or a name/path) and its
    sensors ``sensors`` (ids; default all): its ``[tracker]`` table, then ``overrides`` (any field of
    :class:`~shipsense.config.TrackerConfig`, validated like the file), then the defaults: ``robust`` when the
    noise model is contaminated, a gap limit of 10 periods, the array family's initialiser settings
    (:data:`FAMILY_SETTINGS`), the default bank, and the unit (``ukf``, ``huber_ukf`` when robust; the
    studies' ``filter`` with ``method = "bank"``).

    Raises :class:`~shipsense.errors.ShipsenseError` naming the option on a bad value.
    """
    if isinstance(scenario, TrackerSettings):
        raise TypeError("resolve_settings takes a scenario, not settings")
    sc = load_scenario(scenario)
    given = sc.tracker.model_dump(exclude_unset=True) if sc.tracker is not None else {}
    try:
        cfg = TrackerConfig.model_validate({**given, **overrides})
    except ValidationError as err:
        raise ShipsenseError(format_error(err, "tracker options")) from None
    types = [s.type for s in sc.sensors if sensors is None or s.id in sensors]
    bank = cfg.bank if cfg.bank is not None else default_bank()
    robust = cfg.robust if cfg.robust is not None else sc.noise.model == "contaminated"
    fill = {"robust": bool(robust), "bank": bank,
            "gap_limit_s": cfg.gap_limit_s if cfg.gap_limit_s is not None else 10.0 * sc.period}
    family = dict(FAMILY_SETTINGS[family_of(types)])
    family.setdefault("z_std", bank.z_std)
    fill.update({k: v for k, v in family.items() if getattr(cfg, k) is None})
    if cfg.unit is None:
        fill["unit"] = cfg.filter if cfg.method == "bank" else ("huber_ukf" if robust else "ukf")
    return TrackerSettings.model_validate({**cfg.model_dump(), **fill})


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
