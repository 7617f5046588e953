"""Recorded passages: the long-format CSV that ``shipsense track --data`` reads.

Format (one sample per row, header required; other columns such as ``run``
or ``step`` are ignored)::

    time,sensor,channel,value
    0.0,M1,bx,1.25e-08
    0.0,M1,by,-3.1e-09
    ...

* ``time`` in seconds, non-decreasing down the file, on the scenario's period
  grid (``t0 + k T`` within 1 % of T); a time step with no rows is a gap.
* ``sensor`` is a sensor id of the scenario, ``channel`` one of that
  sensor's channels (``bx by bz``, ``b``, ``tmi``, ``ex ey ez``, ``bearing``).
* ``value`` in SI units (T, V/m, rad); empty or ``nan`` is a missing sample.

Missing rows and missing values are masked (NaN), never treated as zero.
Anything else that is wrong (unknown ids or channels, a duplicate sample,
time going backwards, a time off the grid, a non-numeric value) raises
:class:`RecordingError` naming the row.  This is also the format
``shipsense simulate --out FILE.csv`` writes (with one run).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

REQUIRED = ("time", "sensor", "channel", "value")


class RecordingError(ValueError):
    """A recording is malformed; the message names the file, the row and the problem."""


def read_recording(path, scenario, array=None):
    """Read a recorded passage into ``(times (K,), measurements (K, m))`` aligned with the scenario's channels.

    Parameters
    ----------
    path : str or Path
    scenario : Scenario
    array : SensorArray, optional
        The array whose channel order to use (default ``scenario.array()``).
    """
    path = Path(path)
    array = array or scenario.array()
    column = {ch: i for i, ch in enumerate(array.channels)}
    ids = set(array.ids)
    T = scenario.period
    try:
        fh = open(path, newline="")
    except OSError as err:
        raise RecordingError(f"{path}: cannot open ({err.strerror})") from None
    with fh:
        reader = csv.DictReader(fh)
        if reader.fieldnames is None or any(c not in reader.fieldnames for c in REQUIRED):
            raise RecordingError(f"{path}: the header must contain the columns {', '.join(REQUIRED)} "
                                 f"(got {', '.join(reader.fieldnames or [])})")
        samples = {}
        last_t = -math.inf
        runs = set()
        for line, row in enumerate(reader, start=2):
            where = f"{path}, line {line}"
            if "run" in row and row["run"] not in (None, ""):
                runs.add(row["run"])
                if len(runs) > 1:
                    raise RecordingError(f"{where}: the file holds several runs; keep the rows of one run")
            try:
                t = float(row["time"])
            except (TypeError, ValueError):
                raise RecordingError(f"{where}: time {row['time']!r} is not a number") from None
            if not math.isfinite(t):
                raise RecordingError(f"{where}: time must be finite, got {row['time']!r}")
            if t < last_t:
                raise RecordingError(f"{where}: time goes backwards ({t:g} s after {last_t:g} s); "
                                     "sort the file by time")
            last_t = t
            sid, ch = row["sensor"], row["channel"]
            if sid not in ids:
                raise RecordingError(f"{where}: unknown sensor id {sid!r} (the scenario has: "
                                     f"{', '.join(array.ids)})")
            if (sid, ch) not in column:
                valid = [c for s, c in array.channels if s == sid]
                raise RecordingError(f"{where}: sensor {sid!r} has no channel {ch!r} (it has: {', '.join(valid)})")
            text = (row["value"] or "").strip()
            try:
                value = float(text) if text else math.nan
            except ValueError:
                raise RecordingError(f"{where}: value {text!r} is not a number") from None
            if math.isinf(value):
                raise RecordingError(f"{where}: value is infinite")
            key = (t, sid, ch)
            if key in samples:
                raise RecordingError(f"{where}: duplicate sample for {sid}/{ch} at {t:g} s")
            samples[key] = value
    if not samples:
        raise RecordingError(f"{path}: no samples")
    t0 = min(k[0] for k in samples)
    steps = {}
    for (t, sid, ch), v in samples.items():
        k = round((t - t0) / T)
        if abs(t - t0 - k * T) > 0.01 * T:
            raise RecordingError(f"{path}: time {t:g} s is not on the scenario's {T:g} s grid starting at {t0:g} s")
        steps.setdefault(k, []).append((column[(sid, ch)], v))
    K = max(steps) + 1
    y = np.full((K, array.n_channels), np.nan)
    for k, entries in steps.items():
        for c, v in entries:
            y[k, c] = v
    return t0 + T * np.arange(K), y
