"""From long-format rows to samples: the one validation every recording format goes through.

Each reader (:mod:`~shipsense.recording.tidy_csv`, :mod:`~shipsense.recording.netcdf`,
:mod:`~shipsense.recording.miniseed`) turns its file into :class:`Rows` -- one entry per (time, sensor,
channel) value, NaN where a value is missing -- and :func:`to_samples` checks them and assembles the samples.
So the same recording gives the same samples, and the same mistake the same error, whatever its format:

* every sensor id must be one of the scenario's and every channel one of that sensor's;
* every time must be a finite number of seconds within :data:`TIME_MAX_S`;
* every value must be finite (NaN is a missing value) and within the physical range of its sensor kind
  (:mod:`~shipsense.recording.limits`);
* one channel must not have two values at one time, or at times less than :data:`NEAR_S` apart.

The first entry that breaks a rule (in the order above, then in file order) raises :class:`RecordingError`
naming the file, where in it the entry is (a CSV line, a NetCDF index, a miniSEED trace and sample) and the rule.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from shipsense.errors import ShipsenseError
from shipsense.recording.limits import value_problem

TIME_MAX_S = 1e10
"""Largest time magnitude accepted (s): Unix times fit; 1e308 is a corrupted value."""
NEAR_S = 1e-6
"""Two samples of one channel closer than this (s) are the same sample twice (a clock jitter or a duplicate)."""


class RecordingError(ShipsenseError):
    """A recording is malformed; the message names the file, where in it, and the problem."""


@dataclass(frozen=True)
class Rows:
    """A recording in long format, before validation: entry ``i`` is ``value[i]`` of channel ``channel[i]`` of
    sensor ``sensor[i]`` at ``time[i]``.

    Attributes
    ----------
    source : str
        The file, as messages name it.
    time : ndarray, shape (N,)
        Seconds.
    sensor, channel : ndarray of str, shape (N,)
        Ids and channel names in the scenario's words (a reader applies its mapping first).
    value : ndarray, shape (N,)
        SI units (T, V/m, rad); NaN is a missing value.
    place : callable
        ``place(indices)``: where those entries are in the file, e.g. ``"line 4"`` or ``"lines 2 and 4"``.
    hint : str
        Added to the message of an unknown sensor or channel (e.g. how the format's names map to the scenario's).
    """

    source: str
    time: np.ndarray
    sensor: np.ndarray
    channel: np.ndarray
    value: np.ndarray
    place: Callable[[list[int]], str]
    hint: str = ""


def _fail(rows, indices, message):
    raise RecordingError(f"{rows.source}, {rows.place([int(i) for i in indices])}: {message}")


def _columns(rows, array):
    """Each entry's column in the array's channel order, refusing unknown sensors and channels."""
    ids = list(array.ids)
    hint = f"; {rows.hint}" if rows.hint else ""
    unknown = ~np.isin(rows.sensor, ids)
    if unknown.any():
        i = int(np.argmax(unknown))
        _fail(rows, [i], f"unknown sensor id {str(rows.sensor[i])!r} (the scenario has: {', '.join(ids)}){hint}")
    column = {f"{s}\x1f{c}": j for j, (s, c) in enumerate(array.channels)}
    pairs, inverse = np.unique(np.char.add(np.char.add(rows.sensor.astype(str), "\x1f"), rows.channel.astype(str)),
                               return_inverse=True)
    cols = np.array([column.get(p, -1) for p in pairs.tolist()], dtype=np.int64)[inverse.reshape(-1)]
    if (cols < 0).any():
        i = int(np.argmax(cols < 0))
        sid, ch = str(rows.sensor[i]), str(rows.channel[i])
        valid = [c for s, c in array.channels if s == sid]
        _fail(rows, [i], f"sensor {sid!r} has no channel {ch!r} (it has: {', '.join(valid)}){hint}")
    return cols


def to_samples(rows: Rows, scenario, array=None):
    """Check ``rows`` (see the module docstring) and assemble them into samples.

    Parameters
    ----------
    rows : Rows
    scenario : Scenario
        Its sensors, and its noise (the tolerance of a magnitude channel below zero).
    array : SensorArray, optional
        The array whose channel order to use (default ``scenario.array()``).

    Returns
    -------
    times : ndarray, shape (K,)
        The distinct times, ascending (s); every distinct time is one sample.
    measurements : ndarray, shape (K, m)
        Values in the array's channel order; NaN where a channel has no value at a time.
    """
    array = array or scenario.array()
    if rows.time.size == 0:
        raise RecordingError(f"{rows.source}: no samples")
    cols = _columns(rows, array)
    t = np.asarray(rows.time, dtype=float)
    bad = ~np.isfinite(t)
    if bad.any():
        i = int(np.argmax(bad))
        _fail(rows, [i], f"time must be finite, got {t[i]!r}")
    far = np.abs(t) > TIME_MAX_S
    if far.any():
        i = int(np.argmax(far))
        _fail(rows, [i], f"time {t[i]:.6g} s is beyond +-{TIME_MAX_S:g} s (seconds, e.g. since the recording's "
                         "start or the Unix epoch)")
    v = np.asarray(rows.value, dtype=float)
    inf = np.isinf(v)
    if inf.any():
        _fail(rows, [int(np.argmax(inf))], "value is infinite")
    problem = value_problem(scenario, array, cols, v)
    if problem is not None:
        _fail(rows, [problem[0]], problem[1])
    return _assemble(rows, t, cols, v, array.n_channels)


def _assemble(rows, times, cols, values, m):
    """Samples (one per distinct time, in time order) from entries in any order; a repeated (time, channel) is
    refused naming both entries."""
    order = np.lexsort((times, cols))     # by channel, then time: a channel's samples side by side
    t, c = times[order], cols[order]
    same = (c[1:] == c[:-1]) & (t[1:] - t[:-1] < NEAR_S)
    if same.any():
        i = int(np.argmax(same))
        first, second = sorted((int(order[i]), int(order[i + 1])))
        what = "the same sample twice" if t[i + 1] == t[i] else f"two samples {t[i + 1] - t[i]:.3g} s apart"
        _fail(rows, [first, second], f"{what} (channel {str(rows.sensor[first])} {str(rows.channel[first])} at "
                                     f"{t[i]:.9g} s)")
    # times less than NEAR_S apart are one sample (traces of a format that stores each channel's start time
    # apart from the others', or times written with a different last digit)
    distinct, k = np.unique(t, return_inverse=True)
    starts = np.concatenate([[True], np.diff(distinct) >= NEAR_S])
    cluster = np.cumsum(starts) - 1
    k = cluster[k.reshape(-1)]
    grid = distinct[starts]
    flat = k * m + c
    twice = np.bincount(flat, minlength=grid.size * m) > 1
    if twice.any():   # two values of one channel chained within a sample by others' times
        at = np.flatnonzero(twice[flat])[:2]
        first, second = sorted(int(order[i]) for i in at)
        _fail(rows, [first, second], f"two samples of channel {str(rows.sensor[first])} {str(rows.channel[first])} "
                                     f"within one sample at {grid[k[at[0]]]:.9g} s")
    y = np.full((grid.size, m), np.nan)
    y[k, c] = values[order]
    return grid, y
