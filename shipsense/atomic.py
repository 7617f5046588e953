"""Atomic outputs: a command leaves either all of its files or none of them.

A file is written to a temporary name in its own folder and renamed (a rename within one file system is
atomic); a command that writes several files stages them in a hidden folder beside its output folder and moves
them in only when everything succeeded, so an error or Ctrl-C half-way leaves no half table and no plot of a
run that failed; a run killed outright leaves its hidden folder, which the next run on that output removes.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import uuid
from pathlib import Path


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder and an atomic rename."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path`` with its suffix (for writers that take a file name: NumPy,
    matplotlib, csv); on success it is renamed to ``path``, on any error removed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{uuid.uuid4().hex}.tmp{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


STALE_LEGACY_SECONDS = 3600.0
"""A staging folder without its owner's process id in its name (made by an earlier version) counts as stale
once it is this old (s)."""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:        # another user's process: alive
        return True
    return True


def sweep_stale_stages(out) -> list[Path]:
    """Remove the staging folders of ``out`` (``.OUT.PID.*.partial`` beside it) whose process is gone: a run
    killed outright (SIGKILL, a power cut) cannot remove its own, so the next run on that output does.  A folder
    of a process that still runs (a concurrent run on the same output) is left alone.  Returns those removed."""
    import re
    import time

    out = Path(out)
    removed = []
    for stage in out.parent.glob(f".{out.name}.*.partial") if out.parent.is_dir() else ():
        middle = stage.name[len(out.name) + 2:-len(".partial")]
        ours = re.fullmatch(r"(\d+)\.[a-z0-9_]+", middle)      # PID.RANDOM: another output's has more dots
        if ours:
            stale = int(ours[1]) != os.getpid() and not _alive(int(ours[1]))
        elif re.fullmatch(r"[a-z0-9_]+", middle):             # RANDOM alone: an earlier version's, stale once old
            try:
                stale = time.time() - stage.stat().st_mtime > STALE_LEGACY_SECONDS
            except OSError:
                continue
        else:
            continue
        if stale and stage.is_dir() and not stage.is_symlink():
            shutil.rmtree(stage, ignore_errors=True)
            removed.append(stage)
    return removed


@contextlib.contextmanager
def staged_directory(out):
    """Yield a hidden folder beside ``out`` to write into; on success its files replace their namesakes in
    ``out`` (created if needed; a folder replaces its namesake whole: a training's ``tensorboard`` logs of an
    earlier run into the same ``out``), on any error the folder is removed and ``out`` is left as it was.

    The folder's name carries this process's id (``.OUT.PID.RANDOM.partial``), and stale ones of ``out`` (their
    process gone: a run killed with SIGKILL) are removed first (:func:`sweep_stale_stages`)."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    sweep_stale_stages(out)
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.{os.getpid()}.", suffix=".partial", dir=out.parent))
    try:
        yield stage
        out.mkdir(parents=True, exist_ok=True)
        for f in sorted(stage.iterdir()):
            target = out / f.name
            if f.is_dir() and target.is_dir() and not target.is_symlink():
                shutil.rmtree(target)                   # (os.replace refuses a folder that is not empty)
            os.replace(f, target)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
