"""What the environments built on a batched core share: pickling by rebuilding, closing a figure, and the native
vector envs' base (:class:`CoreVectorEnv`: one autoreset convention, gymnasium's vector info, list seeds)."""

from __future__ import annotations

import copy

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

SEED_HIGH = 2**31 - 1
"""Episode seeds are drawn below this (the environments' generators hand one to the core per reset)."""


class RebuiltOnUnpickle:
    """Pickle a single environment by its JSON-able constructor arguments (``self._kwargs``) and its episode
    state (the core's attributes, the generator, whether it was reset); unpickling rebuilds it from them."""

    def __getstate__(self):
        getattr(self.core, "settle", lambda: None)()       # (work of the core's still in flight: finished)
        # (the core's own pickled state: what it leaves out, e.g. Passage-v1's announced resets, stays out)
        return {"kwargs": self._kwargs, "core": self.core.__getstate__(), "np_random": self._np_random,
                "started": self._started}

    def __setstate__(self, state):
        self.__init__(**state["kwargs"])
        self.core.__dict__.update(state["core"])
        self._np_random = state["np_random"]
        self._started = state["started"]


class ClosesItsFigure:
    """``close()`` for an environment whose ``human`` render keeps a matplotlib figure in ``self._fig``."""

    def close(self):
        if self._fig is not None:
            from shipsense.plotting import plt

            plt.close(self._fig)
            self._fig = None


def reset_rows(options, num_envs):
    """The sub-environments a native vector env's ``reset`` resets: all of them, or those of gymnasium's
    partial reset ``options={"reset_mask": mask}`` (a boolean array of ``num_envs``), which a next-step
    autoreset env needs to serve SB3 (:class:`~shipsense.envs.sb3.VectorEnvAdapter` resets the environments
    that ended in the step that ended them)."""
    mask = None if not options else options.get("reset_mask")
    if mask is None:
        return np.arange(num_envs)
    mask = np.asarray(mask)
    if mask.shape != (num_envs,) or mask.dtype != bool:
        raise ValueError(f"options['reset_mask'] must be a boolean array of shape ({num_envs},), "
                         f"got {mask.dtype} {mask.shape}")
    return np.flatnonzero(mask)


def stream_generators(seed, num_envs, high=SEED_HIGH):
    """One generator per sub-environment of a native vector env: ``seed`` an int (sub-environment ``i`` draws
    from ``seed + i``, as a single env reset with ``seed + i``), None (fresh entropy), or a list of
    ``num_envs`` seeds (None entries: fresh entropy; what SB3's ``VecEnv.seed`` hands over)."""
    if seed is None or isinstance(seed, (int, np.integer)):
        base = np.random.SeedSequence().entropy % high if seed is None else int(seed)
        seeds = [base + i for i in range(num_envs)]
    else:
        seeds = list(seed)
        if len(seeds) != num_envs:
            raise ValueError(f"seed must be an int or a list of {num_envs} seeds (one per environment), "
                             f"got {len(seeds)}")
        seeds = [np.random.SeedSequence().entropy % high if s is None else int(s) for s in seeds]
    return [np.random.Generator(np.random.PCG64(np.random.SeedSequence(s))) for s in seeds]


def seed_ahead(rng, j):
    """The ``j``-th episode seed (``j >= 1``) generator ``rng`` will hand out (one ``integers(SEED_HIGH)`` per
    reset), drawn from a copy: ``rng`` is left as it is."""
    twin = copy.deepcopy(rng)
    for _ in range(int(j) - 1):
        twin.integers(SEED_HIGH)
    return int(twin.integers(SEED_HIGH))


def vector_info(info, live):
    """gymnasium's vector info from a core's step ``info``: every entry ``info[key]`` (an (E,) array) with its mask
    ``info["_key"]`` -- the sub-environments that stepped (``live``), and of those the ones the core's own
    ``info["_key"]`` names, if it gives one (an entry valid only where an episode ended)."""
    out = {}
    for key, value in info.items():
        if not key.startswith("_"):
            out[key], out["_" + key] = value, (live & info["_" + key] if "_" + key in info else live.copy())
    return out


class CoreVectorEnv(VectorEnv):
    """The native vector env on one batched core, the base of every shipsense vector env: one generator per
    sub-environment (:func:`stream_generators`: ``seed`` an int, ``seed + i`` for sub-environment ``i``, or a list
    of ``num_envs`` seeds), ``reset`` of all or of the masked sub-environments (:func:`reset_rows`), **next-step
    autoreset** (``AutoresetMode.NEXT_STEP``, gymnasium 1.x's default: the step after a sub-environment's episode
    ended, by termination or truncation, resets it, ignores its action and returns its first observation with
    reward 0, ``terminated`` and ``truncated`` False), ``info`` in gymnasium's vector convention (per key an
    (num_envs,) array and its ``_key`` mask: the sub-environments that stepped; ``info["episode_metrics"]``, with
    its own masks, for those whose episode ended) and ``rgb_array`` rendering.

    A subclass checks its ``render_mode`` (:meth:`check_render_mode`, before building anything), builds its core
    and calls ``CoreVectorEnv.__init__(self, core, single_spaces, render_mode)``.  The core has ``E``
    environments and

    * ``reset_envs(envs, seeds, fresh=)``: new episodes for environments ``envs``, each drawn from its integer
      seed (one per reset, drawn from the sub-environment's generator) -- or, if the core's
      ``draws_from_generators`` is true, from the sub-environment's generator itself; ``fresh``: the streams were
      just (re)seeded.  If its ``looks_ahead`` is true it also takes ``ahead(e, j)``, the seed environment
      ``e``'s ``j``-th reset from now will get (:func:`seed_ahead`);
    * ``step(actions, envs=None)``: advance environments ``envs`` (default all; the others' actions ignored),
      returning rewards, terminated, truncated (E,) and an info dict of (E,) arrays (optionally with their own
      ``_key`` masks, :func:`vector_info`);
    * ``episode_metrics(envs)``: the metrics (dict of (len(envs),) arrays) of the episodes of ``envs`` that
      ended in their last step;
    * ``observe()`` (E, ...) and ``render(e)``.
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}

    @classmethod
    def check_render_mode(cls, render_mode):
        """Refuse a ``render_mode`` the class does not offer (one ``ValueError``)."""
        if render_mode is not None and render_mode not in cls.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {cls.metadata['render_modes']}, got {render_mode!r}")

    def __init__(self, core, single_spaces, render_mode=None):
        self.core, self.num_envs = core, core.E
        self.single_observation_space, self.single_action_space = single_spaces
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.render_mode = render_mode
        self._rngs = None
        self._prev_done = np.zeros(self.num_envs, dtype=bool)

    def _episode_seeds(self, envs):
        """Each of sub-environments ``envs``'s next episode seed, from its own generator (or the generators
        themselves, for a core that draws from them)."""
        if getattr(self.core, "draws_from_generators", False):
            return [self._rngs[i] for i in envs]
        return [int(self._rngs[i].integers(SEED_HIGH)) for i in envs]

    def _seed_ahead(self, e, j):
        """The episode seed sub-environment ``e``'s ``j``-th reset from now will draw (``j >= 1``), its generator
        left as it is (:func:`seed_ahead`)."""
        return seed_ahead(self._rngs[e], j)

    def _reset_core(self, envs, fresh):
        ahead = {"ahead": self._seed_ahead} if getattr(self.core, "looks_ahead", False) else {}
        self.core.reset_envs(envs, self._episode_seeds(envs), fresh=fresh, **ahead)

    def reset(self, *, seed=None, options=None):
        """Reset every sub-environment, or those of ``options={"reset_mask": mask}``.  ``seed`` (an int: ``seed +
        i`` for sub-environment ``i``; or a list of ``num_envs``, None entries fresh entropy) reseeds the
        sub-environments reset, and only those, as gymnasium's ``SyncVectorEnv`` does: the others go on drawing
        their episodes from their own streams (and the work done ahead for them is still used).  The first reset
        makes every sub-environment's stream, from ``seed`` (or fresh entropy) whatever the mask."""
        envs = reset_rows(options, self.num_envs)
        fresh = seed is not None or self._rngs is None
        if self._rngs is None:
            self._rngs = stream_generators(seed, self.num_envs, SEED_HIGH)
        elif seed is not None:
            streams = stream_generators(seed, self.num_envs, SEED_HIGH)
            for e in envs.tolist():
                self._rngs[e] = streams[e]
        self._reset_core(envs, fresh)
        self._prev_done[envs] = False
        return self.core.observe(), {}

    def step(self, actions):
        """One step of every sub-environment (``actions``: integers, one per sub-environment), those whose episode
        ended in the last step reset instead (next-step autoreset: the class docstring)."""
        n = self.single_action_space.n
        actions = np.asarray(actions).reshape(self.num_envs)
        if actions.dtype.kind not in "iu" or np.any((actions < 0) | (actions >= n)):
            raise ValueError(f"actions must be integers in [0, {n})")
        done = self._autoreset()
        live = ~done
        rewards, terminated, truncated, info = self.core.step(np.where(live, actions, 0),
                                                              envs=np.flatnonzero(live) if done.any() else None)
        rewards = np.where(live, rewards, 0.0)
        terminated, truncated = terminated & live, truncated & live
        ended = terminated | truncated
        info = vector_info(info, live)
        if ended.any():
            rows = np.flatnonzero(ended)
            metrics = {}
            for key, v in self.core.episode_metrics(rows).items():
                full = np.zeros(self.num_envs)
                full[rows] = v
                metrics[key], metrics["_" + key] = full, ended.copy()
            info["episode_metrics"], info["_episode_metrics"] = metrics, ended.copy()
        self._prev_done = ended
        return self.core.observe(), rewards.astype(np.float64), terminated, truncated, info

    def _autoreset(self):
        """Next-step autoreset: the sub-environments whose episode ended in the last step reset now (and ignore
        this step's action); returns their mask."""
        done = self._prev_done
        if done.any():
            self._reset_core(np.flatnonzero(done), False)
        return done

    def render(self):
        if self.render_mode == "rgb_array":
            return tuple(self.core.render(e) for e in range(self.num_envs))
        return None
