"""What the commands share: exit codes, limits of the flags, progress bars, output checks, the work budget and
the first-use notice."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from shipsense.arguments import whole_flag
from shipsense.errors import ShipsenseError

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_BAD_INPUT = 2
EXIT_AMBIGUOUS = 3
EXIT_DEGENERATE = 4
VERDICT_EXIT = {"observable": EXIT_OK, "ambiguous": EXIT_AMBIGUOUS, "degenerate": EXIT_DEGENERATE}


SEED_MAX = 2**63 - 1
RUNS_MAX = 1_000_000
PASSAGES_MAX = 10_000
TIMESTEPS_MAX = 10**9


SEED = whole_flag(0, SEED_MAX)


QUIET = {"on": False}   # `shipsense --quiet ...`: no progress bars (they show only on a terminal anyway)


def progress_bar(total, desc):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="step", leave=False, disable=True if QUIET["on"] else None,
                file=sys.stderr)


def writable(flag, path, directory=False):
    """Refuse an output path that cannot be written, before any work (not a raw OS error after it)."""
    p = Path(path)
    if directory:
        if p.exists() and not p.is_dir():
            raise BadInput(f"{flag} must be a folder, but {path} is a file")
        return
    if p.is_dir():
        raise BadInput(f"{flag} must be a file, but {path} is a folder")
    parent = p.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not (parent.is_dir() and os.access(parent, os.W_OK)):
        raise BadInput(f"{flag}: cannot write {path} (folder {parent} is not a writable folder)")


def within_budget(args, work):
    """Refuse work estimated above ``--max-memory`` / ``--max-minutes`` before any of it is allocated."""
    from shipsense.budget import enforce

    return enforce(work, args.max_memory, args.max_minutes)


def first_use(command, filter_name=None, notice=None):
    """Say on stderr, before work that runs the tracker, that its compiled kernels are about to compile (and so
    that this run's times include compiling): :func:`~shipsense.cli.track.first_use_notice`, or ``notice`` (a
    function giving another command's notice or None)."""
    from shipsense.cli.track import first_use_notice

    notice = first_use_notice(filter_name) if notice is None else notice()
    if notice:
        print(f"{command}: {notice}", file=sys.stderr)


class BadInput(ShipsenseError):
    """A command-line argument the user can fix (one line, exit 2)."""


def json_kwargs(flag, text):
    import json

    if text is None:
        return None
    try:
        value = json.loads(text)
    except json.JSONDecodeError as err:
        raise BadInput(f"{flag} must be a JSON object, e.g. '{{\"k\": 3}}': {err}") from None
    if not isinstance(value, dict):
        raise BadInput(f"{flag} must be a JSON object, got {text!r}")
    return value
