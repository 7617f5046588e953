"""Layout sweeps: cells and seeds, validation, determinism across schedulers, resumption, a lost worker."""

import contextlib
import os
import re
import threading
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")
pd = pytest.importorskip("pandas")

from shipsense.cli import main  # noqa: E402
from shipsense.sweep import EXAMPLE, SweepError, load_sweep, parse_sweep, run_sweep  # noqa: E402
from shipsense.sweep.cells import build_cells, derive_seed, layout_positions, make_tasks  # noqa: E402
from shipsense.sweep.spec import LayoutSpec  # noqa: E402

BASE = (Path(__file__).parents[2] / "shipsense" / "scenarios" / "S2.toml").read_text()
BASE = BASE.replace("steps = 80", "steps = 40").replace("period = 0.5 ", "period = 1.0 ")

SWEEP = """
name = "tiny"
scenario = "base.toml"
template = "M1"
seed = 3
passages = {passages}
chunk = {chunk}
method = "bank"
metrics = {metrics}
[[layouts]]
name = "pair"
generator = "line"
n = 2
angle_deg = 0.0
[[layouts]]
name = "triangle"
generator = "triangle"
[conditions]
noise_scale = [1.0, 3.0]
"""


def _sweep(tmp_path, passages=4, chunk=2, metrics='["convergence", "rmse", "nees_coverage"]', name="sweep.toml"):
    (tmp_path / "base.toml").write_text(BASE)
    path = tmp_path / name
    path.write_text(SWEEP.format(passages=passages, chunk=chunk, metrics=metrics))
    return path


def _table(out):
    df = pd.read_parquet(Path(out) / "results.parquet")
    return df[df.metric != "seconds_per_passage"].reset_index(drop=True)   # time is the machine's, not the task's


def test_generated_layouts_have_their_shape():
    line = layout_positions(LayoutSpec(name="l", generator="line", n=4, spacing=7.0, angle_deg=90.0), -2.0)
    np.testing.assert_allclose(np.diff(line[:, 1]), 7.0)
    np.testing.assert_allclose(line[:, [0, 2]], [[0.0, -2.0]] * 4, atol=1e-12)
    tri = layout_positions(LayoutSpec(name="t", generator="triangle", side=10.0, center=(3.0, -1.0)), -15.0)
    sides = np.linalg.norm(tri - np.roll(tri, 1, axis=0), axis=1)
    np.testing.assert_allclose(sides, 10.0)
    np.testing.assert_allclose(tri[:, :2].mean(axis=0), [3.0, -1.0], atol=1e-12)
    grid = layout_positions(LayoutSpec(name="g", generator="grid", shape=(3, 2), spacing=5.0), 0.0)
    assert len(grid) == 6 and len({tuple(p) for p in grid.round(9)}) == 6


def test_cells_and_seeds_are_stable_and_distinct(tmp_path):
    spec, base = load_sweep(_sweep(tmp_path))
    cells = build_cells(spec, base)
    assert [(c.layout, c.condition["noise_scale"]) for c in cells] == [("pair", 1.0), ("pair", 3.0),
                                                                      ("triangle", 1.0), ("triangle", 3.0)]
    # the noise condition scales each sensor's variance by its square; sensors are the layout's
    assert cells[1].scenario["sensors"][0]["noise_var"] == pytest.approx(9 * 2.5e-19)
    assert [s["id"] for s in cells[2].scenario["sensors"]] == ["triangle-1", "triangle-2", "triangle-3"]
    tasks = make_tasks(spec, cells)
    # common random numbers: the layouts under one condition share their draws, the conditions do not
    seeds = {(t.cell.layout, t.cell.condition["noise_scale"], t.chunk): t.seed for t in tasks}
    assert seeds["pair", 1.0, 0] == seeds["triangle", 1.0, 0] != seeds["pair", 3.0, 0] != seeds["pair", 1.0, 1]
    assert len(set(seeds.values())) == 4
    # a cell's key and seeds do not depend on the other cells of the sweep
    spec1 = parse_sweep({**tomllib.loads((tmp_path / "sweep.toml").read_text()), "layouts": [
        {"name": "triangle", "generator": "triangle"}]})
    again = build_cells(spec1, base)
    assert again[0].key == cells[2].key
    assert derive_seed(3, cells[2].draws, 1) == tasks[5].seed


def test_a_cell_key_is_what_its_results_are_not_the_scenario_prose(tmp_path):
    """Editing the base scenario's description keeps every cell's key (and so its finished tasks); editing a
    value that changes the results (the prior's start ranges) changes them all."""
    spec, base = load_sweep(_sweep(tmp_path))
    keys = [c.key for c in build_cells(spec, base)]
    text = (tmp_path / "base.toml").read_text()
    assert 'description = """' in text
    (tmp_path / "base.toml").write_text(text.replace('description = """', 'description = """Reworded. ', 1))
    reworded = build_cells(spec, base)
    assert [c.key for c in reworded] == keys
    assert reworded[0].scenario["description"].startswith("Reworded. ")      # (the cell still carries it)
    assert "range = [60.0, 120.0]" in text
    (tmp_path / "base.toml").write_text(text.replace("range = [60.0, 120.0]", "range = [70.0, 120.0]", 1))
    farther = [c.key for c in build_cells(spec, base)]
    assert not set(farther) & set(keys)


@pytest.mark.parametrize("change, message", [
    ({"layouts": [{"name": "x", "file": "nope.toml"}]}, r"layouts\['x'\]\.file|nope\.toml: no such file"),
    ({"conditions": {"noise_scale": []}}, r"conditions\.noise_scale: an empty list"),
    ({"conditions": {"salinity": [1.0]}}, r"conditions\.salinity: unknown condition"),
    ({"conditions": {"noise_scale": ["2"]}}, r"conditions\.noise_scale: each value must be a finite number"),
    ({"conditions": {"water_depth": [1.5]}}, r"layout 'pair' under \{'water_depth': 1\.5\}"),
    ({"conditions": {"prior_range": [[300.0, 100.0]]}}, r"conditions\.prior_range: \[min, max\]"),
    ({"conditions": {"manoeuvre_probability": [1.5]}}, r"conditions\.manoeuvre_probability: 1\.5 is outside"),
    ({"passages": "8"}, r"passages: expected int"),
    ({"chunk": 0}, r"chunk: "),
    ({"template": "Q9"}, r"template: 'Q9' is not a sensor"),
    ({"combine": "list", "conditions": {"noise_scale": [1.0, 2.0], "source_scale": [1.0]}}, r"combine = 'list'"),
    ({"layouts": [{"name": "a", "generator": "line"}, {"name": "a", "generator": "triangle"}]}, r"names must be"),
    ({"methd": "bank"}, r"methd: unknown key"),
])
def test_bad_sweeps_are_refused_naming_the_field(tmp_path, change, message):
    data = {**tomllib.loads(_sweep(tmp_path).read_text()), **change}
    with pytest.raises(SweepError, match=message):
        build_cells(parse_sweep(data, "sweep.toml"), tmp_path)


def test_serial_one_and_two_workers_give_identical_tables(tmp_path):
    from distributed import Client, LocalCluster

    spec, base = load_sweep(_sweep(tmp_path))
    run_sweep(spec, base, tmp_path / "serial", workers=0, log=lambda *a: None)
    reference = _table(tmp_path / "serial")
    assert set(reference.metric) == {"convergence_rate", "rmse_m", "nees_mean", "nees_coverage"}
    assert len(reference) == 4 * 4
    for n in (1, 2):
        with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
                Client(cluster) as client:
            run_sweep(spec, base, tmp_path / f"dask{n}", client=client, log=lambda *a: None)
        pd.testing.assert_frame_equal(_table(tmp_path / f"dask{n}"), reference, check_exact=True)


def test_rerun_skips_finished_chunks_and_another_sweep_is_refused(tmp_path):
    path = _sweep(tmp_path)
    spec, base = load_sweep(path)
    out = tmp_path / "out"
    first = run_sweep(spec, base, out, workers=0, log=lambda *a: None)
    assert (first.ran, first.skipped) == (8, 0)
    reference = _table(out)
    victim = sorted((out / "chunks").glob("*.parquet"))[3]
    victim.unlink()
    again = run_sweep(spec, base, out, workers=0, log=lambda *a: None)
    assert (again.ran, again.skipped) == (1, 7) and victim.is_file()
    pd.testing.assert_frame_equal(_table(out), reference, check_exact=True)
    changed = parse_sweep({**tomllib.loads(path.read_text()), "seed": 4})
    with pytest.raises(SweepError, match="holds the results of another sweep"):
        run_sweep(changed, base, out, workers=0, log=lambda *a: None)
    run_sweep(changed, base, out, workers=0, restart=True, log=lambda *a: None)
    assert not _table(out).equals(reference)
    (tmp_path / "stranger").mkdir()
    (tmp_path / "stranger" / "notes.txt").write_text("mine")
    with pytest.raises(SweepError, match="holds no sweep.json"):
        run_sweep(spec, base, tmp_path / "stranger", workers=0, log=lambda *a: None)


def test_a_worker_killed_mid_sweep_loses_and_duplicates_no_rows(tmp_path):
    from distributed import Client, LocalCluster

    spec, base = load_sweep(_sweep(tmp_path, passages=6, chunk=1))
    run_sweep(spec, base, tmp_path / "serial", workers=0, log=lambda *a: None)
    out = tmp_path / "out"
    killed = []

    def kill_one(client):
        while not any((out / "chunks").glob("*.parquet")):
            time.sleep(0.05)
        worker = next(iter(client.scheduler_info()["workers"]))
        killed.append(worker)
        with contextlib.suppress(Exception):   # the process dies before it can answer; its nanny restarts it
            client.run(os._exit, 1, workers=[worker])

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        killer = threading.Thread(target=kill_one, args=(client,), daemon=True)
        killer.start()
        run_sweep(spec, base, out, client=client, log=lambda *a: None)
        killer.join(timeout=30)
    assert killed
    passages = pd.read_parquet(out / "passages.parquet")
    assert len(passages) == 4 * 6 and not passages.duplicated(["cell", "passage"]).any()
    pd.testing.assert_frame_equal(_table(out), _table(tmp_path / "serial"), check_exact=True)


def test_command_line(tmp_path, capsys):
    assert main(["sweep", "--example"]) == 0
    example = capsys.readouterr().out
    assert example == EXAMPLE
    spec = parse_sweep(tomllib.loads(example))
    assert 80 <= len(build_cells(spec, tmp_path)) <= 120
    path = _sweep(tmp_path, metrics='["convergence", "ambiguity"]')
    assert main(["sweep", str(path), "--out", str(tmp_path / "out"), "--workers", "0", "--csv", "--quiet"]) == 0
    results = pd.read_csv(tmp_path / "out" / "results.csv")
    assert set(results.metric) == {"convergence_rate", "ambiguous", "min_chi2"}
    assert set(results.verdict) <= {"observable", "ambiguous", "degenerate"}
    for png in (tmp_path / "out").glob("*.png"):
        png.unlink()
    assert main(["sweep", "--report", str(tmp_path / "out")]) == 0
    assert (tmp_path / "out" / "convergence_rate.png").is_file()
    capsys.readouterr()
    for argv, message in [
        (["sweep", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "x")], "cannot read the sweep file"),
        (["sweep", str(path)], "give SWEEP.toml and --out DIR"),
        (["sweep", "--report", str(tmp_path)], "no finished sweep here"),
        (["sweep", str(path), "--out", str(tmp_path / "out2"), "--workers", "-1"], "--workers: must be"),
    ]:
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert re.search(re.escape(message), err) and "Traceback" not in err
    assert not (tmp_path / "x").exists() and not (tmp_path / "out2").exists()


def test_a_manoeuvre_condition_draws_manoeuvring_passages_and_bounds_them_by_their_manoeuvres(tmp_path):
    """``manoeuvre_probability`` sets the share of passages that manoeuvre; the RMSE/CRLB column's bound is then
    conditional on each passage's true manoeuvres (a turn changes it), and the constant-velocity one without."""
    from shipsense.config import Scenario
    from shipsense.models.field_model import model_from_scenario
    from shipsense.simulator import simulate
    from shipsense.sweep.evaluate import crlb_position

    data = {**tomllib.loads(_sweep(tmp_path).read_text()), "conditions": {"manoeuvre_probability": [0.0, 1.0]}}
    cells = build_cells(parse_sweep(data, "sweep.toml"), tmp_path)
    probabilities = sorted({c.scenario["manoeuvres"]["random"]["probability"] for c in cells})
    assert probabilities == [0.0, 1.0]
    always = Scenario.model_validate(next(c.scenario for c in cells
                                          if c.scenario["manoeuvres"]["random"]["probability"] == 1.0))
    sim = simulate(always, runs=4, seed=1, random=True)
    assert (sim.manoeuvre != 0).any(axis=1).all()                            # every passage manoeuvres
    model = model_from_scenario(always)
    truth = model.state_from_truth(sim.truth)
    conditional = crlb_position(always, model, truth, sim)
    straight = crlb_position(always, model, truth)                         # the constant-velocity bound
    assert conditional.shape == straight.shape and np.isfinite(conditional).all()
    assert not np.allclose(conditional, straight, rtol=1e-3)
    never = Scenario.model_validate(next(c.scenario for c in cells
                                         if c.scenario["manoeuvres"]["random"]["probability"] == 0.0))
    quiet = simulate(never, runs=2, seed=1, random=True)
    assert not quiet.manoeuvre.any()

