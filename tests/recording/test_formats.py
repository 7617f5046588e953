"""Recordings in every format: simulate -> file -> samples round trips, the format by extension or content,
mappings, the missing extra, and one shared error per kind of bad input whatever the format."""

import dataclasses
import importlib

import numpy as np
import pytest

from shipsense import load_scenario, simulate
from shipsense.recording import RecordingError, read_recording, write_recording
from shipsense.recording.formats import format_of
from shipsense.recording.mapping import load_mapping
from shipsense.recording.miniseed import CODES

xr = pytest.importorskip("xarray", reason="the netcdf extra (in dev) is not installed")
obspy = pytest.importorskip("obspy", reason="the seismic extra (in dev) is not installed")

SUFFIXES = (".csv", ".nc", ".h5", ".mseed")


def _with_gaps(sim):
    """The simulation with some values missing (a whole sample of one sensor, and single values)."""
    y, mask = sim.measurements.copy(), sim.mask.copy()
    for k, j in ((3, 0), (3, 1), (3, 2), (10, 6), (40, 4)):
        y[:, k, j], mask[:, k, j] = np.nan, False
    return dataclasses.replace(sim, measurements=y, mask=mask)


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_every_format_reads_back_what_simulate_wrote(tmp_path, suffix):
    sim = _with_gaps(simulate("S2", runs=1, seed=3))
    path = tmp_path / f"rec{suffix}"
    write_recording(sim, path)
    times, y = read_recording(path, sim.scenario)
    np.testing.assert_array_equal(times, sim.times)
    np.testing.assert_array_equal(np.isnan(y), ~sim.mask[0])
    np.testing.assert_allclose(y, sim.measurements[0], rtol=1e-12)   # CSV: repr of each float, exact


def test_netcdf_of_several_runs_is_refused_like_the_csv(tmp_path):
    sim = simulate("S2", runs=2, seed=3)
    for suffix in (".nc", ".csv"):
        write_recording(sim, tmp_path / f"two{suffix}")
        with pytest.raises(RecordingError, match="several runs"):
            read_recording(tmp_path / f"two{suffix}", sim.scenario)
    with pytest.raises(RecordingError, match="one recording"):
        write_recording(sim, tmp_path / "two.mseed")


@pytest.mark.parametrize("suffix, kind", [(".nc", "netcdf"), (".mseed", "miniseed"), (".csv", "csv")])
def test_an_unknown_extension_is_read_by_its_content(tmp_path, suffix, kind):
    sim = simulate("S2", runs=1, seed=3)
    path = tmp_path / f"rec{suffix}"
    write_recording(sim, path)
    renamed = tmp_path / "rec.dat"
    renamed.write_bytes(path.read_bytes())
    assert format_of(renamed) == kind
    np.testing.assert_array_equal(read_recording(renamed, sim.scenario)[1], read_recording(path, sim.scenario)[1])


def test_a_mapping_renames_netcdf_names_and_miniseed_codes(tmp_path):
    sim = simulate("S2", runs=1, seed=3)
    nc = tmp_path / "rec.nc"
    write_recording(sim, nc)
    ds = xr.load_dataset(nc).rename({"value": "B", "time": "t", "sensor": "node"})
    ds = ds.assign_coords(node=["N1", "N2", "N3"])
    ds.to_netcdf(tmp_path / "theirs.nc", engine="h5netcdf")
    ms = tmp_path / "rec.mseed"
    write_recording(sim, ms)
    stream = obspy.read(str(ms))
    for tr in stream:
        tr.stats.station = {"M1": "NODEA"}.get(tr.stats.station, tr.stats.station)
        if tr.stats.channel.endswith("FZ"):
            tr.stats.channel = "HH3"
    stream.write(str(tmp_path / "theirs.mseed"), format="MSEED", encoding="FLOAT64")
    mapping_file = tmp_path / "map.toml"
    mapping_file.write_text('[sensors]\nN1 = "M1"\nN2 = "M2"\nN3 = "A1"\nNODEA = "M1"\n[channels]\nHH3 = "bz"\n'
                            '[netcdf]\nvariable = "B"\ntime = "t"\nsensor = "node"\n')
    mapping = load_mapping(mapping_file)
    for theirs in ("theirs.nc", "theirs.mseed"):
        times, y = read_recording(tmp_path / theirs, sim.scenario, mapping=mapping)
        np.testing.assert_allclose(y, sim.measurements[0], rtol=1e-12)
        with pytest.raises(RecordingError, match="unknown sensor id|has no channel|no variable"):
            read_recording(tmp_path / theirs, sim.scenario)   # without the mapping: named, not guessed
    bad = tmp_path / "bad.toml"
    bad.write_text("[sensor]\nN1 = 'M1'\n")
    with pytest.raises(RecordingError, match="bad.toml: sensor"):
        load_mapping(bad)


def test_a_missing_extra_is_one_line_naming_it(tmp_path, monkeypatch):
    sim = simulate("S2", runs=1, seed=3)
    write_recording(sim, tmp_path / "rec.nc")
    real = importlib.import_module

    def without_xarray(name, *a, **k):
        if name.split(".")[0] in ("xarray", "obspy"):
            raise ImportError(name)
        return real(name, *a, **k)

    monkeypatch.setattr(importlib, "import_module", without_xarray)
    for path, extra in ((tmp_path / "rec.nc", "netcdf"), (tmp_path / "out.mseed", "seismic")):
        with pytest.raises(RecordingError, match=rf"pip install 'shipsense\[{extra}\]'") as info:
            (read_recording if path.exists() else write_recording)(*((path, sim.scenario) if path.exists()
                                                                     else (sim, path)))
        assert "\n" not in str(info.value) and str(path) in str(info.value)


def _write(fmt, path, rows):
    """A file of ``fmt`` holding ``rows`` (time, sensor, channel, value): in NetCDF one time index per row, in
    miniSEED one one-sample trace per row, so that every format can hold every mistake."""
    if fmt == "csv":
        path.write_text("time,sensor,channel,value\n" + "".join(f"{t!r},{s},{c},{v!r}\n" for t, s, c, v in rows))
    elif fmt == "netcdf":
        sensors = list(dict.fromkeys(r[1] for r in rows))
        channels = list(dict.fromkeys(r[2] for r in rows))
        cube = np.full((len(rows), len(sensors), len(channels)), np.nan)
        for i, (_t, s, c, v) in enumerate(rows):
            cube[i, sensors.index(s), channels.index(c)] = v
        xr.Dataset({"value": (("time", "sensor", "channel"), cube)},
                   coords={"time": [r[0] for r in rows], "sensor": sensors, "channel": channels}
                   ).to_netcdf(path, engine="h5netcdf")
    else:
        code = {ch: "M" + c for c, ch in CODES.items()}
        traces = [obspy.Trace(np.array([v], dtype=np.float64),
                              header={"network": "XX", "station": s, "channel": code.get(c, c[:3].upper()),
                                      "starttime": obspy.UTCDateTime(t), "delta": 0.5}) for t, s, c, v in rows]
        obspy.Stream(traces).write(str(path), format="MSEED", encoding="FLOAT64")
    return path


@pytest.mark.parametrize("fmt, suffix", [("csv", ".csv"), ("netcdf", ".nc"), ("miniseed", ".mseed")])
@pytest.mark.parametrize("scenario, rows, message", [
    ("S2", [(0.0, "X9", "bx", 1e-9)], "unknown sensor id 'X9'"),
    ("S2", [(0.0, "M1", "ex", 1e-9)], "sensor 'M1' has no channel 'ex'"),
    ("S2", [(0.5, "M1", "bx", 1e-9), (0.0, "M1", "by", 1e-9), (0.5, "M1", "bx", 2e-9)], "the same sample twice"),
    ("S2", [(0.0, "M1", "bx", 1e-9), (0.0, "M1", "by", 1e308)], r"value 1e\+308 T of M1 by is beyond"),
    ("S2", [(0.0, "M1", "bx", -1e308)], "beyond a magnetometer's physical range"),
    ("S2", [(0.0, "M1", "bz", 98.3)], r"in nT rather than T\?"),
    ("S2", [(0.0, "A1", "bearing", 90.0)], r"in degrees rather than radians\?"),
    ("S1-P2", [(0.0, "E1", "ex", 2e-6), (0.5, "E1", "ey", -3e-6)], "negative, but a envelope electrode"),
])
def test_every_format_refuses_the_same_mistakes_with_the_same_message(tmp_path, fmt, suffix, scenario, rows,
                                                                      message):
    sc = load_scenario(scenario)
    if fmt == "netcdf" and "same sample" in message:
        message = "the same sample twice"
    path = _write(fmt, tmp_path / f"r{suffix}", rows)
    with pytest.raises(RecordingError, match=message) as info:
        read_recording(path, sc)
    text = str(info.value)
    assert text.startswith(f"{path}, ") and "\n" not in text
    where = {"csv": "line", "netcdf": "value[time=", "miniseed": "trace XX."}[fmt]
    assert where in text


def test_a_magnitude_a_little_below_zero_is_noise_and_further_is_refused():
    """An envelope's floor is -5 noise std (a magnitude measured with additive noise); below it is a sign."""
    from shipsense.recording.limits import NEGATIVE_SIGMAS, channel_ranges

    sc = load_scenario("S1-P2")
    array = sc.array()
    low, high = channel_ranges(sc, array)
    std = np.asarray(sc.channel_std)
    np.testing.assert_allclose(low, -NEGATIVE_SIGMAS * std)   # every S1-P2 channel is an envelope
    assert (high == 1.0).all()
    sim = simulate("S1-P2", runs=20, seed=1)   # the simulator's own envelopes dip below zero by noise only
    assert np.nanmin(sim.measurements) < 0 and (np.nan_to_num(sim.measurements, nan=0.0) >= low).all()


def test_the_recordings_guide_states_the_limits_the_reader_applies():
    from pathlib import Path

    from shipsense.recording.limits import FIELD_LIMIT, NEGATIVE_SIGMAS

    page = (Path(__file__).resolve().parents[2] / "docs" / "guide" / "recordings.md").read_text()
    assert f"| magnetometer | \\|value\\| <= {FIELD_LIMIT['magnetometer']:g} T |" in page
    assert f"| electrode | \\|value\\| <= {FIELD_LIMIT['electrode']:g} V/m |" in page
    assert FIELD_LIMIT["accelerometer"] == pytest.approx(2 * np.pi) and "<= 2 pi rad" in page
    assert f">= -{NEGATIVE_SIGMAS:g} noise std" in page
