"""Staged output folders: all of a command's files or none, and a re-run into the same folder."""

import pytest

from shipsense.atomic import staged_directory


def test_a_rerun_replaces_files_and_folders_of_the_same_name(tmp_path):
    out = tmp_path / "out"
    for run in ("first", "second"):
        with staged_directory(out) as stage:
            (stage / "summary.json").write_text(run)
            (stage / "tensorboard").mkdir()
            (stage / "tensorboard" / f"events.{run}").write_text(run)
    assert (out / "summary.json").read_text() == "second"
    assert sorted(p.name for p in (out / "tensorboard").iterdir()) == ["events.second"]
    assert not list(tmp_path.glob(".out.*.partial"))


def test_an_error_leaves_the_folder_as_it_was(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "kept.txt").write_text("kept")
    with pytest.raises(RuntimeError), staged_directory(out) as stage:
        (stage / "kept.txt").write_text("new")
        raise RuntimeError("the command failed")
    assert (out / "kept.txt").read_text() == "kept" and not list(tmp_path.glob(".out.*.partial"))


def test_a_killed_runs_stage_is_swept_by_the_next_run_and_a_live_ones_is_not(tmp_path):
    """A run killed with SIGKILL cannot remove its hidden staging folder; the next run on the same output does,
    unless the folder's process still runs (a concurrent run), and another output's folders are not touched."""
    import os
    import subprocess
    import sys

    from shipsense.atomic import sweep_stale_stages

    out = tmp_path / "out"
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    try:
        killed = tmp_path / f".out.{int(dead.stdout)}.abcd1234.partial"
        live = tmp_path / f".out.{child.pid}.efgh5678.partial"
        other = tmp_path / f".out.v2.{int(dead.stdout)}.abcd1234.partial"   # the output "out.v2"'s
        for d in (killed, live, other):
            d.mkdir()
            (d / "summary.json").write_text("half")
        with staged_directory(out) as stage:
            assert stage.name.startswith(f".out.{os.getpid()}.")
            (stage / "summary.json").write_text("whole")
        assert not killed.exists() and live.exists() and other.exists()
        assert (out / "summary.json").read_text() == "whole"
        assert sweep_stale_stages(tmp_path / "out.v2") == [other]
    finally:
        child.kill()
        child.wait()
