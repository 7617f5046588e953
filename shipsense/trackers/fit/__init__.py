"""Batch least-squares fits of whole passages: the numpy driver (:mod:`~shipsense.trackers.fit.least_squares`),
its compiled Levenberg-Marquardt loop (:mod:`~shipsense.trackers.fit.lm`), robust (Huber) costs and weights
(:mod:`~shipsense.trackers.fit.robust`) and the small compiled solves they share
(:mod:`~shipsense.trackers.linalg`)."""

from shipsense.trackers.fit.least_squares import fit_passages
from shipsense.trackers.fit.robust import Huber, huber_cost

__all__ = ["Huber", "fit_passages", "huber_cost"]
