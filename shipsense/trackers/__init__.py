"""Batched nonlinear Kalman filters, the multiple-initial-value bank, and the project's tracker.

The pipeline (shared/spec/trackers.md): :mod:`~shipsense.trackers.seeding` (the studies' bank seeded from the
first sample), :mod:`~shipsense.trackers.initialiser` (global fits of a window, no prior on position),
:mod:`~shipsense.trackers.bank` (filtering: hypotheses as one batch), :mod:`~shipsense.trackers.restarts`
(batch refits), :mod:`~shipsense.trackers.selection` (the mixture), and :class:`Tracker`, the public tracker
that runs them (:mod:`~shipsense.trackers.tracker`).
"""

from shipsense.trackers.tracker import STATUSES, Tracker, TrackResult

__all__ = ["STATUSES", "TrackResult", "Tracker"]
