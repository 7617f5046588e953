"""``shipsense track --ships 2|auto``: the several-ship tracker over one passage, its table, summary and picture.

:func:`track_ships_to_files` runs :class:`~shipsense.trackers.ships.ShipsTracker` over a passage and writes
``estimates.csv`` with one row per track and sample at which the track exists: ``time``, ``ship`` (the track
id, 1 or 2, which persists), the ship's state (SI), ``std_x``, ``std_y``, the position covariance ``cov_xx``,
``cov_xy``, ``cov_yy`` and the ``status``; :func:`describe_ships` gives the lines ``track`` prints (the
number of ships at the end and each track's final state), :func:`plot_ships` the picture (every track in its
own colour, with 2-sigma ellipses).  The one-ship tracker stays the default of ``track`` (``--ships 1``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shipsense.trackers.ships import ShipsResult, ShipsSettings, ShipsTracker
from shipsense.trackers.tracker.results import STATUSES

SHIPS_CHOICES = ("1", "2", "auto")
"""``--ships``: the most ships tracked at once (``auto``: as many as the tracker can, two)."""


def max_ships(choice) -> int:
    """The most ships of a ``--ships`` choice (:data:`SHIPS_CHOICES`)."""
    return 2 if choice == "auto" else int(choice)


@dataclass
class ShipsSummary:
    """A passage tracked by the several-ship tracker: the tracker, its result (one passage) and the truth."""

    tracker: ShipsTracker
    result: ShipsResult
    truth: np.ndarray | None = None


def track_ships_to_files(scenario, times, measurements, out, *, ships=2, truth=None, progress=False):
    """Track one passage (``times`` (K,) s, ``measurements`` (K, m) SI) with up to ``ships`` ships and write
    ``estimates.csv`` into the folder ``out`` (the module docstring); ``truth`` (J, K, >= 2), optional, the
    ships' true states for the picture.  Returns a :class:`ShipsSummary`."""
    tracker = ShipsTracker(scenario, passages=1, settings=ShipsSettings(max_ships=int(ships)))
    t = np.asarray(times, dtype=float)
    result = tracker.track(t[None], np.asarray(measurements, dtype=float)[None], progress=progress)
    out = Path(out)
    part = out / ".estimates.csv.part"     # renamed at the end: an interrupted run leaves no half table
    try:
        with open(part, "w") as fh:
            fh.write(",".join(["time", "ship", *result.labels, "std_x", "std_y", "cov_xx", "cov_xy", "cov_yy",
                               "status"]) + "\n")
            est, cov, status = result.estimates[0], result.covs[0], result.status_names()[0]
            k, s = np.nonzero(result.present[0])              # sample-major: the tracks of a sample together
            P = cov[k, s, :2, :2]
            cols = [np.char.mod("%.6g", t[k]), np.char.mod("%d", s + 1),
                    *(np.char.mod("%.6g", est[k, s, i]) for i in range(len(result.labels))),
                    np.char.mod("%.4g", np.sqrt(P[:, 0, 0])), np.char.mod("%.4g", np.sqrt(P[:, 1, 1])),
                    np.char.mod("%.6g", P[:, 0, 0]), np.char.mod("%.6g", P[:, 0, 1]), np.char.mod("%.6g", P[:, 1, 1]),
                    status[k, s].astype(str)]
            fh.write("".join(",".join(row) + "\n" for row in zip(*cols)))
    except BaseException:
        part.unlink(missing_ok=True)
        raise
    os.replace(part, out / "estimates.csv")
    return ShipsSummary(tracker, result, None if truth is None else np.asarray(truth))


def describe_ships(summary: ShipsSummary, source: str) -> list[str]:
    """The lines ``shipsense track --ships`` prints: the number of ships at the end and each track's final
    state (or when it ended)."""
    r, T = summary.result, summary.result.times[0]
    o = summary.tracker.settings
    count = int(r.ship_count[0, -1])
    lines = [f"tracked {source} with the several-ship tracker (up to {o.max_ships} ships; an option, not yet the "
             f"default)", f"  ships at the end: {count}"]
    for s in range(r.estimates.shape[2]):
        born, died = int(r.born[0, s]), int(r.died[0, s])
        if born < 0:
            continue
        where = np.flatnonzero(r.present[0, :, s])
        last = where[-1]
        f, c = r.estimates[0, last, s], r.covs[0, last, s]
        when = "at the end" if last == len(T) - 1 else f"last at t = {T[last]:.6g} s"
        lines.append(f"  ship {s + 1} (from t = {T[born]:.6g} s, {when}, {STATUSES[r.status[0, last, s]]}): "
                     f"x = {f[0]:.1f} m, y = {f[1]:.1f} m, v = ({f[2]:.2f}, {f[3]:.2f}) m/s, 2-sigma "
                     f"{2 * np.sqrt(c[0, 0]):.2f} / {2 * np.sqrt(c[1, 1]):.2f} m"
                     + (f"; ended at t = {T[died]:.6g} s" if died >= 0 else ""))
    if r.born[0, 0] < 0:
        lines[1:] = ["  no ship: the one-ship tracker did not start tracking"]
    return lines
