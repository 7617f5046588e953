"""The state and dynamics of Passage-v1 environments (:mod:`shipsense.envs.passage_v1`), batched: E passages,
one batched tracker as their observer, the reads, rewards, observations, episode metrics and baselines of all
of them at once.  The single environment and the native vector one both run on :class:`PassageV1Core`."""

from __future__ import annotations

import copy
from itertools import combinations

import numpy as np

from shipsense.arguments import number
from shipsense.config import load_scenario
from shipsense.design.information_gain import information_gains_at
from shipsense.envs.features import (
    accumulate_steps,
    measure_errors,
    predicted_beliefs,
    read_sensors,
    write_observations,
)
from shipsense.envs.prefetch import PASSAGE_BLOCK, PassagePrefetch
from shipsense.simulator import simulate
from shipsense.trackers import Tracker
from shipsense.trackers.tracker.results import INITIALISING, NO_DATA

RECORDED = ("estimate", "cov", "status", "selected")
"""What the environment keeps of its observer's output (``PassageV1Core.last``, a Sample of these fields)."""


def _copy_outputs(sample, rows, into):
    """What the environment keeps of an observer's output ``sample`` (a
    :class:`~shipsense.trackers.tracker.results.Sample`
    or a dict of its fields) written into rows ``rows`` of the Sample ``into``."""
    for name in RECORDED:
        getattr(into, name)[rows] = sample[name] if isinstance(sample, dict) else getattr(sample, name)


CHI2_2_95 = 5.991464547107979
"""95 % quantile of the chi-square distribution with 2 degrees of freedom."""


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
        # Passage-v1 keeps its observer (and Passage-v2 the observer it was measured with): a bank starts from the
        # complete initialisation window
        tracker = Tracker(sc, passages=num_envs, early_starts=False)
        self.model = tracker.model
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
        # the observer's noise and the one-step transition, in the model's internal units (the estimates are
        # brought there by the model: FieldModel.to_internal, cov_to_internal)
        self._Rinv = np.ascontiguousarray(1.0 / tracker.filter_model.R, dtype=float)
        self._A = np.ascontiguousarray(self.model.A, dtype=float)
        self._scale = np.ascontiguousarray(self.model.x_scale, dtype=float)
        self._first = np.asarray(self.first_channel, dtype=np.int64)
        self._allocate(tracker)

    def _allocate(self, tracker):
        """The state of ``tracker.P`` environments observed by ``tracker`` (of this core's model)."""
        self.tracker = tracker
        self.E = E = tracker.P
        K = self.K
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

    def twin(self, num_envs):
        """A core of ``num_envs`` environments with this one's scenario, arguments, spaces and rewards, its observer
        a sibling of this one's (:meth:`~shipsense.trackers.Tracker.sibling`: the same model, so passage states
        move between the two), with no passage yet: for planners that simulate futures on it (their samples in
        ``y``, their truths in ``truth``) or run episodes of their own (:meth:`reset_envs`)."""
        twin = copy.copy(self)
        twin._allocate(self.tracker.sibling(number("num_envs", num_envs, 1, 100_000, integer=True)))
        return twin

    def copy_envs(self, source, rows, envs):
        """Environments ``envs`` of this core (a :meth:`twin`) set to environment ``rows`` of ``source``'s
        state as its agent and observer know it (``rows`` may repeat): sample index, start, steps since each
        read, last reads, episode sums, the observer's state and output and its predicted gains -- not the
        passage (``y``, ``truth``), which the caller writes."""
        rows, envs = np.asarray(rows, dtype=np.int64), np.asarray(envs, dtype=np.int64)
        for name in ("k", "start", "since", "last_read", "returns", "reads", "gains"):
            getattr(self, name)[envs] = getattr(source, name)[rows]
        _copy_outputs(source.last.take(rows), envs, self.last)
        distinct, which = np.unique(rows, return_inverse=True)
        states = source.tracker.passage_states(distinct)
        self.tracker.set_passage_states(envs, [states[i] for i in which.tolist()])

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
                entry[2] = (int(k[r]), {name: np.copy(getattr(last, name)[r]) for name in RECORDED}, state)
        return entries

    def _record(self, sample, envs):
        _copy_outputs(sample, envs, self.last)

    def _measure(self, envs):
        """Error and 95 % ellipse coverage of ``envs`` at their current sample (stored in the histories;
        compiled, :func:`~shipsense.envs.features.measure_errors`)."""
        error, nees = np.empty(envs.size), np.empty(envs.size)
        measure_errors(envs, self.k, self.last.estimate, self.last.cov, self.truth, CHI2_2_95, self.est_hist,
                       self.errors, self.inside, error, nees)
        return error, nees

    def _predict_gains(self, envs):
        """Predicted drop (nats) of the position covariance's log-det for every action, from the observer's
        estimate and covariance predicted one step, linearised there (0 while the observer has no track)."""
        blind = self._blind(envs)
        if blind.any():
            self.gains[envs[blind]] = 0.0
            envs = envs[~blind]   # (the prior's mean is the array centroid: a sensor may sit there)
        if envs.size == 0:
            return
        n = self.model.n
        x, P = np.empty((envs.size, n)), np.empty((envs.size, n, n))
        predicted_beliefs(envs, self.last.estimate, self.last.cov, self._scale, self._A, x, P)
        self.gains[envs] = information_gains_at(self.model, x, self._Rinv, P, self._first, self.subsets)

    def _blind(self, envs):
        """Whether the observers of ``envs`` have no track yet (status no data or initialising)."""
        return self._blind_status(self.last.status[envs])

    @staticmethod
    def _blind_status(status):
        return (status == NO_DATA) | (status == INITIALISING)

    def integer_actions(self, actions, copy=False):
        """``actions`` as an int64 vector (E,) (a copy with ``copy``); not integers (bools, fractions): one
        ``ValueError``."""
        actions = np.asarray(actions)
        if actions.dtype.kind not in "iu":                    # (not bool, not fractions)
            raise ValueError(f"actions must be integers in [0, {len(self.subsets)}), got {actions.dtype} values")
        return actions.astype(np.int64, copy=copy).reshape(self.E)

    def step(self, actions, envs=None):
        """Advance environments ``envs`` (default all) by one sample with actions (E,) (indices of
        :attr:`subsets`).  Returns rewards, terminated, truncated (E,; never truncated) and an info dict of (E,)
        arrays; entries of environments that did not step are meaningless."""
        actions = self.integer_actions(actions)
        who = self._rows if envs is None else np.asarray(envs, dtype=np.int64)
        y, reads = np.empty((who.size, self.model.m)), np.empty(self.E)
        bad = read_sensors(actions, who, self.subsets, self.sensor_of, self.y, self.k, self.since, self.last_read, y,
                           reads)
        if bad >= 0:
            raise ValueError(f"actions must be integers in [0, {len(self.subsets)}), got {actions[bad]} for "
                             f"environment {bad}")
        if envs is None:          # (every environment: the observer's fresh output is theirs in order)
            _copy_outputs(self.tracker.update(self.times[self.k], y), Ellipsis, self.last)
            error, nees = self._measure(who)
        else:
            self._record(self.tracker.update(self.times[self.k[who]], y, passages=who), who)
            error, nees = np.zeros(self.E), np.zeros(self.E)
            error[who], nees[who] = self._measure(who)
        self._predict_gains(who)
        error_term, energy_term = self.reward_terms(error, reads, who)
        rewards = error_term + energy_term
        accumulate_steps(who, rewards, reads, self.returns, self.reads)
        info = {"error": error, "nees": nees, "inside95": nees <= CHI2_2_95, "reads": reads,
                "error_term": error_term, "energy_term": energy_term, "status": self.last.status.copy(),
                "truth": self.truth[self._rows, self.k, :2], "estimate": self.last.estimate[:, :2].copy()}
        return rewards, self.k >= self.K - 1, np.zeros(self.E, dtype=bool), info

    # -- the reward's parts (a later version's core changes them) --------------------------------------------
    wake_cost = 0.0
    """Energy of waking a sensor not read at the previous step, on top of ``energy_cost`` (none in v1)."""
    budget = np.inf
    """Reads per passage (unlimited in v1)."""

    @property
    def error_weights(self):
        """The weight (K,) of each sample's error term in the reward (every sample's 1 in v1)."""
        return np.ones(self.K)

    def reward_terms(self, error, reads, who):
        """The error and energy terms (E,) of a step's reward from the position errors ``error`` (m) and the
        reads ``reads`` (E,) of environments ``who`` (v1: ``-ln(1 + e / e_s)`` and ``-c reads``)."""
        return -np.log1p(error / self.error_scale), -self.energy_cost * reads

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
        """Observations (E, obs_dim) float32 (the table of :class:`~shipsense.envs.passage_v1.PassageV1Env`;
        compiled, :func:`~shipsense.envs.features.write_observations`)."""
        obs = np.empty((self.E, self.obs_dim), dtype=np.float32)
        write_observations(self.last.estimate, self.last.cov, self.last.status, self.k, self.since, self.gains,
                           self.centre, float(self.position_scale), float(max(self.K - 1, 1)), obs)
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


def action_of(table, want):
    """The action indices (E,) whose rows of ``table`` (A, S) equal ``want`` (E, S)."""
    weights = 1 << np.arange(table.shape[1])
    code = table.astype(np.int64) @ weights
    lookup = np.full(int(code.max()) + 1, -1)
    lookup[code] = np.arange(table.shape[0])
    return lookup[want.astype(np.int64) @ weights]


__all__ = ["CHI2_2_95", "RECORDED", "PassageV1Core", "action_of", "subsets"]
