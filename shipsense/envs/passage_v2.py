"""``shipsense/Passage-v2``: schedule a sensor array's reads under an energy budget, with wake-up costs and an
error that counts at checkpoints.

## Description

One episode is one ship passage drawn from the scenario's prior past its
array, observed by the project's tracker as in ``shipsense/Passage-v1``
(:mod:`shipsense.envs.passage_v1`, whose core this environment runs on).
From the first sample on, the agent chooses at every step which sensors to
read, at most ``k`` of them.  What changes is what the reads cost and what
they earn:

* **wake-up costs**: a read costs ``energy_cost``, and a sensor that was
  not read at the previous step (asleep) costs ``wake_cost`` more to read;
* **a read budget** of ``budget`` reads per passage: a read beyond it is not
  made (the action reads nothing and costs nothing);
* **checkpoints**: the position error counts at ``checkpoints`` samples
  only, evenly spaced and ending at the passage's last, each weighted
  ``K / checkpoints`` (so a passage's error weight is that of v1's every
  step); ``checkpoints = 0`` counts every step, as v1.

These are what make thinking ahead pay: a read's value depends on where the
ship will be at the next checkpoint and on whether the sensor is awake, and
the budget links the steps; the one-step information-greedy policy sees
none of them.

## Action space

``Discrete(A)``, as Passage-v1: an index into ``PassageV2Env.subsets``,
every subset of at most ``k`` of the ``S`` sensors (action 0 reads nothing).

## Observation space

``Box(-1, 1, (11 + 2 S,), float32)``: Passage-v1's ``9 + 2 S`` entries
(the observer's estimate, its uncertainty, status, elapsed fraction, steps
since each sensor's read -- 0 means awake -- and the sensors' predicted
information gains), then

| index | content |
| --- | --- |
| 9+2S | the fraction of the read budget left (1 without a budget) |
| 10+2S | samples to the next checkpoint / (K - 1) (0 at one) |

## Rewards

``-w_t ln(1 + e / error_scale) - energy_cost * reads - wake_cost * wakes``
per step, with ``e`` the observer's position error (m) at the new sample
``t``, ``w_t`` its checkpoint weight (0 between checkpoints) and ``wakes``
the sensors read that were not read at the previous step.  Not capped, as
Passage-v1's.  Both terms are in ``info`` (``error_term``, ``energy_term``).

## Starting state, episode end

As Passage-v1: the observer's run-in reads every sensor until it has a
track (so every sensor starts awake); the episode ends at the passage's
last sample (terminated; never truncated).

## Info

Passage-v1's keys (``error``, ``nees``, ``inside95``, ``reads``,
``error_term``, ``energy_term``, ``status``, ``truth``, ``estimate``) and
``wakes`` and ``budget_left``; at the episode's end ``episode_metrics``:
Passage-v1's (``energy`` the energy spent, wake-ups included) and
``checkpoint_error_m``, the mean error at the checkpoints the agent met.

## Arguments

``scenario``, ``overrides``, ``k``, ``error_scale``, ``render_mode`` as
Passage-v1; ``energy_cost`` (per read, default 0.01), ``wake_cost`` (per
wake-up, default 0.1), ``budget`` (reads per passage, default 20, or None
for none), ``checkpoints`` (a count, default 4; 0 for every step).  All JSON-able; a bad value raises one
``ValueError`` naming the argument.

## Variants (registered)

``shipsense.envs.PASSAGE_V2_VARIANTS``:

* ``shipsense/Passage-v2``: Passage-v1's line of four magnetometers 40 m
  apart, one read per step, with the default costs, budget and checkpoints.
* ``shipsense/PassageManoeuvring-v2``: the same, with ships that turn and
  change speed (the scenario's ``[manoeuvres]``) and the
  interacting-multiple-model observer (``[tracker.motion]``).  Second
  ships are left to a variant once the simulator draws them.
* ``shipsense/PassageHard-v2``: ``shipsense/PassageHard-v1``'s task (six
  magnetometers 30 m apart, two read per step, outliers, dropouts, its
  wide prior) and reward (v1's: no wake-up cost, budget or checkpoints:
  ``wake_cost=0``, ``budget=None``, ``checkpoints=0``), with an observer
  made robust to partial reads under contamination
  (``shipsense.envs.HARD_V2_OBSERVER``, tracker options): its scheduled
  refits and global rescans run the whole passage, where v1's stopped at
  the first step that read two far sensors (the strongest channel read
  fell below half the run-in's peak, which the observer took for the
  closest approach), and its first fit waits for the complete window
  rather than stopping where outliers made the signal look past its peak.

``shipsense/Passage-v2``'s ``reward_threshold`` is the rollout planner's
mean return on held-out passages (docs: the environments guide): an agent
that reaches it plans as well as a one-step lookahead over greedy with
Monte Carlo futures.  The manoeuvring variant's is the same rule on 100
held-out passages (docs: Trained agents, "PassageManoeuvring-v2"); there
rollout is not clearly better than greedy, and greedy-threshold scores
above it on average.  ``shipsense/PassageHard-v2``'s is the best baseline's
mean return on held-out passages, as for Passage-v1's variants (docs: the
agents findings, "PassageHard-v2").

## Version history

* v2, later: ``shipsense/PassageManoeuvring-v2``'s ``reward_threshold``
  measured (-43.9; it was None).  Its dynamics, spaces and rewards are
  unchanged, and so are Passage-v2's.
* v2: wake-up costs, a read budget per passage and an error that counts at
  checkpoints, two observation entries for them, ``wakes`` and
  ``budget_left`` in ``info``.  Why: on Passage-v1 the information-greedy
  policy is near optimal (its headroom over greedy was energy alone), so a
  learned scheduler could only copy it; these are the known sources of
  headroom over myopic scheduling (budgets and switching costs that link
  steps, terminal objectives).
* v1: :mod:`shipsense.envs.passage_v1`.  ``shipsense/PassageHard-v1``'s
  task moved to ``shipsense/PassageHard-v2`` (2026-11-28) with a robust
  observer: on v1's, a few passages where the observer lost the ship
  decided its baselines' means (greedy, which reads where the observer
  believes the ship is, never found it again).
"""

from __future__ import annotations

import numpy as np

from shipsense.arguments import number
from shipsense.envs.features import accumulate_costs, apply_budget, write_budget_features
from shipsense.envs.passage_core import PassageV1Core
from shipsense.envs.passage_v1 import PassageV1Env, PassageV1VectorEnv


class PassageV2Core(PassageV1Core):
    """State and dynamics of E Passage-v2 environments at once: :class:`~shipsense.envs.passage_core.PassageV1Core`
    with wake-up costs, a read budget and checkpoint weights (the module docstring)."""

    def __init__(self, num_envs=1, scenario="S2", overrides=None, k=1, energy_cost=0.01, wake_cost=0.1,
                 budget=20, checkpoints=4, error_scale=1.0):
        super().__init__(num_envs, scenario, overrides, k, energy_cost, error_scale)
        self.wake_cost = number("wake_cost", wake_cost, 0.0, 1e6)
        self.budget = np.inf if budget is None else float(number("budget", budget, 0, 1_000_000, integer=True))
        self.checkpoints = number("checkpoints", checkpoints, 0, self.K - 1, integer=True)
        w = np.zeros(self.K)
        if self.checkpoints == 0:
            w[:] = 1.0
        else:
            at = np.round(np.linspace(self.K - 1, 0, self.checkpoints, endpoint=False)).astype(int)
            w[at] = self.K / self.checkpoints
        self._weights = w
        ahead = np.full(self.K, self.K - 1)      # the next checkpoint at or after each sample
        marks = np.flatnonzero(w > 0)
        ahead[:marks[-1] + 1] = marks[np.searchsorted(marks, np.arange(marks[-1] + 1))]
        self._next_mark = ahead
        self.obs_dim = 11 + 2 * self.S

    def _allocate(self, tracker):
        super()._allocate(tracker)
        self.wakes = np.zeros(self.E)
        self.energy = np.zeros(self.E)
        self.step_wakes = np.zeros(self.E)

    @property
    def error_weights(self):
        return self._weights

    def copy_envs(self, source, rows, envs):
        super().copy_envs(source, rows, envs)
        rows, envs = np.asarray(rows, dtype=np.int64), np.asarray(envs, dtype=np.int64)
        self.wakes[envs], self.energy[envs] = source.wakes[rows], source.energy[rows]

    def reset_envs(self, envs, seeds, fresh=False, ahead=None):
        envs = np.asarray(envs, dtype=int)
        self.wakes[envs] = 0.0
        self.energy[envs] = 0.0
        return super().reset_envs(envs, seeds, fresh, ahead)

    def budget_left(self):
        """The reads left (E,) (inf without a budget)."""
        return self.budget - self.reads

    def step(self, actions, envs=None):
        """Passage-v1's step (:meth:`~shipsense.envs.passage_core.PassageV1Core.step`) after the budget: an action
        reading more sensors than the budget has left reads nothing."""
        actions = self.integer_actions(actions, copy=True)      # (the budget writes into it)
        apply_budget(actions, self.subsets, float(self.budget), self.reads, self.last_read, self.step_wakes)
        rewards, terminated, truncated, info = super().step(actions, envs)
        who = self._rows if envs is None else np.asarray(envs, dtype=np.int64)
        accumulate_costs(who, self.step_wakes, info["energy_term"], self.wakes, self.energy)
        info["wakes"] = self.step_wakes.copy()
        info["budget_left"] = self.budget_left()
        return rewards, terminated, truncated, info

    def reward_terms(self, error, reads, who):
        """``-w_t ln(1 + e / e_s)`` and ``-(c reads + c_w wakes)`` (the module docstring)."""
        weight = self._weights[self.k]
        return -weight * np.log1p(error / self.error_scale), \
            -(self.energy_cost * reads + self.wake_cost * self.step_wakes)

    def episode_metrics(self, envs):
        envs = np.asarray(envs, dtype=int)
        out = super().episode_metrics(envs)
        out["energy"] = self.energy[envs].copy()
        out["wakes"] = self.wakes[envs].copy()
        ks = np.arange(self.K)[None, :]
        marks = (ks > self.start[envs, None]) & (ks <= self.k[envs, None]) & (self._weights[None, :] > 0)
        count = np.maximum(marks.sum(axis=1), 1)
        out["checkpoint_error_m"] = np.where(marks, self.errors[envs], 0.0).sum(axis=1) / count
        return out

    def observe(self):
        """Passage-v1's observations and the two of v2 (the module docstring)."""
        obs = super().observe()
        write_budget_features(float(self.budget), self.reads, self._next_mark, self.k, float(max(self.K - 1, 1)), obs,
                              9 + 2 * self.S)
        return obs


class PassageV2Env(PassageV1Env):
    __doc__ = __doc__

    def __init__(self, scenario="S2", overrides=None, k=1, energy_cost=0.01, wake_cost=0.1, budget=20,
                 checkpoints=4, error_scale=1.0, render_mode=None):
        self.adopt_core(lambda: PassageV2Core(1, scenario, overrides, k, energy_cost, wake_cost, budget, checkpoints,
                                              error_scale), render_mode,
                        dict(scenario=scenario, overrides=overrides, k=k, energy_cost=energy_cost, wake_cost=wake_cost,
                             budget=budget, checkpoints=checkpoints, error_scale=error_scale))


class PassageV2VectorEnv(PassageV1VectorEnv):
    """Native vector version of ``shipsense/Passage-v2``: one :class:`PassageV2Core` (one batched tracker) for all
    sub-environments, as :class:`~shipsense.envs.passage_v1.PassageV1VectorEnv` (next-step autoreset; sub-environment
    ``i`` reset with an integer ``seed`` behaves exactly like a single :class:`PassageV2Env` reset with
    ``seed + i``; the same baselines and shaping potential)."""

    def __init__(self, num_envs=1, scenario="S2", overrides=None, k=1, energy_cost=0.01, wake_cost=0.1,
                 budget=20, checkpoints=4, error_scale=1.0, render_mode=None):
        self.check_render_mode(render_mode)
        self.start_on(PassageV2Core(num_envs, scenario, overrides, k, energy_cost, wake_cost, budget, checkpoints,
                                    error_scale), render_mode)


__all__ = ["PassageV2Core", "PassageV2Env", "PassageV2VectorEnv"]
