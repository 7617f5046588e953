"""The ``shipsense track`` and ``demo`` pipeline: the project's tracker over one passage, outputs in blocks.

:func:`track_to_files` streams a passage (simulated or recorded) through
:class:`~shipsense.trackers.Tracker` one sample at a time and writes

* ``estimates.csv``: ``time``, the state (SI), ``std_x``, ``std_y``, ``selected`` (hypothesis), the truth and
  the error when known (``true_x``, ``true_y``, ``error_m``), then the position covariance ``cov_xx``,
  ``cov_xy``, ``cov_yy`` and the ``status`` (no data, initialising, tracking, restarted, inconsistent,
  manoeuvring); with ``[tracker.motion] model = "imm"``, the motion modes' probabilities ``p_cv``,
  ``p_turn_left``, ``p_turn_right``, ``p_speed``;
* ``selection_log.csv``: ``time``, ``status``, ``selected``, ``hypotheses`` (with weight),
  ``gap_to_second_nats`` (the selected hypothesis's log-likelihood over the runner-up's) and ``ambiguous``
  (hypotheses far apart within a few nats: the tracker cannot tell them apart);

in blocks of :data:`BLOCK` samples, so that time is linear and memory bounded in the passage's length; a
thinned copy (at most :data:`PLOT_POINTS` samples) is kept for the picture.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from shipsense.trackers.tracker.results import INITIALISING, NO_DATA, STATUSES
from shipsense.trackers.tracker.tracker import Tracker

BLOCK = 4096
"""Samples written per block."""
PLOT_POINTS = 2000
"""Samples kept for the picture of a long passage (evenly spaced, the last included)."""


FIRST_USE = ("compiling the numerical kernels on their first use on this machine (about a minute on two "
             "cores; cached for later runs)")


def first_use_notice(filter_name=None):
    """:data:`FIRST_USE` if the tracker's compiled kernels (filter ``filter_name``'s step, default the
    tracker's UKF, or its update where it has no step; its update loop, the predict, the measurement kernel, the
    least-squares loop, the grid search and the restart rule) are not yet compiled on disk for the current
    sources, else None."""
    from shipsense import numba_cache
    from shipsense.models import measurement
    from shipsense.trackers.filters import fused, kernels, time_update
    from shipsense.trackers.fit import lm
    from shipsense.trackers.init import grid
    from shipsense.trackers.tracker import restarts
    from shipsense.trackers.tracker import step as tracker_step

    code = fused.filter_code(filter_name or "ukf")
    # the tracker calls the filter's compiled step where there is one (its update loop and the predict inside),
    # else the update's entry: a kernel it does not call is not asked for (else the notice would never go away)
    entry = (tracker_step.STEP_KERNELS[code] if code in tracker_step.STEP_KERNELS else kernels.UPDATE_KERNELS[code])
    ready = numba_cache.cached(entry, kernels.UPDATE_LOOPS[code], time_update.predict_kernel,
                               measurement.batch_kernel, lm.lm_kernel, grid.grid_solve_kernel,
                               grid.ridge_inverses, restarts.due, tracker_step.prepare_sample)
    return None if ready else FIRST_USE


@dataclass
class TrackSummary:
    """What a tracked passage came to: the tracker, the last sample, errors (with a truth), gaps, and the
    thinned samples for the picture."""

    tracker: Tracker
    samples: int
    final: np.ndarray
    final_cov: np.ndarray
    final_status: str
    ambiguous_at_end: bool
    final_error: float | None = None
    mean_error: float | None = None
    gaps: list = field(default_factory=list)
    plot: dict = field(default_factory=dict)
    peak_snr: float | None = None

    @property
    def tracked(self) -> bool:
        """Whether any sample reached a tracking status (else the estimate is the tracker's initial state)."""
        return bool(np.any(self.plot["status"] > INITIALISING))

    @property
    def restarts(self):
        return int(self.tracker.state.restarts[0])


def fmt(col, spec):
    return np.char.mod(spec, col)


def _write_block(est_fh, log_fh, t, s, truth, labels, modes=()):
    """Rows of a block of samples: ``s`` holds (B, ...) arrays of
    :class:`~shipsense.trackers.tracker.results.Sample`; ``modes``: the tracker's motion modes' names (their
    probabilities are columns ``p_<mode>``)."""
    status = np.asarray(STATUSES)[s["status"]]
    P = s["cov"][:, :2, :2]
    cols = [fmt(t, "%.6g"), *(fmt(s["estimate"][:, i], "%.6g") for i in range(len(labels))),
            fmt(np.sqrt(P[:, 0, 0]), "%.4g"), fmt(np.sqrt(P[:, 1, 1]), "%.4g"), fmt(s["selected"], "%d")]
    if truth is not None:
        err = np.hypot(s["estimate"][:, 0] - truth[:, 0], s["estimate"][:, 1] - truth[:, 1])
        cols += [fmt(truth[:, 0], "%.6g"), fmt(truth[:, 1], "%.6g"), fmt(err, "%.4g")]
    cols += [fmt(P[:, 0, 0], "%.6g"), fmt(P[:, 0, 1], "%.6g"), fmt(P[:, 1, 1], "%.6g"), status]
    cols += [fmt(s["modes"][:, j], "%.4g") for j in range(len(modes))]
    est_fh.write("\n".join(",".join(row) for row in zip(*cols)) + "\n")
    gap = np.where(np.isfinite(s["gap_nats"]), s["gap_nats"], np.nan)
    cols = [fmt(t, "%.6g"), status, fmt(s["selected"], "%d"), fmt(s["hypotheses"], "%d"), fmt(gap, "%.4g"),
            np.where(s["ambiguous"], "true", "false")]
    log_fh.write("\n".join(",".join(row) for row in zip(*cols)) + "\n")


def track_to_files(scenario, times, measurements, out, *, truth=None, method="tracker", unit=None,
                   progress=False) -> TrackSummary:
    """Track one passage (``times`` (K,) s, ``measurements`` (K, m) SI, NaN = missing) and write its outputs
    into the folder ``out`` (see the module docstring); ``truth`` (K, >= 2) adds the errors."""
    out = Path(out)
    tracker = Tracker(scenario, passages=1, method=method, unit=unit)
    y = np.asarray(measurements, dtype=float)
    t = np.asarray(times, dtype=float)
    K = len(t)
    labels = list(tracker.labels)
    keys = ("estimate", "cov", "status", "selected", "hypotheses", "gap_nats", "ambiguous", "modes")
    thin = max(1, -(-K // PLOT_POINTS))
    keep = {k: [] for k in (*keys, "k")}
    header = ["time", *labels, "std_x", "std_y", "selected"]
    header += ["true_x", "true_y", "error_m"] if truth is not None else []
    header += ["cov_xx", "cov_xy", "cov_yy", "status"]
    header += [f"p_{name}" for name in tracker.mode_names]
    steps = range(0, K, BLOCK)
    if progress:
        from tqdm import tqdm

        steps = tqdm(steps, desc="tracking", unit="block", leave=False, disable=None)
    # written to partial files and renamed at the end: an interrupted or failed run leaves no half table
    parts = {name: out / f".{name}.part" for name in ("estimates.csv", "selection_log.csv")}
    stats = [0.0, 0]   # sum and count of the errors once tracking (with the truth)
    try:
        _track_blocks(tracker, t, y, truth, steps, parts, header, labels, keys, keep, thin, stats)
    except BaseException:
        for p in parts.values():
            p.unlink(missing_ok=True)
        raise
    for name, p in parts.items():
        os.replace(p, out / name)
    err_sum, err_n = stats
    s = keep.pop("_last")
    plot = {k: np.concatenate(v) for k, v in keep.items()}
    final_error = None
    if truth is not None:
        final_error = float(np.hypot(*(s.estimate[0, :2] - np.asarray(truth)[-1, :2])))
    return TrackSummary(tracker, K, s.estimate[0], s.cov[0, :2, :2], STATUSES[s.status[0]], bool(s.ambiguous[0]),
                        final_error, err_sum / err_n if err_n else None, list(tracker.gaps), plot,
                        peak_snr(scenario, scenario.array(), y))


def peak_snr(scenario, array, y):
    """The largest field value of ``y`` (K, m) over its channel's noise standard deviation (bearings left out),
    or None without a field value."""
    field_cols = ~np.asarray(array.axial, dtype=bool)
    v = np.abs(y[:, field_cols]) / np.asarray(scenario.channel_std, dtype=float)[field_cols]
    return float(np.nanmax(v)) if np.isfinite(v).any() else None


def _track_blocks(tracker, t, y, truth, steps, parts, header, labels, keys, keep, thin, stats):
    """The samples in blocks: each block tracked, written to the partial tables and thinned for the plot."""
    K = len(t)
    with open(parts["estimates.csv"], "w") as est_fh, open(parts["selection_log.csv"], "w") as log_fh:
        est_fh.write(",".join(header) + "\n")
        log_fh.write("time,status,selected,hypotheses,gap_to_second_nats,ambiguous\n")
        for lo in steps:
            ks = np.arange(lo, min(lo + BLOCK, K))
            block = {k: [] for k in keys}
            for k in ks:
                s = tracker.update(t[k:k + 1], y[None, k])
                for name in keys:
                    block[name].append(getattr(s, name)[0])
            block = {k: np.asarray(v) for k, v in block.items()}
            tb = None if truth is None else np.asarray(truth)[ks]
            _write_block(est_fh, log_fh, t[ks], block, tb, labels, tracker.mode_names)
            if tb is not None:
                tracked = block["status"] > INITIALISING
                e = np.hypot(*(block["estimate"][tracked, :2] - tb[tracked, :2]).T)
                stats[0], stats[1] = stats[0] + e.sum(), stats[1] + e.size
            pick = (ks % thin == 0) | (ks == K - 1)
            for name in keys:
                keep[name].append(block[name][pick])
            keep["k"].append(ks[pick])
    keep["_last"] = s


def state_line(f, c) -> str:
    """A tracked state ``f`` (n,) SI with its covariance ``c`` (n, n) as ``track`` prints it: position,
    velocity and the 2-sigma of x and y."""
    return (f"x = {f[0]:.1f} m, y = {f[1]:.1f} m, v = ({f[2]:.2f}, {f[3]:.2f}) m/s, 2-sigma "
            f"{2 * np.sqrt(c[0, 0]):.2f} / {2 * np.sqrt(c[1, 1]):.2f} m")


def describe(summary: TrackSummary, source: str) -> list[str]:
    """The lines ``shipsense track`` prints about a tracked passage."""
    tr, f, c = summary.tracker, summary.final, summary.final_cov
    what = ("the studies' bank of " f"{tr.H} hypotheses ({tr.unit.name})" if tr.settings.method == "bank" else
            f"the project's tracker ({tr.unit.name}{', robust' if tr.settings.robust else ''})")
    lines = [f"tracked {source} with {what}",
             f"  at the end ({summary.final_status}): {state_line(f, c)}; {summary.restarts} restarts"]
    counts = np.bincount(summary.plot["status"], minlength=len(STATUSES))
    if counts[NO_DATA] == len(summary.plot["status"]):
        lines[1:] = ["  no sample of the passage had a field value: nothing to track"]
    elif not summary.tracked:
        snr = "" if summary.peak_snr is None else f"; the largest field value is {summary.peak_snr:.3g} noise std"
        lines[1:] = [f"  no estimate: the tracker did not start tracking in {summary.samples} sample"
                     f"{'s' if summary.samples != 1 else ''}{snr}"]
    if summary.final_error is not None and summary.tracked:
        lines.append(f"  position error: final {summary.final_error:.2f} m"
                     + (f", mean {summary.mean_error:.2f} m once tracking" if summary.mean_error is not None else ""))
    lines += [f"  gap: {g}" for g in summary.gaps]
    if summary.ambiguous_at_end:
        lines.append("  AMBIGUOUS at the end: hypotheses far apart explain the data almost equally well")
    return lines
