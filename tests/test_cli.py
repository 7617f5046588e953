"""Command line: the documented commands, outputs and exit codes."""

import csv
import subprocess
import sys

import numpy as np

from shipsense.cli import main


def test_version_and_scenarios(capsys):
    out = subprocess.run([sys.executable, "-m", "shipsense.cli", "--version"], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.startswith("shipsense ")
    assert main(["scenarios"]) == 0
    listed = capsys.readouterr().out
    for name in ("S0", "S1-P1", "S1-P2", "S2", "S2-field-trial", "demo"):
        assert name in listed


def test_simulate_writes_npz_csv_and_plot(tmp_path, capsys):
    npz, png, tidy = tmp_path / "s.npz", tmp_path / "s.png", tmp_path / "s.csv"
    assert main(["simulate", "S2", "--runs", "2", "--seed", "1", "--out", str(npz), "--plot", str(png)]) == 0
    data = np.load(npz)
    assert data["measurements"].shape == (2, 80, 7) and png.stat().st_size > 10_000
    assert main(["simulate", "S1-P2", "--runs", "1", "--random", "--out", str(tidy)]) == 0
    rows = list(csv.DictReader(tidy.open()))
    assert len(rows) == 101 * 9 and set(rows[0]) == {"run", "step", "time", "sensor", "channel", "value"}
    assert "closest" in capsys.readouterr().out


def test_bad_input_exits_2_with_one_message(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text((tmp_path / "x").as_posix() and 'period = 0.5\nsteps = "many"\n')
    proc = subprocess.run([sys.executable, "-m", "shipsense.cli", "simulate", str(bad)],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "steps" in proc.stderr
    assert main(["simulate", "no-such-scenario"]) == 2
    assert main(["simulate", "S0", "--out", str(tmp_path / "x.txt")]) == 2
    assert main(["simulate", "S0", "--runs", "0"]) == 2


def test_demo_writes_a_picture(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "demo.png").stat().st_size > 10_000
    assert "N1-mag" in capsys.readouterr().out
