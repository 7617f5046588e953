"""The global initialiser: a passage located with no prior on its position.

In the order of the pipeline: :mod:`~shipsense.trackers.init.detection` (where the signal starts),
:mod:`~shipsense.trackers.init.grid` (candidate passages, the moment eliminated in closed form),
:mod:`~shipsense.trackers.init.distinct` (distinct minima), :mod:`~shipsense.trackers.init.window_fits`
(refined, tested fits of a window) and :mod:`~shipsense.trackers.init.global_init` (the fits as a bank's
hypotheses).
"""

from shipsense.trackers.init.detection import detection_start, fit_end, strongest_snr
from shipsense.trackers.init.global_init import GlobalInit, global_init, unalign
from shipsense.trackers.init.grid import candidate_grid, grid_minima
from shipsense.trackers.init.window_fits import WindowFits, depth_prior, window_fits

__all__ = ["GlobalInit", "WindowFits", "candidate_grid", "depth_prior", "detection_start", "fit_end", "global_init",
           "grid_minima", "strongest_snr", "unalign", "window_fits"]
