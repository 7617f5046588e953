"""Recorded passages: the files ``shipsense track --data`` reads and ``shipsense simulate --out`` writes.

A recording is a long list of values -- one per time, sensor and channel, in SI units -- in one of three
formats: a long-format CSV (:mod:`~shipsense.recording.tidy_csv`), NetCDF/HDF5 through xarray
(:mod:`~shipsense.recording.netcdf`) or miniSEED through ObsPy (:mod:`~shipsense.recording.miniseed`), chosen by
the file's extension or content (:mod:`~shipsense.recording.formats`).  Every reader hands its rows to the one
validation (:mod:`~shipsense.recording.samples`, with the physical ranges of :mod:`~shipsense.recording.limits`)
so a recording reads to the same samples, and a mistake to the same error, whatever its format.  A mapping
(:mod:`~shipsense.recording.mapping`) renames a recording's own sensor and channel names, and
:mod:`~shipsense.recording.passages` splits a recording at gaps too long to predict through.

The entry points: :func:`~shipsense.recording.formats.read_recording`,
:func:`~shipsense.recording.formats.write_recording` and
:class:`~shipsense.recording.samples.RecordingError`.
"""

from shipsense.recording.formats import read_recording, write_recording
from shipsense.recording.samples import RecordingError

__all__ = ["RecordingError", "read_recording", "write_recording"]
