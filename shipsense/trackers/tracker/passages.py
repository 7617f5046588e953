"""The tracker's per-passage state: one typed structure of arrays whose first axis is the passage.

Every field is an array over the passages of a batch; a passage's state is its row in each, so passages are a
batch axis (the compiled step reads and writes the rows it steps) and a passage is carried between trackers
as its rows (:meth:`PassageArrays.row`, :meth:`PassageArrays.put_row`), with its rows of the bank
(:func:`passage_states`, :func:`set_passage_states`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from shipsense.trackers.filters.core import Belief
from shipsense.trackers.tracker.results import Gap, PassageState

WAITING, STARTING, RUNNING, PENDING = 0, 1, 2, 3
"""Phases of a passage: no data yet, detection/initialisation, a bank running, its window fits deferred."""
PHASES = (WAITING, STARTING, RUNNING, PENDING)
HISTORY = ("y_hist", "t_hist")
"""The sample history: a passage that has seen ``k`` samples has only its first ``min(k, history)`` rows
written (:meth:`PassageArrays.row` keeps those)."""


@dataclass
class PassageArrays:
    """The per-passage state of a :class:`~shipsense.trackers.tracker.tracker.Tracker` (P passages, m channels,
    n state components, internal units).  :meth:`layout` gives every field's shape after the passage axis,
    its dtype and its value at a passage's start."""

    n: np.ndarray            # (P,) samples seen: the index of the next one
    phase: np.ndarray        # (P,) int8, one of PHASES
    last_t: np.ndarray       # (P,) time of the last sample, s
    k0: np.ndarray           # (P,) detection sample (-1: none yet)
    peak: np.ndarray         # (P,) largest SNR since the detection
    start: np.ndarray        # (P,) sample the bank (re)started at
    scan: np.ndarray         # (P,) sample of the last scheduled refit (or the first window fit)
    trusted: np.ndarray      # (P,) the last fit passed its test
    excess: np.ndarray       # (P,) reported over bank covariance of a failed fit
    alarms: np.ndarray       # (P,) alarms so far
    restarts: np.ndarray     # (P,) restarts so far
    peak_done: np.ndarray    # (P,) the refit after the peak is done
    ref: np.ndarray          # (P,) position covariance trace at the last (re)start
    nis: np.ndarray          # (P, nis_window) normalised NIS of the selected hypothesis, last samples
    snr: np.ndarray          # (P, 3) SNR of the last three samples (robust detection)
    win: np.ndarray          # (P, keep_init, n) window fits at k0
    win_t0: np.ndarray       # (P,) time of the window's first sample, s
    y_hist: np.ndarray       # (P, history, m) samples, a ring
    t_hist: np.ndarray       # (P, history) their times, s
    own: np.ndarray          # (P,) trace of the selected hypothesis's own position covariance
    cons: np.ndarray         # (P, consistency_window, 2, m) the consistency test's window of terms
    cons_n: np.ndarray       # (P,) samples in that window
    cons_tests: np.ndarray   # (P,) samples tested
    cons_fails: np.ndarray   # (P,) samples the test failed on
    cons_now: np.ndarray     # (P,) it failed on this one
    since: np.ndarray        # (P,) last sample reported manoeuvring (-1: none): refits start after it
    early: np.ndarray        # (P,) its window fits (due or pending) are an early attempt, accepted on their test
    tied: np.ndarray         # (P,) the last sample's selection was ambiguous (a near tie far apart)

    @staticmethod
    def layout(m, n, settings, hist):
        """Field name -> (shape after the passage axis, dtype, value at a passage's start), for ``m`` channels,
        ``n`` state components, the tracker's ``settings`` and ``hist`` samples of history."""
        return {
            "n": ((), int, 0), "phase": ((), np.int8, WAITING), "last_t": ((), float, np.nan), "k0": ((), int, -1),
            "peak": ((), float, 0.0), "start": ((), int, 0), "scan": ((), int, 0), "trusted": ((), bool, True),
            "excess": ((), float, 1.0), "alarms": ((), int, 0), "restarts": ((), int, 0),
            "peak_done": ((), bool, False), "ref": ((), float, np.nan),
            "nis": ((settings.nis_window,), float, np.nan), "snr": ((3,), float, np.nan),
            "win": ((settings.keep_init, n), float, np.nan), "win_t0": ((), float, np.nan),
            "y_hist": ((hist, m), float, np.nan), "t_hist": ((hist,), float, np.nan), "own": ((), float, np.nan),
            "cons": ((settings.consistency_window or 1, 2, m), float, 0.0), "cons_n": ((), int, 0),
            "cons_tests": ((), int, 0), "cons_fails": ((), int, 0), "cons_now": ((), bool, False),
            "since": ((), int, -1), "early": ((), bool, False), "tied": ((), bool, False),
        }

    @classmethod
    def fresh(cls, P, layout):
        """The state of ``P`` passages at their start (``layout``: :meth:`layout`)."""
        return cls(**{name: np.full((P, *shape), value, dtype=dtype) for name, (shape, dtype, value) in layout.items()})

    def reset(self, idx, layout):
        """Passages ``idx`` back at their start."""
        for name, (_, _, value) in layout.items():
            getattr(self, name)[idx] = value

    def row(self, p):
        """Passage ``p``'s state as copies (name -> array without the passage axis; the history's written rows
        only), and the number of those rows."""
        hist = int(min(self.n[p], self.y_hist.shape[1]))
        return {f.name: np.array(getattr(self, f.name)[p][:hist] if f.name in HISTORY else getattr(self, f.name)[p])
                for f in fields(self)}, hist

    def put_row(self, p, values, hist, layout):
        """Passage ``p``'s state set to ``values`` (from :meth:`row`, ``hist`` history rows written)."""
        for name, (_, _, value) in layout.items():
            arr = getattr(self, name)
            if name in HISTORY:
                arr[p] = value
                arr[p][:hist] = values[name]
            else:
                arr[p] = values[name]


def passage_indices(trk, passages):
    """``passages`` as an int64 vector of indices of the tracker ``trk``'s passages (not booleans, not
    fractions)."""
    idx = np.asarray(passages)
    if idx.size == 0:
        return np.zeros(0, dtype=np.int64)
    if idx.ndim != 1 or idx.dtype.kind not in "iu":
        raise ValueError(f"passages must be a sequence of passage indices (integers), got {passages!r}")
    if idx.min() < 0 or idx.max() >= trk.P:
        raise IndexError(f"passages {idx.tolist()} out of range for {trk.P} passages")
    return idx.astype(np.int64)


def check_unpruned(bank):
    """Refuse a bank whose hypotheses were pruned (a passage's rows would not be its own)."""
    if len(bank.idx) != bank.R * bank.H:
        raise ValueError("passage states need a bank without pruning (the tracker method's)")


def passage_states(trk, passages):
    """:meth:`~shipsense.trackers.tracker.tracker.Tracker.passage_states` of the tracker ``trk``."""
    idx = passage_indices(trk, passages)
    check_unpruned(trk.bank)
    H = trk.H
    out = []
    for p in idx.tolist():
        fields_, hist = trk.state.row(p)
        rows = slice(p * H, (p + 1) * H)
        b, modal = trk.bank.belief, trk.bank.modal
        out.append(PassageState(trk.model, hist, fields_, b.mean[rows].copy(), b.chol[rows].copy(),
                                b.ok[rows].copy(), trk.bank.cum[p].copy(),
                                tuple((g.start_s, g.end_s) for g in trk.gaps if g.passage == p),
                                None if modal is None else tuple(a[rows].copy() for a in modal)))
    return out


def set_passage_states(trk, passages, states):
    """:meth:`~shipsense.trackers.tracker.tracker.Tracker.set_passage_states` of the tracker ``trk``."""
    idx = passage_indices(trk, passages)
    states = list(states)
    if idx.size != len(states) or np.unique(idx).size != idx.size:
        raise ValueError(f"give one state for each of distinct passages, got {len(states)} states for "
                         f"passages {idx.tolist()}")
    if any(not isinstance(st, PassageState) or st.model is not trk.model for st in states):
        raise ValueError("passage states must come from this tracker or a sibling (Tracker.sibling)")
    check_unpruned(trk.bank)
    H, b = trk.H, trk.bank.belief
    moved = set(idx.tolist())
    trk.gaps = [g for g in trk.gaps if g.passage not in moved]      # (a previous occupant's)
    for p, st in zip(idx.tolist(), states):
        trk.state.put_row(p, st.fields, st.hist, trk.layout)
        rows = slice(p * H, (p + 1) * H)
        b.mean[rows], b.chol[rows], b.ok[rows] = st.mean, st.chol, st.ok
        if trk.bank.modal is not None:
            for arr, part in zip(trk.bank.modal, st.modal):
                arr[rows] = part
        trk.bank.cum[p] = st.loglik
        trk.gaps.extend(Gap(p, start, end) for start, end in st.gaps)
    trk.bank.belief = Belief(*b)       # written in place: drop a filter's covariance cache

