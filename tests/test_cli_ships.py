"""``shipsense track --ships``: the several-ship tracker's table, summary and picture, simulated and recorded."""

import csv

from shipsense.cli import main


def test_track_ships_writes_one_row_per_track_and_sample(tmp_path, capsys):
    rec = tmp_path / "rec.csv"
    assert main(["simulate", "S2-crossing", "--runs", "1", "--out", str(rec)]) == 0
    capsys.readouterr()
    assert main(["track", "S2-crossing", "--data", str(rec), "--ships", "auto", "--out", str(tmp_path / "t")]) == 0
    out = capsys.readouterr().out
    assert "several-ship tracker" in out and "ships at the end: 2" in out
    assert "ship 1 (" in out and "ship 2 (" in out
    rows = list(csv.DictReader((tmp_path / "t" / "estimates.csv").open()))
    assert {"time", "ship", "x", "y", "std_x", "cov_xx", "cov_xy", "cov_yy", "status"} <= set(rows[0])
    ids = {r["ship"] for r in rows}
    assert ids == {"1", "2"}
    for ship in ids:                                     # one row per track and sample: no time twice per track
        times = [r["time"] for r in rows if r["ship"] == ship]
        assert len(times) == len(set(times)) > 20
    assert (tmp_path / "t" / "track.png").stat().st_size > 10_000
    assert main(["track", "S2-crossing", "--ships", "2", "--no-plot", "--out", str(tmp_path / "s")]) == 0
    assert "ships at the end" in capsys.readouterr().out
    assert (tmp_path / "s" / "estimates.csv").exists() and not (tmp_path / "s" / "track.png").exists()


def test_track_ships_refuses_the_bank_and_leaves_nothing(tmp_path, capsys):
    assert main(["track", "S2-crossing", "--ships", "auto", "--method", "bank", "--out", str(tmp_path / "n")]) == 2
    assert "--ships 2|auto" in capsys.readouterr().err
    assert not (tmp_path / "n").exists()
