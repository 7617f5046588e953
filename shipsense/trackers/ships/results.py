"""What the several-ship tracker reports (:class:`ShipsResult`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shipsense.trackers.tracker.results import STATUSES


@dataclass
class ShipsResult:
    """Labelled tracks of a batch of passages (SI units).

    Track ``i`` (id ``i + 1``) is the same ship for as long as it exists: track 1 is the first ship the
    one-ship tracker found, track 2 the ship born on its residual.

    Attributes
    ----------
    labels : tuple of str
        One ship's state components.
    times : ndarray, shape (P, K)
        Sample times, s.
    estimates : ndarray, shape (P, K, I, n)
        Each track's estimate; NaN where the track does not exist (not born yet, or dead).
    covs : ndarray, shape (P, K, I, n, n)
        Their covariances (the ship's block of the joint covariance once there are two); NaN likewise.
    status : ndarray of int8, shape (P, K, I)
        Status codes (:data:`~shipsense.trackers.tracker.results.STATUSES`) of each track; ``no data`` where
        it does not exist.
    born : ndarray of int, shape (P, I)
        The sample at which each track was born (-1: never).
    died : ndarray of int, shape (P, I)
        The sample from which it no longer exists after leaving the array's reach (-1: never).
    """

    labels: tuple
    times: np.ndarray
    estimates: np.ndarray
    covs: np.ndarray
    status: np.ndarray
    born: np.ndarray
    died: np.ndarray

    @property
    def present(self):
        """Which tracks exist at each sample, bool (P, K, I)."""
        return np.isfinite(self.estimates[..., 0])

    @property
    def ship_count(self):
        """The number of ships at each sample (P, K)."""
        return self.present.sum(axis=-1)

    def status_names(self):
        """Status names (P, K, I)."""
        return np.asarray(STATUSES, dtype=object)[self.status]
