"""The state of ArrayDesign-v1 episodes (:mod:`shipsense.envs.site_design`), batched: per environment its site,
the site's scenario and passages, the scaled per-candidate Fisher matrices and the layout placed so far; steps,
gains and terminal scores over all environments at once.  The single environment and the native vector one both
run on :class:`DesignCore`."""

from __future__ import annotations

import math
import time

import numpy as np

from shipsense.arguments import number
from shipsense.envs.core_env import SEED_HIGH
from shipsense.envs.sites import SITE_FEATURES, Site, sample_site

SCREEN_PASSAGES = 2
"""Passages of an episode that the mirror screen of the ambiguity penalty checks (the first ones)."""
EXHAUSTIVE_LIMIT = 100_000
"""Most layouts :meth:`DesignCore.best_layout` enumerates (ArrayDesignSmall-v1: at most C(25, 3) = 2,300;
ArrayDesign-v1: C(81, 4) = 1,663,740, refused)."""


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

    def best_layout(self, e, chunk=2048):
        """The ``k`` free candidates of environment ``e`` with the largest score (the D-criterion of the episode),
        by enumerating every layout: the criterion's optimum (the ambiguity penalty is not searched).  More than
        :data:`EXHAUSTIVE_LIMIT` layouts raise one ``ValueError`` naming ``policy``.  Returns the candidate indices
        (k,) and their score."""
        import itertools

        free = np.flatnonzero(self.free[e])
        count = math.comb(len(free), self.k)
        if count > EXHAUSTIVE_LIMIT:
            raise ValueError(f"policy exhaustive: {count:,} layouts of {self.k} of {len(free)} free candidates, over "
                             f"its limit of {EXHAUSTIVE_LIMIT:,} (e.g. ArrayDesignSmall-v1's are at most 2,300)")
        layouts = np.array(list(itertools.combinations(free.tolist(), self.k)), dtype=int).reshape(-1, self.k)
        best, top = None, -np.inf
        for rows in np.array_split(layouts, -(-len(layouts) // chunk)):
            sets = np.zeros((1, len(rows), self.N), dtype=bool)
            sets[0, np.arange(len(rows))[:, None], rows] = True
            scores = self._scores(np.full(1, e), sets)[0]
            i = int(np.argmax(scores))
            if scores[i] > top:
                best, top = rows[i], float(scores[i])
        return best, top

    def masks(self):
        return self.free & ~self.placed

    def greedy_actions(self):
        """Sequential greedy D-optimal, per environment (E,): the free candidate whose addition raises the score
        most (the largest ``gain``; -inf where not free)."""
        return np.argmax(self.gain, axis=1)

    def random_actions(self, rng):
        """A uniformly random free candidate per environment (E,), from the generator ``rng`` (one draw per
        candidate and environment; an environment with no free candidate gets 0)."""
        return np.argmax(np.where(self.masks(), rng.random((self.E, self.N)), -1.0), axis=1)

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


__all__ = ["EXHAUSTIVE_LIMIT", "SCREEN_PASSAGES", "DesignCore"]
