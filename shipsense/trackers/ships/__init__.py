"""Several ships at once: a tracker that counts and labels up to two ships whose fields superpose.

:mod:`~shipsense.trackers.ships.joint_model` (the stacked state and the summed measurement),
:mod:`~shipsense.trackers.ships.settings` (the birth and death settings),
:mod:`~shipsense.trackers.ships.tracker` (the one-ship tracker, births on its residual, the joint filter,
deaths) and :mod:`~shipsense.trackers.ships.results` (labelled tracks).
"""

from shipsense.trackers.ships.joint_model import JointModel
from shipsense.trackers.ships.results import ShipsResult
from shipsense.trackers.ships.settings import ShipsSettings
from shipsense.trackers.ships.tracker import ShipsTracker

__all__ = ["JointModel", "ShipsResult", "ShipsSettings", "ShipsTracker"]
