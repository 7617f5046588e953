"""What the tracker reports: status codes, one sample of every passage, a batch of
tracked passages, a passage's whole state, and gaps.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

STATUSES = ("no data", "initialising", "tracking", "restarted", "inconsistent", "manoeuvring")
"""Status names, indexed by the status codes of :class:`TrackResult`.  ``manoeuvring``: tracking, with the
motion modes of a turn or a speed change holding most of the probability (``[tracker.motion]``)."""
NO_DATA, INITIALISING, TRACKING, RESTARTED, INCONSISTENT, MANOEUVRING = range(6)


@dataclass(frozen=True)
class Gap:
    """A gap in a passage's samples longer than the tracker's limit (predicted through)."""

    passage: int
    start_s: float
    end_s: float

    def __str__(self):
        return (f"passage {self.passage}: no sample for {self.end_s - self.start_s:.3g} s "
                f"(t = {self.start_s:.6g} to {self.end_s:.6g} s), predicted through")


@dataclass
class Sample:
    """The tracker's output for one sample of every passage (SI units).

    ``estimate`` (P, n), ``cov`` (P, n, n), ``status`` (P,) (codes of :data:`STATUSES`), ``gap_nats`` (P,)
    (log-likelihood of the selected hypothesis over the runner-up; inf with one), ``ambiguous`` (P,)
    (hypotheses far apart within ``report_nats``), ``hypotheses`` (P,) (with weight), ``selected`` (P,) (the
    selected hypothesis of the bank, -1 before there is one), ``modes`` (P, M) (the selected hypothesis's motion
    modes' probabilities, :data:`~shipsense.models.motion_modes.MODES`; NaN before there is one; (P, 0) without
    motion modes).
    """

    estimate: np.ndarray
    cov: np.ndarray
    status: np.ndarray
    gap_nats: np.ndarray
    ambiguous: np.ndarray
    hypotheses: np.ndarray
    selected: np.ndarray
    modes: np.ndarray

    def take(self, rows):
        """The :class:`Sample` of passages ``rows`` (indices or a slice; fancy indices copy)."""
        return Sample(*(getattr(self, f)[rows] for f in Sample.__dataclass_fields__))


@dataclass(frozen=True)
class PassageState:
    """One passage's whole state in a :class:`Tracker` (:meth:`Tracker.passage_states`), to be carried on by
    the tracker it came from or one of its siblings (:meth:`Tracker.sibling`; :meth:`Tracker.set_passage_states`).

    ``fields``: the per-passage state (name -> array without the passage axis); the sample history holds only
    its ``hist`` first rows (the rest unwritten: a passage that has seen fewer samples than the history keeps);
    ``mean``, ``chol``, ``ok``, ``loglik``: its bank's hypotheses (internal units); ``gaps``: its gaps (start
    and end times, s); ``modal``: its hypotheses' motion modes (the rows of the bank's
    :class:`~shipsense.trackers.filters.imm.ModeBelief`), None without motion modes."""

    model: object
    hist: int
    fields: dict
    mean: np.ndarray
    chol: np.ndarray
    ok: np.ndarray
    loglik: np.ndarray
    gaps: tuple
    modal: tuple | None = None


@dataclass
class TrackResult:
    """A batch of tracked passages (SI): per sample estimates (P, K, n), full covariances (P, K, n, n), status
    codes (P, K) (:data:`STATUSES`), the selection figures of :class:`Sample`, the times (P, K), the gaps, and the
    motion modes' probabilities (P, K, M) of the modes ``mode_names`` (M = 0 without motion modes)."""

    labels: tuple
    times: np.ndarray
    estimates: np.ndarray
    covs: np.ndarray
    status: np.ndarray
    gap_nats: np.ndarray
    ambiguous: np.ndarray
    hypotheses: np.ndarray
    gaps: list = field(default_factory=list)
    modes: np.ndarray | None = None
    mode_names: tuple = ()

    @property
    def position_cov(self):
        """Position covariances (P, K, 2, 2), m²."""
        return self.covs[..., :2, :2]

    def status_names(self):
        """Status names (P, K)."""
        return np.asarray(STATUSES, dtype=object)[self.status]
