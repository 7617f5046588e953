"""What the single environments built on a batched core share: pickling by rebuilding, and closing a figure."""

from __future__ import annotations


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
