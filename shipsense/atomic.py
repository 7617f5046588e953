"""Atomic outputs: a command leaves either all of its files or none of them.

A file is written to a temporary name in its own folder and renamed (a rename within one file system is
atomic); a command that writes several files stages them in a hidden folder beside its output folder and moves
them in only when everything succeeded, so an error or Ctrl-C half-way leaves no half table and no plot of a
run that failed.
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


@contextlib.contextmanager
def staged_directory(out):
    """Yield a hidden folder beside ``out`` to write into; on success its files replace their namesakes in
    ``out`` (created if needed; a folder replaces its namesake whole: a training's ``tensorboard`` logs of an
    earlier run into the same ``out``), on any error the folder is removed and ``out`` is left as it was."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent))
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
