"""The studies' bank tally: run chunk by run chunk, it keeps what the full record would give; their output
folder draws the figures last."""

import json
import subprocess
import sys

import numpy as np
import pytest

from shipsense.config import load_scenario
from shipsense.models.field_model import model_from_scenario
from shipsense.reproduce import common
from shipsense.reproduce.common import LEAN, Output, Stages, bank_summary, bank_tally, finish, rmse_plot, run_chunks
from shipsense.simulator import simulate
from shipsense.trackers.bank.bank import run_bank
from shipsense.trackers.bank.seeding import seed_hypotheses
from shipsense.trackers.metrics import mrmse, trmse


@pytest.fixture(scope="module")
def s0_runs():
    sc = load_scenario("S0")
    model = model_from_scenario(sc)
    sim = simulate(sc, runs=5, seed=4)
    seeds, P0 = seed_hypotheses(model, sim.measurements[:, 0], sc.tracker.bank)
    return model, sim.measurements[:, :80], model.state_from_truth(sim.truth)[:, :80], seeds, P0


def test_run_chunks_cover_the_runs_once():
    assert run_chunks(5, 2) == [slice(0, 2), slice(2, 4), slice(4, 5)]
    assert run_chunks(0, 3) == []
    with pytest.raises(ValueError, match="chunk must be at least 1 run, got 0"):
        run_chunks(5, 0)


def test_a_tally_in_chunks_equals_the_whole_banks_record(s0_runs):
    model, y, truth, seeds, P0 = s0_runs
    whole = run_bank("ukf", model, y, seeds, P0, store=LEAN)
    tally = bank_tally("ukf", model, y, seeds, P0, truth, chunk=2)                # chunks of 2, 2 and 1 runs
    assert tally.runs == 5
    np.testing.assert_array_equal(tally.final_loglik, whole.cum_loglik[:, :, -1])
    np.testing.assert_array_equal(tally.selected_means, whole.selected_means)
    np.testing.assert_array_equal(tally.selected_last, whole.selected[:, -1])
    np.testing.assert_array_equal(tally.trmse, trmse(whole.positions, truth[:, None]))
    for h in range(seeds.shape[1]):                                             # MRMSE from the summed squares
        want = mrmse(whole.positions[:, h], truth)
        got = tally.mrmse(h)
        assert got.keys() == want.keys()
        np.testing.assert_allclose([got[k] for k in want], [want[k] for k in want], rtol=1e-12)
    a, tr_a = bank_summary(whole, truth)
    b, tr_b = bank_summary(tally, truth)
    np.testing.assert_array_equal(tr_a, tr_b)
    assert a == b


def test_a_tally_takes_every_initial_covariance_shape_the_bank_takes(s0_runs):
    """``P0`` shared (n, n), per hypothesis (H, n, n) or per run and hypothesis (R, H, n, n): the same tally
    (the bank broadcasts them alike); no runs is refused."""
    model, y, truth, seeds, P0 = s0_runs
    y, truth, seeds = y[:, :30], truth[:, :30], seeds[:, :4]
    want = bank_tally("ukf", model, y, seeds, P0, truth, chunk=2)
    for shape in ((4,), (5, 4)):
        got = bank_tally("ukf", model, y, seeds, np.broadcast_to(P0, shape + P0.shape), truth, chunk=2)
        np.testing.assert_array_equal(got.trmse, want.trmse)
        np.testing.assert_array_equal(got.selected_means, want.selected_means)
    with pytest.raises(ValueError, match="at least one run"):
        bank_tally("ukf", model, y[:0], seeds[:0], P0, truth[:0])


def test_the_studies_draw_their_figures_last_and_import_matplotlib_only_then(tmp_path, monkeypatch):
    # (a fresh process: this one may have imported matplotlib already)
    code = ("import sys, shipsense.reproduce, shipsense.reproduce.s0, shipsense.reproduce.s1, "
            "shipsense.reproduce.s2, shipsense.reproduce.wide; print('matplotlib' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True).stdout.strip() == "False"
    events = []
    monkeypatch.setattr(common, "release_free_memory", lambda: events.append("heap given back"))
    o = Output(tmp_path / "out")
    t = np.linspace(0.0, 10.0, 11)
    path = rmse_plot(o, "curves.png", "a title", t, {"a": 1.0 + t, "b": 2.0 + t})
    assert path == tmp_path / "out" / "curves.png" and not path.exists() and o.files == []
    o.figure("other.png", lambda: events.append("drawn") or common._rmse_plot("b", t, {"c": t + 1.0}, "m"))
    assert events == []
    summary = finish(o, Stages(["runs", "figures"], "test", enabled=False), {"answer": 42, "seconds": None})
    assert events == ["heap given back", "drawn"]                   # the heap given back first
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert o.files == [path, tmp_path / "out" / "other.png", tmp_path / "out" / "summary.json"]
    written = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert written == summary and written["answer"] == 42 and written["seconds"] > 0.0
    o.summary({"again": True})                                      # (drawn once)
    assert events == ["heap given back", "drawn"] and len(o.files) == 4
