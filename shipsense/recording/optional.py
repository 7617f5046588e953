"""The optional packages some recording formats need, imported on first use with a clear message when absent."""

from __future__ import annotations

import importlib

from shipsense.recording.samples import RecordingError

EXTRAS = {"xarray": "netcdf", "h5netcdf": "netcdf", "h5py": "netcdf", "obspy": "seismic"}
"""The package extra (``pip install 'shipsense[EXTRA]'``) that brings each optional package."""


def need(module, path, what):
    """Import ``module`` for reading or writing ``path`` (a ``what`` file), or raise
    :class:`~shipsense.recording.samples.RecordingError` naming the extra that installs it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        extra = EXTRAS[module.split(".")[0]]
        raise RecordingError(f"{path}: {what} files need the optional package {module.split('.')[0]}: "
                             f"pip install 'shipsense[{extra}]'") from None
