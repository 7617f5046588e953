"""``shipsense/Passage-v0``: schedule which sensors to read while the tracker follows a passing ship.

**The old version**, kept registered to compare with earlier results: use
``shipsense/Passage-v1`` (:mod:`shipsense.envs.passage_v1`), whose action
cannot exceed the budget and whose reward is not capped.  Measured on v0
(issue 18): with the default budget the best policy is "read everything";
the error term is capped at 100 m, so a diverged observer looks like a
small error; a ``MultiBinary`` action over budget is silently trimmed.

## Description

One episode is one ship passage drawn from the scenario's prior past its
array.  The project's tracker (:class:`shipsense.trackers.Tracker`) runs
inside the environment as the observer (``observer="bank"``: the studies'
multiple-initial-value bank instead): it sees every sensor's first sample,
and from then on the agent chooses at every step which sensors to read.
Reading costs energy, which is what limits seabed nodes.  The agent sees the
tracker's output (its estimate, covariance, hypotheses and status), never the
truth.

## Action space

``MultiBinary(n_sensors)``: 1 = read that sensor at this step.  Energy budget:
at most ``max_reads`` sensors per step.  **Trimming rule**: if more are
requested, the first ``max_reads`` requested sensors in index order are read
and the rest dropped; ``info["trimmed"]`` counts the dropped ones.

## Observation space

``Box(-1, 1, (8 + H + S,), float32)``, all finite and clipped (H: the
observer's hypotheses, 5 for the tracker):

| index | content |
| --- | --- |
| 0-1 | selected estimate's position relative to the array centroid / ``position_scale`` |
| 2-3 | its velocity / 10 m/s |
| 4-5 | ``(log10(std_x), log10(std_y)) / 3`` of its position (the tracker's covariance) |
| 6 .. 6+H-1 | the hypotheses' normalised log-likelihoods / 50, in [-1, 0] |
| 6+H .. 6+H+S-1 | per sensor: ``log10(1 + SNR) / 5`` of its strongest channel if read this step, else 0 |
| 6+H+S | the tracker's status / 4 (0 no data, 0.25 initialising, 0.5 tracking, 0.75 restarted, 1 inconsistent) |
| last | elapsed fraction of the passage |

## Rewards

``-min(error / error_scale, 10) - energy_cost * reads`` with ``error`` the
selected estimate's position error (m); both terms are in ``info``.

## Episode end

Terminated when the passage ends (its last sample).  There is no other
termination; truncation comes only from a ``TimeLimit`` wrapper if the user
adds one (none is registered).

## Arguments

``scenario`` (shipped name or TOML path), ``overrides`` (dict of top-level
scenario fields, e.g. ``{"steps": 60}``), ``observer`` (``"tracker"``, the
default, or ``"bank"``), ``filter`` (filter unit name; default the tracker's,
or the scenario's for the bank), ``max_reads`` (default: all sensors),
``energy_cost`` (0.01 per read), ``error_scale`` (10 m), ``render_mode``
(``"rgb_array"``).  All JSON-able.

## Version history

* v1 (``shipsense/Passage-v1``, another module): supersedes this one.
* v0 (2026-11-26): the vector env's seeded partial reset reseeds only the
  masked sub-environments (as Passage-v1's; dynamics, reward and spaces
  unchanged).
* v0 (revised with the one-tracker change): the observer is the project's
  tracker, its covariance and status in the observation (width ``8 + H + S``).
  ``observer="bank"`` keeps the first version's observer (the studies' bank,
  seeded from the first sample), with the status entry added.  Results from
  the first version are comparable only with ``observer="bank"``.
* v0 (first version): the studies' bank as the observer.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numba import njit

from shipsense import numba_cache
from shipsense.config import load_scenario
from shipsense.envs.arguments import number
from shipsense.envs.core_env import SEED_HIGH, CoreVectorEnv, RebuiltOnUnpickle
from shipsense.envs.features import error_and_nees, track_features
from shipsense.simulator import simulate
from shipsense.trackers import Tracker

PASSAGE_BLOCK = 16
"""Passages simulated per simulator call and environment (see :meth:`PassageCore.reset_envs`)."""


class PassageCore:
    """The environment's state and dynamics for E environments at once (E = 1 for :class:`PassageEnv`)."""

    def __init__(self, num_envs=1, scenario="S2", overrides=None, filter=None, max_reads=None, energy_cost=0.01,
                 error_scale=10.0, observer="tracker"):
        sc = load_scenario(scenario)
        if overrides:
            sc = sc.with_updates(**overrides)
        if sc.prior is None:
            raise ValueError(f"scenario {sc.name!r} has no [prior]: Passage-v0 draws passages from it")
        if observer not in ("tracker", "bank"):
            raise ValueError(f"observer must be 'tracker' or 'bank', got {observer!r}")
        self.scenario = sc
        num_envs = number("num_envs", num_envs, 1, 100_000, integer=True)
        energy_cost = number("energy_cost", energy_cost, 0.0, 1e6)
        error_scale = number("error_scale", error_scale, 1e-3, 1e6)
        self.tracker = Tracker(sc, passages=num_envs, method=observer, unit=filter)
        self.model = self.tracker.model
        arr = self.model.array
        self.S = len(arr.ids)
        self.H = self.tracker.H
        self.max_reads = self.S if max_reads is None else number("max_reads", max_reads, 1, self.S, integer=True)
        self.energy_cost = energy_cost
        self.error_scale = error_scale
        self.E = num_envs
        self.K = sc.steps
        self.centre = arr.positions[:, :2].mean(axis=0)
        self.position_scale = 1.5 * sc.prior.range[1]
        self.sensor_of = arr.channel_sensor
        self.first_channel = np.flatnonzero(np.diff(np.concatenate([[-1], self.sensor_of])))   # channels by sensor
        self.std = sc.channel_std
        self.obs_dim = 8 + self.H + self.S
        self.y = np.zeros((self.E, self.K, self.model.m))
        self.truth = np.zeros((self.E, self.K, self.model.n))
        self._snr_obs = np.zeros((self.E, self.K, self.S))
        self._env_index = np.arange(self.E)
        self.k = np.zeros(self.E, dtype=int)
        self.last_read = np.zeros((self.E, self.S), dtype=bool)
        self.times = sc.times
        self.last = self.tracker.prior_sample()    # the observer's latest output per environment
        self._passages = {}   # environment -> passages simulated ahead (measurements, truth)

    # -- episodes ---------------------------------------------------------------
    def reset_envs(self, envs, seeds, fresh=False):
        """Draw new passages for ``envs`` (indices) and seed their banks.

        Passages are simulated in blocks of :data:`PASSAGE_BLOCK` per
        environment (one simulator call instead of one per episode): an
        environment whose block is used up simulates the next one from the
        integer in ``seeds``; ``fresh`` (a reset with an explicit seed) drops
        the rest of its block first.  A seed is consumed by every reset, so
        the sequence of passages depends only on the seeds.
        """
        envs = np.asarray(envs, dtype=int)
        for e, s in zip(envs, seeds):  # each environment draws from its own reproducible stream
            queue = self._passages.setdefault(int(e), [])
            if fresh:
                queue.clear()
            if not queue:
                sim = simulate(self.scenario, runs=PASSAGE_BLOCK, seed=int(s), random=True)
                queue.extend(zip(sim.measurements, self.model.state_from_truth(sim.truth)))
            self.y[e], self.truth[e] = queue.pop(0)
            self._snr_obs[e] = self._snr_feature(self.y[e])
        self.tracker.reset_passages(envs)
        # the detection: every sensor's first sample goes to the reset environments' observer
        self._record(self.tracker.update(self.times[0], self.y[envs, 0], passages=envs), envs)
        self.k[envs] = 0
        self.last_read[envs] = True
        return self._observe()[envs]

    def _snr_feature(self, y):
        """``log10(1 + SNR) / 5`` of every sensor's strongest channel, per sample (K, S)."""
        snr = np.abs(np.where(np.isfinite(y), y, 0.0)) / self.std
        return np.log10(1.0 + np.maximum.reduceat(snr, self.first_channel, axis=1)) / 5.0

    def step(self, actions, envs=None):
        """Advance environments ``envs`` (default all) by one sample with actions (E, S).

        Returns rewards (E,), terminated (E,) and an info dict of (E,) arrays;
        entries of environments that did not step are meaningless.
        """
        want = np.asarray(actions).astype(bool).reshape(self.E, self.S)
        if self.max_reads < self.S:
            read = want & (np.cumsum(want, axis=1) <= self.max_reads)  # the trimming rule: first max_reads in order
            trimmed = want.sum(axis=1) - read.sum(axis=1)
        else:
            read, trimmed = want, np.zeros(self.E, dtype=int)
        if envs is None:
            self.k += 1
        else:
            self.k[np.asarray(envs, dtype=int)] += 1
        who = self._env_index if envs is None else np.asarray(envs, dtype=int)
        y = np.where(read[:, self.sensor_of], self.y[self._env_index, self.k], np.nan)[who]
        self._record(self.tracker.update(self.times[self.k[who]], y, passages=who), who)
        if envs is None:
            self.last_read[:] = read
        else:
            self.last_read[envs] = read[envs]
        return self._rewards(read, trimmed)

    def _record(self, sample, envs):
        for name in ("estimate", "cov", "status", "selected"):
            getattr(self.last, name)[envs] = getattr(sample, name)

    def _rewards(self, read, trimmed):
        E = self.E
        truth, est, error, nees = np.empty((E, 2)), np.empty((E, 2)), np.empty(E), np.empty(E)
        reads, error_term, energy_term, rewards = np.empty(E, dtype=np.int64), np.empty(E), np.empty(E), np.empty(E)
        _rewards(self.truth, self.k, self.last.estimate, self.last.cov, read, self.error_scale, self.energy_cost,
                 truth, est, error, nees, reads, error_term, energy_term, rewards)
        info = {"truth": truth, "estimate": est, "error": error, "nees": nees, "selected": self.last.selected.copy(),
                "reads": reads, "trimmed": trimmed, "error_term": error_term, "energy_term": energy_term}
        return rewards, self.k >= self.K - 1, info

    def _observe(self):
        obs = np.empty((self.E, self.obs_dim), dtype=np.float32)
        _observe(self.last.estimate, self.last.cov, self.tracker.bank.cum, self._snr_obs, self.k, self.last_read,
                 self.last.status, self.centre, float(self.position_scale), float(max(self.K - 1, 1)), obs)
        return obs

    def render(self, e=0):
        """RGB picture of environment ``e``: array, truth, hypotheses and the selected estimate."""
        from shipsense.plotting import draw_array, figure_to_rgb, plt

        fig, ax = plt.subplots(figsize=(5, 5), dpi=80)
        draw_array(ax, self.model.array, label=False)
        k = self.k[e]
        ax.plot(*self.truth[e, : k + 1, :2].T, "-", color="tab:red", label="truth")
        means = self.tracker.bank.means().reshape(self.E, self.H, -1)[e]
        live = np.isfinite(self.tracker.bank.cum[e])
        ax.scatter(means[live, 0], means[live, 1], s=10, color="0.5", label="hypotheses")
        ax.plot(*self.last.estimate[e, :2], "o", color="tab:blue", label="estimate")
        r = self.position_scale
        ax.set_xlim(self.centre[0] - r, self.centre[0] + r)
        ax.set_ylim(self.centre[1] - r, self.centre[1] + r)
        ax.set_aspect("equal")
        ax.legend(loc="upper right", fontsize=7)
        ax.set_title(f"step {k}", fontsize=9)
        return figure_to_rgb(fig)


@njit(cache=True, error_model="numpy", nogil=True)
def _rewards(truth_all, k, est_all, cov, read, error_scale, energy_cost, truth, est, error, nees, reads, error_term,
             energy_term, rewards):
    """:meth:`PassageCore._rewards`' numbers of every environment (see the module docstring's rewards)."""
    for e in range(k.size):
        ke = k[e]
        truth[e, 0], truth[e, 1] = truth_all[e, ke, 0], truth_all[e, ke, 1]
        est[e, 0], est[e, 1] = est_all[e, 0], est_all[e, 1]
        error[e], nees[e] = error_and_nees(est[e, 0] - truth[e, 0], est[e, 1] - truth[e, 1], cov[e, 0, 0],
                                           cov[e, 0, 1], cov[e, 1, 1])
        n = 0
        for s in range(read.shape[1]):
            n += read[e, s]
        reads[e] = n
        x = error[e] / error_scale
        error_term[e] = -(x if not x >= 10.0 else 10.0)
        energy_term[e] = -energy_cost * n
        rewards[e] = error_term[e] + energy_term[e]


@njit(cache=True, error_model="numpy", nogil=True)
def _observe(est, cov, cum, snr_obs, k, last_read, status, centre, position_scale, steps, obs):
    """:meth:`PassageCore._observe` into ``obs`` (E, 8 + H + S) float32: the table's entries in float64,
    clipped to [-1, 1]; NaN -> -1 among the log-likelihoods (a run with no finite likelihood), 0 elsewhere."""
    H, S = cum.shape[1], last_read.shape[1]
    row = np.empty(obs.shape[1])
    for e in range(est.shape[0]):
        track_features(est[e], cov[e], centre, position_scale, row)
        top = cum[e, 0]                                        # np.max: NaN if any is
        for h in range(1, H):
            if top == top and not cum[e, h] <= top:
                top = cum[e, h]
        for h in range(H):
            row[6 + h] = (cum[e, h] - top) / 50.0
        for s in range(S):
            row[6 + H + s] = snr_obs[e, k[e], s] * (1.0 if last_read[e, s] else 0.0)
        row[6 + H + S] = status[e] / 4.0
        row[7 + H + S] = k[e] / steps
        for i in range(row.size):
            v = row[i]
            if v != v:
                obs[e, i] = -1.0 if 6 <= i < 6 + H else 0.0
            else:
                obs[e, i] = min(max(v, -1.0), 1.0)


def _spaces(core):
    low = -np.ones(core.obs_dim, dtype=np.float32)
    high = np.ones(core.obs_dim, dtype=np.float32)
    low[-2:] = 0.0
    high[6:6 + core.H] = 0.0
    return spaces.Box(low, high, dtype=np.float32), spaces.MultiBinary(core.S)


class PassageEnv(RebuiltOnUnpickle, gym.Env):
    __doc__ = __doc__
    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(self, scenario="S2", overrides=None, filter=None, max_reads=None, energy_cost=0.01,
                 error_scale=10.0, render_mode=None, observer="tracker"):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.core = PassageCore(1, scenario, overrides, filter, max_reads, energy_cost, error_scale, observer)
        self.observation_space, self.action_space = _spaces(self.core)
        self.render_mode = render_mode
        self._started = False
        self._kwargs = dict(scenario=scenario, overrides=overrides, filter=filter, max_reads=max_reads,
                            energy_cost=energy_cost, error_scale=error_scale, render_mode=render_mode,
                            observer=observer)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        obs = self.core.reset_envs([0], [int(self.np_random.integers(SEED_HIGH))], fresh=seed is not None)
        self._started = True
        return obs[0], {}

    def step(self, action):
        if not self._started:
            raise RuntimeError("call reset() before step()")
        if self.core.k[0] >= self.core.K - 1:
            raise RuntimeError("the passage has ended: call reset()")
        rewards, terminated, info = self.core.step(np.asarray(action)[None])
        obs = self.core._observe()[0]
        return obs, float(rewards[0]), bool(terminated[0]), False, {k: v[0] for k, v in info.items()}

    def render(self):
        if self.render_mode == "rgb_array":
            return self.core.render(0)
        return None


class PassageVectorEnv(CoreVectorEnv):
    """Native vector version of ``shipsense/Passage-v0``: the same :class:`PassageCore` on a batch.

    Sub-environment ``i`` reset with ``seed`` behaves exactly like a single
    :class:`PassageEnv` reset with ``seed + i``.  Autoreset mode: next step; ``reset(options={"reset_mask":
    mask})`` resets only the masked sub-environments (gymnasium's partial reset, what SB3's adapter calls);
    with a seed it reseeds only them, as gymnasium's ``SyncVectorEnv`` does (:meth:`CoreVectorEnv.reset`).
    With many environments a step makes temporaries of 0.1-1 MB; on glibc,
    call :func:`shipsense.tune_allocator` once in the training process (about
    25 % more steps per second at 64 environments; ``shipsense train`` does).
    """

    def __init__(self, num_envs=1, scenario="S2", overrides=None, filter=None, max_reads=None, energy_cost=0.01,
                 error_scale=10.0, render_mode=None, observer="tracker"):
        self._check_render_mode(render_mode)
        self.num_envs = int(num_envs)
        self.core = PassageCore(self.num_envs, scenario, overrides, filter, max_reads, energy_cost, error_scale,
                                observer)
        self._batch(_spaces(self.core), render_mode)

    def _observation(self):
        return self.core._observe()

    def step(self, actions):
        actions = np.asarray(actions).reshape(self.num_envs, -1)
        done = self._autoreset()
        live = np.flatnonzero(~done)
        # environments that just reset do not step; the others advance together
        rewards, terminated, info = self.core.step(actions, envs=live if done.any() else None)
        rewards = np.where(done, 0.0, rewards)
        terminated = np.where(done, False, terminated)
        obs = self.core._observe()
        self._prev_done = terminated.copy()
        truncated = np.zeros(self.num_envs, dtype=bool)
        return obs, rewards.astype(np.float64), terminated, truncated, info


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
