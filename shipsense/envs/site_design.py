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

``BASELINES = ("random", "greedy", "convex")`` through :meth:`baseline`:
uniform over the free candidates; sequential greedy D-optimal on the
episode's own criterion; ``convex``: :func:`shipsense.design.designer.design_array`
(relaxation, rounding, exchange, ambiguity cuts, branch and bound) on the
site's scenario, free candidates and passages, then its sensors in turn.

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

import math
import time

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from shipsense.arguments import number
from shipsense.envs.core_env import SEED_HIGH, ClosesItsFigure, CoreVectorEnv
from shipsense.envs.sites import SITE_FEATURES, Site, sample_site

SCREEN_PASSAGES = 2


def _check_kwargs(scenario, k, half_width, spacing, passages, stride, ambiguity_penalty, ambiguity, max_steps, site,
                  reward):
    from shipsense.config import load_scenario
    from shipsense.design.placement import grid_candidates

    try:
        base = load_scenario(scenario)
    except Exception as err:
        raise ValueError(f"scenario: {err}") from None
    if base.prior is None:
        raise ValueError(f"scenario {base.name!r} has no [prior]: a site's traffic replaces it, so it needs one")
    half_width = number("half_width", half_width, 5.0, 1e4)
    spacing = number("spacing", spacing, half_width / 20.0, half_width)      # at most 41 x 41 candidates
    xy = grid_candidates([(-half_width, -half_width), (half_width, -half_width), (half_width, half_width),
                          (-half_width, half_width)], spacing, 0.0)[:, :2]
    k = number("k", k, 1, len(xy), integer=True)
    passages = number("passages", passages, 1, 1000, integer=True)
    stride = number("stride", stride, 1, max(1, base.steps - 1), integer=True)
    penalty = number("ambiguity_penalty", ambiguity_penalty, 0.0, 1e6)
    if ambiguity not in ("mirror", "full"):
        raise ValueError(f"ambiguity must be 'mirror' or 'full', got {ambiguity!r}")
    if reward not in ("terminal", "incremental"):
        raise ValueError(f"reward must be 'terminal' or 'incremental', got {reward!r}")
    max_steps = 2 * k if max_steps is None else number("max_steps", max_steps, k, 10**6, integer=True)
    if site is not None:
        site = Site.from_dict(site)
        free = int(site.free(xy).sum())
        if free < k:
            raise ValueError(f"site: its exclusions leave {free} free candidate(s), fewer than k = {k}")
    return base, xy, k, passages, stride, penalty, max_steps, site


class DesignCore:
    """The state of ``num_envs`` ArrayDesign-v1 episodes (used by the single and the vector env).

    Per episode: the site, its scenario, the candidate model and the scaled per-candidate Fisher matrices
    ``J`` (E, P, N, n, n) with their prior term ``eps`` and scale ``c`` (:func:`build_problem`).  Steps and
    terminal scores are batched over the environments; setting up an episode is per site (each site has its
    own physics: depth, medium).
    """

    def __init__(self, num_envs, scenario="S1-P2", k=4, half_width=30.0, spacing=7.5, passages=4, stride=4,
                 ambiguity_penalty=2.0, ambiguity="mirror", max_steps=None, site=None, reward="terminal"):
        (self.base, self.xy, self.k, self.P, self.stride, self.penalty, self.max_steps,
         self.fixed_site) = _check_kwargs(scenario, k, half_width, spacing, passages, stride, ambiguity_penalty,
                                          ambiguity, max_steps, site, reward)
        self.incremental = reward == "incremental"
        self.E, self.N = int(num_envs), len(self.xy)
        self.half_width, self.ambiguity = float(half_width), ambiguity
        from shipsense.models.field_model import model_from_scenario

        self.n = model_from_scenario(self.base).n
        E, N, P, n = self.E, self.N, self.P, self.n
        self.J = np.zeros((E, P, N, n, n))
        self.eps = np.ones(E)
        self.logc = np.zeros(E)
        self.free = np.zeros((E, N), dtype=bool)
        self.placed = np.zeros((E, N), dtype=bool)
        self.count = np.zeros(E, dtype=int)
        self.t = np.zeros(E, dtype=int)
        self.gain = np.zeros((E, N))                   # score rise of each candidate placed next (-inf: not free)
        self.current = np.zeros(E)                     # score of the placed set
        self.final_ambiguous = np.zeros(E)             # the ended episodes' metrics (episode_metrics)
        self.final_seconds = np.zeros(E)
        self.features = np.zeros((E, SITE_FEATURES), dtype=np.float32)
        self.started = np.zeros(E)
        self.sites = [None] * E
        self.scenarios = [None] * E
        self.models = [None] * E
        self.thetas = [None] * E
        self.truth = [None] * E
        self.passage_seeds = np.zeros(E, dtype=np.int64)
        self.obs_dim = SITE_FEATURES + 3 * N + 1
        self._models = {}

    # -- episodes ---------------------------------------------------------------------
    draws_from_generators = True
    """:meth:`reset_envs` draws from the environments' generators (:class:`~shipsense.envs.core_env.CoreVectorEnv`
    passes them)."""

    def reset_envs(self, envs, rngs, fresh=False):
        """Draw a site (and its passages) for each environment in ``envs`` with the generators ``rngs`` (``fresh``,
        whether they were just seeded, changes nothing)."""
        from shipsense.design.placement import build_problem
        from shipsense.models.field_model import candidate_model
        from shipsense.simulator import sample_passages
        from shipsense.trackers.tracker.settings import resolve_settings

        for e, rng in zip(envs, rngs):
            site = self.fixed_site if self.fixed_site is not None else sample_site(rng, self.half_width, self.xy,
                                                                                   self.k)
            seed = int(rng.integers(SEED_HIGH))
            sc = site.scenario(self.base)
            cands = np.column_stack([self.xy, np.full(self.N, -site.water_depth_m)])
            model = self._models.get(site.water_depth_m)
            if model is None:    # the candidate model depends on the site only through the depth
                model = self._models[site.water_depth_m] = candidate_model(sc, cands)
            truth = sample_passages(sc, self.P, seed=seed)
            thetas = model.to_internal(model.state_from_truth(truth))
            bank = resolve_settings(sc).bank
            prior_std = model.to_internal(bank.state_std(model.labels))
            problem = build_problem(model, thetas, sc.steps, self.k, prior_std, stride=self.stride)
            self.J[e], self.eps[e], self.logc[e] = problem.J, problem.eps, math.log(problem.scale)
            self.free[e] = site.free(self.xy)
            self.placed[e] = False
            self.count[e] = self.t[e] = 0
            self.sites[e], self.scenarios[e], self.models[e], self.thetas[e] = site, sc, model, thetas
            self.truth[e], self.passage_seeds[e] = truth, seed
            self.features[e] = site.features(self.half_width)
            self.started[e] = time.perf_counter()
        envs = np.asarray(list(envs), dtype=int)
        self.current[envs] = 0.0
        self._update_gain(envs)

    def _update_gain(self, envs):
        """The score rise of every free candidate placed next, for the environments ``envs``: one batch of
        (N x P) log-determinants per environment."""
        if not len(envs):
            return
        J = self.J[envs]                                                        # (e, P, N, n, n)
        base = self.eps[envs, None, None, None] * np.eye(self.n) + np.einsum("epnij,en->epij", J,
                                                                               self.placed[envs].astype(float))
        T = base[:, None] + np.swapaxes(J, 1, 2)                                # (e, N, P, n, n)
        sign, logdet = np.linalg.slogdet(T)
        scores = (np.where(sign > 0, logdet, -np.inf).mean(axis=-1) + self.n * self.logc[envs, None]) / self.n
        self.gain[envs] = np.where(self.masks()[envs], scores - self.current[envs, None], -np.inf)

    def gain_feature(self):
        """The gains divided by the largest one per environment, 0 where not free (the observation's block)."""
        ok = np.isfinite(self.gain)
        top = np.where(ok, self.gain, -np.inf).max(axis=1, keepdims=True)
        top = np.where(np.isfinite(top) & (top > 0), top, 1.0)
        return np.where(ok, np.clip(self.gain / top, -2.0, 2.0), 0.0).astype(np.float32)

    def _scores(self, envs, sets):
        """Scores of boolean layouts ``sets`` (len(envs), B, N): mean log det(I + sum D J D) / n per layout."""
        J = self.J[envs]                                                        # (e, P, N, n, n)
        S = np.einsum("epnij,ebn->ebpij", J, sets.astype(float))
        M = self.eps[envs, None, None, None, None] * np.eye(self.n) + S
        sign, logdet = np.linalg.slogdet(M)
        logdet = np.where(sign > 0, logdet, -np.inf).mean(axis=-1)               # (e, B)
        return (logdet + self.n * self.logc[envs, None]) / self.n

    def score(self, e, chosen):
        """The score of candidate indices ``chosen`` in environment ``e`` (order-free)."""
        mask = np.zeros(self.N, dtype=bool)
        mask[list(chosen)] = True
        return float(self._scores(np.full(1, e), mask[None, None])[0, 0])

    def masks(self):
        return self.free & ~self.placed

    def observe(self):
        return np.concatenate([self.features, self.free.astype(np.float32), self.placed.astype(np.float32),
                               self.gain_feature(), (self.count / self.k).astype(np.float32)[:, None]], axis=1)

    def _ambiguous(self, e):
        from shipsense.design.observability import DEFAULT_CHI2, check_array, mirror_screen
        from shipsense.models.field_model import subset_model

        chosen = np.flatnonzero(self.placed[e])
        if len(chosen) < self.k:
            return True
        model = subset_model(self.models[e], chosen)
        steps = self.scenarios[e].steps
        if self.ambiguity == "full":
            return check_array(model, self.thetas[e][:4], steps, starts=8).verdict == "ambiguous"
        return mirror_screen(model, self.thetas[e][:SCREEN_PASSAGES], steps) < DEFAULT_CHI2

    def step(self, actions, envs=None):
        """Advance environments ``envs`` (default all) by one action each (``actions`` (E,), the others' ignored).
        Returns rewards, terminated, truncated (E,) and an info dict of (E,) arrays: ``invalid``, ``placed`` and,
        with its mask ``_layout``, the ``layout`` of the episodes that ended (their metrics:
        :meth:`episode_metrics`); entries of environments that did not step are meaningless."""
        a = np.asarray(actions).reshape(self.E).astype(int)
        if np.any((a < 0) | (a >= self.N)):
            raise ValueError(f"actions must be in [0, {self.N}), got {actions}")
        rows = np.arange(self.E) if envs is None else np.asarray(envs, dtype=int)
        a = a[rows]
        valid = self.masks()[rows, a]
        self.placed[rows[valid], a[valid]] = True
        self.count[rows] += valid
        self.t[rows] += 1
        before = self.current[rows]
        self.current[rows] = self._scores(rows, self.placed[rows, None])[:, 0]
        rewards = np.zeros(self.E)
        rewards[rows] = np.where(valid, self.current[rows] - before if self.incremental else 0.0, -1.0)
        terminated, truncated = np.zeros(self.E, dtype=bool), np.zeros(self.E, dtype=bool)
        terminated[rows] = self.count[rows] >= self.k
        truncated[rows] = ~terminated[rows] & (self.t[rows] >= self.max_steps)
        invalid = np.zeros(self.E, dtype=bool)
        invalid[rows] = ~valid
        ended = terminated | truncated
        layout = np.empty(self.E, dtype=object)
        self._update_gain(rows)
        if ended.any():
            now = time.perf_counter()
            for e in np.flatnonzero(ended):
                s = self.current[e]
                ambiguous = self._ambiguous(e)
                rewards[e] += (0.0 if self.incremental else s) - self.penalty * ambiguous
                self.final_ambiguous[e], self.final_seconds[e] = float(ambiguous), now - self.started[e]
                layout[e] = np.column_stack(
                    [self.xy[self.placed[e]], np.full(self.count[e], -self.sites[e].water_depth_m)]).tolist()
        info = {"invalid": invalid, "placed": self.count.copy(), "layout": layout, "_layout": ended}
        return rewards, terminated, truncated, info

    def episode_metrics(self, envs):
        """The metrics (dict of (len(envs),) arrays) of the episodes of ``envs`` that ended in their last step:
        ``score``, ``ambiguous`` (0 or 1) and ``seconds``."""
        return {"score": self.current[envs], "ambiguous": self.final_ambiguous[envs],
                "seconds": self.final_seconds[envs]}

    # -- drawing -------------------------------------------------------------------------
    def render(self, e, ax=None):
        from matplotlib.patches import Circle

        from shipsense.plotting import figure_to_rgb, plt

        fig = None
        if ax is None:
            fig, ax = plt.subplots(figsize=(5, 5), dpi=80)
        site = self.sites[e]
        hw = self.half_width
        for x, y, r in site.exclusions:
            ax.add_patch(Circle((x, y), r, color="tab:red", alpha=0.2, label="exclusion"))
        truth = self.truth[e]
        steps = self.scenarios[e].steps * self.scenarios[e].period
        for x0, y0, vx, vy in truth[:, :4]:
            ax.plot([x0, x0 + vx * steps], [y0, y0 + vy * steps], color="tab:blue", lw=0.6, alpha=0.5)
        free = self.free[e] & ~self.placed[e]
        gain = self.gain_feature()[e]
        ax.scatter(*self.xy[free].T, s=4 + 40 * np.clip(gain[free], 0, 1), color="0.5",
                   label="free (size: gain if placed next)")
        ax.scatter(*self.xy[self.placed[e]].T, s=70, color="tab:orange", edgecolor="k", label="placed")
        ax.set_xlim(-1.6 * hw, 1.6 * hw)
        ax.set_ylim(-1.6 * hw, 1.6 * hw)
        ax.set_aspect("equal")
        ax.set_title(f"{self.count[e]} of {self.k} placed; depth {site.water_depth_m:.0f} m; lane "
                     f"{site.heading_deg:.0f} deg", fontsize=9)
        return figure_to_rgb(fig) if fig is not None else None


def _spaces(core):
    obs = spaces.Box(-2.0, 2.0, (core.obs_dim,), np.float32)
    return obs, spaces.Discrete(core.N)


class SiteDesignEnv(ClosesItsFigure, gym.Env):
    __doc__ = __doc__
    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 2}
    BASELINES = ("random", "greedy", "convex")

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
        return {"random": RandomPolicy, "greedy": GreedyPolicy, "convex": ConvexPolicy}[name](self)


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
        return int(np.argmax(self.env.core.gain[0]))      # -inf where not free


class ConvexPolicy:
    """:func:`~shipsense.design.designer.design_array` on the site's scenario, free candidates and passages (the
    episode's own, same stride), then its sensors one per step."""

    def __init__(self, env):
        self.env = env
        self.plan, self.for_site = [], None

    def __call__(self, obs):
        from shipsense.design.designer import design_array

        core = self.env.core
        if self.for_site is not core.sites[0] or core.count[0] == 0 and not self.plan:
            free = np.flatnonzero(core.free[0])
            cands = self.env.candidates[free]
            result = design_array(core.scenarios[0], core.k, candidates=cands, passages=core.P,
                                  seed=int(core.passage_seeds[0]), stride=core.stride, random_layouts=1)
            self.plan = [int(free[i]) for i in result.placement.chosen]
            self.for_site = core.sites[0]
        mask = core.masks()[0]
        while self.plan:
            a = self.plan.pop(0)
            if mask[a]:
                return a
        return int(np.flatnonzero(mask)[0])


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

    def action_masks(self):
        """Boolean masks (num_envs, N) of the candidates each environment can take."""
        return self.core.masks().copy()
