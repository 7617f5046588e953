"""Resumable runs: an output folder that names the run it holds, and one file per finished task.

``shipsense sweep`` and ``shipsense reproduce`` (the studies S0, S1, S2 and the wide study) run many tasks
into one output folder::

    <marker>          JSON: the run's identity, and whatever else its writer records (status, versions, timing)
    chunks/<task>.*   one file per finished task, written atomically (:mod:`shipsense.atomic`)

The identity is a few JSON fields that must all be equal for the folder to be resumed: the hash of the run's
canonical spec (:func:`canonical_hash`, which changes with anything that changes the results) and, where it
helps the message, the arguments it was made from.  :meth:`TaskStore.check` decides what a folder can take,
before anything is written:

* missing or empty: a new run;
* its marker holds this run's identity: resumed -- the tasks with a file in ``chunks/`` are finished (a task
  interrupted while its file was written left none: the file is renamed into place only once complete);
* its marker holds another identity, or cannot be read: refused unless ``restart``;
* not empty and without a marker: refused, ``restart`` or not -- it is not a run's folder, and nothing in it is
  removed.

``restart`` starts the run afresh in a folder that holds one (this run's or another's): :meth:`TaskStore.begin`
removes its task files, the writer's own files (``owns``) and its marker, then marks the folder as this run's.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

from shipsense.atomic import atomic_write_bytes
from shipsense.errors import ShipsenseError

CHUNKS = "chunks"
"""The folder of the finished tasks' files, inside the output folder."""


def canonical_hash(obj) -> str:
    """SHA-256 of an object's canonical JSON (sorted keys, no whitespace): the identity of a run, a sweep's cell
    or its draws (formatting and key order do not count)."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


class TaskStore:
    """The output folder ``folder`` of a run whose identity is ``identity`` (a dict of JSON values).

    ``marker``: the marker's file name; ``what``: what the run is called in messages ("sweep", "wide-study
    run"); ``owns``: names or glob patterns of the files the run writes beside its tasks' (its tables, its
    figures), removed with them on a restart; ``error``: the exception class of a refusal (a
    :class:`~shipsense.errors.ShipsenseError`: input the user can fix).
    """

    def __init__(self, folder, identity: dict, *, marker: str = "run.json", what: str = "run", owns=(),
                 error: type[ShipsenseError] = ShipsenseError):
        self.folder = Path(folder)
        self.identity = json.loads(json.dumps(identity))   # as the marker will read back (tuples are lists)
        self.marker = self.folder / marker
        self.chunks = self.folder / CHUNKS
        self.what = what
        self.owns = tuple(owns)
        self.error = error
        self.resumed = None

    def check(self, restart: bool = False) -> bool:
        """Whether this run resumes the folder (True), or starts afresh (False: a new or empty folder, or --
        with ``restart`` -- one holding this run's or another run's results, which :meth:`begin` removes).
        Refuses another run's folder without ``restart``, and a folder that is not empty and holds no marker.
        Reads only."""
        folder = self.folder
        if folder.exists() and not folder.is_dir():
            raise self.error(f"--out {folder}: exists and is not a folder")
        if not self.marker.is_file():
            if folder.is_dir() and any(folder.iterdir()):
                raise self.error(f"--out {folder}: the folder is not empty and holds no {self.marker.name} (not a "
                                 f"{self.what}'s results); choose another --out")
            self.resumed = False
            return False
        found = self._recorded()
        same = isinstance(found, dict) and all(found.get(k) == v for k, v in self.identity.items())
        if not same and not restart:
            raise self.error(f"--out {folder}: holds the results of another {self.what} ({self._difference(found)}); "
                             "pass --restart to discard them, or choose another --out")
        self.resumed = same and not restart
        return self.resumed

    def finished(self) -> set[str]:
        """The names of the tasks with a file in ``chunks/`` (its name without the suffix).  Temporary files of
        writes under way or interrupted are hidden names, not counted."""
        if not self.chunks.is_dir():
            return set()
        return {p.name.rsplit(".", 1)[0] for p in self.chunks.iterdir() if p.is_file() and not p.name.startswith(".")}

    def begin(self, **fields) -> None:
        """Make the folder this run's, after :meth:`check`: unless resumed, remove the task files, the files the
        run ``owns`` and the marker found there (the marker last: a restart interrupted half-way is still
        another run's folder); then write the marker (:meth:`mark`)."""
        if self.resumed is None:
            raise RuntimeError("TaskStore.begin before TaskStore.check")
        if not self.resumed:
            for path in [self.chunks, *(p for pattern in self.owns for p in self.folder.glob(pattern))]:
                if path.is_dir() and not path.is_symlink():
                    shutil.rmtree(path)
                else:
                    path.unlink(missing_ok=True)
            self.marker.unlink(missing_ok=True)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.mark(**fields)

    def mark(self, **fields) -> None:
        """(Re)write the marker, atomically: the identity, then ``fields``."""
        data = {**self.identity, **fields}
        atomic_write_bytes(self.marker, (json.dumps(data, indent=2, default=str) + "\n").encode())

    def path(self, name: str) -> Path:
        """The path of a task's file ``name`` (with its suffix) in ``chunks/``."""
        return self.chunks / name

    def write(self, name: str, data: bytes) -> None:
        """Store a finished task's file ``name`` (with its suffix): written to a temporary name, then renamed."""
        self.chunks.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(self.path(name), data)

    def _recorded(self):
        """The marker's JSON object, or why it cannot be read."""
        try:
            found = json.loads(self.marker.read_text())
        except (OSError, ValueError) as err:
            return f"{type(err).__name__}: {err}"
        return found if isinstance(found, dict) else "not a JSON object"

    def _difference(self, found) -> str:
        if not isinstance(found, dict):
            return f"its {self.marker.name} is unreadable: {found}"
        return "; ".join(f"{k} {_short(found.get(k))}, not {_short(v)}" for k, v in self.identity.items()
                         if found.get(k) != v)


def _short(value) -> str:
    """A value of an identity for a message: strings (hashes) to their first 12 characters."""
    return value[:12] if isinstance(value, str) else json.dumps(value)
