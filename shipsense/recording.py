"""Recorded passages: the long-format CSV that ``shipsense track --data`` reads.

Format (one sample per row, header required; other columns such as ``run``
or ``step`` are ignored)::

    time,sensor,channel,value
    0.0,M1,bx,1.25e-08
    0.0,M1,by,-3.1e-09
    ...

* ``time`` in seconds; rows may come in any order (logs concatenated sensor
  by sensor are common) and are ordered by time on reading; every distinct
  time is one sample (sensors need not be sampled together, and the times
  need not lie on the scenario's period grid: the tracker uses them).
* ``sensor`` is a sensor id of the scenario, ``channel`` one of that
  sensor's channels (``bx by bz``, ``b``, ``tmi``, ``ex ey ez``, ``bearing``).
* ``value`` in SI units (T, V/m, rad); empty or ``nan`` is a missing sample.

Missing rows and missing values are masked (NaN), never treated as zero.
Anything else that is wrong (unknown ids or channels, the same sample twice
or two samples of one channel less than a microsecond apart, a non-numeric
or infinite value, a time that is not a finite number or beyond 1e10 s, text
that is not UTF-8 -- a byte-order mark is fine --, a field the CSV reader
cannot take) raises :class:`RecordingError` naming the row or rows.  This is also the format
``shipsense simulate --out FILE.csv`` writes (with one run).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from shipsense.errors import ShipsenseError

REQUIRED = ("time", "sensor", "channel", "value")
TIME_MAX_S = 1e10
"""Largest time magnitude accepted (s): Unix times fit; 1e308 is a corrupted value."""
NEAR_S = 1e-6
"""Two samples of one channel closer than this (s) are the same sample twice (a clock jitter or a duplicate)."""


class RecordingError(ShipsenseError):
    """A recording is malformed; the message names the file, the row and the problem."""


def read_recording(path, scenario, array=None):
    """Read a recorded passage into ``(times (K,), measurements (K, m))`` aligned with the scenario's channels
    (one sample per distinct time, in time order).

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
    try:
        fh = open(path, newline="", encoding="utf-8-sig")   # UTF-8, with or without a byte-order mark
    except OSError as err:
        raise RecordingError(f"{path}: cannot open ({err.strerror})") from None
    with fh:
        reader = csv.DictReader(fh)
        try:
            if reader.fieldnames is None or any(c not in reader.fieldnames for c in REQUIRED):
                raise RecordingError(f"{path}: the header must contain the columns {', '.join(REQUIRED)} "
                                     f"(got {', '.join(reader.fieldnames or [])})")
            times, cols, values, lines = _rows(reader, path, ids, column, array)
        except UnicodeDecodeError as err:
            raise RecordingError(f"{path}: not UTF-8 text (byte {err.start} of a block cannot be decoded); save the "
                                 "file as UTF-8") from None
        except csv.Error as err:
            raise RecordingError(f"{path}, line {reader.line_num}: not a CSV row ({err})") from None
    if not times:
        raise RecordingError(f"{path}: no samples")
    return _assemble(path, np.array(times), np.array(cols), np.array(values), np.array(lines), array.n_channels)


def _rows(reader, path, ids, column, array):
    """Parse every row: times, channel columns, values (NaN = missing) and line numbers, checking each."""
    times, cols, values, lines = [], [], [], []
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
        if abs(t) > TIME_MAX_S:
            raise RecordingError(f"{where}: time {t:.6g} s is beyond +-{TIME_MAX_S:g} s (seconds, e.g. since the "
                                 "recording's start or the Unix epoch)")
        sid, ch = row["sensor"], row["channel"]
        if sid not in ids:
            raise RecordingError(f"{where}: unknown sensor id {sid!r} (the scenario has: {', '.join(array.ids)})")
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
        times.append(t)
        cols.append(column[(sid, ch)])
        values.append(value)
        lines.append(line)
    return times, cols, values, lines


def _assemble(path, times, cols, values, lines, m):
    """Samples (one per distinct time, in time order) from rows in any order; a repeated (time, channel) is
    refused naming both lines."""
    order = np.lexsort((times, cols))     # by channel, then time: a channel's samples side by side
    t, c = times[order], cols[order]
    same = (c[1:] == c[:-1]) & (t[1:] - t[:-1] < NEAR_S)
    if same.any():
        i = int(np.argmax(same))
        first, second = sorted((int(lines[order[i]]), int(lines[order[i + 1]])))
        what = "the same sample twice" if t[i + 1] == t[i] else f"two samples {t[i + 1] - t[i]:.3g} s apart"
        raise RecordingError(f"{path}, lines {first} and {second}: {what} (channel column {int(c[i])} at "
                             f"{t[i]:.9g} s)")
    grid, k = np.unique(t, return_inverse=True)
    y = np.full((grid.size, m), np.nan)
    y[k, c] = values[order]
    return grid, y
