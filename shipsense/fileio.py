"""Atomic file writes: a temporary file in the same folder, then a rename (no half-written file is ever seen)."""

from __future__ import annotations

import os
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


def atomic_write_files(files: dict) -> None:
    """Write several files ``{path: bytes}`` atomically each; if one fails, the ones already written are removed.

    The contents are all in memory before the first write, so a failure while
    producing them leaves nothing behind either.
    """
    written = []
    try:
        for path, data in files.items():
            atomic_write_bytes(Path(path), data)
            written.append(Path(path))
    except BaseException:
        for path in written:
            path.unlink(missing_ok=True)
        raise
