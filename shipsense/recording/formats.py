"""Reading and writing recordings in any of the formats: chosen by the file's extension, else by its content.

======================== ============================================ ==============================
format                   extensions                                   reader, writer
======================== ============================================ ==============================
long-format CSV          ``.csv`` (and any file that is not below)    :mod:`~shipsense.recording.tidy_csv`
NetCDF / HDF5 (xarray)   ``.nc .nc4 .cdf .netcdf .h5 .hdf5 .he5``     :mod:`~shipsense.recording.netcdf`
miniSEED (ObsPy)         ``.mseed .miniseed .ms .msd``                :mod:`~shipsense.recording.miniseed`
======================== ============================================ ==============================

A file whose extension is none of these is read by its first bytes: the HDF5 or NetCDF-3 signature, or a
miniSEED record header; anything else is read as CSV.  NetCDF/HDF5 needs the ``netcdf`` extra and miniSEED the
``seismic`` extra (``pip install 'shipsense[netcdf,seismic]'``); without it, reading or writing such a file
is refused with one line naming the extra.
"""

from __future__ import annotations

import re
from pathlib import Path

from shipsense.recording import miniseed, netcdf, tidy_csv
from shipsense.recording.mapping import Mapping
from shipsense.recording.samples import RecordingError, to_samples

SUFFIXES = {"csv": (".csv",), "netcdf": (".nc", ".nc4", ".cdf", ".netcdf", ".h5", ".hdf5", ".he5"),
            "miniseed": (".mseed", ".miniseed", ".ms", ".msd")}
"""File extensions of each format (any case)."""
_HDF5 = b"\x89HDF\r\n\x1a\n"
_MSEED2 = re.compile(rb"^[0-9 ]{6}[DRQM][ \x00]")


def format_of(path) -> str:
    """``"csv"``, ``"netcdf"`` or ``"miniseed"``: by the extension of ``path``, else by its first bytes."""
    suffix = Path(path).suffix.lower()
    for name, suffixes in SUFFIXES.items():
        if suffix in suffixes:
            return name
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError as err:
        raise RecordingError(f"{path}: cannot open ({err.strerror})") from None
    if head.startswith(_HDF5) or head[:3] == b"CDF":
        return "netcdf"
    if _MSEED2.match(head) or head.startswith(b"MS3"):
        return "miniseed"
    return "csv"


def read_recording(path, scenario, array=None, mapping=None):
    """Read a recorded passage into ``(times (K,), measurements (K, m))`` aligned with the scenario's channels
    (one sample per distinct time, in time order; NaN where a channel has no value).

    Parameters
    ----------
    path : str or Path
        A recording in any of the formats (see the module docstring).
    scenario : Scenario
    array : SensorArray, optional
        The array whose channel order to use (default ``scenario.array()``).
    mapping : Mapping, optional
        Renames of the recording's names (:func:`~shipsense.recording.mapping.load_mapping`); default none.

    Raises
    ------
    RecordingError
        One line naming the file, where in it, and what is wrong (see
        :mod:`~shipsense.recording.samples`).
    """
    path = Path(path)
    array = array or scenario.array()
    mapping = mapping or Mapping()
    if not path.is_file():
        raise RecordingError(f"{path}: no such file" if not path.exists() else f"{path}: not a file")
    kind = format_of(path)
    if kind == "netcdf":
        rows = netcdf.read_rows(path, mapping, array)
    elif kind == "miniseed":
        rows = miniseed.read_rows(path, mapping)
    else:
        rows = tidy_csv.read_rows(path, mapping)
    return to_samples(rows, scenario, array)


def check_writable(path):
    """Refuse, before any work, a recording ``path`` whose extension no writer takes or whose format's optional
    package is missing."""
    from shipsense.recording.optional import need

    kind = next((name for name, suffixes in SUFFIXES.items() if Path(path).suffix.lower() in suffixes), None)
    if kind is None:
        raise RecordingError(f"{path}: the extension must be one of "
                             f"{' '.join(s for v in SUFFIXES.values() for s in v)}")
    for module in {"netcdf": ("xarray", "h5netcdf", "h5py"), "miniseed": ("obspy",), "csv": ()}[kind]:
        need(module, path, {"netcdf": netcdf.WHAT, "miniseed": miniseed.WHAT}[kind])


def write_recording(sim, path):
    """Write the passages of ``sim`` (a :class:`~shipsense.simulator.Simulation`) to ``path`` in the format of
    its extension: ``.csv`` (every run, with ``run`` and ``step`` columns), NetCDF/HDF5 (every run; a ``run``
    dimension when there are several) or miniSEED (one run)."""
    path = Path(path)
    kind = next((name for name, suffixes in SUFFIXES.items() if path.suffix.lower() in suffixes), None)
    if kind == "netcdf":
        netcdf.write(sim, path)
    elif kind == "miniseed":
        miniseed.write(sim, path)
    elif kind == "csv":
        tidy_csv.write(sim, path)
    else:
        raise RecordingError(f"{path}: the extension must be one of "
                             f"{' '.join(s for v in SUFFIXES.values() for s in v)}")
