"""How a recording's names map to the scenario's: the ``--mapping FILE.toml`` of ``shipsense track``.

Every format reads its sensor and channel names (a CSV's ``sensor`` and ``channel`` columns, a NetCDF file's
``sensor`` and ``channel`` coordinates, a miniSEED trace's station and channel code) and renames them with the
mapping before the shared validation; a name the mapping does not list is kept.  A mapping file::

    [sensors]            # the recording's name -> the scenario's sensor id
    NODE1 = "M1"
    "XX.NODE2.00" = "M2" # miniSEED: NETWORK.STATION.LOCATION is tried before the station alone

    [channels]           # the recording's channel name (miniSEED: the whole code) -> the scenario's channel
    HHX = "bx"

    [netcdf]             # the names of the NetCDF/HDF5 variable and its dimensions (defaults shown)
    variable = "value"
    time = "time"
    sensor = "sensor"
    channel = "channel"
    run = "run"

miniSEED channel codes the mapping does not list go through the default table of
:mod:`~shipsense.recording.miniseed` (instrument and orientation letters: ``?FZ`` is ``bz``, ...).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from shipsense.recording.samples import RecordingError

HINT = "the recordings guide lists the names, and --mapping FILE.toml renames a recording's own"
"""How an unknown sensor's or channel's message ends."""


class NetcdfNames(BaseModel):
    """The names of a NetCDF/HDF5 recording's data variable and of its dimensions."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    variable: str = "value"
    time: str = "time"
    sensor: str = "sensor"
    channel: str = "channel"
    run: str = "run"


class Mapping(BaseModel):
    """Renames of a recording's sensor and channel names (see the module docstring); empty by default."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    sensors: dict[str, str] = Field(default_factory=dict)
    channels: dict[str, str] = Field(default_factory=dict)
    netcdf: NetcdfNames = Field(default_factory=NetcdfNames)
    source: str = ""

    @property
    def hint(self) -> str:
        return HINT if not self.source else f"the mapping {self.source} does not list it"

    def sensor_ids(self, names):
        """``names`` (array of str) renamed to the scenario's sensor ids where the mapping lists them."""
        return _renamed(names, self.sensors)

    def channel_names(self, names):
        """``names`` (array of str) renamed to the scenario's channel names where the mapping lists them."""
        return _renamed(names, self.channels)


def _renamed(names, table):
    names = np.asarray(names, dtype=str)
    if not table or names.size == 0:
        return names
    unique, inverse = np.unique(names, return_inverse=True)
    return np.array([table.get(n, n) for n in unique.tolist()], dtype=str)[inverse.reshape(-1)]


def load_mapping(path) -> Mapping:
    """The mapping in the TOML file ``path`` (None: no renames); a bad file raises
    :class:`~shipsense.recording.samples.RecordingError` naming it and the key."""
    if path is None:
        return Mapping()
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as err:
        raise RecordingError(f"{path}: cannot read the mapping ({err})") from None
    except tomllib.TOMLDecodeError as err:
        raise RecordingError(f"{path}: not valid TOML ({err})") from None
    try:
        return Mapping.model_validate({**data, "source": str(path)})
    except ValidationError as err:
        e = err.errors()[0]
        where = ".".join(str(p) for p in e["loc"])
        raise RecordingError(f"{path}: {where}: {e['msg']} (a mapping has [sensors], [channels] and [netcdf]; "
                             "see the recordings guide)") from None
