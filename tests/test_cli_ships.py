"""``shipsense track --ships``: the several-ship tracker's table, summary and picture, simulated and recorded."""

import csv

import numpy as np

from shipsense import simulate
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
    assert not {"true_ship", "true_x", "error_m"} & set(rows[0])   # a recording: no truth
    assert (tmp_path / "t" / "track.png").stat().st_size > 10_000


def test_track_ships_of_a_simulated_crossing_gives_each_track_its_true_ship_and_error(tmp_path, capsys):
    assert main(["track", "S2-crossing", "--ships", "2", "--no-plot", "--out", str(tmp_path / "s")]) == 0
    assert "ships at the end" in capsys.readouterr().out
    assert not (tmp_path / "s" / "track.png").exists()
    rows = list(csv.DictReader((tmp_path / "s" / "estimates.csv").open()))
    header = list(rows[0])
    assert header.index("std_y") < header.index("true_ship") < header.index("error_m") < header.index("cov_xx")
    sim = simulate("S2-crossing", runs=1)                      # the passage track simulated (the scenario's seed)
    k = {f"{t:.6g}": i for i, t in enumerate(sim.times)}
    matched = {}
    for r in rows:
        j = int(r["true_ship"])
        matched.setdefault(r["ship"], set()).add(j)
        true = sim.ships[0, j, k[r["time"]], :2]
        np.testing.assert_allclose([float(r["true_x"]), float(r["true_y"])], true, rtol=1e-5, atol=1e-4)
        err = np.hypot(float(r["x"]) - true[0], float(r["y"]) - true[1])
        np.testing.assert_allclose(float(r["error_m"]), err, rtol=1e-3, atol=1e-3)
    # each track follows one true ship, the two tracks different ones, and it is near that ship at the end
    assert sorted(matched) == ["1", "2"] and all(len(v) == 1 for v in matched.values())
    assert matched["1"] != matched["2"]
    for ship in ("1", "2"):
        errors = [float(r["error_m"]) for r in rows if r["ship"] == ship]
        assert np.median(errors[len(errors) // 2:]) < 5.0


def test_track_ships_refuses_the_bank_and_leaves_nothing(tmp_path, capsys):
    assert main(["track", "S2-crossing", "--ships", "auto", "--method", "bank", "--out", str(tmp_path / "n")]) == 2
    assert "--ships 2|auto" in capsys.readouterr().err
    assert not (tmp_path / "n").exists()
