"""Passage simulator: truth states and sensor measurements, batched over runs and steps.

:func:`simulate` draws one passage per run (the scenario's nominal passage, or
random passages from its prior), evaluates every sensor with the one
measurement model (:class:`shipsense.physics.array.SensorArray`) in a single
batched call, and adds noise, outliers and dropouts.  Electrode envelopes can
come from the raw shaft-rate chain and accelerometer bearings from the
eigenvector chain instead of the shortcut models.

Manoeuvres (the scenario's ``[manoeuvres]`` table, :mod:`shipsense.physics.manoeuvre`): the nominal
passage makes the scheduled turns and speed changes, random passages draw theirs from
``[manoeuvres.random]``; the motion is integrated exactly, the electric dipole stays along the keel and the
body-fixed share of the magnetic moment turns with the hull.  Without the table the passages are straight,
as they always were.

Traffic (the scenario's ``[traffic]`` table, :mod:`shipsense.config.traffic`): a run can hold several ships.
Ship 0 is the passage above; its companions are drawn from ``[prior]`` or placed by a named encounter with it
(:mod:`shipsense.physics.traffic`), each with its own source, and every sensor reads the sum of their noiseless
readings (the nearest ship's bearing on bearing channels), with the noise added once.  Random manoeuvres
(``[manoeuvres.random]``) are drawn for every ship; the nominal passage's scheduled manoeuvres belong to ship 0
only (a named encounter is placed on ship 0's straight track, and a manoeuvre of either ship moves their
closest approach).  The seismic chain hears the nearest ship; the raw envelope chain is for one ship.

Reproducibility: each random ingredient (prior, noise, outliers, dropouts,
chains, manoeuvres, traffic) has its own stream spawned from ``seed`` (the manoeuvres' and then the
traffic's last, so that adding them moved no earlier draw: ship 0's passage, the noise and everything else
are the same with and without companions), and every draw has the runs
axis first, so run ``i`` of a batch does not depend on how many runs the batch
has (except the heavy-tailed seismic option, which is reproducible but not
prefix-stable).
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from shipsense.config import Scenario, load_scenario
from shipsense.config.manoeuvres import nominal_manoeuvres
from shipsense.config.traffic import span
from shipsense.physics.array import SensorArray
from shipsense.physics.envelope import envelope_chain, magnitude_envelope_chain, raw_channels
from shipsense.physics.manoeuvre import LABELS, SPEED_CHANGE, TURN, Manoeuvres, manoeuvring_motion, turned_moment
from shipsense.physics.motion import cv_positions
from shipsense.physics.noise import dropout_mask
from shipsense.physics.seismic import eigen_bearing, simulate_vibration, wrap_axial
from shipsense.physics.traffic import GEOMETRIES, companion_tracks, superposed_readings

STATE_LABELS = ("x", "y", "vx", "vy", "z", "mx", "my", "mz", "p")
"""Columns of :attr:`Simulation.truth`: position, velocity, source height, magnetic moment, electric moment."""

_STREAMS = ("prior", "prior_dir", "noise", "outlier", "dropout", "envelope", "seismic", "seismic_tail", "manoeuvre",
            "traffic")
_TRAFFIC_STREAMS = ("count", "geometry", "prior", "prior_dir", "source", "source_dir", "manoeuvre")


@dataclass(frozen=True)
class Simulation:
    """Result of :func:`simulate`.

    Attributes
    ----------
    scenario : Scenario
    array : SensorArray
    times : ndarray, shape (steps,)
        Sample times, s.
    truth : ndarray, shape (runs, steps, 9)
        True states, columns :data:`STATE_LABELS` (SI).
    clean : ndarray, shape (runs, steps, m)
        Noise-free measurements (SI; bearings in rad).
    measurements : ndarray, shape (runs, steps, m)
        Noisy measurements; NaN where ``mask`` is False.
    mask : ndarray of bool, shape (runs, steps, m)
        True where a component was recorded.
    heading : ndarray, shape (runs, steps)
        True course angle ``atan2(v_y, v_x)`` (from east, counter-clockwise), in (-pi, pi], rad.
    speed : ndarray, shape (runs, steps)
        True speed, m/s.
    manoeuvre : ndarray of int8, shape (runs, steps)
        What the ship is doing at each sample: index into
        :data:`~shipsense.physics.manoeuvre.LABELS` (straight, turn, speed change).
    manoeuvres : Manoeuvres
        Every run's manoeuvre schedule (no manoeuvre: an empty one).
    companions : ndarray, shape (runs, ships - 1, steps, 9), optional
        True states of ships 1, 2, ... (the ``[traffic]`` table; None with one ship); a run's ships beyond
        its ``ship_count`` do not sail (their rows are drawn but read nothing).
    ship_count : ndarray of int, shape (runs,), optional
        Number of ships in each run (None: one).
    """

    scenario: Scenario
    array: SensorArray
    times: np.ndarray
    truth: np.ndarray
    clean: np.ndarray
    measurements: np.ndarray
    mask: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    manoeuvre: np.ndarray
    manoeuvres: Manoeuvres
    companions: np.ndarray | None = None
    ship_count: np.ndarray | None = None
    STATE_LABELS = STATE_LABELS    # (the truth's columns; a class constant, not a field)

    @property
    def channels(self):
        """(sensor id, channel name) of each measurement column."""
        return self.array.channels

    @property
    def runs(self) -> int:
        return self.truth.shape[0]

    @property
    def positions(self) -> np.ndarray:
        """True source positions (runs, steps, 3)."""
        return self.truth[..., [0, 1, 4]]

    @property
    def ships_present(self) -> np.ndarray:
        """Which ships sail in each run, bool (runs, ships); ship 0 always."""
        if self.companions is None:
            return np.ones((self.runs, 1), dtype=bool)
        return np.arange(1 + self.companions.shape[1])[None, :] < self.ship_count[:, None]

    @property
    def ships(self) -> np.ndarray:
        """True states of every ship (runs, ships, steps, 9), ship 0 first (``truth``); NaN for a ship that
        does not sail in a run."""
        if self.companions is None:
            return self.truth[:, None]
        every = np.concatenate([self.truth[:, None], self.companions], axis=1)
        return np.where(self.ships_present[:, :, None, None], every, np.nan)

    def save_npz(self, path):
        """Write arrays and channel labels to a NumPy ``.npz`` file.

        Besides the measurements and the truth: ``heading``, ``speed`` and ``manoeuvre`` (per sample, with
        ``manoeuvre_labels``), and the manoeuvre schedule as JSON (``manoeuvre_schedule``: one list of
        records per run, :meth:`~shipsense.physics.manoeuvre.Manoeuvres.to_records`, with
        ``body_fixed_share``).  With several ships (``[traffic]``): ``ships`` (:attr:`ships`) and
        ``ship_count``.
        """
        schedule = {"body_fixed_share": self.manoeuvres.body_fixed_share, "runs": self.manoeuvres.to_records()}
        np.savez_compressed(
            path, times=self.times, truth=self.truth, clean=self.clean, measurements=self.measurements,
            mask=self.mask, state_labels=np.array(STATE_LABELS),
            sensor_ids=np.array([c[0] for c in self.channels]), channel_names=np.array([c[1] for c in self.channels]),
            sensor_positions=self.array.positions, scenario_toml_name=np.array(self.scenario.name),
            heading=self.heading, speed=self.speed, manoeuvre=self.manoeuvre, manoeuvre_labels=np.array(LABELS),
            manoeuvre_schedule=np.array(json.dumps(schedule)),
            **({} if self.companions is None else {"ships": self.ships, "ship_count": self.ship_count}),
        )


def _passages(sc: Scenario, runs: int, random: bool, streams) -> np.ndarray:
    """Initial truth (runs, 9): x, y, vx, vy, z, mx, my, mz, p."""
    x0 = np.zeros((runs, 9))
    ps = sc.passage
    x0[:, 4] = ps.z
    if not random:
        x0[:, 0:2] = ps.start
        x0[:, 2:4] = ps.velocity
        x0[:, 5:8] = ps.moment if ps.moment is not None else 0.0
        x0[:, 8] = ps.p if ps.p is not None else 0.0
        return x0
    pr = sc.prior
    if pr is None:
        raise ValueError(f"scenario {sc.name!r} has no [prior] section: random passages need one")
    u = streams["prior"].random((runs, 6))
    centre = array_centre(sc)
    rng_ = pr.range[0] + (pr.range[1] - pr.range[0]) * u[:, 0]
    brg = np.deg2rad(pr.bearing_deg[0] + (pr.bearing_deg[1] - pr.bearing_deg[0]) * u[:, 1])
    start = centre + rng_[:, None] * np.stack([np.cos(brg), np.sin(brg)], axis=-1)
    if pr.cpa is not None:   # closest approach to the centroid uniform in [cpa_min, cpa_max]
        cpa = pr.cpa[0] + (pr.cpa[1] - pr.cpa[0]) * u[:, 2]
        course = brg + np.pi + np.arcsin(np.clip(cpa / rng_, -1.0, 1.0))
    else:
        offset = pr.course_offset_deg[0] + (pr.course_offset_deg[1] - pr.course_offset_deg[0]) * u[:, 2]
        course = brg + np.pi + np.deg2rad(offset)
    speed = pr.speed[0] + (pr.speed[1] - pr.speed[0]) * u[:, 3]
    x0[:, 0:2] = start
    x0[:, 2:4] = speed[:, None] * np.stack([np.cos(course), np.sin(course)], axis=-1)
    prior_source(pr, u[:, 4], u[:, 5], streams["prior_dir"], x0)
    return x0


def prior_source(pr, u_moment, u_p, directions, x):
    """Write a source drawn from the passage prior ``pr`` into states ``x`` (..., 9): the moment's size
    log-uniform in ``pr.moment`` at the uniforms ``u_moment`` (...), its direction isotropic (normals of the
    generator ``directions``), and the electric dipole log-uniform in ``pr.p`` at ``u_p`` (...); the parts the
    prior does not give stay as they are."""
    if pr.moment is not None:
        mag = np.exp(np.log(pr.moment[0]) + np.log(pr.moment[1] / pr.moment[0]) * u_moment)
        d = directions.standard_normal(u_moment.shape + (3,))
        x[..., 5:8] = mag[..., None] * d / np.linalg.norm(d, axis=-1, keepdims=True)
    if pr.p is not None:
        x[..., 8] = np.exp(np.log(pr.p[0]) + np.log(pr.p[1] / pr.p[0]) * u_p)


def array_centre(sc: Scenario) -> np.ndarray:
    """The centroid (2,) of the scenario's sensors in the horizontal plane, m: the centre of its passages."""
    return np.array([s.position[:2] for s in sc.sensors]).mean(axis=0)


def sample_passages(scenario, runs: int, seed: int = 0, random: bool = True) -> np.ndarray:
    """Initial truth states (runs, 9) of passages: drawn from the scenario's prior (or the nominal one).

    Columns :data:`STATE_LABELS`; the same draws :func:`simulate` makes for ``seed``.
    """
    return sample_manoeuvring_passages(scenario, runs, seed, random)[0]


def sample_manoeuvring_passages(scenario, runs: int, seed: int = 0, random: bool = True):
    """Initial truth states (runs, 9) of passages and their manoeuvre schedule: :func:`sample_passages` and
    the manoeuvres of the scenario's ``[manoeuvres]`` table (random passages' draws from
    ``[manoeuvres.random]``, the nominal passage's schedule; none without the table), the same draws
    :func:`simulate` makes for ``seed``.

    Returns
    -------
    x0 : ndarray, shape (runs, 9)
    manoeuvres : Manoeuvres
    """
    sc = load_scenario(scenario)
    seeds = np.random.SeedSequence(seed).spawn(len(_STREAMS))
    streams = {name: np.random.default_rng(s) for name, s in zip(_STREAMS, seeds)}
    x0 = _passages(sc, runs, random, streams)
    return x0, passage_manoeuvres(sc, x0, random, streams)


def _random_manoeuvres(sc: Scenario, x0, streams) -> Manoeuvres:
    """One manoeuvre or none per random passage, drawn from ``[manoeuvres.random]`` (runs axis first, so
    prefix-stable): a turn of uniform rate and total turn to port or starboard, or a speed change of
    log-uniform factor at a uniform acceleration, starting uniformly in the window."""
    cfg = sc.manoeuvres
    runs = x0.shape[0]
    if cfg is None or cfg.random is None:
        return Manoeuvres.none(runs, 0.0 if cfg is None else cfg.body_fixed_share)
    rnd = cfg.random
    u = streams["manoeuvre"].random((runs, 6))
    window = rnd.start if rnd.start is not None else (0.0, sc.period * (sc.steps - 1))
    start = window[0] + (window[1] - window[0]) * u[:, 5]
    turn = u[:, 1] < rnd.turn_share
    rate = np.deg2rad(rnd.turn_rate_deg_s[0] + (rnd.turn_rate_deg_s[1] - rnd.turn_rate_deg_s[0]) * u[:, 2])
    total = np.deg2rad(rnd.turn_deg[0] + (rnd.turn_deg[1] - rnd.turn_deg[0]) * u[:, 3])
    side = np.where(u[:, 4] < 0.5, 1.0, -1.0)
    f_lo, f_hi = rnd.speed_factor
    factor = np.exp(np.log(f_lo) + np.log(f_hi / f_lo) * u[:, 3])
    acc = rnd.acceleration[0] + (rnd.acceleration[1] - rnd.acceleration[0]) * u[:, 2]
    speed = np.hypot(x0[:, 2], x0[:, 3])
    change = speed * (factor - 1.0)
    duration = np.where(turn, total / rate, np.abs(change) / acc)
    kind = np.where(u[:, 0] < rnd.probability, np.where(turn, TURN, SPEED_CHANGE), 0)
    return Manoeuvres.from_slots(kind[:, None], start[:, None], duration[:, None],
                                 np.where(turn, side * rate, 0.0)[:, None],
                                 np.where(turn, 0.0, np.sign(change) * acc)[:, None], cfg.body_fixed_share)


def passage_manoeuvres(sc: Scenario, x0, random: bool, streams) -> Manoeuvres:
    """The manoeuvre schedule of passages starting at ``x0`` (runs, 9): the nominal passage's scheduled
    manoeuvres, or random passages' draws from ``[manoeuvres.random]``."""
    if random:
        return _random_manoeuvres(sc, x0, streams)
    return nominal_manoeuvres(sc.manoeuvres, sc.passage.velocity, x0.shape[0])


def manoeuvring_truth(x0, manoeuvres: Manoeuvres, times):
    """True states (runs, K, 9) (columns :data:`STATE_LABELS`), course (unwrapped, rad) and labels (runs, K)
    of passages starting at ``x0`` (runs, 9) with a schedule: exact motion, the moment's body-fixed share
    turned with the hull (:mod:`shipsense.physics.manoeuvre`)."""
    pos, vel, course, label = manoeuvring_motion(x0[:, 0:2], x0[:, 2:4], manoeuvres, times)
    truth = np.repeat(x0[:, None, :], np.shape(times)[-1], axis=1)
    truth[..., 0:2], truth[..., 2:4] = pos, vel
    turn = course - np.arctan2(x0[:, None, 3], x0[:, None, 2])        # the hull's turn since t = 0
    truth[..., 5:8] = turned_moment(x0[:, None, 5:8], turn, manoeuvres.body_fixed_share)
    return truth, course, label


def keel_dipole(velocity, p):
    """Horizontal electric dipole ``p v/|v|`` along the keel, (..., 3)."""
    speed = np.linalg.norm(velocity, axis=-1, keepdims=True)
    d = p[..., None] * velocity / np.where(speed > 0, speed, 1.0)
    return np.concatenate([d, np.zeros(d.shape[:-1] + (1,))], axis=-1)


def simulation_bytes(sc: Scenario, runs: int) -> float:
    """Memory a :func:`simulate` of ``runs`` runs allocates, roughly (bytes): truth, clean field, noise,
    measurements and mask, float64, per run and step, and each companion ship's truth and field (the commands
    refuse work above a limit before any of it is allocated)."""
    m, n = sc.array().n_channels, len(STATE_LABELS)
    others = 0 if sc.traffic is None else sc.traffic.max_ships - 1
    return float(runs) * sc.steps * (5 * m + n + others * (2 * m + n)) * 8.0


def simulate(scenario, runs: int | None = None, seed: int | None = None, *, random: bool = False) -> Simulation:
    """Simulate passages past a scenario's array.

    Parameters
    ----------
    scenario : Scenario, str or path
        A scenario object, a shipped scenario name or a TOML path.
    runs : int, optional
        Monte Carlo runs (default: the scenario's ``runs``).
    seed : int, optional
        Seed (default: the scenario's ``seed``).
    random : bool
        Draw each run's passage from the scenario's ``[prior]`` instead of
        repeating the nominal passage.

    Returns
    -------
    Simulation

    Examples
    --------
    >>> sim = simulate("S0", runs=4, seed=1)
    >>> sim.measurements.shape
    (4, 300, 3)
    """
    sc = load_scenario(scenario)
    runs = sc.runs if runs is None else int(runs)
    if runs < 1:
        raise ValueError(f"runs must be >= 1, got {runs}")
    seed = sc.seed if seed is None else int(seed)
    seeds = np.random.SeedSequence(seed).spawn(len(_STREAMS))
    streams = {name: np.random.default_rng(s) for name, s in zip(_STREAMS, seeds)}
    array = sc.array()
    times = sc.times
    x0 = _passages(sc, runs, random, streams)
    manoeuvres = passage_manoeuvres(sc, x0, random, streams)

    truth, heading, label = _ship_truth(x0, manoeuvres, times)
    speed = np.hypot(truth[..., 2], truth[..., 3])
    sources = truth[..., [0, 1, 4]]
    moments = truth[..., 5:8]
    dipoles = keel_dipole(truth[..., 2:4], truth[..., 8])
    clean = array.measure(sources, moments, dipoles)
    companions = count = None
    heard = np.broadcast_to(sources[..., None, :], sources.shape[:-1] + (array.group("accelerometer").size, 3))
    if sc.traffic is not None and sc.traffic.max_ships > 1:
        tstreams = {name: np.random.default_rng(s)
                    for name, s in zip(_TRAFFIC_STREAMS, seeds[_STREAMS.index("traffic")].spawn(len(_TRAFFIC_STREAMS)))}
        companions, count = _companions(sc, x0, random, tstreams, times)
        clean, heard = _superpose(array, truth, clean, companions, count)

    m = array.n_channels
    std = sc.channel_std
    shape = (runs, sc.steps, m)
    noise = std * streams["noise"].standard_normal(shape)
    if sc.noise.model == "contaminated":
        outlier = streams["outlier"].random(shape) < sc.noise.eps
        noise = np.where(outlier, sc.noise.outlier_scale * noise, noise)
    meas = clean + noise

    axial = array.axial
    if axial.any():
        if sc.seismic.mode == "chain":
            meas[..., axial] = _seismic_chain(sc, array, heard, streams)
        elif sc.seismic.bias_deg:
            meas[..., axial] += np.deg2rad(sc.seismic.bias_deg)
        meas[..., axial] = wrap_axial(meas[..., axial])
    if sc.envelope_chain.mode == "raw" and any(t == "electrode" and k in ("envelope", "magnitude")
                                               for t, k in zip(array.types, array.kinds)):
        cols, env = _envelope_chain(sc, array, x0, manoeuvres, streams)
        meas[..., cols] = env

    mask = dropout_mask(streams["dropout"], shape, sc.noise.dropout)
    meas = np.where(mask, meas, np.nan)
    return Simulation(sc, array, times, truth, clean, meas, mask, heading, speed, label, manoeuvres, companions,
                      count)


def _ship_truth(x0, manoeuvres: Manoeuvres, times):
    """True states (runs, K, 9), heading and manoeuvre labels (runs, K) of passages starting at ``x0`` (runs,
    9): straight, or manoeuvring by the schedule."""
    runs, steps = x0.shape[0], np.shape(times)[-1]
    if manoeuvres.any:
        truth, course, label = manoeuvring_truth(x0, manoeuvres, times)
        heading = np.arctan2(np.sin(course), np.cos(course))
    else:
        truth = np.repeat(x0[:, None, :], steps, axis=1)
        truth[..., 0:2] = cv_positions(x0[:, 0:2], x0[:, 2:4], times)
        heading = np.broadcast_to(np.arctan2(x0[:, None, 3], x0[:, None, 2]), (runs, steps)).copy()
        label = np.zeros((runs, steps), dtype=np.int8)
    return truth, heading, label


def _uniform(u, lo_hi):
    """``lo + (hi - lo) u`` of a ``(lo, hi)`` pair (broadcast against ``u``)."""
    lo, hi = np.asarray(lo_hi, dtype=float)[..., 0], np.asarray(lo_hi, dtype=float)[..., 1]
    return lo + (hi - lo) * u


def _companions(sc: Scenario, x0, random: bool, tstreams, times):
    """True states (runs, C, K, 9) of ship 0's companions and the ship count (runs,) of every run, drawn from
    the traffic's own streams ``tstreams`` (runs axis first: prefix-stable)."""
    cfg = sc.traffic
    runs, C = x0.shape[0], cfg.max_ships - 1
    lo, hi = span(cfg.count)
    count = np.minimum(lo + np.floor((hi - lo + 1) * tstreams["count"].random(runs)).astype(int), hi)
    geometry = np.array([GEOMETRIES.index(g) for g in cfg.geometries])
    u = tstreams["geometry"].random((runs, C, 5))
    separation = _uniform(u[..., 0], span(cfg.separation))
    offset = _uniform(u[..., 1], span(cfg.time_offset))
    angle = np.deg2rad(_uniform(u[..., 2], span(cfg.crossing_angle_deg)))
    ratio = _uniform(u[..., 3], [cfg.ratio_span(g) for g in cfg.geometries])
    side = np.where(u[..., 4] < 0.5, 1.0, -1.0)
    xc = np.repeat(x0[:, None, :], C, axis=1)
    named = geometry > 0
    if named.any():
        centre = array_centre(sc)
        xc[..., 0:2], xc[..., 2:4] = companion_tracks(x0[:, None, :], centre, geometry, separation, offset, angle,
                                                      ratio, side)
        if random:   # a source of its own, drawn from the prior as ship 0's is
            us = tstreams["source"].random((runs, C, 2))
            prior_source(sc.prior, us[..., 0], us[..., 1], tstreams["source_dir"], xc)
    if not named.all():
        drawn = _passages(sc, runs * C, True, tstreams).reshape(runs, C, -1)
        drawn[..., 0:2] -= drawn[..., 2:4] * offset[..., None]       # starting its passage time_offset later
        xc = np.where(named[None, :, None], xc, drawn)
    flat = xc.reshape(runs * C, -1)
    mcfg = sc.manoeuvres
    if random and mcfg is not None and mcfg.random is not None:
        manoeuvres = _random_manoeuvres(sc, flat, tstreams)
    else:
        manoeuvres = Manoeuvres.none(runs * C, 0.0 if mcfg is None else mcfg.body_fixed_share)
    truth = _ship_truth(flat, manoeuvres, times)[0]
    return truth.reshape((runs, C) + truth.shape[1:]), count


def _superpose(array: SensorArray, truth, clean, companions, count):
    """The readings of every sailing ship together (:func:`~shipsense.physics.traffic.superposed_readings`),
    (runs, K, m), and the source each accelerometer hears, the nearest sailing ship's (runs, K, S_acc, 3)."""
    ships = np.concatenate([truth[:, None], companions], axis=1)
    src = ships[..., [0, 1, 4]]
    readings = np.concatenate([clean[:, None], array.measure(
        src[:, 1:], ships[:, 1:, :, 5:8], keel_dipole(ships[:, 1:, :, 2:4], ships[:, 1:, :, 8]))], axis=1)
    present = np.arange(ships.shape[1])[None, :] < count[:, None]
    acc = array.group("accelerometer")
    dist = np.linalg.norm(src[..., None, :] - array.positions[acc], axis=-1)        # (runs, S, K, S_acc)
    dist = np.where(present[:, :, None, None], dist, np.inf)
    nearest = np.argmin(dist, axis=1)                                               # (runs, K, S_acc)
    heard = np.take_along_axis(src[:, :, :, None, :], nearest[:, None, :, :, None], axis=1)[:, 0]
    channel_nearest = nearest[..., np.searchsorted(acc, array.channel_sensor[array.axial])]
    return superposed_readings(readings, present, array.axial, channel_nearest), heard


RAW_CHUNK_BYTES = 4 * 2**20
"""Raw shaft-rate samples the envelope chain simulates at once (runs beyond it go in chunks)."""


def _envelope_chain(sc: Scenario, array: SensorArray, x0, manoeuvres: Manoeuvres, streams):
    """Envelopes of the envelope and magnitude electrodes from simulated raw shaft-rate channels.

    Every such sensor records its three channels raw; an envelope sensor reports each channel's envelope, a
    magnitude sensor the envelope of ``|E|`` (:func:`~shipsense.physics.envelope.extract_magnitude_envelope`).
    Returns the measurement columns and their envelopes (runs, steps, columns).
    """
    ch = sc.envelope_chain
    times = sc.times
    dt = 1.0 / ch.raw_rate_hz
    raw_t = np.arange(times[0] - ch.pad_s, times[-1] + ch.pad_s + 0.5 * dt, dt)
    elec = array.group("electrode")
    kinds = np.array([array.kinds[i] for i in elec])
    chained = np.isin(kinds, ("envelope", "magnitude"))
    is_mag = kinds[chained] == "magnitude"
    cols = [np.flatnonzero(np.isin(array.channel_sensor, elec[chained][sel])) for sel in (~is_mag, is_mag)
            if sel.any()]
    # runs in chunks of about RAW_CHUNK_BYTES of raw samples: every run's chain is its own, and the noise is
    # drawn run after run (C order), so the chunks give the one batch's envelopes exactly
    per_run = raw_t.size * int(chained.sum()) * 3 * 8
    rows = max(1, RAW_CHUNK_BYTES // per_run)
    envelopes = []
    for lo in range(0, x0.shape[0], rows):
        x = x0[lo:lo + rows]
        if manoeuvres.any:    # the raw samples' own positions and keel directions
            pos, vel, _, _ = manoeuvring_motion(x[:, 0:2], x[:, 2:4], manoeuvres.take(slice(lo, lo + rows)), raw_t)
            dip = keel_dipole(vel, x[:, None, 8])
        else:
            pos = cv_positions(x[:, 0:2], x[:, 2:4], raw_t)
            dip = keel_dipole(x[:, None, 2:4], x[:, None, 8])
        src = np.concatenate([pos, np.broadcast_to(x[:, None, 4:5], (x.shape[0], raw_t.size, 1))], axis=-1)
        E = array.electric_field(src, dip)[..., chained, :]          # (runs, n_raw, S_chain, 3)
        raw = raw_channels(E.reshape(E.shape[:2] + (-1,)), raw_t, ch.shaft_hz, noise_std=ch.raw_noise_std,
                           rng=streams["envelope"]).reshape(E.shape)
        parts = []
        if (~is_mag).any():
            r = raw[..., ~is_mag, :]
            parts.append(envelope_chain(r.reshape(r.shape[:2] + (-1,)), raw_t, times, ch.raw_rate_hz,
                                        ch.lowpass_hz))
        if is_mag.any():
            parts.append(magnitude_envelope_chain(raw[..., is_mag, :], raw_t, times, ch.raw_rate_hz, ch.lowpass_hz))
        envelopes.append(np.concatenate(parts, axis=-1))
    return np.concatenate(cols), np.concatenate(envelopes)


def _seismic_chain(sc: Scenario, array: SensorArray, heard, streams):
    """Eigen-bearings from simulated triaxial windows, (runs, steps, S_acc), of the source each accelerometer
    hears, ``heard`` (runs, steps, S_acc, 3)."""
    cfg = sc.seismic
    idx = array.group("accelerometer")
    n = max(int(round(cfg.sample_rate_hz * sc.period)), 3)
    L = simulate_vibration(
        streams["seismic"], array.positions[idx], heard, n, amplitude=cfg.amplitude,
        range_ref=cfg.range_ref, range_exponent=cfg.range_exponent, noise_std=cfg.sensor_noise,
        multipath_gain=cfg.multipath_gain, multipath_bias_deg=cfg.multipath_bias_deg, noise_dof=cfg.noise_dof,
        tail_rng=streams["seismic_tail"])
    return eigen_bearing(L) + np.deg2rad(cfg.bias_deg)
