"""NetCDF and HDF5 recordings, through xarray (the ``netcdf`` extra: xarray and h5netcdf).

Layout: one data variable ``value`` (SI units, NaN = missing) over the dimensions ``time`` (seconds, or
datetimes, read as seconds since the Unix epoch), ``sensor`` (coordinate: the scenario's sensor ids) and
``channel`` (coordinate: channel names ``bx by bz b tmi ex ey ez e bearing``), in any order; a ``run``
dimension of length one is dropped (several runs are refused, as in a CSV).  A sensor that lacks a channel
of the cube holds NaN there.  The names of the variable and its dimensions, and renames of the sensor and
channel names, come from a mapping (:class:`~shipsense.recording.mapping.Mapping`).

``shipsense simulate --out FILE.nc`` (or ``.h5``) writes this layout (NetCDF-4, an HDF5 file), with a
``run`` dimension when it writes several runs and, along ``sensor``, each sensor's ``sensor_type``,
``sensor_kind`` and ``sensor_position`` (m).
"""

from __future__ import annotations

import numpy as np

from shipsense.recording.optional import need
from shipsense.recording.samples import RecordingError, Rows

WHAT = "NetCDF/HDF5"


def _seconds(coord):
    """A time coordinate as seconds (datetimes: since the Unix epoch)."""
    values = np.asarray(coord)
    if np.issubdtype(values.dtype, np.datetime64):
        return (values - np.datetime64(0, "s")) / np.timedelta64(1, "s")
    if np.issubdtype(values.dtype, np.timedelta64):
        return values / np.timedelta64(1, "s")
    return values.astype(float)


def read_rows(path, mapping, array) -> Rows:
    """The rows of the NetCDF/HDF5 file ``path``: every cell of the value cube whose sensor and channel the
    scenario has, and every cell with a value (a value of a sensor or channel the scenario lacks is refused by
    the shared validation)."""
    xr = need("xarray", path, WHAT)
    need("h5netcdf", path, WHAT)
    need("h5py", path, WHAT)
    names = mapping.netcdf
    try:
        ds = xr.open_dataset(path, decode_timedelta=True)
    except Exception as err:   # each engine fails its own way on a file that is not its format
        first = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise RecordingError(f"{path}: not a NetCDF/HDF5 file xarray can read ({first})") from None
    with ds:
        if names.variable not in ds.data_vars:
            raise RecordingError(f"{path}: no variable {names.variable!r} (the file has: "
                                 f"{', '.join(map(str, ds.data_vars)) or 'none'}); name yours in --mapping's [netcdf]")
        da = ds[names.variable]
        dims = (names.time, names.sensor, names.channel)
        if names.run in da.dims:
            if da.sizes[names.run] != 1:
                raise RecordingError(f"{path}: the file holds several runs ({da.sizes[names.run]} along "
                                     f"{names.run!r}); keep one")
            da = da.isel({names.run: 0})
        if set(da.dims) != set(dims):
            raise RecordingError(f"{path}: variable {names.variable!r} must have the dimensions "
                                 f"{', '.join(dims)} (it has: {', '.join(map(str, da.dims))}); name them in "
                                 "--mapping's [netcdf]")
        if not np.issubdtype(da.dtype, np.number):
            raise RecordingError(f"{path}: variable {names.variable!r} holds {da.dtype}, not numbers")
        for d in dims:
            if d not in da.coords:
                raise RecordingError(f"{path}: dimension {d!r} has no coordinate (its times, sensor ids or "
                                     "channel names)")
        da = da.transpose(*dims)
        times = _seconds(da[names.time].values)
        sensors = mapping.sensor_ids(np.asarray(da[names.sensor].values).astype(str))
        channels = mapping.channel_names(np.asarray(da[names.channel].values).astype(str))
        cube = np.asarray(da.values, dtype=float)
    K, S, C = cube.shape
    known = set(array.channels)
    combo = np.array([[(s, c) in known for c in channels] for s in sensors], dtype=bool).reshape(S, C)
    keep = (combo[None] | ~np.isnan(cube)).reshape(-1)
    origin = np.flatnonzero(keep)
    k, s, c = np.unravel_index(origin, cube.shape)
    raw_sensors = np.asarray(sensors)
    raw_channels = np.asarray(channels)

    def place(indices):
        cells = [np.unravel_index(origin[i], cube.shape) for i in indices]
        return " and ".join(f"{names.variable}[{names.time}={int(a)}, {names.sensor}={str(raw_sensors[b])!r}, "
                            f"{names.channel}={str(raw_channels[d])!r}]" for a, b, d in cells)

    return Rows(str(path), times[k], raw_sensors[s] if S else np.array([], dtype=str),
                raw_channels[c] if C else np.array([], dtype=str), cube.reshape(-1)[origin], place, mapping.hint)


def write(sim, path):
    """Write the passages of ``sim`` (a :class:`~shipsense.simulator.Simulation`) in this layout to ``path``."""
    xr = need("xarray", path, WHAT)
    need("h5netcdf", path, WHAT)
    need("h5py", path, WHAT)
    array = sim.array
    names = list(dict.fromkeys(c for _, c in array.channels))
    runs, K, m = sim.measurements.shape
    cube = np.full((runs, K, len(array.ids), len(names)), np.nan)
    for j, (sid, ch) in enumerate(array.channels):
        cube[:, :, array.ids.index(sid), names.index(ch)] = sim.measurements[:, :, j]
    dims = ("run", "time", "sensor", "channel")
    value = xr.Variable(dims, cube, attrs={
        "units": "SI: T (magnetometer), V/m (electrode), rad (accelerometer bearing)",
        "long_name": "recorded field value, NaN where missing"})
    ds = xr.Dataset(
        {"value": value if runs > 1 else value.isel(run=0),
         "sensor_type": ("sensor", np.array(array.types, dtype=str)),
         "sensor_kind": ("sensor", np.array(array.kinds, dtype=str)),
         "sensor_position": (("sensor", "xyz"), np.asarray(array.positions, dtype=float), {"units": "m"})},
        coords={"time": ("time", np.asarray(sim.times, dtype=float), {"units": "s"}),
                "sensor": np.array(array.ids, dtype=str), "channel": np.array(names, dtype=str),
                **({"run": np.arange(runs)} if runs > 1 else {})},
        attrs={"title": f"shipsense simulation of scenario {sim.scenario.name}", "source": "shipsense simulate"})
    ds.to_netcdf(path, engine="h5netcdf")
