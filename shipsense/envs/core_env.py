"""What the environments built on a batched core share: pickling by rebuilding, closing a figure, and the
native vector envs' partial reset."""

from __future__ import annotations

import numpy as np


class RebuiltOnUnpickle:
    """Pickle a single environment by its JSON-able constructor arguments (``self._kwargs``) and its episode
    state (the core's attributes, the generator, whether it was reset); unpickling rebuilds it from them."""

    def __getstate__(self):
        return {"kwargs": self._kwargs, "core": self.core.__dict__, "np_random": self._np_random,
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


def stream_generators(seed, num_envs, high=2**31 - 1):
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
