"""Recorded passages: the CSV round trip, gaps, and one clear error per kind of bad file."""

import numpy as np
import pytest

from shipsense import load_scenario, simulate
from shipsense.recording import RecordingError, read_recording, tidy_csv


def test_round_trip_through_the_simulators_csv(tmp_path):
    sim = simulate("S2", runs=1, seed=3)
    path = tmp_path / "rec.csv"
    tidy_csv.write(sim, path)
    times, y = read_recording(path, sim.scenario)
    np.testing.assert_allclose(times, sim.times)
    np.testing.assert_allclose(y, sim.measurements[0], rtol=1e-12)


def _write(tmp_path, rows, header="time,sensor,channel,value"):
    path = tmp_path / "r.csv"
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def test_missing_values_are_masked_and_times_are_the_samples(tmp_path):
    sc = load_scenario("S2")
    rows = ["0.0,M1,bx,1e-9", "0.0,M1,by,", "1.0,M1,bx,nan", "1.5,M2,bz,2e-9", "1.7,M1,bz,3e-9"]
    times, y = read_recording(_write(tmp_path, rows), sc)
    np.testing.assert_allclose(times, [0.0, 1.0, 1.5, 1.7])   # irregular: every distinct time is a sample
    assert y[0, 0] == 1e-9 and np.isnan(y[0, 1]) and np.isnan(y[1, 0]) and np.isnan(y[1]).all()
    assert y[2, 5] == 2e-9 and y[3, 2] == 3e-9 and np.isnan(y[3, :2]).all()


def test_rows_in_any_order_read_as_the_sorted_file(tmp_path):
    sim = simulate("S2", runs=1, seed=3)
    path = tmp_path / "rec.csv"
    tidy_csv.write(sim, path)
    header, *rows = path.read_text().splitlines()
    by_sensor = sorted(rows, key=lambda r: (r.split(",")[-3], float(r.split(",")[-4])))   # sensor by sensor
    shuffled = tmp_path / "shuffled.csv"
    shuffled.write_text("\n".join([header, *by_sensor[::-1]]) + "\n")
    for t1, y1 in (read_recording(shuffled, sim.scenario),):
        t0, y0 = read_recording(path, sim.scenario)
        np.testing.assert_array_equal(t1, t0)
        np.testing.assert_array_equal(y1, y0)


@pytest.mark.parametrize("rows, header, message", [
    (["0.0,X9,bx,1e-9"], None, "unknown sensor id 'X9'"),
    (["0.0,M1,ex,1e-9"], None, "has no channel 'ex'"),
    (["0.5,M1,bx,1e-9", "0.0,M1,by,1e-9", "0.5,M1,bx,2e-9"], None, "lines 2 and 4: the same sample twice"),
    (["inf,M1,bx,1e-9"], None, "time must be finite"),
    (["0.0,M1,bx,abc"], None, "is not a number"),
    (["0.0,M1,bx,1e-9"], "t,sensor,channel,value", "header must contain"),
    (["0,0.0,M1,bx,1e-9", "1,0.0,M1,by,1e-9"], "run,time,sensor,channel,value", "several runs"),
])
def test_bad_recordings_give_one_clear_message(tmp_path, rows, header, message):
    sc = load_scenario("S2")
    path = _write(tmp_path, rows, header or "time,sensor,channel,value")
    with pytest.raises(RecordingError, match=message) as info:
        read_recording(path, sc)
    assert str(path) in str(info.value)


@pytest.mark.parametrize("rows, message", [
    (["0.5,M1,bx,1e-9", "0.500000001,M1,bx,2e-9"], "lines 2 and 3: two samples 1e-09 s apart"),
    (["1e308,M1,bx,1e-9"], "beyond"),
    (["0.0,M1,bx," + "1" * 200_000], "not a CSV row"),
])
def test_near_duplicates_absurd_times_and_huge_fields_are_refused(tmp_path, rows, message):
    with pytest.raises(RecordingError, match=message):
        read_recording(_write(tmp_path, rows), load_scenario("S2"))


@pytest.mark.parametrize("encoding, ok", [("utf-8", True), ("utf-8-sig", True), ("utf-16", False),
                                          ("latin-1", None)])
def test_utf8_with_or_without_a_bom_reads_and_other_encodings_are_named(tmp_path, encoding, ok):
    """UTF-8 with a byte-order mark reads like UTF-8 (its header was not recognised); UTF-16 is refused as not
    UTF-8; Latin-1 reads when it is plain ASCII and is refused as not UTF-8 when it is not."""
    sc = load_scenario("S2")
    path = tmp_path / "r.csv"
    text = "time,sensor,channel,value\n0.0,M1,bx,1e-9\n"
    if ok is None:   # Latin-1 with a non-ASCII byte (a comment column)
        text = "time,sensor,channel,value,note\n0.0,M1,bx,1e-9,caf\u00e9\n"
    path.write_bytes(text.encode(encoding))
    if ok:
        times, y = read_recording(path, sc)
        assert times.tolist() == [0.0] and y[0, 0] == 1e-9
    else:
        with pytest.raises(RecordingError, match="not UTF-8"):
            read_recording(path, sc)
