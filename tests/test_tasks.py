"""The resumable task store: the marker names the run, finished tasks are files; the same run resumes, another
is refused unless restarted, a folder that is no run's is never touched, an interrupted write counts for
nothing."""

import json
import os

import pytest

from shipsense import atomic
from shipsense.errors import ShipsenseError
from shipsense.tasks import TaskStore, canonical_hash

IDENTITY = {"study": "demo", "hash": canonical_hash({"runs": 3}), "runs": 3}


def _started(folder, identity=IDENTITY, **kw):
    """A run that wrote two tasks and a table of its own into ``folder``."""
    store = TaskStore(folder, identity, owns=("table.csv", "*.png"), **kw)
    assert store.check() is False
    store.begin(status="running")
    store.write("a-c0000.npz", b"a")
    store.write("b.json", b"{}")
    (folder / "table.csv").write_text("x\n")
    (folder / "plot.png").write_bytes(b"png")
    return store


def test_the_same_run_resumes_its_finished_tasks(tmp_path):
    _started(tmp_path / "out")
    assert json.loads((tmp_path / "out" / "run.json").read_text()) == {**IDENTITY, "status": "running"}
    again = TaskStore(tmp_path / "out", dict(IDENTITY), owns=("table.csv", "*.png"))
    assert again.check() is True
    assert again.finished() == {"a-c0000", "b"}
    again.begin(status="complete")                       # resumed: nothing removed, the marker rewritten
    assert again.finished() == {"a-c0000", "b"} and (tmp_path / "out" / "table.csv").is_file()
    assert json.loads(again.marker.read_text())["status"] == "complete"
    assert again.path("b.json").read_bytes() == b"{}"


def test_another_run_is_refused_with_one_message_naming_what_differs(tmp_path):
    _started(tmp_path / "out")
    other = {**IDENTITY, "hash": canonical_hash({"runs": 5}), "runs": 5}
    store = TaskStore(tmp_path / "out", other, what="demo run")
    with pytest.raises(ShipsenseError, match=r"--out .*out: holds the results of another demo run \(hash [0-9a-f]{12}"
                       r", not [0-9a-f]{12}; runs 3, not 5\); pass --restart to discard them, or choose another "
                       r"--out$"):
        store.check()
    assert json.loads(store.marker.read_text())["runs"] == 3                 # refused: nothing touched
    assert store.finished() == {"a-c0000", "b"}


def test_restart_discards_another_runs_tasks_and_own_files_and_keeps_the_rest(tmp_path):
    out = tmp_path / "out"
    _started(out)
    (out / "notes.txt").write_text("mine")
    other = {**IDENTITY, "runs": 5}
    store = TaskStore(out, other, owns=("table.csv", "*.png"))
    assert store.check(restart=True) is False
    assert store.finished() == {"a-c0000", "b"}                              # check reads only
    store.begin()
    assert store.finished() == set() and not store.chunks.exists()
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "run.json"]
    assert json.loads(store.marker.read_text()) == other


def test_restart_of_the_same_run_starts_afresh(tmp_path):
    _started(tmp_path / "out")
    store = TaskStore(tmp_path / "out", IDENTITY, owns=("table.csv", "*.png"))
    assert store.check(restart=True) is False
    store.begin()
    assert store.finished() == set() and not (tmp_path / "out" / "plot.png").exists()


def test_a_folder_that_is_no_runs_is_refused_even_with_restart(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "chunks").mkdir()
    (tmp_path / "mine" / "chunks" / "x.npz").write_bytes(b"mine")
    for restart in (False, True):
        with pytest.raises(ShipsenseError, match=r"the folder is not empty and holds no run.json \(not a run's "
                           "results\\); choose another --out"):
            TaskStore(tmp_path / "mine", IDENTITY).check(restart)
    assert (tmp_path / "mine" / "chunks" / "x.npz").read_bytes() == b"mine"
    (tmp_path / "file").write_text("x")
    with pytest.raises(ShipsenseError, match="exists and is not a folder"):
        TaskStore(tmp_path / "file", IDENTITY).check()
    (tmp_path / "empty").mkdir()
    assert TaskStore(tmp_path / "empty", IDENTITY).check() is False


def test_an_unreadable_marker_is_another_runs_and_the_error_class_is_the_callers(tmp_path):
    class Mine(ShipsenseError):
        pass

    _started(tmp_path / "out")
    (tmp_path / "out" / "run.json").write_text("{not json")
    store = TaskStore(tmp_path / "out", IDENTITY, what="sweep", error=Mine)
    with pytest.raises(Mine, match=r"holds the results of another sweep \(its run.json is unreadable: "
                       "JSONDecodeError"):
        store.check()
    (tmp_path / "out" / "run.json").write_text("[1, 2]")
    with pytest.raises(Mine, match="unreadable: not a JSON object"):
        store.check()
    assert store.check(restart=True) is False
    store.begin()
    assert json.loads(store.marker.read_text()) == IDENTITY


def test_an_interrupted_task_write_is_not_counted(tmp_path, monkeypatch):
    store = _started(tmp_path / "out")

    def interrupted(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(atomic.os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        store.write("c-c0001.npz", b"half")
    monkeypatch.setattr(atomic.os, "replace", os.replace)
    (store.chunks / ".d-c0002.npz.0123abcd.tmp").write_bytes(b"half")      # a write killed outright
    resumed = TaskStore(tmp_path / "out", IDENTITY)
    assert resumed.check() is True and resumed.finished() == {"a-c0000", "b"}


def test_begin_needs_check_and_the_hash_ignores_key_order(tmp_path):
    with pytest.raises(RuntimeError, match="before TaskStore.check"):
        TaskStore(tmp_path / "out", IDENTITY).begin()
    assert canonical_hash({"a": 1, "b": [1, 2]}) == canonical_hash({"b": [1, 2], "a": 1})
    assert canonical_hash({"a": 1}) != canonical_hash({"a": 2})
    # an identity with tuples reads back from the marker as lists, and still resumes
    store = TaskStore(tmp_path / "out", {"span": (1.0, 2.0)})
    store.check()
    store.begin()
    assert TaskStore(tmp_path / "out", {"span": (1.0, 2.0)}).check() is True
