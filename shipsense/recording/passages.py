"""A recording split into passages at gaps too long to predict through.

The tracker predicts through a gap between samples longer than its ``gap_limit_s`` and reports it; a gap
longer than a passage gap (by default :data:`PASSAGE_GAP_LIMITS` gap limits) is not a gap in one passage but
the end of one and the start of another (a recording of a day with two ships, or a clock that jumped), so
the samples on either side are tracked as separate passages, each from the tracker's initial state.
"""

from __future__ import annotations

import numpy as np

PASSAGE_GAP_LIMITS = 10.0
"""The default passage gap, in tracker gap limits (``[tracker] gap_limit_s``, default 10 periods)."""


def split(times, gap_s):
    """Slices of ``times`` (K,), ascending s, into passages: a new passage starts after every step longer than
    ``gap_s``."""
    times = np.asarray(times, dtype=float)
    cuts = np.flatnonzero(np.diff(times) > gap_s) + 1
    bounds = np.concatenate([[0], cuts, [times.size]]).astype(int)
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]
