"""The long-format CSV: one value per row, ``time,sensor,channel,value``.

Format (header required; other columns such as ``run`` or ``step`` are ignored)::

    time,sensor,channel,value
    0.0,M1,bx,1.25e-08
    0.0,M1,by,-3.1e-09
    ...

* ``time`` in seconds; rows may come in any order (logs concatenated sensor by sensor are common).
* ``sensor`` is a sensor id of the scenario, ``channel`` one of that sensor's channels (``bx by bz``, ``b``,
  ``tmi``, ``ex ey ez``, ``e``, ``bearing``); a mapping (:class:`~shipsense.recording.mapping.Mapping`) renames
  the file's names first.
* ``value`` in SI units (T, V/m, rad); empty or ``nan`` is a missing value.

What this module refuses itself (:class:`~shipsense.recording.samples.RecordingError` naming the line): a
header without the four columns or naming one of them twice, the rows of several runs (a ``run`` column with
more than one value), a time or value that is not a number, text that is not UTF-8 (a byte-order mark is
fine), a field the CSV reader cannot take; everything else is the validation every format shares
(:func:`~shipsense.recording.samples.to_samples`).  ``shipsense simulate --out FILE.csv`` writes this format
(with a ``run`` and a ``step`` column).
"""

from __future__ import annotations

import csv
import math

import numpy as np

from shipsense.recording.samples import RecordingError, Rows

REQUIRED = ("time", "sensor", "channel", "value")

TRUTH_KEYS = ("run", "ship", "step", "time")
"""The truth CSV's first columns (:func:`write_truth`); the state's labels follow."""


def read_rows(path, mapping) -> Rows:
    """The rows of the CSV file ``path`` (names renamed by ``mapping``)."""
    try:
        fh = open(path, newline="", encoding="utf-8-sig")   # UTF-8, with or without a byte-order mark
    except OSError as err:
        raise RecordingError(f"{path}: cannot open ({err.strerror})") from None
    with fh:
        reader = csv.reader(fh)
        try:
            header = next(reader, None)
            index = _header(path, header)
            times, sensors, channels, values, lines = _rows(reader, path, index)
        except UnicodeDecodeError as err:
            raise RecordingError(f"{path}: not UTF-8 text (byte {err.start} of a block cannot be decoded); save the "
                                 "file as UTF-8") from None
        except csv.Error as err:
            raise RecordingError(f"{path}, line {reader.line_num}: not a CSV row ({err})") from None
    lines = np.array(lines, dtype=np.int64)

    def place(indices):
        found = sorted(int(lines[i]) for i in indices)
        return f"line {found[0]}" if len(found) == 1 else "lines " + " and ".join(map(str, found))

    return Rows(str(path), np.array(times, dtype=float), mapping.sensor_ids(np.array(sensors, dtype=str)),
                mapping.channel_names(np.array(channels, dtype=str)), np.array(values, dtype=float), place,
                mapping.hint)


def _header(path, header):
    """Column index of each required column (and of ``run``, or None), refusing a header without them or with
    one of them twice."""
    header = [h.strip() for h in (header or [])]
    if any(c not in header for c in REQUIRED):
        raise RecordingError(f"{path}: the header must contain the columns {', '.join(REQUIRED)} "
                             f"(got {', '.join(header)})")
    for c in (*REQUIRED, "run"):
        at = [i + 1 for i, h in enumerate(header) if h == c]
        if len(at) > 1:
            raise RecordingError(f"{path}, line 1: the header names the column {c!r} twice (columns "
                                 f"{' and '.join(map(str, at))}); keep one")
    return {c: header.index(c) if c in header else None for c in (*REQUIRED, "run")}


def _rows(reader, path, index):
    """Parse every row: times, sensors, channels, values (NaN = missing) and line numbers."""
    times, sensors, channels, values, lines = [], [], [], [], []
    it, isn, ich, iv, irun = (index[c] for c in (*REQUIRED, "run"))
    width = max(i for i in index.values() if i is not None) + 1
    first_run = None
    for line, row in enumerate(reader, start=2):
        if not row:
            continue   # a blank line
        where = f"{path}, line {line}"
        if len(row) < width:
            row = row + [""] * (width - len(row))
        if irun is not None and row[irun] != "":
            if first_run is None:
                first_run = row[irun]
            elif row[irun] != first_run:
                raise RecordingError(f"{where}: the file holds several runs; keep the rows of one run")
        try:
            t = float(row[it])
        except ValueError:
            raise RecordingError(f"{where}: time {row[it]!r} is not a number") from None
        text = row[iv].strip()
        try:
            value = float(text) if text else math.nan
        except ValueError:
            raise RecordingError(f"{where}: value {text!r} is not a number") from None
        times.append(t)
        sensors.append(row[isn])
        channels.append(row[ich])
        values.append(value)
        lines.append(line)
    return times, sensors, channels, values, lines


def write(sim, path):
    """Write the measurements of ``sim`` (a :class:`~shipsense.simulator.Simulation`) as this format with a
    ``run`` and a ``step`` column: ``run, step, time, sensor, channel, value`` (value empty if missing)."""
    runs, steps, _ = sim.measurements.shape
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["run", "step", "time", "sensor", "channel", "value"])
        for r in range(runs):
            for k in range(steps):
                t = f"{sim.times[k]:.6g}"
                row = sim.measurements[r, k]
                for c, (sid, name) in enumerate(sim.channels):
                    w.writerow([r, k, t, sid, name, "" if not sim.mask[r, k, c] else repr(float(row[c]))])


def write_truth(sim, path):
    """Write the truth of ``sim`` as CSV: :data:`TRUTH_KEYS` and the state (``sim.STATE_LABELS``, SI), one row
    per run, sailing ship and sample; ship 0 is the scenario's own passage."""
    ships, present = sim.ships, sim.ships_present
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([*TRUTH_KEYS, *sim.STATE_LABELS])
        for r in range(sim.runs):
            for s in np.flatnonzero(present[r]):
                for k in range(sim.times.size):
                    w.writerow([r, s, k, f"{sim.times[k]:.6g}", *map(repr, ships[r, s, k].tolist())])

