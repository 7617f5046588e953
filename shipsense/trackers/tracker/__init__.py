"""The project's passage tracker (:class:`Tracker`): detection, the global initialiser, a bank of its fits,
restarts from batch refits and the consistency alarms, one sample of every passage at a time.

:mod:`~shipsense.trackers.tracker.settings` (the settings, resolved once, and the per-family table),
:mod:`~shipsense.trackers.tracker.results` (statuses and outputs), :mod:`~shipsense.trackers.tracker.tracker`
(the tracker), :mod:`~shipsense.trackers.tracker.passages` (its per-passage state),
:mod:`~shipsense.trackers.tracker.step` (its compiled sample step),
:mod:`~shipsense.trackers.tracker.restarts` (refits and when they are due) and
:mod:`~shipsense.trackers.tracker.consistency` (the windowed innovation test); the source studies' bank as a
tracker is :mod:`~shipsense.trackers.tracker.study_bank`.
"""

from shipsense.trackers.tracker.results import (
    INCONSISTENT,
    INITIALISING,
    NO_DATA,
    RESTARTED,
    STATUSES,
    TRACKING,
    Gap,
    PassageState,
    Sample,
    TrackResult,
)
from shipsense.trackers.tracker.settings import FAMILY_SETTINGS, TrackerSettings, prior_belief, resolve_settings
from shipsense.trackers.tracker.study_bank import StudyBankTracker
from shipsense.trackers.tracker.tracker import Tracker

__all__ = ["INCONSISTENT", "INITIALISING", "NO_DATA", "RESTARTED", "STATUSES", "TRACKING", "Gap", "PassageState",
           "Sample", "StudyBankTracker", "TrackResult", "Tracker", "TrackerSettings", "FAMILY_SETTINGS", "prior_belief",
           "resolve_settings"]
