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
sensor alone were read at the next step, linearised at the observer's
one-step prediction with the observer's own noise model; 0 while the
observer has no track (its estimate is then the prior's mean, where a
linearisation means nothing).

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
prior's mean whatever is read, so those samples would add the same 50-100 m
errors to every policy's return and hide the scheduling (measured on S2
before the run-in: the first 30 of 80 samples made up most of every
baseline's return).  A passage that never gets a track leaves the agent one
step.  The run-in does not depend on the agent, so the environment does the
run-ins of its next passages ahead, in batches, on the process's background
thread while the agent steps (:meth:`PassageV1Core.reset_envs`; episodes are
the same to the bit; ``SHIPSENSE_THREADS=1`` keeps everything on the calling
thread).

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
* v0 (``shipsense/Passage-v0``, :mod:`shipsense.envs.passage`): a
  ``MultiBinary`` action trimmed to ``max_reads``, the error reward capped at
  100 m; kept registered for comparison with earlier results.
"""

from __future__ import annotations

import math
import os
import weakref
from functools import partial
from itertools import combinations

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numba import njit

from shipsense import numba_cache, parallel
from shipsense.config import load_scenario
from shipsense.envs.arguments import number
from shipsense.envs.core_env import SEED_HIGH, ClosesItsFigure, CoreVectorEnv, RebuiltOnUnpickle, seed_ahead
from shipsense.envs.features import at_least, error_and_nees, track_features
from shipsense.models.measurement import FIELD, batch_kernel, kernel_of
from shipsense.simulator import simulate
from shipsense.trackers import Tracker
from shipsense.trackers.fit.linalg import solve_many_in_place
from shipsense.trackers.tracker.results import INITIALISING, NO_DATA

PASSAGE_BLOCK = 16
"""Passages simulated per simulator call and environment (see :meth:`PassageV1Core.reset_envs`)."""
EXPECT_BATCH = 16
"""Announced seeded resets (:meth:`PassageV1Env.expect_seeds`) whose passages' run-ins are done ahead in one batch;
at most two batches are drawn ahead."""
_RECORDED = ("estimate", "cov", "status", "selected")
"""What the environment keeps of its observer's output (:attr:`PassageV1Core.last`)."""


def _copy_outputs(sample, rows, into):
    """What the environment keeps of an observer's output ``sample`` (a
    :class:`~shipsense.trackers.tracker.results.Sample` or a dict of its fields) written into rows ``rows`` of the
    Sample ``into``."""
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


class _Later:
    """Work left to the background thread (:func:`~shipsense.parallel.background`, under
    :func:`~shipsense.parallel.serial`): :meth:`result` waits for it, or does it here if it has not started (or
    if this is a forked child, where the parent's background thread does not exist)."""

    def __init__(self, fn):
        self._fn, self._done, self._value = fn, False, None
        self._pid = os.getpid()
        self._future = parallel.background().submit(self._serial)

    def _serial(self):
        with parallel.serial():
            return self._fn()

    def result(self):
        if not self._done:
            if self._pid != os.getpid() or self._future.cancel():   # here, with this thread's splits
                self._value = self._fn()
            else:
                self._value = self._future.result()
            self._done, self._fn, self._future = True, None, None
        return self._value

    def cancel(self):
        """Drop the work if it has not started (a later :meth:`result` does it here)."""
        if not self._done:
            self._future.cancel()

    def __getstate__(self):
        return {"_fn": None, "_done": True, "_value": self.result(), "_future": None, "_pid": None}


def _rest_of_block(core, entries):
    """Background work: the run-ins of queue ``entries`` of the core weakly referenced by ``core`` (nothing if it
    is gone: the queued work does not keep a dropped environment alive)."""
    core = core()
    return None if core is None else core._run_ins(entries)


def _blocks_ahead(core, seeds, first_only=False):
    """Background work: blocks drawn from ``seeds``, the run-ins of their passages in one batch (a passage's run-in
    does not depend on the passages beside it) -- with ``first_only``, of their first passages only (what seeded
    resets use of a block, :meth:`PassageV1Core.expect`) -- for the core weakly referenced by ``core``."""
    core = core()
    if core is None:
        return None
    blocks = [core._block(seed) for seed in seeds]
    core._run_ins([entry for block in blocks for entry in (block[:1] if first_only else block)])
    return blocks


class _Part:
    """One block's share of work left to the background that draws several blocks (the next blocks of several
    environments, :meth:`PassageV1Core._leave_ahead`, or announced ones, :meth:`PassageV1Core.expect`):
    :meth:`result` is its block (waiting for the work, or doing it here if it has not started); :meth:`cancel`
    drops the share, and the work once every share is dropped.  ``seed``: the block's."""

    def __init__(self, job, index, seed, live):
        self.job, self.index, self.seed, self._live, self._block = job, index, seed, live, None

    def result(self):
        if self._block is None:      # (taken out of the work's result: a block used is not kept by the others)
            blocks = self.job.result()
            self._block, blocks[self.index] = blocks[self.index], None
        return self._block

    def cancel(self):
        self._live[self.index] = False
        if not any(self._live):
            self.job.cancel()


class PassageV1Core:
    """State and dynamics of E Passage-v1 environments at once (E = 1 for :class:`PassageV1Env`)."""

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
        self.last = self.tracker._prior_sample()
        self.gains = np.zeros((E, len(self.subsets)))   # predicted gain (nats) of every action
        self._passages = {}      # environment -> its queue of passages, [y, truth, run-in, job] each
        self._next = {}          # environment -> its next block, left to the background (reset_envs): a _Part
        self._wanted = {}        # environment -> the seed of its next block, not yet left to the background
        self._expected = {}      # block seed -> its block with the first run-in, left to the background: a _Part
        self._to_expect = iter(())   # block seeds announced (expect), not yet left to the background
        # (the next blocks of this many environments are left in one piece of work, their run-ins in one batch)
        self._group = max(1, min(self.E, self.tracker.independent_batch // PASSAGE_BLOCK))
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
        """Draw new passages for ``envs`` (indices) from integer ``seeds``, each with its observer's run-in
        done (:meth:`_run_ins`).  Passages are simulated in blocks of :data:`PASSAGE_BLOCK` per environment; an
        explicit seed (``fresh``) drops the rest of a block first.  Returns the observations of ``envs``.

        ``ahead(e, j)``, optional: the seed environment ``e``'s ``j``-th reset from now will be given.  With it
        (if :func:`~shipsense.parallel.background_allowed`), a reset that is not ``fresh`` leaves the run-ins its
        environments need later -- the rest of their blocks, and their next block, drawn from the seed the reset
        that empties the block will get -- to the process's background thread
        (:func:`~shipsense.parallel.background`), where they are done while the environments step; the next
        blocks of several environments go together, their run-ins in one batch (:meth:`_leave_ahead`).  Nothing
        changes but when they are done: a passage's run-in does not depend on the batch or thread it runs in, a
        block is used only if its seed is the one that reset draws (else it is drawn again here), and work the
        background has not started when it is needed is done here."""
        envs = np.asarray(envs, dtype=int)
        for e, s in zip(envs.tolist(), seeds):   # each environment draws from its own reproducible stream
            queue = self._passages.setdefault(e, [])
            if fresh:                            # (the work left for what is dropped: cancelled if not started)
                for job in self._jobs([e]):
                    job.cancel()
                self._next.pop(e, None)
                self._wanted.pop(e, None)
                queue.clear()
            if not queue:
                queue.extend(self._take_block(e, int(s)))
        later = ahead is not None and not fresh and parallel.background_allowed()
        # the run-ins these resets need now; without the background and unless the seeds are fresh (an
        # evaluation's reset(seed=...) per episode would waste the rest of every block), with those of every
        # passage queued in any environment, in one batch
        now = ([self._passages[e][0] for e in envs.tolist()] if fresh or later else
               [entry for queue in self._passages.values() for entry in queue])
        self._settle(now)
        states = []
        for e in envs.tolist():
            self.y[e], self.truth[e], (self.k[e], record, state), _ = self._passages[e].pop(0)
            _copy_outputs(record, e, self.last)
            states.append(state)
        if later:
            for e in envs.tolist():
                queue = self._passages[e]
                rest = [entry for entry in queue if entry[2] is None and entry[3] is None]
                if rest:
                    job = _Later(partial(_rest_of_block, weakref.ref(self), rest))
                    for entry in rest:
                        entry[3] = job
                if e not in self._next and e not in self._wanted:
                    self._wanted[e] = int(ahead(e, len(queue) + 1))
            self._leave_ahead()
        self.tracker.set_passage_states(envs, states)
        self.start[envs] = self.k[envs]
        self.since[envs] = 0.0
        self.last_read[envs] = True
        self.returns[envs] = 0.0
        self.reads[envs] = 0.0
        self._measure(envs)
        self._predict_gains(envs)
        return self.observe()[envs]

    def _block(self, seed):
        """The queue entries ``[y, truth, run-in, job]`` of a block of passages simulated from ``seed`` (no run-in
        yet)."""
        sim = simulate(self.scenario, runs=PASSAGE_BLOCK, seed=seed, random=True)
        return [[y, truth, None, None] for y, truth in zip(sim.measurements, self.model.state_from_truth(sim.truth))]

    def _leave_ahead(self):
        """Leave the next blocks wanted (:attr:`_wanted`) to the background, the next blocks of :attr:`_group`
        environments in one piece of work: once that many want one, or at once when an environment wanting one
        has half a block or less left.  Their run-ins in one batch cost less a passage than a block's alone
        (2.8-2.9 against 3.4 ms of CPU, Passage-v1, six blocks against one: ``benchmarks/where_time_goes.py
        runins``; at 64 envs 19.1-21.3k against 16.7-19.2k env-steps/s: benchmarks/LOG.md)."""
        while self._wanted and (len(self._wanted) >= self._group or any(
                len(self._passages.get(e, ())) <= PASSAGE_BLOCK // 2 for e in self._wanted)):
            envs = list(self._wanted)[:self._group]
            seeds = [self._wanted.pop(e) for e in envs]
            job, live = _Later(partial(_blocks_ahead, weakref.ref(self), seeds)), [True] * len(envs)
            for i, (e, seed) in enumerate(zip(envs, seeds)):
                self._next[e] = _Part(job, i, seed, live)

    def _take_block(self, e, seed):
        """Environment ``e``'s next block of queue entries: the one drawn ahead if it was drawn from ``seed``, or
        the announced one of ``seed`` (:meth:`expect`), if the background did not fail it; else drawn here (as
        when it was only wanted, not yet left to the background)."""
        self._wanted.pop(e, None)
        block = self._next.pop(e, None)
        if block is not None and block.seed != seed:   # drawn from another seed (a user drew from the generator)
            block.cancel()
            block = None
        if block is None:                    # announced (expect): its first passage's run-in done ahead
            block = self._expected.pop(seed, None)
            if block is not None:
                self._expect_ahead()
        if block is not None:
            try:
                return block.result()
            except Exception:                # the background's attempt failed: drawn here, as without it
                pass
        return self._block(seed)

    def expect(self, seeds):
        """Announce that the next resets will draw blocks from ``seeds`` (an iterable of block seeds, in order,
        read as needed) and each use only its first passage, as seeded resets do (an evaluation's episodes):
        those blocks and their first passages' run-ins are drawn ahead on the background thread,
        :data:`EXPECT_BATCH` at a time, at most two batches ahead.  Nothing changes but when the work is done: a
        block is used only by a reset that draws its seed, and a passage's run-in does not depend on its batch.
        Replaces an earlier announcement; without the background (:func:`~shipsense.parallel.background_allowed`)
        it does nothing."""
        self._drop_expected()
        if parallel.background_allowed():
            self._to_expect = iter(seeds)
            self._expect_ahead()

    def _expect_ahead(self):
        """Leave announced blocks (:meth:`expect`) to the background, a batch at a time, whenever at most one batch's
        worth is out (so at most two batches are)."""
        while len(self._expected) <= EXPECT_BATCH:
            seeds = []
            try:
                for seed in self._to_expect:
                    seed = int(seed)
                    if seed not in self._expected and seed not in seeds:
                        seeds.append(seed)
                    if len(seeds) == EXPECT_BATCH:
                        break
                else:                # (read to its end: let it go)
                    self._to_expect = iter(())
            except Exception:        # (a seed the announcement cannot read ends it: its reset says what is wrong)
                self._to_expect = iter(())
            if not seeds:
                return
            job, live = _Later(partial(_blocks_ahead, weakref.ref(self), seeds, first_only=True)), [True] * len(seeds)
            for i, seed in enumerate(seeds):
                self._expected[seed] = _Part(job, i, seed, live)

    def _drop_expected(self):
        """Forget the announced blocks (:meth:`expect`): the work not started is cancelled."""
        for part in self._expected.values():
            part.cancel()
        self._expected.clear()
        self._to_expect = iter(())

    def _jobs(self, envs):
        """The work left to the background for environments ``envs``: their queues' and next blocks'."""
        jobs = [self._next[e] for e in envs if e in self._next]
        for e in envs:
            jobs += [entry[3] for entry in self._passages.get(e, ()) if entry[3] is not None]
        return jobs

    def _settle(self, entries):
        """Give queue ``entries`` their run-ins: those left to the background waited for (or, not started, done
        here), the others done here in one batch."""
        for entry in entries:
            if entry[3] is not None:
                try:
                    entry[3].result()
                except Exception:            # the background's attempt failed: done here (raising if it fails here)
                    pass
                entry[3] = None
        self._run_ins([entry for entry in entries if entry[2] is None])

    def settle(self):
        """Finish every run-in left to the background thread (:meth:`reset_envs`; work the background failed
        is done here): nothing this core will use is then in flight (pickling calls it; work for passages a
        seeded reset dropped may still be running, for nothing)."""
        for e, block in list(self._next.items()):
            try:
                block.result()
            except Exception:                # (failed: its reset draws the block itself, from the same seed)
                del self._next[e]
        self._settle([entry for queue in self._passages.values() for entry in queue if entry[3] is not None])

    def __getstate__(self):
        self.settle()
        # (announced blocks are not part of the state: a reset draws its block itself)
        return {**self.__dict__, "_expected": {}, "_to_expect": iter(())}

    def __setstate__(self, state):
        self.__dict__.update({"_expected": {}, "_to_expect": iter(()), **state})

    def drop_pending(self):
        """Cancel the run-ins left to the background that have not started (``close()`` calls it: an environment
        closed does not keep the background thread busy); a later reset does what it needs itself."""
        for job in self._jobs(set(self._passages) | set(self._next)):
            job.cancel()
        self._wanted.clear()
        self._drop_expected()

    def _run_ins(self, entries):
        """The observer's run-in of queued passages ``entries`` (``[y, truth, None, ...]`` lists; the run-in is put
        in their third place; returns ``entries``), in batches on a sibling of the observer
        (:meth:`~shipsense.trackers.Tracker.sibling`): a passage's run-in does not depend on the agent (every
        sensor is read) nor on the passages beside it in a batch, so it is the one it would have had in its
        environment, at a fraction of the cost (its window fits in one batch: 2.8-3.3 ms of CPU a passage in a
        batch of 16 to 96, 8.7-8.9 alone: ``benchmarks/where_time_goes.py runins``).  A batch holds at most
        :attr:`~shipsense.trackers.Tracker.independent_batch` passages (102): in a larger one the banks' starts
        move at rounding.

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
            last = trk._prior_sample()
            _copy_outputs(trk.update(self.times[0], y[:, 0]), rows, last)
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
        :attr:`subsets`).  Returns rewards, terminated (E,) and an info dict of (E,) arrays; entries of
        environments that did not step are meaningless."""
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
        return rewards, self.k >= self.K - 1, info

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


def information_gains(Hm, Rinv, P, first_channel, subsets):
    """Drop (nats) of the position block's log-det of covariances ``P`` (E, n, n) when the sensors of each of
    ``subsets`` (A, S) are read, in information form: Jacobians ``Hm`` (E, m, n), inverse noise variances
    ``Rinv`` (m,), channels grouped by sensor from ``first_channel`` (S,, increasing; a sensor whose start
    equals the next one's has no channel).  Returns (E, A): ``log det P_pp - log det ((P^-1 + sum over the
    read channels of H_i^T H_i / R_i)^-1)_pp`` (``pp`` the position block), 0 where that is negative or not
    finite (a singular ``P``, a non-finite Jacobian row of a sensor read) and for a subset that reads
    nothing.  ``subsets`` are booleans (any nonzero entry reads its sensor).  Compiled (:func:`_gains`): the
    environment calls it every step."""
    Hm, P = (np.ascontiguousarray(a, dtype=float) for a in (Hm, P))
    out = np.empty((P.shape[0], len(subsets)))
    _gains(Hm, np.ascontiguousarray(Rinv, dtype=float), P, np.asarray(first_channel, dtype=np.int64),
           np.ascontiguousarray(subsets, dtype=np.bool_), out)
    return out


def information_gains_at(model, x, Rinv, P, first_channel, subsets):
    """:func:`information_gains` with the Jacobians of ``model`` at its internal states ``x`` (E, n): in one
    compiled call with the model's compiled measurement kernel (the Jacobians :meth:`FieldModel.H` gives, from
    the same kernel), else through ``model.H``."""
    spec = kernel_of(model)
    if spec is None or spec[0] != FIELD:
        return information_gains(model.H(x), Rinv, P, first_channel, subsets)
    P = np.ascontiguousarray(P, dtype=float)
    out = np.empty((P.shape[0], len(subsets)))
    _gains_at(np.ascontiguousarray(x, dtype=float), spec, np.ascontiguousarray(Rinv, dtype=float), P,
              np.asarray(first_channel, dtype=np.int64), np.ascontiguousarray(subsets, dtype=np.bool_), out)
    return out


@njit(cache=True, error_model="numpy", nogil=True)
def _gains_at(X, spec, Rinv, P, first_channel, subsets, out):
    """:func:`information_gains_at`: the states' Jacobians from the measurement kernel's batch
    (:func:`~shipsense.models.measurement.batch_kernel`, as ``model.H``), then :func:`_gains`."""
    E, n = X.shape
    m = Rinv.shape[0]
    Hm = np.empty((E, m, n))
    batch_kernel(X, spec, np.empty((E, m)), Hm, True)
    _gains(Hm, Rinv, P, first_channel, subsets, out)


@njit(cache=True, error_model="numpy", nogil=True)
def _gains(Hm, Rinv, P, first_channel, subsets, out):
    E, m, n = Hm.shape
    S = first_channel.size
    Js = np.empty((S, n, n))
    Pinv, M, X = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    reads = np.zeros(subsets.shape[0], dtype=np.bool_)
    for t in range(subsets.shape[0]):
        for s in range(S):
            reads[t] |= subsets[t, s]
    for e in range(E):
        for s in range(S):                      # each sensor's information sum_i H_i^T H_i / R_i
            hi = first_channel[s + 1] if s + 1 < S else m
            for a in range(n):
                for b in range(n):
                    acc = 0.0
                    for i in range(first_channel[s], hi):
                        acc += Hm[e, i, a] * Rinv[i] * Hm[e, i, b]
                    Js[s, a, b] = acc
        for a in range(n):                      # P^-1: one elimination, the identity's columns
            for b in range(n):
                M[a, b] = P[e, a, b]
                Pinv[a, b] = 1.0 if a == b else 0.0
        solve_many_in_place(M, Pinv, n, n)
        before = math.log(abs(P[e, 0, 0] * P[e, 1, 1] - P[e, 0, 1] * P[e, 1, 0]))
        for t in range(subsets.shape[0]):
            if not reads[t]:                    # (reading nothing gains nothing)
                out[e, t] = 0.0
                continue
            for a in range(n):                  # the first two columns of (P^-1 + J)^-1
                for b in range(n):
                    acc = Pinv[a, b]
                    for s in range(S):
                        if subsets[t, s]:
                            acc += Js[s, a, b]
                    M[a, b] = acc
                X[a, 0] = 1.0 if a == 0 else 0.0
                X[a, 1] = 1.0 if a == 1 else 0.0
            solve_many_in_place(M, X, n, 2)
            g = before - math.log(abs(X[0, 0] * X[1, 1] - X[0, 1] * X[1, 0]))
            out[e, t] = max(g, 0.0) if math.isfinite(g) else 0.0


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
        rewards, terminated, info = self.core.step(np.array([int(action)]))
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
    all sub-environments.

    Sub-environment ``i`` reset with an integer ``seed`` behaves exactly like a single :class:`PassageV1Env`
    reset with ``seed + i``; ``seed`` may also be a list of ``num_envs`` seeds (``None`` entries draw fresh
    entropy).  **Autoreset mode: next step** (``AutoresetMode.NEXT_STEP``, gymnasium 1.x): the step after a
    sub-environment terminated resets it, ignores its action and returns its first observation with reward 0,
    ``terminated`` and ``truncated`` False.  ``info`` holds, per key, an (num_envs,) array and the ``_key``
    mask of the sub-environments it is valid for (those that stepped); ``info["episode_metrics"]`` (with its
    own masks) for those that terminated.  ``reset(options={"reset_mask": mask})`` (gymnasium's partial reset)
    resets only the masked sub-environments, each from its own stream: SB3's adapter
    (:class:`~shipsense.envs.sb3.VectorEnvAdapter`) calls it in the step an episode ends.  With a ``seed`` it
    reseeds only them, as gymnasium's ``SyncVectorEnv`` does; the others' streams and the run-ins done ahead
    for them are kept.
    """

    BASELINES = BASELINES
    potential = staticmethod(observation_potential)
    """The shaping potential of training (:func:`observation_potential`)."""

    def __init__(self, num_envs=1, scenario="S2", overrides=None, k=1, energy_cost=0.01, error_scale=1.0,
                 render_mode=None):
        self._check_render_mode(render_mode)
        self.core = PassageV1Core(num_envs, scenario, overrides, k, energy_cost, error_scale)
        self.num_envs = self.core.E
        self.subsets = self.core.subsets
        self._batch(_spaces(self.core), render_mode)

    def _observation(self):
        return self.core.observe()

    def step(self, actions):
        actions = np.asarray(actions).reshape(self.num_envs)
        if actions.dtype.kind not in "iu" or np.any((actions < 0) | (actions >= len(self.subsets))):
            raise ValueError(f"actions must be integers in [0, {len(self.subsets)})")
        done = self._autoreset()
        live = ~done
        rewards, terminated, info = self.core.step(np.where(live, actions, 0),
                                                   envs=np.flatnonzero(live) if done.any() else None)
        rewards = np.where(live, rewards, 0.0)
        terminated = terminated & live
        infos = {}
        for key, v in info.items():
            infos[key], infos["_" + key] = v, live.copy()
        if terminated.any():
            ended = np.flatnonzero(terminated)
            metrics = {}
            for key, v in self.core.episode_metrics(ended).items():
                full = np.zeros(self.num_envs)
                full[ended] = v
                metrics[key], metrics["_" + key] = full, terminated.copy()
            infos["episode_metrics"], infos["_episode_metrics"] = metrics, terminated.copy()
        self._prev_done = terminated.copy()
        return (self.core.observe(), rewards.astype(np.float64), terminated,
                np.zeros(self.num_envs, dtype=bool), infos)

    def close_extras(self, **kwargs):
        self.core.drop_pending()

    def baseline(self, name, seed=None):
        """The batched baseline policy ``name``: ``policy(obs) -> actions`` (num_envs,)."""
        _check_baseline(name)
        return _Policy(self.core, name, seed, single=False)


__all__ = ["BASELINES", "PassageV1Core", "PassageV1Env", "PassageV1VectorEnv", "information_gains",
           "information_gains_at", "observation_potential", "subsets"]


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
