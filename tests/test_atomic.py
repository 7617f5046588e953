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
