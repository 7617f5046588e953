"""``shipsense track --data``: one or several recordings tracked in one process, each into its own folder.

The recordings (files, folders of them, or glob patterns) are all read and checked before anything is
tracked or written, so a bad one ends the command with one line naming it and exit code 2, and nothing
written.  Then each is split into passages at gaps longer than the passage gap
(:mod:`~shipsense.recording.passages`) and each passage tracked (:func:`~shipsense.cli.track.track_to_files`)
into its folder:

* one recording: ``OUT/`` itself (``OUT/passage-N/`` for each passage when it is split);
* several: ``OUT/<name>/`` for each (the file's name without its extension), and ``OUT/summary.csv``.

The compiled kernels load once for them all: a folder of recordings pays the start-up once.  The summary
table (one row per passage: samples, the status and state at the end, the 2-sigma, restarts, gaps, ambiguity)
is printed, and written to ``summary.csv`` when more than one passage is tracked.
"""

from __future__ import annotations

import csv
import glob
from pathlib import Path

import numpy as np

from shipsense.cli.common import BadInput

SUMMARY = ("recording", "passage", "samples", "start_s", "end_s", "missing_pct", "status", "x_m", "y_m", "vx_mps",
           "vy_mps", "two_sigma_x_m", "two_sigma_y_m", "restarts", "gaps", "ambiguous", "folder")
"""Columns of ``summary.csv``."""


def expand(items) -> list[Path]:
    """The recordings that ``--data`` names: files, the recordings in folders (by extension, not recursive,
    sorted) and glob patterns (sorted), each once in the order given."""
    from shipsense.recording.formats import SUFFIXES

    known = {s for v in SUFFIXES.values() for s in v}
    found = []
    for item in items:
        p = Path(item)
        if p.is_dir():
            inside = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in known)
            if not inside:
                raise BadInput(f"--data: folder {item} holds no recordings (files ending in {' '.join(sorted(known))})")
            found += inside
        elif not p.exists() and glob.has_magic(item):
            matches = sorted(Path(m) for m in glob.glob(item) if Path(m).is_file())
            if not matches:
                raise BadInput(f"--data: no file matches {item!r}")
            found += matches
        else:
            found.append(p)
    seen, unique = set(), []
    for f in found:
        key = f.resolve()
        if key not in seen:
            seen.add(key)
            unique.append(f)
    return unique


def folders(out: Path, files) -> list[Path]:
    """The output folder of each recording: ``out`` for one, ``out/<name>`` for several (two recordings of one
    name are refused)."""
    if len(files) == 1:
        return [out]
    names = {}
    for f in files:
        name = f.stem
        if name in names:
            raise BadInput(f"--data: {names[name]} and {f} would both write to {out / name}; rename one")
        names[name] = f
    return [out / f.stem for f in files]


def _row(recording, passage, times, y, summary, folder):
    f, c = summary.final, summary.final_cov
    return {"recording": str(recording), "passage": passage, "samples": len(times), "start_s": f"{times[0]:.6g}",
            "end_s": f"{times[-1]:.6g}", "missing_pct": f"{100 * np.isnan(y).mean():.1f}",
            "status": summary.final_status, "x_m": f"{f[0]:.1f}", "y_m": f"{f[1]:.1f}", "vx_mps": f"{f[2]:.2f}",
            "vy_mps": f"{f[3]:.2f}", "two_sigma_x_m": f"{2 * np.sqrt(c[0, 0]):.2f}",
            "two_sigma_y_m": f"{2 * np.sqrt(c[1, 1]):.2f}", "restarts": summary.restarts, "gaps": len(summary.gaps),
            "ambiguous": "yes" if summary.ambiguous_at_end else "no", "folder": str(folder)}


def print_table(rows):
    """The summary table, aligned, on stdout."""
    shown = ("recording", "passage", "samples", "status", "x_m", "y_m", "two_sigma_x_m", "two_sigma_y_m",
             "restarts", "gaps", "ambiguous")
    heads = {"two_sigma_x_m": "2sig_x_m", "two_sigma_y_m": "2sig_y_m"}
    cells = [[heads.get(k, k) for k in shown]] + [[str(r[k]) for k in shown] for r in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(shown))]
    for row in cells:
        print("  ".join(cell.ljust(w) if i < 2 or i == 3 else cell.rjust(w)
                        for i, (cell, w) in enumerate(zip(row, widths))).rstrip())


def track_recordings(args, sc) -> int:
    """``shipsense track SCENARIO --data ...`` (see the module docstring)."""
    from shipsense import budget
    from shipsense.atomic import staged_directory
    from shipsense.cli.common import EXIT_OK, QUIET, first_use, within_budget
    from shipsense.cli.track import describe, track_to_files
    from shipsense.recording import RecordingError, read_recording
    from shipsense.recording.mapping import load_mapping
    from shipsense.recording.passages import PASSAGE_GAP_LIMITS, split
    from shipsense.trackers.tracker.settings import resolve_settings

    out = Path(args.out)
    files = expand(args.data)
    targets = folders(out, files)
    try:
        mapping = load_mapping(args.mapping)
        for f in files:
            if not f.is_file():
                raise RecordingError(f"{f}: no such file" if not f.exists() else f"{f}: not a file")
        within_budget(args, budget.sequence((budget.recording(f, sc) for f in files),
                                            f"{len(files)} recordings", "the recordings"))
        recordings = [(f, *read_recording(f, sc, mapping=mapping)) for f in files]   # all checked before any work
    except RecordingError as err:
        raise BadInput(str(err)) from None
    gap_limit = float(resolve_settings(sc).gap_limit_s)
    passage_gap = args.passage_gap if args.passage_gap is not None else PASSAGE_GAP_LIMITS * gap_limit
    first_use("track", args.filter)
    ships = getattr(args, "ships", "1") != "1"      # (its options checked by the command: cmd_track)
    if ships:   # (the several-ship tracker imported only when asked for)
        from shipsense.cli.ships import describe_ships, track_ships_into
    rows, described = [], []
    with staged_directory(out) as stage:   # every recording's tables and plots, or nothing
        for (f, times, y), target in zip(recordings, targets):
            parts = split(times, passage_gap)
            if len(parts) > 1:
                steps = np.diff(times)[[p.stop - 1 for p in parts[:-1]]]
                print(f"{f}: {len(parts)} passages (gaps of {', '.join(f'{s:.3g}' for s in steps)} s, longer than "
                      f"the passage gap of {passage_gap:.3g} s), each tracked on its own")
            for n, part in enumerate(parts, start=1):
                folder = target / f"passage-{n}" if len(parts) > 1 else target
                (stage / folder.relative_to(out)).mkdir(parents=True, exist_ok=True)
                t, yp = times[part], y[part]
                what = (f"recording {f}{f' passage {n}' if len(parts) > 1 else ''} ({len(t)} samples, "
                        f"{100 * np.isnan(yp).mean():.1f} % of values missing)")
                if ships:
                    summary = track_ships_into(sc, t, yp, stage / folder.relative_to(out), args,
                                               f"{sc.name}: {f.name}, several ships")
                    described.append(describe_ships(summary, what))
                    continue
                try:
                    summary = track_to_files(sc, t, yp, stage / folder.relative_to(out), method=args.method,
                                             unit=args.filter, progress=not QUIET["on"])
                except ValueError as err:
                    raise BadInput(str(err)) from None
                if not args.no_plot:
                    from shipsense.plotting import plot_track

                    plot_track(summary, t, stage / folder.relative_to(out) / "track.png",
                               title=f"{sc.name}: {f.name}{f', passage {n}' if len(parts) > 1 else ''}")
                rows.append(_row(f, n, t, yp, summary, folder))
                described.append(describe(summary, what))
        if len(rows) > 1:
            with open(stage / "summary.csv", "w", newline="") as fh:
                w = csv.DictWriter(fh, fieldnames=SUMMARY)
                w.writeheader()
                w.writerows(rows)
    if ships:
        for lines in described:
            print("\n".join(lines))
        print(f"wrote {len(described)} tracked passage(s) into {out} (estimates.csv"
              f"{'' if args.no_plot else ', track.png'} in each folder)")
        return EXIT_OK
    if len(rows) == 1:
        for line in described[0]:
            print(line)
        print(f"wrote {out / 'estimates.csv'}, {out / 'selection_log.csv'}"
              + ("" if args.no_plot else f" and {out / 'track.png'}"))
    else:
        print_table(rows)
        print(f"wrote {len(rows)} tracked passages of {len(files)} recording(s) into {out} (estimates.csv, "
              f"selection_log.csv{'' if args.no_plot else ', track.png'} in each folder) and {out / 'summary.csv'}")
    return EXIT_OK
