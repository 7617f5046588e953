"""What the environments built on a batched core share: pickling by rebuilding, closing a figure, and the
native vector envs' partial reset."""

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


class CoreVectorEnv(VectorEnv):
    """A native vector env on one batched core: one generator per sub-environment (:func:`stream_generators`),
    ``reset`` of all or of the masked sub-environments (:func:`reset_rows`), next-step autoreset
    (:meth:`_autoreset`) and ``rgb_array`` rendering.

    A subclass checks its ``render_mode`` (:meth:`_check_render_mode`, before building anything), sets
    ``self.core`` (``reset_envs(envs, seeds, fresh=)``, ``render(e)``) and ``self.num_envs``, calls
    :meth:`_batch` with its single spaces, and defines ``_observation()`` (every sub-environment's) and
    ``step``.
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}

    @classmethod
    def _check_render_mode(cls, render_mode):
        if render_mode is not None and render_mode not in cls.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {cls.metadata['render_modes']}, got {render_mode!r}")

    def _batch(self, single_spaces, render_mode):
        self.single_observation_space, self.single_action_space = single_spaces
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.render_mode = render_mode
        self._rngs = None
        self._prev_done = np.zeros(self.num_envs, dtype=bool)

    def _reseed(self, seed):
        self._rngs = stream_generators(seed, self.num_envs, SEED_HIGH)

    def _episode_seeds(self, envs):
        """Each of sub-environments ``envs``'s next episode seed, from its own generator."""
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
        their episodes from their own streams (and the run-ins done ahead for them are still used).  The first
        reset makes every sub-environment's stream, from ``seed`` (or fresh entropy) whatever the mask."""
        envs = reset_rows(options, self.num_envs)
        fresh = seed is not None or self._rngs is None
        if self._rngs is None:
            self._reseed(seed)
        elif seed is not None:
            streams = stream_generators(seed, self.num_envs, SEED_HIGH)
            for e in envs.tolist():
                self._rngs[e] = streams[e]
        self._reset_core(envs, fresh)
        self._prev_done[envs] = False
        return self._observation(), {}

    def _autoreset(self):
        """Next-step autoreset: the sub-environments that ended in the last step reset now (and ignore this
        step's action); returns their mask."""
        done = self._prev_done
        if done.any():
            self._reset_core(np.flatnonzero(done), False)
        return done

    def render(self):
        if self.render_mode == "rgb_array":
            return tuple(self.core.render(e) for e in range(self.num_envs))
        return None
