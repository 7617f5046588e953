"""Shared helpers of the reference experiments: output folder, tables, figures, progress."""

from __future__ import annotations

import csv
import json
import sys
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from shipsense.allocator import release_free_memory
from shipsense.json_numbers import jsonable
from shipsense.trackers.metrics import convergence_rate, mrmse, squared_axis_errors

LEAN = ("positions", "loglik", "selected")
"""What the studies' banks keep (``run_bank(store=)``): positions, likelihoods and the selected track -- what
:func:`bank_summary` reads (a full record of S0's dense bank at 200 runs is ~245 MB)."""


class Output:
    """An experiment's output folder: ``summary.json``, CSV tables and PNG figures.

    Figures are drawn last (:meth:`draw`, or with the summary): a study's runs hold the most memory, and
    matplotlib (imported for the figures) and the figures' own memory came on top of the runs' arrays and the
    heap they had grown.  Drawn once the runs' arrays are gone (:func:`finish`), after the heap's free pages
    are given back (:func:`~shipsense.allocator.release_free_memory`), they come on top of much less:
    ``reproduce S0`` peaked at 321 MiB, now at 284-287, still while its figures are drawn (benchmarks/LOG.md,
    2026-11-27)."""

    def __init__(self, directory):
        self.dir = Path(directory)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.files = []
        self._figures = []

    def csv(self, name, header, rows):
        path = self.dir / name
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(header)
            for row in rows:
                w.writerow([_fmt(v) for v in row])
        self.files.append(path)
        return path

    def figure(self, name, draw, *args, **kwargs):
        """Save the figure ``draw(*args, **kwargs)`` makes (matplotlib's) as ``name`` with the summary: its
        arguments are kept until then, so give it what it plots, not the study's arrays."""
        self._figures.append((name, partial(draw, *args, **kwargs)))
        return self.dir / name

    def draw(self):
        """Draw and save the figures recorded (:meth:`figure`), after giving the heap's free pages back."""
        figures, self._figures = self._figures, []
        if not figures:
            return
        release_free_memory()
        from shipsense.plotting import plt

        for name, draw in figures:
            fig = draw()
            path = self.dir / name
            try:
                fig.savefig(path, dpi=110)
            finally:
                plt.close(fig)
            self.files.append(path)

    def summary(self, data):
        """Write ``summary.json``, after any figures not drawn yet (:meth:`draw`)."""
        self.draw()
        path = self.dir / "summary.json"
        path.write_text(json.dumps(jsonable(data), indent=2) + "\n")
        self.files.append(path)
        return path


def _fmt(v):
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.6g}"
    return v


class Stages:
    """A progress bar over the named parts of an experiment (stderr)."""

    def __init__(self, names, desc, enabled=True):
        from tqdm import tqdm

        self.bar = tqdm(total=len(names), desc=desc, unit="part", disable=not enabled or None, file=sys.stderr)
        self.t0 = time.perf_counter()

    def step(self, label):
        self.bar.set_postfix_str(label)

    def done(self):
        self.bar.update(1)

    def close(self):
        self.bar.close()
        return time.perf_counter() - self.t0


def finish(out, stages, summary):
    """A study's end: its figures (``out``'s, :meth:`Output.draw`) as the last of its ``stages``
    (:class:`Stages`, the last one named "figures"), then its ``summary`` written with ``"seconds"`` set to
    the time of every stage.  Call it once the runs' arrays are gone (the runs a function of their own)."""
    stages.step("figures")
    out.draw()
    stages.done()
    summary["seconds"] = stages.close()
    out.summary(summary)
    return summary


RUN_CHUNK = 50
"""Runs per batch in the studies' banks and initialiser runs (:func:`bank_tally`, :func:`global_init_summary`):
the records and their summaries' temporaries scale with it (S0's dense bank: 57 MB at 200 runs).  Passages are
independent, so the figures do not depend on it; batches of 50 runs (600-1,800 filters) keep the steps' speed."""


def run_chunks(runs, chunk=RUN_CHUNK):
    """Slices of ``runs`` runs, ``chunk`` (>= 1) at a time."""
    if int(chunk) < 1:
        raise ValueError(f"chunk must be at least 1 run, got {chunk}")
    return [slice(s, min(s + chunk, runs)) for s in range(0, runs, chunk)]


@dataclass(frozen=True)
class BankTally:
    """What the studies read of a bank over runs (:func:`bank_summary`), in O(R H + R K + H K) memory
    instead of the bank's records' O(R H K): gathered run chunk by run chunk (:func:`bank_tally`).

    Attributes: ``seeds`` (R, H, n); ``trmse`` (R, H) each hypothesis's TRMSE in each run;
    ``final_loglik`` (R, H) cumulative log-likelihoods at the last step (-inf once pruned);
    ``selected_means`` (R, K, n) the maximum-likelihood track; ``sq_err`` (H, K, 2) sums over runs of each
    hypothesis's squared x and y errors (:meth:`mrmse`); ``runs`` R.
    """

    seeds: np.ndarray
    trmse: np.ndarray
    final_loglik: np.ndarray
    selected_means: np.ndarray
    sq_err: np.ndarray

    @classmethod
    def of(cls, bank, truth):
        """The tally of a :class:`~shipsense.trackers.bank.bank.BankRun` (positions, likelihoods and the selected
        track kept: :data:`LEAN`) against ``truth`` (R, K, n).  The same numbers as
        :func:`~shipsense.trackers.metrics.trmse` (formed in place: two arrays of the record's (R, H, K) size
        at a time) and ``bank.final_loglik``."""
        sq, dy2 = squared_axis_errors(bank.positions, np.asarray(truth)[:, None])  # (R, H, K) each
        sq_err = np.stack([sq.sum(axis=0), dy2.sum(axis=0)], axis=-1)              # (H, K, 2)
        sq += dy2
        del dy2
        tr = np.sqrt(sq, out=sq).mean(axis=-1)                                     # position_error's numbers
        return cls(np.asarray(bank.seeds), tr, bank.final_loglik, bank.selected_means, sq_err)

    @classmethod
    def concat(cls, parts):
        """One tally of consecutive run chunks' tallies."""
        parts = list(parts)
        cat = {f: np.concatenate([getattr(p, f) for p in parts]) for f in
               ("seeds", "trmse", "final_loglik", "selected_means")}
        return cls(**cat, sq_err=np.sum([p.sq_err for p in parts], axis=0))

    @property
    def runs(self):
        return len(self.trmse)

    @property
    def selected_last(self):
        """The hypothesis selected at the last step (R,)."""
        return np.argmax(self.final_loglik, axis=1)

    def mrmse(self, h):
        """:func:`~shipsense.trackers.metrics.mrmse` of hypothesis ``h``'s track over the runs."""
        ms = self.sq_err[h] / self.runs                                             # (K, 2) mean square errors
        rx, ry = np.sqrt(ms).mean(axis=0)
        return {"x": float(rx), "y": float(ry), "r": float(np.sqrt(ms.sum(axis=1)).mean())}


def bank_tally(unit, model, y, seeds, P0, truth, chunk=RUN_CHUNK):
    """:func:`~shipsense.trackers.bank.bank.run_bank` on passages ``y`` (R >= 1, K, m) from ``seeds`` (R, H, n) and
    ``P0`` (any shape ``run_bank`` takes), run chunk of runs by chunk (:data:`RUN_CHUNK`), without pruning or
    prior likelihoods, tallied against ``truth`` (:class:`BankTally`)."""
    from shipsense.trackers.bank.bank import run_bank

    if len(y) == 0:
        raise ValueError("bank_tally needs at least one run")
    P0 = np.broadcast_to(np.asarray(P0, dtype=float), seeds.shape + seeds.shape[-1:])     # (R, H, n, n)
    parts = []
    for sl in run_chunks(len(y), chunk):
        b = run_bank(unit, model, y[sl], seeds[sl], P0[sl], store=LEAN)
        parts.append(BankTally.of(b, truth[sl]))
        del b
    return BankTally.concat(parts)


def bank_summary(bank, truth, centre=(0.0, 0.0)):
    """Per-hypothesis table and selection figures of a bank over runs (truth (R, K, n)).

    ``bank``: a :class:`~shipsense.trackers.bank.bank.BankRun` or its :class:`BankTally`.  Seed ranges and
    bearings are taken from ``centre`` (the array centroid).  Returns the figures and the TRMSE (R, H)."""
    t = bank if isinstance(bank, BankTally) else BankTally.of(bank, truth)
    tr, final_ll, seeds = t.trmse, t.final_loglik, t.seeds
    rel = seeds[..., :2] - np.asarray(centre)
    hyps = [{"range_m": float(np.mean(np.linalg.norm(rel[:, h], axis=-1))),
             "bearing_rad": float(np.arctan2(rel[0, h, 1], rel[0, h, 0]) % (2 * np.pi)),
             "trmse_m": float(np.nanmean(tr[:, h])),
             "mean_loglik": float(np.nanmean(np.where(np.isfinite(final_ll[:, h]), final_ll[:, h], np.nan)))}
            for h in range(seeds.shape[1])]
    sel = t.selected_last
    sel_means = t.selected_means
    return {
        "hypotheses": hyps,
        "selected_index": int(np.bincount(sel, minlength=seeds.shape[1]).argmax()),
        "selected_mrmse_m": mrmse(sel_means, truth),
        "selection_accuracy": float(np.mean(sel == np.nanargmin(np.where(np.isnan(tr), np.inf, tr), axis=1))),
        "convergence_rate": convergence_rate(sel_means, truth),
    }, tr


def bar_charts(out, name, title, hyp, labels=None):
    """Bar charts of per-hypothesis TRMSE and mean cumulative log-likelihood (:meth:`Output.figure`); the
    hypotheses labelled from 1 unless ``labels`` are given, as the studies' tables number them."""
    return out.figure(name, _bar_charts, title, hyp, labels)


def _bar_charts(title, hyp, labels):
    from shipsense.plotting import plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 4), layout="constrained")
    x = np.arange(len(hyp))
    ax[0].bar(x, [h["trmse_m"] for h in hyp], color="tab:blue")
    ax[0].set_yscale("log")
    ax[0].set_ylabel("TRMSE [m] (mean over runs)")
    ll = np.array([h["mean_loglik"] for h in hyp], dtype=float)
    ax[1].bar(x, ll - np.nanmax(ll), color="tab:orange")
    ax[1].set_yscale("symlog")
    ax[1].set_ylabel("mean final log-likelihood - best [nats]")
    for a in ax:
        a.set_xticks(x, labels if labels is not None else [str(i + 1) for i in x], fontsize=7)
        a.set_xlabel("hypothesis")
        a.grid(alpha=0.3, axis="y")
    fig.suptitle(title)
    return fig


def rmse_plot(out, name, title, times, curves, ylabel="RMSE_k [m]"):
    """Line plot of RMSE_k curves {label: (K,)} (:meth:`Output.figure`)."""
    return out.figure(name, _rmse_plot, title, times, curves, ylabel)


def _rmse_plot(title, times, curves, ylabel):
    from shipsense.plotting import plt

    fig, ax = plt.subplots(figsize=(8, 4.5), layout="constrained")
    for label, c in curves.items():
        ax.plot(times, c, label=label)
    ax.set_yscale("log")
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(title)
    return fig


def prior_grid(sc):
    """The initialiser's grid of start ranges (8, from 20 m to 1.2x the prior's farthest) and speeds (3, over
    the prior's span) for scenario ``sc``."""
    return {"ranges": np.geomspace(20.0, 1.2 * sc.prior.range[1], 8), "speeds": np.linspace(*sc.prior.speed, 3)}


def track_global(unit, model, y, sc, *, refit_peak=None, return_init=False, **options):
    """Global initialiser then the bank, every passage from its own window (one batch).

    Returns estimates (R, K, n) SI, position covariances (R, K, 2, 2) (NaN
    inside the fitted stretch, before the bank starts: NEES assesses the
    bank) and the seconds spent in the initialiser itself (and, with
    ``return_init``, the :class:`~shipsense.trackers.init.global_init.GlobalInit`).
    ``options`` (e.g. ``snr_start``, ``z_std``, ``refine``, ``through_peak``)
    go to :func:`~shipsense.trackers.init.global_init.global_init`.  With ``refit_peak``
    the tracker continues with :func:`refit_stage`.
    """
    from shipsense.reproduce.studies import track_with_global_init
    from shipsense.trackers.init.global_init import global_init, unalign

    t1 = time.perf_counter()
    gi = global_init(model, y, **prior_grid(sc), **options)
    t_init = time.perf_counter() - t1
    est, bank = track_with_global_init(unit, model, y, gi, store=("pos_cov",))   # what is read here
    cov = unalign(bank.selected_pos_cov, gi.start, y.shape[1])
    if refit_peak is not None:
        est, cov = refit_stage(unit, model, y, gi, est, cov, refit_peak, options.get("z_std"))
    return (est, cov, t_init, gi) if return_init else (est, cov, t_init)


def track_restarting(unit, model, y, sc, **options):
    """The project's tracker (:class:`~shipsense.trackers.Tracker`) on passages ``y`` (R, K, m) of scenario
    ``sc`` (the sensors of ``model``), with the filter ``unit`` (None: the tracker's own, as users get it) and
    initialiser ``options`` (``snr_start``, ``refine``, ``explore_samples``, ``z_std``).

    Returns the :class:`~shipsense.trackers.tracker.results.TrackResult` (estimates, covariances and status per
    sample, SI), the seconds per passage spent in the initialiser's window fits, the restarts per passage
    (R,) and the tracker (its state after the last sample: e.g. ``k0``, the detection of each passage).
    """
    from shipsense.trackers import Tracker

    kw = {} if unit is None else {"unit": unit.name}
    tr = Tracker(sc, passages=len(y), sensors=list(model.array.ids), **kw, **options)
    res = tr.track(sc.times[: y.shape[1]], y)
    return res, tr.seconds["initialiser"], tr.state.restarts, tr


def refit_stage(unit, model, y, gi, est, cov, refit_peak, z_std=None):
    """After the closest approach: each passage re-fitted once its signal has fallen to ``refit_peak`` of
    its peak (:func:`~shipsense.reproduce.studies.refit_after_peak`, with the depth prior ``z_std``), then a
    bank without process noise from the fit.  Returns the estimates and position covariances with the
    samples from the refit on replaced."""
    from shipsense.reproduce.studies import continue_from, refit_after_peak
    from shipsense.trackers.init.window_fits import depth_prior

    again = refit_after_peak(model, y, gi, est, refit_peak, prior=depth_prior(model, z_std))
    est, cov, _ = continue_from(unit, model.without_process_noise(), y, again, est, cov)
    return est, cov


def global_init_summary(unit, model, y, truth, sc, snr_start=5.0):
    """The global initialiser on a scenario's runs, then ``unit`` as a bank of its minima (no refits)."""
    from shipsense.trackers.metrics import position_error

    est = np.concatenate([track_global(unit, model, y[sl], sc, snr_start=snr_start)[0]   # passages independent
                          for sl in run_chunks(len(y))])
    return {"convergence_rate": convergence_rate(est, truth), "selected_mrmse_m": mrmse(est, truth),
            "final_error_median_m": float(np.median(position_error(est, truth)[:, -1])),
            "filter": unit.name, "snr_start": snr_start}
