"""Command line: the documented commands, outputs and exit codes."""

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

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
    bad.write_text('period = 0.5\nsteps = "many"\n')
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


def test_track_a_simulated_and_a_recorded_passage(tmp_path, capsys):
    assert main(["track", "S1-P2", "--out", str(tmp_path / "sim")]) == 0
    out = capsys.readouterr().out
    assert "the project's tracker" in out and "position error" in out
    est = list(csv.DictReader((tmp_path / "sim" / "estimates.csv").open()))
    assert len(est) == 101 and float(est[-1]["error_m"]) < 1.0
    assert {"cov_xx", "cov_xy", "cov_yy", "status", "std_x", "selected", "error_m"} <= set(est[0])
    assert est[0]["status"] == "initialising" and est[-1]["status"] in ("tracking", "restarted")
    assert float(est[-1]["std_x"]) ** 2 == pytest.approx(float(est[-1]["cov_xx"]), rel=1e-3)
    assert (tmp_path / "sim" / "track.png").stat().st_size > 10_000
    assert main(["track", "S1-P2", "--method", "bank", "--filter", "ukf", "--out", str(tmp_path / "bank")]) == 0
    assert "the studies' bank of 12 hypotheses (ukf)" in capsys.readouterr().out
    rec = tmp_path / "rec.csv"
    assert main(["simulate", "S2", "--runs", "1", "--out", str(rec)]) == 0
    header, *rows = rec.read_text().splitlines()
    rec.write_text("\n".join([header, *rows[:60], *rows[200:]]) + "\n")   # a gap of about 20 samples (10 s)
    assert main(["track", "S2", "--data", str(rec), "--out", str(tmp_path / "rec")]) == 0
    out = capsys.readouterr().out
    assert "values missing" in out and "gap: passage 0: no sample for" in out and "predicted through" in out
    log = list(csv.DictReader((tmp_path / "rec" / "selection_log.csv").open()))
    assert len(log) == len({r.split(",")[2] for r in [*rows[:60], *rows[200:]]})   # one line per distinct time
    assert set(log[0]) == {"time", "status", "selected", "hypotheses", "gap_to_second_nats", "ambiguous"}
    # rows in any order (here sensor by sensor, as concatenated logs come) give the same track
    shuffled = tmp_path / "shuffled.csv"
    shuffled.write_text("\n".join([header, *sorted(rows[:60] + rows[200:], key=lambda r: r.split(",")[3])]) + "\n")
    assert main(["track", "S2", "--data", str(shuffled), "--out", str(tmp_path / "shuffled")]) == 0
    assert (tmp_path / "shuffled" / "estimates.csv").read_text() == (tmp_path / "rec" / "estimates.csv").read_text()


def test_track_bad_input_exits_2(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,sensor,channel,value\n0.0,NOPE,bx,1e-9\n")
    assert main(["track", "S2", "--data", str(bad), "--out", str(tmp_path / "never")]) == 2
    assert not (tmp_path / "never").exists()              # a rejected input leaves no output directory
    assert "unknown sensor id" in capsys.readouterr().err
    assert main(["track", "S2", "--filter", "kalman"]) == 2


def test_reproduce_writes_the_documented_summary_keys(tmp_path, capsys):
    import json

    keys = {
        "S0": ["seed_ranges_m", "true_range_m", "basin_radius_m", "hypotheses", "selected_index", "selected_mrmse_m",
               "selection_accuracy", "convergence_rate", "filter_units"],
        "S1": ["P1", "P2", "symmetry_table", "raw_chain"],
        "S2": ["one_vs_two", "outliers", "seismic_low_snr", "field_trial_geometry", "field_trial"],
    }
    for name, expected in keys.items():
        assert main(["reproduce", name, "--runs", "3", "--out", str(tmp_path / name)]) == 0
        summary = json.loads((tmp_path / name / "summary.json").read_text())
        assert all(k in summary for k in expected), (name, set(expected) - set(summary))
    s0 = json.loads((tmp_path / "S0" / "summary.json").read_text())
    assert set(s0["hypotheses"][0]) == {"range_m", "bearing_rad", "trmse_m", "mean_loglik"}
    assert set(s0["selected_mrmse_m"]) == {"x", "y", "r"}
    assert set(s0["filter_units"]["srcdkf"]) == {"mrmse_r_m", "convergence_rate", "us_per_filter_step"}
    # the study's S0 (Q = 0.1 I in SI units, bearings from north): a seed 16 m from the truth and hypotheses
    # #11, #12, #7 on top by likelihood (its Figure 7); read from +x, no seed is within 90 m
    assert s0["bearing_convention"] == "north" and s0["loglik_top3"] == [11, 12, 7]
    assert 15.0 < s0["seed_nearest_m"] < 17.0 and s0["bearing_conventions"]["east"]["seed_nearest_m"] > 90.0
    assert s0["seed_nearest_m"] < s0["basin_radius_m"] and s0["seed_inside_basin_rate"] == 1.0   # inside the basin
    assert s0["top3_mrmse_m"][0]["hypothesis"] == 11 and s0["top3_mrmse_m"][0]["r"] < 10.0
    s1 = json.loads((tmp_path / "S1" / "summary.json").read_text())
    assert {"hypotheses", "selection_accuracy", "ambiguous_pairs"} <= set(s1["P1"])
    assert set(s1["raw_chain"]) >= {"ideal_mrmse_r_m", "raw_mrmse_r_m"}
    # the study's S1: on P2 hypotheses #3, #7, #11 converge and the other nine diverge; on the collinear P1
    # #4, #8, #12 reach the mirror track
    assert s1["P2"]["converged_hypotheses"] == [3, 7, 11] and s1["P1"]["mirror_hypotheses"] == [4, 8, 12]
    assert s1["P2"]["mirror_hypotheses"] == []
    # a sensor at the origin cannot tell passages mirrored about either axis; one on an axis, about that axis
    groups = {(r["sensor"], r["channel"]): r["identical_passages"] for r in s1["symmetry_table"]}
    for ch in ("ex", "ey", "ez"):
        assert groups[("(0,0)", ch)] == [[1, 2, 3, 4]]
        assert groups[("(0,5)", ch)] == [[1, 2], [3, 4]] and groups[("(5,0)", ch)] == [[1, 4], [2, 3]]
    # the project's tracker (global initialiser + the scenario's unit) tracks S0 and S1-P2 to a few metres
    assert s0["global_init"]["final_error_median_m"] < 3.0 and s0["global_init"]["convergence_rate"] == 1.0
    assert s1["P2_global_init"]["final_error_median_m"] < 3.0 and s1["P2_global_init"]["convergence_rate"] == 1.0
    s2 = json.loads((tmp_path / "S2" / "summary.json").read_text())
    assert set(s2["one_vs_two"]["ekf"]) >= {"one_mrmse_r_m", "two_mrmse_r_m"}
    assert set(s2["outliers"]["0.1"]) == {"ukf_mrmse_r_m", "huber_ukf_mrmse_r_m"}
    assert {"magnetic_only_mrmse_r_m", "fused_mrmse_r_m"} <= set(s2["seismic_low_snr"])
    # the study's outlier ordering: the Huber UKF (its Figure 4 filter) beats the UKF once there are outliers
    assert s2["seismic_low_snr"]["filter"] == "huber_ukf"
    assert all(s2["outliers"][e]["huber_ukf_mrmse_r_m"] < s2["outliers"][e]["ukf_mrmse_r_m"] for e in ("0.1", "0.2"))
    low = s2["seismic_low_snr"]
    assert low["with_outliers"]["magnetic_only_mrmse_r_m"] < low["ukf"]["with_outliers"]["magnetic_only_mrmse_r_m"]
    # the study's field-trial findings (one passage per road): magnetic tracking within ~5 m near the closest
    # approach; misalignment a main error source; bearings biased by 20 degrees worse than magnetic-only
    trial = s2["field_trial"]
    mag = trial["bias_deg"]["0"]["magnetic_only"]
    assert mag["error_near_cpa_m"] < 5.0
    assert mag["error_near_cpa_m"] > 2.0 * trial["magnetic_only_aligned"]["error_near_cpa_m"]
    assert trial["bias_deg"]["20"]["fused"]["error_near_cpa_m"] > 2.0 * mag["error_near_cpa_m"]
    # each study is a task on the sweep's path: a finished one is skipped when the same command runs again
    assert json.loads((tmp_path / "S2" / "run.json").read_text()) == {"study": "S2", "runs": 3, "seed": 0}
    capsys.readouterr()
    assert main(["reproduce", "S2", "--runs", "3", "--out", str(tmp_path / "S2")]) == 0
    assert "1 of 1 studies already finished" in capsys.readouterr().out
    assert json.loads((tmp_path / "S2" / "summary.json").read_text()) == s2
    assert main(["reproduce", "S9"]) == 2


def test_reproduce_wide_writes_the_documented_summary_keys(tmp_path):
    import json

    assert main(["reproduce", "wide", "--runs", "4", "--workers", "0", "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    for family in ("one_magnetometer", "two_magnetometers", "envelope_p2"):
        for method in ("miv_bank", "global_init", "global_init_refit", "global_init_restarts"):
            assert {"convergence_rate", "mrmse_r_m", "rmse_over_pcrlb", "rmse_over_crlb_tracking", "nees_mean",
                    "seconds_per_passage"} <= set(summary[family][method])
    parts = ("consistency", "consistency_dwna", "consistency_default_process_noise")
    for c in (summary[part][name] for part in parts for name in ("S0", "S1-P2", "S2")):
        lo, hi = c["band"]
        assert 0 < lo < 2 < hi and c["consistent"] == (c["nees_mean"] is not None and lo <= c["nees_mean"] <= hi)


def _figures(summary):
    """A wide summary without its timings."""
    if isinstance(summary, dict):
        return {k: _figures(v) for k, v in summary.items() if "seconds" not in k and k != "tasks_resumed"}
    return summary


def test_reproduce_wide_runs_on_the_sweep_path_chunked_resumable_and_schedule_free(tmp_path, capsys):
    """The wide study runs as the sweep does: chunks with their own seeds, so serial and two Dask workers give
    the same figures; finished chunks are skipped when rerun (one deleted chunk is the only one run again);
    another run's chunks are refused; the options belong to the wide study only."""
    import json

    from shipsense.reproduce import wide

    serial = wide.run(runs=4, out=tmp_path / "serial", chunk=2, progress=False)
    dask = wide.run(runs=4, out=tmp_path / "dask", chunk=2, progress=False, workers=2)
    assert _figures(serial) == _figures(dask)
    # pooling chunks is exact: the pooled bound from summed information equals the one from all passages
    assert serial["two_magnetometers"]["miv_bank"]["rmse_over_pcrlb_pooled"] is not None
    (tmp_path / "serial" / "chunks" / "envelope_p2-c0001.npz").unlink()
    again = wide.run(runs=4, out=tmp_path / "serial", chunk=2, progress=False)
    assert "14 already finished" in capsys.readouterr().out and _figures(again) == _figures(serial)
    assert json.loads((tmp_path / "serial" / "summary.json").read_text())["tasks_resumed"] == 14
    assert main(["reproduce", "wide", "--runs", "6", "--workers", "0", "--out", str(tmp_path / "serial")]) == 2
    assert "another wide-study run" in capsys.readouterr().err
def test_check_exit_codes_and_json(capsys):
    import json

    assert main(["check", "S1-P2", "--json", "--passages", "2"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data) >= {"verdict", "min_chi2", "pairs", "fim_rank", "fim_condition", "resolvability"}
    assert data["verdict"] == "observable"
    res = data["resolvability"]
    assert res["share"] == 0.9 and len(res["per_draw_m"]) == 2 and res["separation_m"] == max(res["per_draw_m"])
    assert main(["check", "S1-P1", "--json", "--passages", "2"]) == 3
    data = json.loads(capsys.readouterr().out)
    assert data["verdict"] == "ambiguous" and data["pairs"]
    assert main(["check", "no-such-layout.toml"]) == 2


def test_design_writes_a_layout_that_check_accepts(tmp_path, capsys):
    out = tmp_path / "design"
    assert main(["design", "S1-P2", "--k", "3", "--passages", "4", "--bb-seconds", "1", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["bounds.png", "design.json", "design.png", "layout.toml"]
    import json

    report = json.loads((out / "design.json").read_text())
    assert report["certified_gap"] >= 0 and report["verdict"] == "observable" and len(report["sensors"]) == 3
    assert main(["check", str(out / "layout.toml"), "--passages", "2"]) == 0
    cands = tmp_path / "cands.csv"
    cands.write_text("x,y,cost\n" + "\n".join(f"{x},{y},{1 + (x > 0)}" for x in (-20, 0, 20) for y in (-20, 0, 20)))
    assert main(["design", "S1-P2", "--k", "3", "--candidates", str(cands), "--budget", "4", "--passages", "3",
                 "--out", str(tmp_path / "cheap")]) == 0
    cheap = json.loads((tmp_path / "cheap" / "design.json").read_text())
    assert sum(1 + (p[0] > 0) for p in cheap["sensors"]) <= 4
    capsys.readouterr()
    assert main(["design", "S1-P2", "--k", "3", "--candidates", str(cands), "--out", str(tmp_path / "x")]) == 2
    assert "budget" in capsys.readouterr().err                            # costs without a budget
    assert main(["design", "S1-P2", "--k", "3", "--out", str(tmp_path / "x.toml")]) == 2   # --out is a folder
    assert "--out is the report folder" in capsys.readouterr().err
    assert main(["design", "S1-P2", "--k", "0"]) == 2
    assert main(["design", "S1-P2", "--k", "3", "--criterion", "Z"]) == 2


def test_train_scheduling_writes_a_model_and_an_evaluation(tmp_path):
    import json

    import pytest

    pytest.importorskip("stable_baselines3")
    assert main(["--quiet", "train", "scheduling", "--timesteps", "128", "--n-envs", "2", "--eval-episodes", "1",
                 "--eval-every", "128", "--imitate", "none", "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "evaluation.json").read_text())
    assert summary["algorithm"] == "PPO" and summary["env"] == "shipsense/Passage-v1"
    assert summary["env_kwargs"] == {} and summary["shaping"] == 1.0 and summary["imitate_policy"] is None
    assert summary["timesteps"] >= 128 and np.isfinite(summary["best"]["return"]["mean"])
    assert (tmp_path / "best_model.zip").is_file() and (tmp_path / "learning_curve.png").is_file()


def test_an_unexpected_error_is_one_line_and_debug_shows_the_traceback(monkeypatch, capsys):
    from shipsense.cli import common, parser

    def broken(args):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(parser, "cmd_scenarios", broken)
    assert main(["scenarios"]) == common.EXIT_INTERNAL
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "internal error: ZeroDivisionError: a bug" in err and "--debug" in err
    with pytest.raises(ZeroDivisionError):
        main(["--debug", "scenarios"])


def test_import_shipsense_is_light_and_its_names_arrive_on_use():
    """``import shipsense`` registers the environments and imports neither the simulator nor scipy.signal; the
    public names load on first use (benchmarks/import_time.py measures the time)."""
    code = ("import sys, shipsense, gymnasium as gym; "
            "assert 'shipsense/Passage-v1' in gym.registry; "
            "assert 'scipy.signal' not in sys.modules and 'shipsense.simulator' not in sys.modules; "
            "assert callable(shipsense.simulate) and shipsense.load_scenario('S2').name == 'S2'; "
            "from shipsense import Scenario, STATE_LABELS")
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("argv,field", [
    (["simulate", "S2", "--runs", "1e9"], "--runs"), (["simulate", "S2", "--runs", "0"], "--runs"),
    (["simulate", "S2", "--seed", "-1"], "--seed"), (["track", "S2", "--seed", "-5"], "--seed"),
    (["design", "S1-P2", "--k", "3", "--passages", "0"], "--passages"),
    (["check", "S1-P2", "--passages", "-2"], "--passages"),
    (["train", "scheduling", "--timesteps", "0"], "--timesteps"), (["reproduce", "S0", "--runs", "1"], "--runs"),
    (["sweep", "x.toml", "--out", "d", "--workers", "-1"], "--workers"),
    (["simulate", "S2", "--runs", "900000"], "--max-memory"),
    (["simulate", "S2", "--max-memory", "nan"], "--max-memory"),
    (["simulate", "S2", "--max-minutes", "-1"], "--max-minutes"),
    (["reproduce", "S0", "--runs", "1000000"], "--max-memory"),
    (["reproduce", "wide", "--runs", "40000"], "--max-minutes"),
    (["reproduce", "all", "--runs", "100000"], "--max-memory"),
    (["train", "scheduling", "--timesteps", "1000000000"], "--max-minutes"),
    (["check", "S1-P2", "--passages", "10000", "--max-minutes", "10"], "--max-minutes"),
    (["track", "S2", "--max-minutes", "1e-6"], "--max-minutes"),
    (["design", "S1-P2", "--k", "3", "--passages", "10000", "--max-minutes", "1"], "--max-minutes"),
    (["design", "S1-P2", "--k", "3", "--bb-work", "-1"], "--bb-work"),
    (["design", "S1-P2", "--k", "3", "--bb-seconds", "0"], "--bb-seconds"),
    (["check", "S1-P2", "S1-P2", "S1-P2", "--passages", "2000", "--max-minutes", "4"], "--max-minutes"),
    (["check", "S2", "--junit", f"{__file__}/x.xml"], "--junit"),      # a file as the folder
    (["simulate", "S2", "--runs", "2", "--out", f"{__file__}/x.npz"], "--out"),
    (["demo", "--out", __file__], "--out"),
])
def test_bad_counts_and_too_much_work_are_one_line_and_exit_2(argv, field, capsys):
    """Counts and seeds are checked before any work (a negative seed was a numpy error, --passages 0 a division
    by zero, --runs 1e9 a 67 GB allocation); work estimated above the memory or time limit is refused before
    anything is allocated, naming the flag that raises the limit (these cases would run for hours or days)."""
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2 and field in err and "Traceback" not in err and "internal error" not in err


def test_an_interrupted_track_leaves_no_half_table(tmp_path, monkeypatch):
    """track writes estimates.csv and selection_log.csv in blocks to partial files and renames them at the end:
    a failure half-way leaves neither the tables nor the partial files."""
    from shipsense.trackers import Tracker

    calls = {"n": 0}
    update = Tracker.update

    def failing(self, *a, **k):
        calls["n"] += 1
        if calls["n"] > 50:
            raise KeyboardInterrupt
        return update(self, *a, **k)

    monkeypatch.setattr(Tracker, "update", failing)
    out = tmp_path / "run"
    assert main(["track", "S2", "--out", str(out)]) == 130
    assert not any(p.name.endswith((".csv", ".part")) for p in out.glob("*")) if out.exists() else True


def test_check_gates_several_layouts_with_junit_and_the_worst_exit_code(tmp_path, capsys):
    """The CI gate: several files, one verdict each, the worst outcome as the exit code (ambiguous 3; a file
    that cannot be read 2, reported as an error without hiding the others) and a JUnit XML report."""
    from xml.etree import ElementTree as ET

    junit = tmp_path / "check.xml"
    assert main(["check", "S1-P2", "S1-P1", "--passages", "2", "--junit", str(junit)]) == 3
    suite = ET.parse(junit).getroot()
    assert suite.get("tests") == "2" and suite.get("failures") == "1" and suite.get("errors") == "0"
    cases = {c.get("name"): c for c in suite.iter("testcase")}
    assert cases["S1-P2"].find("failure") is None and cases["S1-P1"].find("failure").get("type") == "ambiguous"
    for case in cases.values():   # the resolvability rides along as a property, whatever the verdict
        prop = case.find("properties/property")
        assert prop.get("name") == "resolvable_separation_m" and float(prop.get("value")) > 0
        assert "two ships" in case.find("system-out").text
    capsys.readouterr()
    assert main(["check", "S1-P2", str(tmp_path / "missing.toml"), "--passages", "2", "--json",
                 "--junit", str(junit)]) == 2
    docs = json.loads(capsys.readouterr().out)
    assert [d["verdict"] for d in docs] == ["observable", "error"] and "no such file" in docs[1]["error"]
    assert ET.parse(junit).getroot().get("errors") == "1"
    assert main(["check", "S1-P2", "--junit", str(tmp_path / "check.txt")]) == 2


def test_check_of_a_line_of_magnitude_electrodes_fails_and_of_vector_electrodes_passes(tmp_path, capsys):
    from pathlib import Path

    import shipsense

    text = (Path(shipsense.__file__).parent / "scenarios" / "S1-P1.toml").read_text()
    assert text.count('kind = "envelope"') == 3
    for kind, code in (("magnitude", 3), ("vector", 0)):
        layout = tmp_path / f"line-{kind}.toml"
        layout.write_text(text.replace('kind = "envelope"', f'kind = "{kind}"'))
        assert main(["check", str(layout), "--passages", "2"]) == code, capsys.readouterr().out


def test_the_pre_commit_hook_runs_the_check():
    from pathlib import Path

    hooks = (Path(__file__).resolve().parents[1] / ".pre-commit-hooks.yaml").read_text()
    assert "id: shipsense-check" in hooks and "entry: shipsense check" in hooks and "language: python" in hooks


def test_quiet_turns_the_progress_bars_off(tmp_path):
    from shipsense.cli import common

    assert main(["--quiet", "simulate", "S2", "--runs", "1", "--out", str(tmp_path / "s.npz")]) == 0
    assert common.progress_bar(3, "x").disable is True
    assert main(["simulate", "S2", "--runs", "1", "--out", str(tmp_path / "s.npz")]) == 0
    assert common.QUIET["on"] is False


def test_the_memory_estimate_of_a_simulation_covers_what_it_allocates():
    """The budget's simulation estimate is an estimate of the arrays a simulation really holds."""
    from shipsense import budget, load_scenario, simulate

    sc = load_scenario("S2")
    sim = simulate(sc, runs=3)
    held = sum(a.nbytes for a in (sim.truth, sim.clean, sim.measurements))
    est = budget.simulation(sc, 3).bytes
    assert held <= est <= 3 * held, (held, est)


def test_a_failing_demo_leaves_nothing_behind(tmp_path, monkeypatch):
    """demo stages its files and moves them in only when all are written: a failure in the last plot leaves
    neither the output folder's tables nor a staging folder."""
    import shipsense.plotting

    def broken(*a, **k):
        raise RuntimeError("plot failed")

    monkeypatch.setattr(shipsense.plotting, "plot_track", broken)
    out = tmp_path / "demo"
    assert main(["--quiet", "demo", "--out", str(out)]) == 1
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_a_failing_simulate_plot_leaves_neither_file(tmp_path, monkeypatch):
    """simulate --out and --plot are both written or neither: a failing plot removes the measurements too."""
    import shipsense.plotting

    def broken(*a, **k):
        raise RuntimeError("plot failed")

    monkeypatch.setattr(shipsense.plotting, "plot_simulation", broken)
    assert main(["simulate", "S2", "--runs", "2", "--out", str(tmp_path / "m.npz"),
                 "--plot", str(tmp_path / "m.png")]) == 1
    assert list(tmp_path.iterdir()) == []
    assert main(["simulate", "S2", "--runs", "2", "--out", str(tmp_path / "m.npz")]) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["m.npz"]


def test_a_terminated_demo_leaves_nothing_behind(tmp_path):
    """SIGTERM (a CI cancel, `timeout`) unwinds like Ctrl-C: the staged files are removed, exit 130."""
    import signal
    import time

    proc = subprocess.Popen([sys.executable, "-c", "import sys; from shipsense.cli import main; "
                             "sys.exit(main(['--quiet', 'demo', '--out', 'D']))"], cwd=tmp_path,
                            stderr=subprocess.PIPE, text=True)
    time.sleep(3.0)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    if proc.returncode == 0:   # finished before the signal: everything is there, nothing staged
        assert sorted(p.name for p in tmp_path.iterdir()) == ["D"]
    else:
        assert proc.returncode == 130 and "interrupted" in err, (proc.returncode, err)
        assert list(tmp_path.iterdir()) == []


def test_an_interruption_inside_compiled_code_is_an_interruption(monkeypatch, capsys):
    """A signal handler that raises while a numba kernel runs surfaces as a SystemError caused by the
    KeyboardInterrupt: it is reported as an interruption (exit 130), not an internal error."""
    from shipsense.cli import parser

    def interrupted_in_a_kernel(args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as err:
            raise SystemError("CPUDispatcher(<function hed_points>) returned a result with an exception set") from err

    monkeypatch.setattr(parser, "cmd_scenarios", interrupted_in_a_kernel)
    assert main(["scenarios"]) == 130
    assert "interrupted" in capsys.readouterr().err


def test_the_track_figure_draws_the_motion_modes_when_the_tracker_has_them(tmp_path, monkeypatch):
    """With the IMM (S2-turn sets it) the figure gains a third panel, the selected hypothesis's mode
    probabilities stacked to 1 wherever a hypothesis is selected; the constant-velocity figure keeps two."""
    import matplotlib.figure

    drawn = []
    save = matplotlib.figure.Figure.savefig

    def keep(fig, *a, **k):
        drawn.append([(ax.get_title(), [c.get_paths() for c in ax.collections]) for ax in fig.axes])
        return save(fig, *a, **k)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", keep)
    assert main(["--quiet", "track", "S2-turn", "--out", str(tmp_path / "turn")]) == 0
    assert main(["--quiet", "track", "S2", "--out", str(tmp_path / "straight")]) == 0
    turn, straight = drawn[-2], drawn[-1]
    assert len(straight) == 2 and not any("motion modes" in title for title, _ in straight)
    assert len(turn) == 3
    title, bands = turn[2]
    assert "motion modes" in title and len(bands) == 4          # cv, turn left, turn right, speed
    v = bands[-1][0].vertices                                    # the last band's edges: the top is the total
    top = [v[v[:, 0] == x, 1].max() for x in np.unique(v[:, 0])]
    assert np.allclose(top, 1.0, atol=1e-6)
