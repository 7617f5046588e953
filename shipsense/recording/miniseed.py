"""miniSEED recordings, through ObsPy (the ``seismic`` extra).

Each trace is one channel of one sensor over a run of regularly spaced samples: sample ``j`` is at
``starttime + j / sampling_rate`` (seconds since the Unix epoch).  A trace's station code is the sensor id
(or ``NETWORK.STATION.LOCATION`` and the station are looked up in a mapping's ``[sensors]``), and its channel
code the channel, through a mapping's ``[channels]`` (the whole code) or else :data:`CODES` (the code's
instrument and orientation letters; the band letter, the first, is the sampling rate's and any is read):

=========== ===============================================================
code        channel
=========== ===============================================================
``?FE``     ``bx`` (magnetometer, east)
``?FN``     ``by`` (magnetometer, north)
``?FZ``     ``bz`` (magnetometer, up)
``?FF``     ``b`` (magnetometer, total field magnitude)
``?FT``     ``tmi`` (magnetometer, total-field anomaly)
``?QE``     ``ex`` (electrode, east)
``?QN``     ``ey`` (electrode, north)
``?QZ``     ``ez`` (electrode, up)
``?QF``     ``e`` (electrode, magnitude)
``?YB``     ``bearing`` (accelerometer's bearing, rad)
=========== ===============================================================

Samples must be floating-point values in SI units (T, V/m, rad): a trace of integers (counts) is refused --
remove the instrument response first (ObsPy's ``Trace.remove_response``).  Several traces of one channel are
read together (a gap between them is a run of missing samples); overlapping traces are the same samples twice.

``shipsense simulate --runs 1 --out FILE.mseed`` writes one trace per channel and unbroken run of samples
(network ``XX``, the sensor id as station, the codes above with the band letter of the sampling rate,
``FLOAT64`` samples, the scenario's time 0 at the Unix epoch); it refuses several runs (a miniSEED file is
one recording) and a sensor id that is not a station code (up to five letters and digits).
"""

from __future__ import annotations

import re

import numpy as np

from shipsense.recording.optional import need
from shipsense.recording.samples import RecordingError, Rows

WHAT = "miniSEED"
CODES = {"FE": "bx", "FN": "by", "FZ": "bz", "FF": "b", "FT": "tmi", "QE": "ex", "QN": "ey", "QZ": "ez", "QF": "e",
         "YB": "bearing"}
"""A channel code's instrument and orientation letters -> the channel (the band letter is any)."""
NETWORK = "XX"
"""The network code ``simulate`` writes."""
BANDS = ((80.0, "H"), (10.0, "B"), (1.0, "M"), (0.5, "L"), (0.05, "V"), (0.0, "U"))
"""SEED band letters by sampling rate (Hz): the first whose rate the sampling rate exceeds."""


def read_rows(path, mapping) -> Rows:
    """The rows of the miniSEED file ``path``: every sample of every trace."""
    obspy = need("obspy", path, WHAT)
    try:
        stream = obspy.read(str(path), format="MSEED")
    except Exception as err:   # ObsPy's decoders raise their own classes on a file that is not miniSEED
        first = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise RecordingError(f"{path}: not a miniSEED file ObsPy can read ({first})") from None
    times, sensors, channels, values, where = [], [], [], [], []
    for n, tr in enumerate(stream):
        data = np.ma.getdata(tr.data)
        if not np.issubdtype(data.dtype, np.floating):
            raise RecordingError(f"{path}, trace {tr.id}: samples are {data.dtype} (counts?), not values in SI "
                                 "units; remove the instrument response first (ObsPy's Trace.remove_response)")
        st = tr.stats
        full = f"{st.network}.{st.station}.{st.location}"
        sensor = mapping.sensors.get(full, mapping.sensors.get(st.station, st.station))
        code = st.channel
        channel = mapping.channels.get(code, CODES.get(code[1:], code) if len(code) == 3 else code)
        v = data.astype(float)
        if np.ma.isMaskedArray(tr.data):
            v = np.where(np.ma.getmaskarray(tr.data), np.nan, v)
        times.append(st.starttime.timestamp + np.arange(st.npts) * st.delta)
        sensors.append(np.full(st.npts, sensor))
        channels.append(np.full(st.npts, channel))
        values.append(v)
        where.append(np.full(st.npts, n))
    if not times:
        return Rows(str(path), np.zeros(0), np.zeros(0, dtype=str), np.zeros(0, dtype=str), np.zeros(0),
                    lambda i: "", mapping.hint)
    trace = np.concatenate(where)
    start = np.concatenate([[0], np.cumsum([tr.stats.npts for tr in stream])[:-1]])

    def place(indices):
        return " and ".join(f"trace {stream[int(trace[i])].id}, sample {int(i - start[trace[i]])}" for i in indices)

    return Rows(str(path), np.concatenate(times), np.concatenate(sensors).astype(str),
                np.concatenate(channels).astype(str), np.concatenate(values), place,
                "station codes are sensor ids and channel codes follow the recordings guide's table; "
                + mapping.hint)


def band(rate_hz):
    """The SEED band letter of a sampling rate (Hz)."""
    return next(letter for low, letter in BANDS if rate_hz > low)


def write(sim, path):
    """Write the one run of ``sim`` (a :class:`~shipsense.simulator.Simulation`) to ``path``."""
    obspy = need("obspy", path, WHAT)
    if sim.runs != 1:
        raise RecordingError(f"{path}: a miniSEED file holds one recording; simulate with --runs 1 (or write "
                             ".csv or .nc for several runs)")
    for sid in sim.array.ids:
        if not re.fullmatch(r"[A-Za-z0-9]{1,5}", sid):
            raise RecordingError(f"{path}: sensor id {sid!r} is not a miniSEED station code (1 to 5 letters and "
                                 "digits); write .csv or .nc")
    times = np.asarray(sim.times, dtype=float)
    steps = np.diff(times)
    if steps.size and not np.allclose(steps, steps[0], rtol=1e-9, atol=0.0):
        raise RecordingError(f"{path}: miniSEED needs regularly spaced samples; write .csv or .nc")
    delta = float(steps[0]) if steps.size else 1.0
    letter = band(1.0 / delta)
    code = {ch: letter + c for c, ch in CODES.items()}
    traces = []
    for j, (sid, ch) in enumerate(sim.array.channels):
        y = sim.measurements[0, :, j]
        header = {"network": NETWORK, "station": sid, "location": "", "channel": code[ch], "delta": delta,
                  "starttime": obspy.UTCDateTime(float(times[0]))}
        traces.append(obspy.Trace(np.ma.masked_invalid(y.astype(np.float64)), header=header))
    stream = obspy.Stream(traces).split()   # a masked sample ends a trace: one trace per unbroken run
    stream.write(str(path), format="MSEED", encoding="FLOAT64")
