"""``shipsense track --data`` on recordings: every format round trip through simulate, several recordings in one
call, passages split at long gaps, degenerate recordings drawn, and each bad input one line, exit 2, nothing
written."""

import csv
import importlib

import pytest

from shipsense.cli import main

pytest.importorskip("xarray", reason="the netcdf extra (in dev) is not installed")
pytest.importorskip("obspy", reason="the seismic extra (in dev) is not installed")


def _table(path):
    with open(path) as fh:
        return list(csv.DictReader(fh))


def test_every_format_round_trips_through_simulate_and_track_in_one_call(tmp_path, capsys):
    files = [tmp_path / name for name in ("a.csv", "b.nc", "c.h5", "d.mseed")]
    for f in files:
        assert main(["--quiet", "simulate", "S2", "--runs", "1", "--seed", "4", "--out", str(f)]) == 0
    out = tmp_path / "out"
    capsys.readouterr()
    assert main(["--quiet", "track", "S2", "--data", *map(str, files), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    summary = _table(out / "summary.csv")
    assert [r["recording"] for r in summary] == list(map(str, files))
    assert all(str(f) in printed for f in files)
    estimates = [(out / f.stem / "estimates.csv").read_text() for f in files]
    assert all(e == estimates[0] for e in estimates)    # the same passage, whatever the format
    assert all((out / f.stem / "track.png").stat().st_size > 10_000 for f in files)
    assert len({(r["x_m"], r["y_m"], r["status"]) for r in summary}) == 1


def test_a_folder_of_recordings_and_no_plot(tmp_path, capsys):
    folder = tmp_path / "recs"
    for seed in (1, 2):
        assert main(["--quiet", "simulate", "S2", "--runs", "1", "--seed", str(seed), "--random",
                     "--out", str(folder / f"p{seed}.csv")]) == 0
    (folder / "notes.txt").write_text("not a recording")
    out = tmp_path / "out"
    assert main(["--quiet", "track", "S2", "--data", str(folder), "--out", str(out), "--no-plot"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["p1", "p2", "summary.csv"]
    assert not list(out.rglob("*.png"))


def _rows(path, rows, header="time,sensor,channel,value"):
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def _passage(tmp_path, name="rec.csv"):
    path = tmp_path / name
    assert main(["--quiet", "simulate", "S2", "--runs", "1", "--out", str(path)]) == 0
    return path


@pytest.mark.parametrize("rows, header, message", [
    (["0.0,M1,bx,1e308"], None, "beyond a magnetometer's physical range"),
    (["0.0,M1,bx,1e-9,2e-9"], "time,sensor,channel,value,value", "names the column 'value' twice"),
    (["0.0,M9,bx,1e-9"], None, "unknown sensor id 'M9'"),
    (["0.0,M1,bx,1e-9", "0.0,M1,bx,1e-9"], None, "the same sample twice"),
])
def test_a_bad_recording_among_several_is_one_line_exit_2_and_nothing_written(tmp_path, capsys, rows, header,
                                                                              message):
    good = _passage(tmp_path)
    bad = _rows(tmp_path / "bad.csv", rows, header or "time,sensor,channel,value")
    out = tmp_path / "out"
    capsys.readouterr()
    assert main(["--quiet", "track", "S2", "--data", str(good), str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(bad) in err and message in err
    assert not out.exists() and [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_names_that_collide_an_empty_folder_and_a_missing_extra_are_refused(tmp_path, capsys, monkeypatch):
    (tmp_path / "x").mkdir()
    (tmp_path / "y").mkdir()
    a, b = _passage(tmp_path / "x"), _passage(tmp_path / "y")
    assert main(["--quiet", "track", "S2", "--data", str(a), str(b), "--out", str(tmp_path / "o")]) == 2
    assert "would both write to" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["--quiet", "track", "S2", "--data", str(tmp_path / "empty"), "--out", str(tmp_path / "o")]) == 2
    assert "holds no recordings" in capsys.readouterr().err
    assert main(["--quiet", "simulate", "S2", "--runs", "2", "--out", str(tmp_path / "r2.mseed")]) == 2
    assert "--runs 1" in capsys.readouterr().err
    real = importlib.import_module
    monkeypatch.setattr(importlib, "import_module",
                        lambda name, *a, **k: (_ for _ in ()).throw(ImportError(name)) if name == "obspy"
                        else real(name, *a, **k))
    assert main(["--quiet", "simulate", "S2", "--runs", "1", "--out", str(tmp_path / "r.mseed")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install 'shipsense[seismic]'" in err and not (tmp_path / "r.mseed").exists()


def test_a_day_long_gap_splits_the_recording_into_passages(tmp_path, capsys):
    rec = _passage(tmp_path)
    with open(rec, "a") as fh:
        fh.write("0,80,100000.0,M1,bx,1e-9\n")
    out = tmp_path / "out"
    capsys.readouterr()
    assert main(["--quiet", "track", "S2", "--data", str(rec), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "2 passages" in printed and "passage gap" in printed
    summary = _table(out / "summary.csv")
    assert [r["samples"] for r in summary] == ["80", "1"] and summary[0]["status"] == "tracking"
    assert float(summary[0]["end_s"]) < 100 and float(summary[1]["start_s"]) == 1e5
    assert (out / "passage-1" / "estimates.csv").exists() and (out / "passage-2" / "track.png").exists()
    # a passage gap longer than the gap: one passage, the gap predicted through and reported
    assert main(["--quiet", "track", "S2", "--data", str(rec), "--passage-gap", "1e6", "--out",
                 str(tmp_path / "one")]) == 0
    assert "gap: passage 0" in capsys.readouterr().out
    assert main(["--quiet", "track", "S2", "--data", str(rec), "--passage-gap", "-1"]) == 2


def test_degenerate_recordings_and_a_zero_moment_run_and_draw_what_there_is(tmp_path, capsys):
    rec = _passage(tmp_path)
    header, *rows = rec.read_text().splitlines()
    zero = tmp_path / "zero.csv"
    zero.write_text("\n".join([header] + [",".join(r.split(",")[:5] + ["0.0"]) for r in rows]) + "\n")
    one = tmp_path / "one.csv"
    one.write_text("\n".join([header] + rows[:7]) + "\n")
    scenario = tmp_path / "zero-moment.toml"
    from importlib import resources

    text = (resources.files("shipsense") / "scenarios" / "S2.toml").read_text()
    scenario.write_text(text.replace("moment = [1e4, 1e4, 1e4]", "moment = [0.0, 0.0, 0.0]"))
    runs = [["track", "S2", "--data", str(zero)], ["track", "S2", "--data", str(one)], ["track", str(scenario)]]
    for n, args in enumerate(runs):
        out = tmp_path / f"out{n}"
        capsys.readouterr()
        assert main(["--quiet", *args, "--out", str(out)]) == 0
        printed = capsys.readouterr().out
        assert "no estimate: the tracker did not start tracking" in printed and "position error" not in printed
        assert (out / "track.png").stat().st_size > 10_000


def test_negative_envelopes_are_refused_and_small_noise_dips_are_not(tmp_path, capsys):
    rec = tmp_path / "s1.csv"
    assert main(["--quiet", "simulate", "S1-P2", "--runs", "1", "--out", str(rec)]) == 0
    assert main(["--quiet", "track", "S1-P2", "--data", str(rec), "--out", str(tmp_path / "ok"), "--no-plot"]) == 0
    header, *rows = rec.read_text().splitlines()
    flipped = tmp_path / "flipped.csv"
    flipped.write_text("\n".join([header] + [r.replace(",1e-", ",-1e-").replace(",0.00", ",-0.00") for r in rows])
                       + "\n")
    capsys.readouterr()
    assert main(["--quiet", "track", "S1-P2", "--data", str(flipped), "--out", str(tmp_path / "no")]) == 2
    err = capsys.readouterr().err
    assert "is negative, but a envelope electrode channel is a magnitude" in err and not (tmp_path / "no").exists()
