"""Batched nonlinear Kalman filters, the multiple-initial-value bank, and the project's tracker.

The pipeline: :mod:`~shipsense.trackers.bank.seeding` (the studies' bank seeded from the
first sample), :mod:`~shipsense.trackers.init` (global fits of a window, no prior on position),
:mod:`~shipsense.trackers.bank.bank` (filtering: hypotheses as one batch), :mod:`~shipsense.trackers.tracker.restarts`
(batch refits), :mod:`~shipsense.trackers.bank.selection` (the mixture), and :class:`Tracker`, the public tracker
that runs them (:mod:`~shipsense.trackers.tracker`).
"""

from shipsense.trackers.tracker.results import STATUSES, TrackResult
from shipsense.trackers.tracker.tracker import Tracker

__all__ = ["STATUSES", "TrackResult", "Tracker"]
