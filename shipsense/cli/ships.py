"""``shipsense track --ships 2|auto``: the several-ship tracker over one passage, its table, summary and picture.

:func:`track_ships_to_files` runs :class:`~shipsense.trackers.ships.ShipsTracker` over a passage and writes
``estimates.csv`` with one row per track and sample at which the track exists: ``time``, ``ship`` (the track
id, 1 or 2, which persists), the ship's state (SI), ``std_x``, ``std_y``; on a simulated passage the true ship
the track follows and its error (``true_ship``, ``true_x``, ``true_y``, ``error_m``: :func:`truth_columns`);
the position covariance ``cov_xx``, ``cov_xy``, ``cov_yy`` and the ``status``.  :func:`describe_ships` gives
the lines ``track`` prints (the number of ships at the end and each track's final state),
:func:`~shipsense.plotting.plot_ships` the picture (every track in its own colour, with 2-sigma ellipses).
The one-ship tracker stays the default of ``track`` (``--ships 1``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shipsense.atomic import atomic_path
from shipsense.cli.common import QUIET, BadInput
from shipsense.cli.track import fmt, state_line
from shipsense.trackers.metrics import label_assignment
from shipsense.trackers.ships import ShipsResult, ShipsSettings, ShipsTracker
from shipsense.trackers.tracker.results import STATUSES


def max_ships(choice) -> int:
    """The most ships of a ``--ships`` choice (``1``, ``2``, or ``auto``: as many as the tracker can, two)."""
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
    with atomic_path(Path(out) / "estimates.csv") as tmp, open(tmp, "w") as fh:
        fh.write(",".join(["time", "ship", *result.labels, "std_x", "std_y",
                           *(() if truth is None else ("true_ship", "true_x", "true_y", "error_m")),
                           "cov_xx", "cov_xy", "cov_yy", "status"]) + "\n")
        est, cov, status = result.estimates[0], result.covs[0], result.status_names()[0]
        k, s = np.nonzero(result.present[0])              # sample-major: the tracks of a sample together
        P = cov[k, s, :2, :2]
        cols = [fmt(t[k], "%.6g"), fmt(s + 1, "%d"), *(fmt(est[k, s, i], "%.6g") for i in range(len(result.labels))),
                fmt(np.sqrt(P[:, 0, 0]), "%.4g"), fmt(np.sqrt(P[:, 1, 1]), "%.4g")]
        if truth is not None:
            j, xy, err = truth_columns(est, truth, k, s)
            cols += [fmt(j, "%d"), fmt(xy[:, 0], "%.6g"), fmt(xy[:, 1], "%.6g"), fmt(err, "%.4g")]
        cols += [fmt(P[:, 0, 0], "%.6g"), fmt(P[:, 0, 1], "%.6g"), fmt(P[:, 1, 1], "%.6g"), status[k, s].astype(str)]
        fh.write("".join(",".join(row) + "\n" for row in zip(*cols)))
    return ShipsSummary(tracker, result, None if truth is None else np.asarray(truth))


def truth_columns(estimates, truth, k, s):
    """The true ship each row's track follows, its true position and the track's error, for the rows at samples
    ``k`` (N,) of tracks ``s`` (N,) of one passage's ``estimates`` (K, I, >= 2), against the true ships ``truth``
    (J, K, >= 2; NaN where a ship does not sail).

    The tracker does not keep the truth's order (track 1 is the ship it found first), so tracks and ships are
    matched once over the passage by :func:`~shipsense.trackers.metrics.label_assignment` (the optimal assignment
    of truncated squared distances, GOSPA's cut-off).  Returns the true ship (N,) int (the truth's numbering,
    ``ship`` of ``simulate --truth``'s file: 0 the scenario's own passage; -1 for a track matched to no ship),
    its position (N, 2), m, and the horizontal error (N,), m; NaN where the track has no ship or its ship does
    not sail at that sample."""
    truth = np.asarray(truth, dtype=float)
    ship_track = label_assignment(estimates, np.moveaxis(truth, 0, 1))            # (J,): the track of each ship
    track_ship = np.full(estimates.shape[1], -1)
    matched = np.flatnonzero(ship_track >= 0)
    track_ship[ship_track[matched]] = matched
    j = track_ship[s]
    xy = np.where((j >= 0)[:, None], truth[np.maximum(j, 0), k, :2], np.nan)
    return j, xy, np.hypot(*(estimates[k, s, :2] - xy).T)


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
                     f"{state_line(f, c)}" + (f"; ended at t = {T[died]:.6g} s" if died >= 0 else ""))
    if r.born[0, 0] < 0:
        lines[1:] = ["  no ship: the one-ship tracker did not start tracking"]
    return lines


def track_ships_into(sc, times, measurements, folder, args, title, truth=None) -> ShipsSummary:
    """``track --ships 2|auto`` of one passage into ``folder``: :func:`track_ships_to_files` (a bad input as
    :class:`~shipsense.cli.common.BadInput`) and, unless ``--no-plot``, the picture ``track.png`` titled
    ``title``."""
    try:
        summary = track_ships_to_files(sc, times, measurements, folder, ships=max_ships(args.ships), truth=truth,
                                       progress=not QUIET["on"])
    except ValueError as err:
        raise BadInput(str(err)) from None
    if not args.no_plot:
        from shipsense.plotting import plot_ships

        plot_ships(summary.result, summary.tracker.base.array, Path(folder) / "track.png", truth=summary.truth,
                   title=title)
    return summary

