"""``shipsense/Passage-v1``: read ``k`` of the array's sensors per step while the tracker follows a passing ship.

## Description

One episode is one ship passage drawn from the scenario's prior past its
array.  The project's tracker (:class:`shipsense.trackers.Tracker`, its
covariance calibrated: docs: Results) runs inside the environment as the
observer.  It sees every sensor's first sample (the detection); from then on
the agent chooses at every step which sensors to read, at most ``k`` of them
(a seabed node's energy budget), each read costing ``energy_cost``.  The
agent sees the observer's output and what the observer predicts each sensor
would tell it, never the truth.

## Action space

``Discrete(A)``: an index into ``PassageV1Env.subsets``, every subset of
the ``S`` sensors with at most ``k`` members, in order of size then
lexicographic: action 0 reads nothing, actions ``1 .. S`` read one sensor
(sensor ``a - 1``), then the pairs, ...  An over-budget choice cannot be
expressed.  ``A = sum_{j <= k} C(S, j)``.

## Observation space

``Box(-1, 1, (9 + 2 S,), float32)``, all finite (``position_scale``: 1.5 x the prior's farthest start):

| index | content |
| --- | --- |
| 0-1 | the observer's position estimate relative to the array centroid / ``position_scale``, clipped |
| 2-3 | its velocity / 10 m/s, clipped |
| 4-5 | ``log10(std_x) / 3``, ``log10(std_y) / 3`` of its position covariance, clipped (1 mm .. 1 km) |
| 6 | the position correlation coefficient |
| 7 | the observer's status / 4 (0 no data, 0.25 initialising, 0.5 tracking, 0.75 restarted, 1 inconsistent) |
| 8 | elapsed fraction of the passage |
| 9 .. 8+S | per sensor: steps since it was last read / (K - 1), clipped to 1 |
| 9+S .. 8+2S | per sensor: its predicted information gain ``g / (1 + g)`` (below) |

``g`` is the drop (nats) of the log-det of the position covariance if that
sensor alone were read at the next step (:mod:`shipsense.design.information_gain`),
linearised at the observer's one-step prediction with the observer's own
noise model; 0 while the observer has no track (its estimate is then the
prior's mean, where a linearisation means nothing).

## Rewards

``-ln(1 + error / error_scale) - energy_cost * reads`` per step, with
``error`` the distance (m) of the observer's position estimate from the
truth after the step.  The error term uses the truth (the environment has
it), not the observer's covariance: a reward on the observer's own
covariance would pay an optimistic observer for being optimistic.  It is
logarithmic (metre-level improvements count while a 1 km error is not a
thousand times a 1 m one) but **not capped**: a diverged observer keeps
earning ever more negative rewards (10 km off: -9.2 per step with the
default 1 m scale).  Both terms are in ``info``.

## Starting state

A passage drawn from the scenario's ``[prior]`` (start range, bearing, course
offset, speed, moment) under the seed.  **Run-in**: the observer reads every
sensor from the first sample until it reports a track (its detection and the
global fit of its first window, 15 s of samples for magnetometers); the
agent's control starts there (the observation's elapsed
fraction says where).  While the observer has no track its estimate is the
prior's mean whatever is read, so those samples would add the same large
errors to every policy's return and hide the scheduling (on S2, before the
run-in, they made up most of every baseline's return: docs: Results).  A
passage that never gets a track leaves the agent one step.  The run-in does
not depend on the agent, so the environment does the run-ins of its next
passages ahead, in batches, on the process's background thread while the
agent steps (:mod:`shipsense.envs.prefetch`; episodes are the same to the
bit; ``SHIPSENSE_THREADS=1`` keeps everything on the calling thread).

## Episode end

Terminated at the passage's last sample (``K`` the scenario's ``steps``;
the episode has ``K - 1 - run-in`` steps).  No truncation.

## Info keys

Every step: ``error`` (m), ``nees`` (the position's normalised squared
error under the observer's covariance), ``inside95`` (``nees <= 5.991``),
``reads``, ``error_term``, ``energy_term``, ``truth`` and ``estimate`` (m),
``status``.  At the episode's end also ``episode_metrics``: ``mean_error_m``
(the task metric: the mean position error over the episode's steps),
``final_error_m``, ``coverage95`` (share of steps with the truth inside
the observer's 95 % ellipse), ``reads_per_step``, ``energy`` (the episode's
energy cost) and ``return`` -- plain floats.

## Baselines

:meth:`PassageV1Env.baseline` (``BASELINES``): ``random`` (a uniformly
random subset of exactly ``k`` sensors), ``round-robin`` (the ``k`` sensors
read longest ago; ties to the lowest index), ``greedy`` (the subset of ``k``
sensors with the largest predicted drop of the position covariance's
log-det, all subsets searched; round-robin while the observer has no track).

## Arguments

``scenario`` (shipped name or TOML path), ``overrides`` (dict of top-level
scenario fields, e.g. ``{"steps": 60}``), ``k`` (reads per step, default 1),
``energy_cost`` (per read, default 0.01), ``error_scale`` (m, default 1),
``render_mode`` (``"rgb_array"`` or ``"human"``).  All JSON-able; a bad
value raises one ``ValueError`` naming the argument.

## Variants (registered)

``shipsense.envs.PASSAGE_V1_VARIANTS`` (S2's noise, 0.5 nT magnetometers):

* ``shipsense/Passage-v1``: four vector magnetometers on a line 40 m apart,
  one read per step, 100 samples, starts 100-160 m out: which magnetometer
  is near the ship changes along the passage.
* ``shipsense/PassageEasy-v1``: S2's array (two magnetometers and a bearing
  accelerometer within 10 m), one read per step.
* ``shipsense/PassageHard-v1``: six magnetometers 30 m apart, 2 of 6 per
  step, 10 % outliers (10 sigma), 10 % dropouts, starts 100-250 m out,
  moments 3e3-3e4 A m^2, 120 samples.

Their ``reward_threshold`` is the greedy baseline's mean return on held-out
passages (docs: Results, ``experiments/passage_baselines.py``); for the hard
variant the best baseline's (random), as greedy, which trusts an observer
that loses most of those passages, scores worse there.  Keyword
arguments to ``gymnasium.make`` replace a variant's: ``overrides`` replaces
its whole ``overrides`` dict.

## Version history

* v1: the agent picks a subset of at most ``k`` sensors (``Discrete``, no
  trimming), uncapped log-error reward, time since each read and predicted
  information gains observed, episode metrics and baselines.  Since
  2026-11-26 the vector env's seeded partial reset reseeds only the masked
  sub-environments (gymnasium's ``SyncVectorEnv`` rule; it reseeded all, so
  the others' later blocks of passages came from the new seeds): no
  version bump, as the dynamics, reward and spaces are unchanged.
* v0 (``shipsense/Passage-v0``): a ``MultiBinary`` action trimmed to
  ``max_reads``, the error reward capped at 100 m, the hypotheses'
  likelihoods and the SNRs of the sensors read observed.  Retired on
  2026-11-28: its module, registration and tests removed (it could not run
  on v1's core as arguments); the docs' Results keep its figures.
"""

from __future__ import annotations

import math
from itertools import combinations

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numba import njit

from shipsense import numba_cache
from shipsense.arguments import number
from shipsense.config import load_scenario
from shipsense.design.information_gain import information_gains_at
from shipsense.envs.core_env import SEED_HIGH, ClosesItsFigure, CoreVectorEnv, RebuiltOnUnpickle, seed_ahead
from shipsense.envs.features import at_least, error_and_nees, track_features
from shipsense.envs.prefetch import PASSAGE_BLOCK, PassagePrefetch
from shipsense.simulator import simulate
from shipsense.trackers import Tracker
from shipsense.trackers.tracker.results import INITIALISING, NO_DATA

_RECORDED = ("estimate", "cov", "status", "selected")
"""What the environment keeps of its observer's output (:attr:`PassageV1Core.last`)."""


def _copy_outputs(sample, rows, into):
    """What the environment keeps of an observer's output ``sample`` (a
    :class:`~shipsense.trackers.tracker.results.Sample`
    or a dict of its fields) written into rows ``rows`` of the Sample ``into``."""
    for name in _RECORDED:
        getattr(into, name)[rows] = sample[name] if isinstance(sample, dict) else getattr(sample, name)


CHI2_2_95 = 5.991464547107979
"""95 % quantile of the chi-square distribution with 2 degrees of freedom."""
BASELINES = ("random", "round-robin", "greedy")


def subsets(S, k):
    """All subsets of at most ``k`` of ``S`` sensors as a boolean matrix (A, S): by size, then lexicographic."""
    rows = [np.zeros(S, dtype=bool)]
    for j in range(1, k + 1):
        for c in combinations(range(S), j):
            r = np.zeros(S, dtype=bool)
            r[list(c)] = True
            rows.append(r)
    return np.array(rows)


class PassageV1Core(PassagePrefetch):
    """State and dynamics of E Passage-v1 environments at once (E = 1 for :class:`PassageV1Env`); their passages
    are queued and their run-ins done ahead (:class:`~shipsense.envs.prefetch.PassagePrefetch`)."""

    def __init__(self, num_envs=1, scenario="S2", overrides=None, k=1, energy_cost=0.01, error_scale=1.0):
        num_envs = number("num_envs", num_envs, 1, 100_000, integer=True)
        energy_cost = number("energy_cost", energy_cost, 0.0, 1e6)
        error_scale = number("error_scale", error_scale, 1e-6, 1e6, lo_open=True)
        if overrides is not None and not isinstance(overrides, dict):
            raise ValueError(f"overrides must be a dict of scenario fields, got {type(overrides).__name__}")
        try:
            sc = load_scenario(scenario)
            if overrides:
                sc = sc.with_updates(**overrides)
        except Exception as exc:   # a missing file, a bad field: one line naming the argument
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise ValueError(f"scenario/overrides: {first}") from None
        if sc.prior is None:
            raise ValueError(f"scenario {sc.name!r} has no [prior]: Passage-v1 draws passages from it")
        self.scenario = sc
        self.tracker = Tracker(sc, passages=num_envs)
        self.model = self.tracker.model
        arr = self.model.array
        self.S = len(arr.ids)
        self.k_reads = number("k", k, 1, self.S, integer=True)
        self.subsets = subsets(self.S, self.k_reads)
        self.full = np.flatnonzero(self.subsets.sum(axis=1) == self.k_reads)   # actions reading exactly k
        self.energy_cost, self.error_scale = energy_cost, error_scale
        self.E, self.K = num_envs, sc.steps
        self.centre = arr.positions[:, :2].mean(axis=0)
        self.position_scale = 1.5 * sc.prior.range[1]
        self.sensor_of = arr.channel_sensor
        self.first_channel = np.flatnonzero(np.diff(np.concatenate([[-1], self.sensor_of])))
        self.obs_dim = 9 + 2 * self.S
        self.times = sc.times
        E, K = self.E, self.K
        self.y = np.zeros((E, K, self.model.m))
        self.truth = np.zeros((E, K, self.model.n))
        self.est_hist = np.zeros((E, K, 2))
        self.errors = np.zeros((E, K))
        self.inside = np.zeros((E, K), dtype=bool)
        self.returns = np.zeros(E)
        self.reads = np.zeros(E)
        self.k = np.zeros(E, dtype=int)
        self.start = np.zeros(E, dtype=int)   # the sample the agent's control starts at (after the run-in)
        self.since = np.zeros((E, self.S))
        self.last_read = np.zeros((E, self.S), dtype=bool)
        self.last = self.tracker.prior_sample()
        self.gains = np.zeros((E, len(self.subsets)))   # predicted gain (nats) of every action
        # (the next blocks of this many environments are left in one piece of work, their run-ins in one batch)
        PassagePrefetch.__init__(self, max(1, min(self.E, self.tracker.independent_batch // PASSAGE_BLOCK)))
        self._rows = np.arange(E)
        # the observer's noise (internal units) and the one-step transition
        self._Rinv = np.ascontiguousarray(1.0 / self.tracker.filter_model.R, dtype=float)
        self._A = self.model.A
        self._xs = self.model.x_scale
        self._xs2 = np.outer(self._xs, self._xs)
        self._first = np.asarray(self.first_channel, dtype=np.int64)

    # -- episodes ---------------------------------------------------------------
    looks_ahead = True
    """:meth:`reset_envs` takes ``ahead`` (:class:`~shipsense.envs.core_env.CoreVectorEnv` passes it)."""

    def reset_envs(self, envs, seeds, fresh=False, ahead=None):
        """Draw new passages for ``envs`` (indices) from integer ``seeds``, each with its observer's run-in done
        (:meth:`run_ins`), off the environments' queues (:meth:`~shipsense.envs.prefetch.PassagePrefetch.take_passages`:
        passages are simulated in blocks of :data:`~shipsense.envs.prefetch.PASSAGE_BLOCK` per environment; an
        explicit seed, ``fresh``, drops the rest of a block first; with ``ahead(e, j)``, the seed environment
        ``e``'s ``j``-th reset from now will be given, the run-ins needed later are done ahead on the background
        thread).  Returns the observations of ``envs``."""
        envs = np.asarray(envs, dtype=int)
        states = []
        for e, entry in zip(envs.tolist(), self.take_passages(envs, seeds, fresh, ahead)):
            y, truth, (k, record, state), _ = entry
            self.y[e], self.truth[e], self.k[e] = y, truth, k
            _copy_outputs(record, e, self.last)
            states.append(state)
        self.tracker.set_passage_states(envs, states)
        self.start[envs] = self.k[envs]
        self.since[envs] = 0.0
        self.last_read[envs] = True
        self.returns[envs] = 0.0
        self.reads[envs] = 0.0
        self._measure(envs)
        self._predict_gains(envs)
        return self.observe()[envs]

    def draw_block(self, seed):
        """The queue entries ``[y, truth, run-in, job]`` of a block of passages simulated from ``seed`` (no run-in
        yet)."""
        sim = simulate(self.scenario, runs=PASSAGE_BLOCK, seed=seed, random=True)
        return [[y, truth, None, None] for y, truth in zip(sim.measurements, self.model.state_from_truth(sim.truth))]

    def run_ins(self, entries):
        """The observer's run-in of queued passages ``entries`` (``[y, truth, None, ...]`` lists; the run-in is put
        in their third place; returns ``entries``), in batches on a sibling of the observer
        (:meth:`~shipsense.trackers.Tracker.sibling`): a passage's run-in does not depend on the agent (every
        sensor is read) nor on the passages beside it in a batch, so it is the one it would have had in its
        environment, at a fraction of the cost (its window fits in one batch).  A batch holds at most
        :attr:`~shipsense.trackers.Tracker.independent_batch` passages: in a larger one the banks' starts move at
        rounding.

        Every sensor is read from the first sample until the observer has a track (its detection and its
        first fit): a passage stops at the sample its window completes, and the windows are fitted together
        at the end (:meth:`~shipsense.trackers.Tracker.fit_pending`).  A passage that never gets a track
        stops two samples before its end."""
        size = self.tracker.independent_batch
        for lo in range(0, len(entries), size):
            part = entries[lo:lo + size]
            R = len(part)
            trk = self.tracker.sibling(R)
            y = np.stack([entry[0] for entry in part])
            rows, k = np.arange(R), np.zeros(R, dtype=int)
            last = trk.update(self.times[0], y[:, 0])      # (a fresh Sample of every passage: the run-ins' record)
            waiting = rows[self._blind_status(last.status) & (k < self.K - 2)]
            while waiting.size:
                k[waiting] += 1
                _copy_outputs(trk.update(self.times[k[waiting]], y[waiting, k[waiting]], passages=waiting,
                                         defer_fits=True), waiting, last)
                waiting = waiting[~trk.pending(waiting) & self._blind_status(last.status[waiting])
                                  & (k[waiting] < self.K - 2)]
            fitted, sample = trk.fit_pending()
            _copy_outputs(sample, fitted, last)
            for r, (entry, state) in enumerate(zip(part, trk.passage_states(rows))):
                entry[2] = (int(k[r]), {name: np.copy(getattr(last, name)[r]) for name in _RECORDED}, state)
        return entries

    def _record(self, sample, envs):
        _copy_outputs(sample, envs, self.last)

    def _measure(self, envs):
        """Error and 95 % ellipse coverage of ``envs`` at their current sample (stored in the histories;
        compiled, :func:`_measure`)."""
        error, nees = np.empty(envs.size), np.empty(envs.size)
        _measure(envs, self.k, self.last.estimate, self.last.cov, self.truth, CHI2_2_95, self.est_hist, self.errors,
                 self.inside, error, nees)
        return error, nees

    def _predict_gains(self, envs):
        """Predicted drop (nats) of the position covariance's log-det for every action, from the observer's
        estimate and covariance predicted one step, linearised there (0 while the observer has no track)."""
        blind = self._blind(envs)
        self.gains[envs[blind]] = 0.0
        envs = envs[~blind]   # (the prior's mean is the array centroid: a sensor may sit there)
        if envs.size == 0:
            return
        x = (self.last.estimate[envs] / self._xs) @ self._A.T
        P = self.last.cov[envs] / self._xs2
        P = self._A @ P @ self._A.T
        self.gains[envs] = information_gains_at(self.model, x, self._Rinv, P, self._first, self.subsets)

    def _blind(self, envs):
        """Whether the observers of ``envs`` have no track yet (status no data or initialising)."""
        return self._blind_status(self.last.status[envs])

    @staticmethod
    def _blind_status(status):
        return (status == NO_DATA) | (status == INITIALISING)

    def step(self, actions, envs=None):
        """Advance environments ``envs`` (default all) by one sample with actions (E,) (indices of
        :attr:`subsets`).  Returns rewards, terminated, truncated (E,; never truncated) and an info dict of (E,)
        arrays; entries of environments that did not step are meaningless."""
        actions = np.asarray(actions)
        if actions.dtype.kind not in "iu":                    # (not bool, not fractions)
            raise ValueError(f"actions must be integers in [0, {len(self.subsets)}), got {actions.dtype} values")
        actions = actions.astype(np.int64, copy=False).reshape(self.E)
        who = self._rows if envs is None else np.asarray(envs, dtype=np.int64)
        y, reads = np.empty((who.size, self.model.m)), np.empty(self.E)
        bad = _read(actions, who, self.subsets, self.sensor_of, self.y, self.k, self.since, self.last_read, y, reads)
        if bad >= 0:
            raise ValueError(f"actions must be integers in [0, {len(self.subsets)}), got {actions[bad]} for "
                             f"environment {bad}")
        self._record(self.tracker.update(self.times[self.k[who]], y, passages=who), who)
        error, nees = np.zeros(self.E), np.zeros(self.E)
        error[who], nees[who] = self._measure(who)
        self._predict_gains(who)
        error_term = -np.log1p(error / self.error_scale)
        energy_term = -self.energy_cost * reads
        rewards = error_term + energy_term
        _accumulate(who, rewards, reads, self.returns, self.reads)
        info = {"error": error, "nees": nees, "inside95": nees <= CHI2_2_95, "reads": reads,
                "error_term": error_term, "energy_term": energy_term, "status": self.last.status.copy(),
                "truth": self.truth[self._rows, self.k, :2].copy(), "estimate": self.last.estimate[:, :2].copy()}
        return rewards, self.k >= self.K - 1, np.zeros(self.E, dtype=bool), info

    def episode_metrics(self, envs):
        """The episodes' metrics of ``envs`` (at their last sample): dict of (len(envs),) arrays."""
        envs = np.asarray(envs, dtype=int)
        steps = np.maximum(self.k[envs] - self.start[envs], 1)
        ks = np.arange(self.K)[None, :]
        live = (ks > self.start[envs, None]) & (ks <= self.k[envs, None])   # the agent's steps
        return {"mean_error_m": np.where(live, self.errors[envs], 0.0).sum(axis=1) / steps,
                "final_error_m": self.errors[envs, self.k[envs]],
                "coverage95": np.where(live, self.inside[envs], False).sum(axis=1) / steps,
                "steps": steps.astype(float),
                "reads_per_step": self.reads[envs] / steps,
                "energy": self.reads[envs] * self.energy_cost,
                "return": self.returns[envs].copy()}

    def observe(self):
        """Observations (E, obs_dim) float32 (see the module docstring's table; compiled, :func:`_observe`)."""
        obs = np.empty((self.E, self.obs_dim), dtype=np.float32)
        _observe(self.last.estimate, self.last.cov, self.last.status, self.k, self.since, self.gains, self.centre,
                 float(self.position_scale), float(max(self.K - 1, 1)), obs)
        return obs

    # -- baselines (batched: one action per environment) ---------------------------
    def round_robin_actions(self):
        """The ``k`` sensors read longest ago (ties to the lowest index), as action indices (E,)."""
        order = np.argsort(-self.since, axis=1, kind="stable")[:, :self.k_reads]
        want = np.zeros((self.E, self.S), dtype=bool)
        np.put_along_axis(want, order, True, axis=1)
        return action_of(self.subsets, want)

    def greedy_actions(self):
        """The subset of ``k`` sensors with the largest predicted gain (E,); round-robin without a track."""
        best = self.full[np.argmax(self.gains[:, self.full], axis=1)]
        return np.where(self._blind(self._rows), self.round_robin_actions(), best)

    def random_actions(self, rng):
        """A uniformly random subset of exactly ``k`` sensors per environment (E,)."""
        return self.full[rng.integers(0, self.full.size, self.E)]

    # -- rendering ----------------------------------------------------------------
    def render(self, e=0):
        """RGB picture of environment ``e``: the array (sensors read at this step ringed), the true and estimated
        tracks so far and the estimate's 95 % ellipse."""
        from shipsense.plotting import draw_array, figure_to_rgb, plt

        fig, ax = plt.subplots(figsize=(5, 5), dpi=80)
        arr = self.model.array
        draw_array(ax, arr, label=True)
        read = np.flatnonzero(self.last_read[e])
        ax.scatter(arr.positions[read, 0], arr.positions[read, 1], s=260, facecolor="none", edgecolor="tab:green",
                   lw=2, zorder=6, label="read")
        k = self.k[e]
        ax.plot(*self.truth[e, : k + 1, :2].T, "-", color="tab:red", label="truth")
        ax.plot(*self.est_hist[e, : k + 1].T, "-", color="tab:blue", lw=0.8, label="estimate")
        mean, cov = self.last.estimate[e, :2], self.last.cov[e, :2, :2]
        w, V = np.linalg.eigh(cov)
        t = np.linspace(0, 2 * np.pi, 60)
        pts = mean[:, None] + V @ (np.sqrt(np.clip(w, 0, None) * CHI2_2_95)[:, None] * np.stack([np.cos(t), np.sin(t)]))
        ax.plot(pts[0], pts[1], "-", color="tab:blue", lw=1.0, label="95 % ellipse")
        ax.plot(*mean, "o", color="tab:blue")
        r = self.position_scale
        ax.set_xlim(self.centre[0] - r, self.centre[0] + r)
        ax.set_ylim(self.centre[1] - r, self.centre[1] + r)
        ax.set_aspect("equal")
        ax.legend(loc="upper right", fontsize=7)
        ax.set_title(f"step {k}: error {self.errors[e, k]:.3g} m", fontsize=9)
        return figure_to_rgb(fig)


def observation_potential(obs):
    """``-1/2 ln det`` (nats, position in m) of the observer's position covariance as observations (..., obs_dim)
    state it (indices 4-6; the stds' clip at 1 mm .. 1 km and a correlation of at most 1 - 1e-6 in magnitude):
    the potential of ``shipsense train scheduling --shaping`` (:class:`~shipsense.envs.sb3.PotentialShaping`).
    A read that shrinks the covariance raises it by about the predicted gain of the observation's last
    columns."""
    obs = np.asarray(obs, dtype=float)
    rho2 = np.minimum(obs[..., 6] ** 2, 1.0 - 1e-6)
    return -0.5 * (6.0 * np.log(10.0) * (obs[..., 4] + obs[..., 5]) + np.log1p(-rho2))


@njit(cache=True, error_model="numpy", nogil=True)
def _observe(est, cov, status, k, since, gains, centre, position_scale, steps, obs):
    """:meth:`PassageV1Core.observe` into ``obs`` (E, 9 + 2 S) float32: the table's entries in float64 (NaN
    -> 0, +-inf -> +-1), clipped to [-1, 1]."""
    S = since.shape[1]
    row = np.empty(obs.shape[1])
    for e in range(est.shape[0]):
        track_features(est[e], cov[e], centre, position_scale, row)
        row[6] = cov[e, 0, 1] / math.sqrt(at_least(cov[e, 0, 0] * cov[e, 1, 1], 1e-300))
        row[7] = status[e] / 4.0
        row[8] = k[e] / steps
        for s in range(S):
            row[9 + s] = since[e, s] / steps
            g = at_least(gains[e, 1 + s], 0.0)             # the single-sensor actions
            row[9 + S + s] = g / (1.0 + g)
        for i in range(row.size):
            v = row[i]
            v = 0.0 if v != v else v
            obs[e, i] = min(max(v, -1.0), 1.0)


@njit(cache=True, error_model="numpy", nogil=True)
def _read(actions, who, subsets, sensor_of, y_all, k, since, last_read, y, reads):
    """The reads of :meth:`PassageV1Core.step`: every environment's reads (``reads``, float) under its action
    (a row of ``subsets``); for environments ``who``, the next sample (``k``), its channels of the sensors read
    (``y``, the others NaN), the read mask (``last_read``) and the steps since each sensor was read
    (``since``: 0 read, else one more).  Returns -1, or the first environment whose action is not a row of
    ``subsets`` (then nothing is written)."""
    S = subsets.shape[1]
    for e in range(actions.size):
        if actions[e] < 0 or actions[e] >= subsets.shape[0]:
            return e                                    # (nothing written)
    for e in range(actions.size):
        count = 0
        for s in range(S):
            count += subsets[actions[e], s]
        reads[e] = count
    for i in range(who.size):
        e = who[i]
        row = subsets[actions[e]]
        k[e] += 1
        for j in range(y.shape[1]):
            y[i, j] = y_all[e, k[e], j] if row[sensor_of[j]] else np.nan
        for s in range(S):
            last_read[e, s] = row[s]
            since[e, s] = 0.0 if row[s] else since[e, s] + 1.0
    return -1


@njit(cache=True, error_model="numpy", nogil=True)
def _accumulate(who, rewards, reads, returns, total_reads):
    """The episode's sums of environments ``who``: their rewards and reads."""
    for i in range(who.size):
        e = who[i]
        returns[e] += rewards[e]
        total_reads[e] += reads[e]


@njit(cache=True, error_model="numpy", nogil=True)
def _measure(envs, k, est, cov, truth, limit, est_hist, errors, inside, error, nees):
    """:meth:`PassageV1Core._measure` of environments ``envs``: the position error (into ``error``) and NEES
    (``nees``; inf where not finite) at each one's current sample, stored in the histories."""
    for r in range(envs.size):
        e = envs[r]
        ke = k[e]
        error[r], q = error_and_nees(est[e, 0] - truth[e, ke, 0], est[e, 1] - truth[e, ke, 1], cov[e, 0, 0],
                                     cov[e, 0, 1], cov[e, 1, 1])
        nees[r] = q if math.isfinite(q) else np.inf
        est_hist[e, ke, 0], est_hist[e, ke, 1] = est[e, 0], est[e, 1]
        errors[e, ke] = error[r]
        inside[e, ke] = nees[r] <= limit


def action_of(table, want):
    """The action indices (E,) whose rows of ``table`` (A, S) equal ``want`` (E, S)."""
    weights = 1 << np.arange(table.shape[1])
    code = table.astype(np.int64) @ weights
    lookup = np.full(int(code.max()) + 1, -1)
    lookup[code] = np.arange(table.shape[0])
    return lookup[want.astype(np.int64) @ weights]


def _spaces(core):
    low = -np.ones(core.obs_dim, dtype=np.float32)
    low[7:9] = 0.0
    low[9:] = 0.0
    return spaces.Box(low, np.ones(core.obs_dim, dtype=np.float32), dtype=np.float32), \
        spaces.Discrete(len(core.subsets))


class _Policy:
    """A baseline policy: ``policy(obs) -> action`` (reads the environment's internal state; ``obs`` unused)."""

    def __init__(self, core, name, seed, single):
        self.core, self.name, self.single = core, name, single
        self.rng = np.random.default_rng(seed)

    def __call__(self, obs=None):
        c = self.core
        a = (c.random_actions(self.rng) if self.name == "random" else
             c.round_robin_actions() if self.name == "round-robin" else c.greedy_actions())
        return int(a[0]) if self.single else a

    def __repr__(self):
        return f"<{self.name} baseline of Passage-v1>"


def _check_baseline(name):
    if name not in BASELINES:
        raise ValueError(f"unknown baseline {name!r}; offered: {', '.join(BASELINES)}")


class PassageV1Env(RebuiltOnUnpickle, ClosesItsFigure, gym.Env):
    __doc__ = __doc__
    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 4}
    BASELINES = BASELINES
    potential = staticmethod(observation_potential)

    def __init__(self, scenario="S2", overrides=None, k=1, energy_cost=0.01, error_scale=1.0, render_mode=None):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.core = PassageV1Core(1, scenario, overrides, k, energy_cost, error_scale)
        self.observation_space, self.action_space = _spaces(self.core)
        self.subsets = self.core.subsets
        self.render_mode = render_mode
        self._started = False
        self._fig = None
        self._kwargs = dict(scenario=scenario, overrides=overrides, k=k, energy_cost=energy_cost,
                            error_scale=error_scale, render_mode=render_mode)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        obs = self.core.reset_envs([0], [int(self.np_random.integers(SEED_HIGH))], fresh=seed is not None,
                                   ahead=lambda e, j: seed_ahead(self.np_random, j))
        self._started = True
        if self.render_mode == "human":
            self.render()
        return obs[0], {}

    def expect_seeds(self, seeds):
        """Announce that the next resets will be ``reset(seed=s)`` for ``s`` in ``seeds``, in that order (an
        evaluation's episodes, :func:`~shipsense.envs.evaluation.run_episodes`): their passages and run-ins are
        then done ahead on the background thread, in batches.  Optional: every episode is the same with or
        without it, and a reset with another seed, or none, draws its passage as ever."""
        from gymnasium.utils import seeding

        self.core.expect(int(seeding.np_random(int(s))[0].integers(SEED_HIGH)) for s in seeds)   # (as needed)

    def step(self, action):
        if not self._started:
            raise RuntimeError("call reset() before step()")
        if self.core.k[0] >= self.core.K - 1:
            raise RuntimeError("the passage has ended: call reset()")
        if not (0 <= action < self.action_space.n if type(action) is int else self.action_space.contains(action)):
            raise ValueError(f"action must be an integer in [0, {self.action_space.n}), got {action!r}")
        rewards, terminated, _, info = self.core.step(np.array([int(action)]))
        obs = self.core.observe()[0]
        info = {k: v[0] for k, v in info.items()}
        done = bool(terminated[0])
        if done:
            info["episode_metrics"] = {k: float(v[0]) for k, v in self.core.episode_metrics([0]).items()}
        if self.render_mode == "human":
            self.render()
        return obs, float(rewards[0]), done, False, info

    def close(self):
        self.core.drop_pending()
        super().close()

    def baseline(self, name, seed=None):
        """The baseline policy ``name`` (one of :attr:`BASELINES`): ``policy(obs) -> action``; ``seed`` seeds
        ``random``'s own generator (the environment's is left alone)."""
        _check_baseline(name)
        return _Policy(self.core, name, seed, single=True)

    def render(self):
        if self.render_mode == "rgb_array":
            return self.core.render(0)
        if self.render_mode == "human":
            from shipsense.plotting import plt

            img = self.core.render(0)
            if self._fig is None:
                plt.ion()
                self._fig, ax = plt.subplots()
                ax.set_axis_off()
                self._img = ax.imshow(img)
            else:
                self._img.set_data(img)
            self._fig.canvas.draw_idle()
            plt.pause(1.0 / self.metadata["render_fps"])
        return None


class PassageV1VectorEnv(CoreVectorEnv):
    """Native vector version of ``shipsense/Passage-v1``: one :class:`PassageV1Core` (one batched tracker) for
    all sub-environments, on :class:`~shipsense.envs.core_env.CoreVectorEnv` (next-step autoreset, gymnasium's
    vector ``info`` with ``_key`` masks, an int or a list of seeds, the partial reset
    ``reset(options={"reset_mask": mask})`` that SB3's adapter, :class:`~shipsense.envs.sb3.VectorEnvAdapter`,
    calls in the step an episode ends).

    Sub-environment ``i`` reset with an integer ``seed`` behaves exactly like a single :class:`PassageV1Env`
    reset with ``seed + i``.  A seeded partial reset reseeds only the masked sub-environments; the others'
    streams and the run-ins done ahead for them are kept.
    """

    BASELINES = BASELINES
    potential = staticmethod(observation_potential)
    """The shaping potential of training (:func:`observation_potential`)."""

    def __init__(self, num_envs=1, scenario="S2", overrides=None, k=1, energy_cost=0.01, error_scale=1.0,
                 render_mode=None):
        self.check_render_mode(render_mode)
        core = PassageV1Core(num_envs, scenario, overrides, k, energy_cost, error_scale)
        super().__init__(core, _spaces(core), render_mode)
        self.subsets = core.subsets

    def close_extras(self, **kwargs):
        self.core.drop_pending()

    def baseline(self, name, seed=None):
        """The batched baseline policy ``name``: ``policy(obs) -> actions`` (num_envs,)."""
        _check_baseline(name)
        return _Policy(self.core, name, seed, single=False)


__all__ = ["BASELINES", "PassageV1Core", "PassageV1Env", "PassageV1VectorEnv", "observation_potential", "subsets"]


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
