"""``shipsense/ArrayDesign-v1``: lay ``k`` sensors at a site drawn from a documented distribution.

## Description

Each episode draws a **site** (:mod:`shipsense.envs.sites`, distribution in
:data:`~shipsense.envs.sites.SITE_DISTRIBUTION`) under the reset seed: the
traffic the array must watch (lane heading and spread, closest-approach
offsets, speeds, the ship's electric source strength), the water depth and
exclusion zones in the square candidate region.  The agent places ``k``
copies of the base scenario's first sensor (S1-P2: envelope electrodes) on
the free candidates of a grid, one per step.  When the ``k``-th is placed
the layout is scored with the project's design criterion: the Bayesian
D-criterion over ``passages`` passages drawn from the site, with the
tracker's prior (:func:`shipsense.design.placement.build_problem`, the same
problem ``shipsense design`` solves), minus a penalty when the layout is
ambiguous (:mod:`shipsense.design.observability`).

The per-candidate Fisher matrices of the site's passages are built once per
episode (they are additive across sensors), so a step is a mask update and
the terminal score one batched log-determinant.

## Action space

``Discrete(N)``: the candidate to place next (N = grid points of the
square, 81 by default).  ``action_masks()`` gives the free candidates
(outside the exclusions, not yet used); it is reachable through
``gymnasium.make`` (``env.get_wrapper_attr("action_masks")()``, as
sb3-contrib's MaskablePPO asks for it).  An invalid pick (excluded or
taken) is a no-op with reward -1, so unmasked agents can train too.

## Observation space

``Box(-2, 2, (10 + 3 N + 1,), float32)``:

=====================  ==========================================================
index                  meaning
=====================  ==========================================================
0, 1                   cos, sin of the lane's mean heading
2                      heading spread / 30 deg
3, 4                   closest-approach range (low, high) / half_width
5, 6                   speed range (low, high) / 10 m/s
7, 8                   log10 of the source strength range (low, high, A m) / 3
9                      water depth / 30 m
10 .. 10+N-1           1 where the candidate is free of exclusions
10+N .. 10+2N-1        1 where a sensor stands
10+2N .. 10+3N-1       the candidate's gain: how much the score would rise if it
                       were placed next, divided by the largest gain (0 on
                       excluded and taken candidates; greedy picks the 1)
10+3N                  fraction of the k sensors placed
=====================  ==========================================================

## Rewards

0 per valid placement, -1 per invalid pick; at the end ``score -
ambiguity_penalty x ambiguous``.  With ``reward="incremental"`` a valid
placement earns the rise of the score it brings instead, and the end only
the penalty: the undiscounted return is the same (the rises telescope to the
score), the credit comes at each step.  ``score`` is the D-criterion in nats per
state component, ``mean_s log det(I + sum_i D J_si D) / n`` (J: Fisher
information of passage s at candidate i; D: the prior standard deviations;
the information gained over the prior), a function of the set of chosen
candidates only: the reward does not depend on the order of the picks.
``ambiguous``: with ``ambiguity="mirror"`` (default, the cheap one) a mirror
image of one of the first two passages across the layout's symmetry lines is
far away yet within chi-square 25 (:func:`~shipsense.design.observability.mirror_screen`:
exact for collinear layouts, a screen otherwise); with ``"full"`` the
project's ambiguity check (:func:`~shipsense.design.observability.check_array`,
batched least-squares fits, far slower) says ``ambiguous``.

## Starting state

A site drawn from the distribution, no sensor placed.

## Episode end

Terminated when ``k`` sensors stand; truncated after ``max_steps`` steps
(default ``2 k``): the unfinished layout is scored as it stands and counted
as ambiguous.

## Info

At the end of an episode ``info["episode_metrics"]``: ``score``,
``ambiguous`` (0 or 1), ``seconds`` (wall time from the end of ``reset`` to
the last step: the time the policy took to produce the design) and
``info["layout"]`` (the chosen positions, m).  Every step: ``invalid``,
``placed``.

## Arguments

``scenario`` ("S1-P2"; it needs a ``[prior]``), ``k`` (4), ``half_width`` (m,
30), ``spacing`` (m, 7.5), ``passages`` (4), ``stride`` (4: every 4th sample
enters the Fisher matrices), ``ambiguity_penalty`` (2.0), ``ambiguity``
("mirror" or "full"), ``reward`` ("terminal" or "incremental"), ``max_steps`` (None: 2 k), ``site`` (None: drawn; or a
fixed site as a dict of :class:`~shipsense.envs.sites.Site` fields),
``render_mode`` (``"rgb_array"`` or ``"human"``).  Bad values raise one
``ValueError`` naming the argument.

## Baselines

``BASELINES = ("random", "greedy", "convex", "exhaustive")`` through :meth:`SiteDesignEnv.baseline`:
uniform over the free candidates; sequential greedy D-optimal on the
episode's own criterion; ``convex``: :func:`shipsense.design.designer.design_array`
(relaxation, rounding, exchange, ambiguity cuts, branch and bound) on the
site's scenario, free candidates and passages, then its sensors in turn;
``exhaustive``: the layout of largest score among all of ``k`` free
candidates, by enumeration (the criterion's optimum; refused above 100,000
layouts: for ArrayDesignSmall-v1, not ArrayDesign-v1).
The native vector version offers ``random`` and ``greedy`` batched
(:meth:`SiteDesignVectorEnv.baseline`), the teachers of behaviour cloning
(``shipsense train placement --imitate greedy``).

## Version history

* v1: a site per episode under the seed, terminal Bayesian D-criterion with an ambiguity penalty (order-free),
  precomputed Fisher matrices (a step is a mask update), masks through ``gymnasium.make``, a time limit, a native
  vector version, baselines.  Since 2026-11-28 the native vector version autoresets in the next step
  (gymnasium 1.x's default, the convention of every shipsense vector env,
  :class:`~shipsense.envs.core_env.CoreVectorEnv`: the step after an episode ended resets it, ignores its
  action and returns reward 0) and offers the partial reset ``reset(options={"reset_mask": mask})``; it reset
  in the same step, with ``info["final_obs"]`` and ``info["final_info"]``.  Its episodes are the same (each
  sub-environment draws its sites from its own stream as before), so no version bump: the dynamics, reward
  and spaces are unchanged.
* v0 (:class:`shipsense.envs.array_design.ArrayDesignEnv`, still registered): one fixed scenario and 8 fixed
  passages judged by the tracker (run at every step); its seed did nothing and its reward depended on the pick
  order.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from shipsense.arguments import number
from shipsense.envs.core_env import ClosesItsFigure, CoreVectorEnv
from shipsense.envs.site_design_core import DesignCore


def _spaces(core):
    obs = spaces.Box(-2.0, 2.0, (core.obs_dim,), np.float32)
    return obs, spaces.Discrete(core.N)


class SiteDesignEnv(ClosesItsFigure, gym.Env):
    __doc__ = __doc__
    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 2}
    BASELINES = ("random", "greedy", "convex", "exhaustive")

    def __init__(self, scenario="S1-P2", k=4, half_width=30.0, spacing=7.5, passages=4, stride=4,
                 ambiguity_penalty=2.0, ambiguity="mirror", max_steps=None, site=None, reward="terminal",
                 render_mode=None):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.core = DesignCore(1, scenario, k, half_width, spacing, passages, stride, ambiguity_penalty, ambiguity,
                               max_steps, site, reward)
        self.observation_space, self.action_space = _spaces(self.core)
        self.render_mode = render_mode
        self._started = False
        self._fig = None

    @property
    def k(self):
        return self.core.k

    @property
    def candidates(self):
        """Candidate positions (N, 3) of the current site (m; z on its seabed)."""
        depth = self.core.sites[0].water_depth_m if self.core.sites[0] is not None else 0.0
        return np.column_stack([self.core.xy, np.full(self.core.N, -depth)])

    @property
    def chosen(self):
        return np.flatnonzero(self.core.placed[0])

    def action_masks(self):
        """Boolean mask (N,) of the candidates that can be chosen (free of exclusions, not taken)."""
        return self.core.masks()[0].copy()

    def score(self, chosen):
        """The episode's score of a layout (candidate indices), whatever the order."""
        return self.core.score(0, chosen)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.core.reset_envs([0], [self.np_random])
        self._started = True
        return self.core.observe()[0], {}

    def step(self, action):
        if not self._started:
            raise RuntimeError("call reset() before step()")
        if self.core.count[0] >= self.core.k or self.core.t[0] >= self.core.max_steps:
            raise RuntimeError("the episode has ended: call reset()")
        rewards, terminated, truncated, batch = self.core.step(np.array([int(action)]))
        info = {"invalid": bool(batch["invalid"][0]), "placed": int(batch["placed"][0])}
        if terminated[0] or truncated[0]:
            info["episode_metrics"] = {k: float(v[0]) for k, v in self.core.episode_metrics([0]).items()}
            info["layout"] = batch["layout"][0]
        if self.render_mode == "human":
            self.render()
        return self.core.observe()[0], float(rewards[0]), bool(terminated[0]), bool(truncated[0]), info

    def render(self):
        if self.render_mode == "rgb_array":
            return self.core.render(0) if self._started else None
        if self.render_mode == "human" and self._started:
            from shipsense.plotting import plt

            if self._fig is None:
                self._fig, self._ax = plt.subplots(figsize=(5, 5))
            self._ax.clear()
            self.core.render(0, ax=self._ax)
            plt.pause(1.0 / self.metadata["render_fps"])
        return None

    def baseline(self, name):
        """The policy ``name`` (one of :attr:`BASELINES`): a callable obs -> action that reads this env."""
        if name not in self.BASELINES:
            raise ValueError(f"policy {name!r} is not offered by ArrayDesign-v1 (offered: {', '.join(self.BASELINES)})")
        return {"random": RandomPolicy, "greedy": GreedyPolicy, "convex": ConvexPolicy,
                "exhaustive": ExhaustivePolicy}[name](self)


class RandomPolicy:
    """A uniformly random free candidate (the env's own generator)."""

    def __init__(self, env):
        self.env = env

    def __call__(self, obs):
        free = np.flatnonzero(self.env.action_masks())
        return int(self.env.np_random.choice(free))


class GreedyPolicy:
    """Sequential greedy D-optimal: the free candidate whose addition raises the episode's score most."""

    def __init__(self, env):
        self.env = env

    def __call__(self, obs):
        return int(self.env.core.greedy_actions()[0])


class LayoutPolicy:
    """A policy that chooses a whole layout when a site starts (:meth:`layout`), then places its sensors one per
    step (a taken or excluded one skipped)."""

    def __init__(self, env):
        self.env = env
        self.plan, self.for_site = [], None

    def layout(self, core):
        """The candidate indices to place on the current site of ``core``."""
        raise NotImplementedError

    def __call__(self, obs):
        core = self.env.core
        if self.for_site is not core.sites[0] or core.count[0] == 0 and not self.plan:
            self.plan = [int(i) for i in self.layout(core)]
            self.for_site = core.sites[0]
        mask = core.masks()[0]
        while self.plan:
            a = self.plan.pop(0)
            if mask[a]:
                return a
        return int(np.flatnonzero(mask)[0])


class ConvexPolicy(LayoutPolicy):
    """:func:`~shipsense.design.designer.design_array` on the site's scenario, free candidates and passages (the
    episode's own, same stride), then its sensors one per step."""

    def layout(self, core):
        from shipsense.design.designer import design_array

        free = np.flatnonzero(core.free[0])
        result = design_array(core.scenarios[0], core.k, candidates=self.env.candidates[free], passages=core.P,
                              seed=int(core.passage_seeds[0]), stride=core.stride, random_layouts=1)
        return free[result.placement.chosen]


class ExhaustivePolicy(LayoutPolicy):
    """The layout of largest score among all of ``k`` free candidates (:meth:`DesignCore.best_layout
    <shipsense.envs.site_design_core.DesignCore.best_layout>`: the criterion's optimum, the reference no policy can
    pass on the score), then its sensors one per step; for small tasks (ArrayDesignSmall-v1), a larger one is
    refused."""

    def layout(self, core):
        return core.best_layout(0)[0]


class SiteDesignVectorEnv(CoreVectorEnv):
    """Native vector version of ``shipsense/ArrayDesign-v1``: one :class:`DesignCore` over ``num_envs`` sites, on
    :class:`~shipsense.envs.core_env.CoreVectorEnv` (next-step autoreset, gymnasium's vector ``info`` with
    ``_key`` masks, the partial reset ``reset(options={"reset_mask": mask})``).  ``reset(seed=s)`` seeds
    environment ``i`` with ``s + i``; ``reset(seed=[s0, s1, ...])`` seeds each with its own (None: fresh
    entropy).  Environment ``i`` reset with seed ``s`` draws the same site as :class:`SiteDesignEnv` reset with
    ``s``.
    """

    def __init__(self, num_envs=1, scenario="S1-P2", k=4, half_width=30.0, spacing=7.5, passages=4, stride=4,
                 ambiguity_penalty=2.0, ambiguity="mirror", max_steps=None, site=None, reward="terminal",
                 render_mode=None):
        num_envs = number("num_envs", num_envs, 1, 4096, integer=True)
        self.check_render_mode(render_mode)
        core = DesignCore(num_envs, scenario, k, half_width, spacing, passages, stride, ambiguity_penalty,
                          ambiguity, max_steps, site, reward)
        super().__init__(core, _spaces(core), render_mode)

    BASELINES = ("random", "greedy")
    """The baselines offered batched (:meth:`baseline`); ``convex`` (seconds per site) only by the single env."""

    def action_masks(self):
        """Boolean masks (num_envs, N) of the candidates each environment can take."""
        return self.core.masks().copy()

    def baseline(self, name, seed=None):
        """The batched baseline policy ``name`` (one of :attr:`BASELINES`): ``policy(obs) -> actions`` (num_envs,),
        reading the environments' state (``obs`` unused): ``greedy`` the largest gain in each environment (as the
        single env's), ``random`` a uniformly random free candidate from its own generator seeded with ``seed``
        (the environments' generators are left alone).  Behaviour cloning takes its teacher here
        (:func:`~shipsense.envs.training.imitate`)."""
        if name not in self.BASELINES:
            raise ValueError(f"policy {name!r} is not offered by ArrayDesign-v1's vector env (offered: "
                             f"{', '.join(self.BASELINES)})")
        core = self.core
        if name == "greedy":
            return lambda obs=None: core.greedy_actions()
        rng = np.random.default_rng(seed)
        return lambda obs=None: core.random_actions(rng)
