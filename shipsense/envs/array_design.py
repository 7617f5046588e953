"""``shipsense/ArrayDesign-v0`` (the old version, kept registered; use ``shipsense/ArrayDesign-v1``,
:mod:`shipsense.envs.site_design`): place k sensors one by one on a candidate set.

## Description

One episode places ``k`` copies of the scenario's first sensor on a grid of
candidate positions.  When the k-th sensor is placed, the finished layout is
judged by the tracker itself: the project's tracker (``observer="bank"``:
the scenario's bank) tracks a fixed batch of passages drawn from the prior
(the same batch every episode, so rewards are comparable), and the reward is
its convergence rate minus its mean TRMSE / 100 m.  Optionally each placement is shaped by its information gain (the
increase of the prior-averaged log det of the Fisher information).  The
ambiguity verdict of the finished layout is in ``info``.

## Action space

``Discrete(n_candidates)``: the candidate to place next.  ``action_masks()``
returns the candidates still free (for sb3-contrib's MaskablePPO).  An
invalid pick (an occupied candidate) is a no-op with reward -1, so plain PPO
works too.  With ``continuous=True``: ``Box(-1, 1, (2,))``, a position in the
candidate square, snapped to the nearest free candidate.

## Observation space

``Box(0, 1, (n_candidates + 1,), float32)``: 1 where a sensor stands, then
the fraction of the k sensors placed.

## Rewards

0 per placement (plus ``shaping`` x information gain if ``shaping > 0``);
at the last one ``convergence_rate - min(TRMSE / 100 m, 1)``.  -1 for an
invalid pick.

## Episode end

Terminated after k valid placements.

## Arguments

``scenario``, ``k`` (3), ``half_width`` (m, 30), ``spacing`` (m, 7.5),
``passages`` (8), ``shaping`` (0.0), ``continuous`` (False), ``seed_passages``
(10000), ``check_ambiguity`` (True), ``observer`` (``"tracker"`` or
``"bank"``), ``render_mode``.  All JSON-able.

## Version history

* v0 (revised with the one-tracker change): layouts are judged with the
  project's tracker; ``observer="bank"`` keeps the first version's judge.
* v0 (first version): the scenario's bank as the judge.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from shipsense.arguments import number
from shipsense.config import load_scenario
from shipsense.design.fisher import passage_fim
from shipsense.design.observability import check_array
from shipsense.design.placement import grid_candidates
from shipsense.models.field_model import candidate_model, subset_model
from shipsense.simulator import keel_dipole, sample_passages, simulate
from shipsense.trackers import Tracker
from shipsense.trackers.metrics import convergence_rate, trmse


class ArrayDesignEnv(gym.Env):
    __doc__ = __doc__
    metadata = {"render_modes": ["rgb_array"], "render_fps": 2}

    def __init__(self, scenario="S1-P2", k=3, half_width=30.0, spacing=7.5, passages=8, shaping=0.0,
                 continuous=False, seed_passages=10_000, check_ambiguity=True, render_mode=None, observer="tracker"):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        sc = load_scenario(scenario)
        if sc.prior is None:
            raise ValueError(f"scenario {sc.name!r} has no [prior]: the layout is judged on passages from it")
        if observer not in ("tracker", "bank"):
            raise ValueError(f"observer must be 'tracker' or 'bank', got {observer!r}")
        self.observer = observer
        self.scenario = sc
        self.k = number("k", k, 1, 1000, integer=True)
        half_width = number("half_width", half_width, 0.5, 1e5)
        spacing = number("spacing", spacing, half_width / 200.0, 2.0 * half_width)   # at most 401 x 401 candidates
        passages = number("passages", passages, 1, 10_000, integer=True)
        seed_passages = number("seed_passages", seed_passages, 0, 2**63 - 1, integer=True)
        shaping = number("shaping", shaping, 0.0, 1e6)
        z = sc.sensors[0].position[2]
        box = [(-half_width, -half_width), (half_width, -half_width), (half_width, half_width),
               (-half_width, half_width)]
        centre = np.array([s.position[:2] for s in sc.sensors]).mean(axis=0)
        self.candidates = grid_candidates(box, spacing, z) + np.array([*centre, 0.0])
        self.N = len(self.candidates)
        if not 1 <= self.k <= self.N:
            raise ValueError(f"k must be between 1 and {self.N}, got {k}")
        self.half_width = float(half_width)
        self.centre = centre
        self.model = candidate_model(sc, self.candidates)
        sim = simulate(sc, runs=passages, seed=seed_passages, random=True)
        self._sim = sim
        self._truth = self.model.state_from_truth(sim.truth)
        self.shaping = shaping
        if self.shaping:
            truth = sample_passages(sc, 4, seed=seed_passages)
            thetas = self.model.to_internal(self.model.state_from_truth(truth))
            self._fim = passage_fim(self.model, thetas, sc.steps, per_sensor=True, stride=4)   # (S, N, n, n)
        self.check_ambiguity = bool(check_ambiguity)
        self.continuous = bool(continuous)
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32) if continuous else spaces.Discrete(self.N)
        self.observation_space = spaces.Box(0.0, 1.0, (self.N + 1,), np.float32)
        self.render_mode = render_mode
        self._kwargs = dict(scenario=scenario, k=k, half_width=half_width, spacing=spacing, passages=passages,
                            shaping=shaping, continuous=continuous, seed_passages=seed_passages,
                            check_ambiguity=check_ambiguity, render_mode=render_mode, observer=observer)
        self.chosen = []

    # -- helpers -----------------------------------------------------------------
    def _obs(self):
        obs = np.zeros(self.N + 1, dtype=np.float32)
        obs[self.chosen] = 1.0
        obs[-1] = len(self.chosen) / self.k
        return obs

    def action_masks(self):
        """Boolean mask of the candidates that can still be chosen (MaskablePPO)."""
        mask = np.ones(self.N, dtype=bool)
        mask[self.chosen] = False
        return mask

    def _logdet(self, chosen):
        if not chosen:
            return 0.0
        M = np.eye(self._fim.shape[-1]) * 1e-6 + self._fim[:, chosen].sum(axis=1)
        return float(np.linalg.slogdet(M)[1].mean())

    def _judge(self):
        """Track the fixed passages with the finished layout (the observer: the project's tracker or the bank)."""
        sc = self.scenario
        model = subset_model(self.model, self.chosen)
        # measurements of the chosen sensors: the template's channels at the chosen positions
        meas = simulate_layout(sc, self.candidates[self.chosen], self._sim)
        template = sc.sensors[0]
        layout = sc.model_copy(update={"sensors": [
            template.model_copy(update={"id": f"C{i}", "position": tuple(map(float, self.candidates[i]))})
            for i in self.chosen]})
        est = Tracker(layout, passages=len(meas), method=self.observer).track(self._sim.times, meas).estimates
        conv = convergence_rate(est, self._truth)
        err = float(trmse(est, self._truth).mean())
        info = {"convergence_rate": conv, "trmse_m": err, "layout": self.candidates[self.chosen].tolist()}
        if self.check_ambiguity:
            thetas = model.to_internal(self._truth[:1, 0])
            v = check_array(model, thetas, sc.steps, starts=4)
            info.update(verdict=v.verdict, min_chi2=float(v.min_chi2))
        return conv - min(err / 100.0, 1.0), info

    # -- gymnasium API -------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.chosen = []
        return self._obs(), {}

    def step(self, action):
        if len(self.chosen) >= self.k:
            raise RuntimeError("the layout is complete: call reset()")
        if self.continuous:
            a = np.clip(np.asarray(action, dtype=float).reshape(2), -1, 1)
            target = self.centre + a * self.half_width
            d = np.hypot(*(self.candidates[:, :2] - target).T)
            d[self.chosen] = np.inf
            i = int(np.argmin(d))
        else:
            i = int(action)
            if not 0 <= i < self.N:
                raise ValueError(f"action must be in [0, {self.N}), got {action}")
        if i in self.chosen:
            return self._obs(), -1.0, False, False, {"invalid": True, "placed": len(self.chosen)}
        before = self._logdet(self.chosen) if self.shaping else 0.0
        self.chosen.append(i)
        reward = self.shaping * (self._logdet(self.chosen) - before) if self.shaping else 0.0
        info = {"invalid": False, "placed": len(self.chosen)}
        terminated = len(self.chosen) == self.k
        if terminated:
            quality, judged = self._judge()
            reward += quality
            info.update(judged)
        return self._obs(), float(reward), terminated, False, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        from shipsense.plotting import figure_to_rgb, plt

        fig, ax = plt.subplots(figsize=(5, 5), dpi=80)
        ax.scatter(self.candidates[:, 0], self.candidates[:, 1], s=8, color="0.7")
        if self.chosen:
            ax.scatter(*self.candidates[self.chosen, :2].T, s=60, color="tab:orange", edgecolor="k")
        ax.set_aspect("equal")
        ax.set_title(f"{len(self.chosen)} of {self.k} placed", fontsize=9)
        return figure_to_rgb(fig)

    def __getstate__(self):
        return {"kwargs": self._kwargs, "chosen": list(self.chosen), "np_random": self._np_random}

    def __setstate__(self, state):
        self.__init__(**state["kwargs"])
        self.chosen = state["chosen"]
        self._np_random = state["np_random"]


def simulate_layout(scenario, positions, sim):
    """Measurements (R, K, m) of copies of the scenario's first sensor at ``positions`` for ``sim``'s passages.

    The noise of the template sensor is redrawn from a fixed seed, so a layout's
    score depends only on the layout.
    """
    sc = scenario
    template = sc.sensors[0]
    sensors = [template.model_copy(update={"id": f"L{i}", "position": tuple(map(float, p))})
               for i, p in enumerate(positions)]
    layout = sc.model_copy(update={"sensors": sensors})
    array = layout.array()
    truth = sim.truth
    clean = array.measure(truth[..., [0, 1, 4]], truth[..., 5:8], keel_dipole(truth[..., 2:4], truth[..., 8]))
    rng = np.random.default_rng(12345)
    return clean + layout.channel_std * rng.standard_normal(clean.shape)
