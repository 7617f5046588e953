"""The studies as tasks (shipsense.reproduce.run_studies): each study's folder is a task store -- a finished
study is skipped, another run's folder refused unless restarted, an interrupted one run again.  The study
itself is a stand-in here (the real ones: tests/test_cli.py)."""

import json

import pytest

import shipsense.reproduce as reproduce
from shipsense import atomic
from shipsense.errors import ShipsenseError


@pytest.fixture
def ran(monkeypatch):
    """The studies run (a list of their tasks), each writing a table, a figure and its summary."""
    calls = []

    def run_study(task):
        calls.append(task)
        summary = {"runs": task.runs, "seed": task.seed, "call": len(calls)}
        return {"summary": summary, "files": {"a.csv": b"x\n", "summary.json": json.dumps(summary).encode(),
                                              "z.png": b"png"}}

    monkeypatch.setattr(reproduce, "run_study", run_study)
    return calls


def _run(tmp_path, runs=3, **kw):
    return reproduce.run_studies(["S2"], runs, tmp_path, progress=False, log=lambda *a: None, **kw)["S2"]


def test_a_finished_study_is_skipped_and_read_back(tmp_path, ran):
    first = _run(tmp_path)
    assert json.loads((tmp_path / "S2" / "run.json").read_text()) == {"study": "S2", "runs": 3, "seed": 0}
    assert _run(tmp_path) == first and len(ran) == 1


def test_another_run_is_refused_unless_restarted(tmp_path, ran):
    _run(tmp_path)
    with pytest.raises(ShipsenseError, match=r"holds the results of another S2 run \(runs 3, not 5\)"):
        _run(tmp_path, runs=5)
    assert len(ran) == 1
    assert _run(tmp_path, runs=5, restart=True)["call"] == 2
    assert json.loads((tmp_path / "S2" / "run.json").read_text())["runs"] == 5
    assert _run(tmp_path, runs=5, restart=True)["call"] == 3                  # restart: afresh, the same run too


def test_a_study_interrupted_while_its_files_are_written_runs_again(tmp_path, ran, monkeypatch):
    write = atomic.atomic_write_bytes

    def interrupted(path, data):
        if path.name == "summary.json":
            raise KeyboardInterrupt
        write(path, data)

    monkeypatch.setattr(atomic, "atomic_write_bytes", interrupted)
    with pytest.raises(KeyboardInterrupt):
        _run(tmp_path)
    assert (tmp_path / "S2" / "a.csv").is_file() and not (tmp_path / "S2" / "summary.json").exists()
    monkeypatch.setattr(atomic, "atomic_write_bytes", write)
    assert _run(tmp_path)["call"] == 2 and len(ran) == 2
