"""Time to first track: the samples a tracker still spends initialising although the data already locate the ship.

Run:  python experiments/first_track.py [--passages 200] [--family NAME ...] [--condition clean [faulty]]
                                        [--out results/first_track]

Passages: the consistency experiment's (``experiments/tracker_consistency.py``: its families -- one
magnetometer S0, the S2 pair M1/M2, the S1-P2 envelopes -- random passages from each scenario's prior, its
seeds in chunks of 100, clean and with its faults).  The project's tracker
(:class:`shipsense.trackers.Tracker`, its defaults) tracks them; the bound is the constant-velocity CRLB of
each sample (:func:`shipsense.sweep.evaluate.crlb_position`: every sample up to it, the bank's prior).

The samples judged are the ``located`` ones, where the bound's position standard deviation along its larger
axis (:func:`shipsense.trackers.metrics.crlb_sd`) is under 5 m.  Per family and condition:

* ``initialising``: the share of located samples still ``initialising`` (or ``no data``), and the passages
  with any such sample;
* over the located samples the tracker reports a track on (every status but those two):
  ``rmse_over_crlb``, the RMSE of the position against the root-mean of the bound's position trace on the
  same samples (1 is efficient), and ``coverage``, the share with the truth inside the reported 95 %
  ellipse (0.95 is honest);
* the same two over the ``early`` located samples: those before the detection's full initialisation window
  (``window_s``) has passed, which a tracker that waits for the complete window reports as initialising;
* ``seconds_per_passage``: tracking time.

Writes ``first_track.json`` and ``.csv``.
"""

from __future__ import annotations

import json
import time
from itertools import product
from pathlib import Path

import numpy as np
from tracker_consistency import (  # (this folder: the consistency experiment's passages)
    FAMILIES,
    chunks,
    passage_arguments,
    scenario,
)

from shipsense import simulate
from shipsense.sweep.evaluate import crlb_position
from shipsense.trackers import Tracker
from shipsense.trackers.metrics import crlb_sd, position_crlb_trace, position_nees
from shipsense.trackers.tracker.results import INITIALISING, NO_DATA

LOCATED_SD_M = 5.0
INSIDE_95 = 5.991464547107979   # chi-square (2 dof) 95 % quantile


def chunk_stats(family, condition, seed, passages):
    """Sums over one chunk of passages."""
    sc = scenario(family, condition)
    sim = simulate(sc, runs=passages, seed=seed, random=True)
    tr = Tracker(sc, passages=passages, sensors=FAMILIES[family][1])
    cols = np.isin([c[0] for c in sim.channels], tr.model.array.ids)
    t0 = time.perf_counter()
    res = tr.track(sim.times, sim.measurements[..., cols])
    seconds = time.perf_counter() - t0
    truth = tr.model.state_from_truth(sim.truth)
    block = crlb_position(sc, tr.model, truth)
    located = crlb_sd(block) < LOCATED_SD_M
    waiting = np.isin(res.status, (INITIALISING, NO_DATA))
    shown = located & ~waiting
    k = np.arange(truth.shape[1])[None, :]
    k0 = np.where(tr.state.k0 >= 0, tr.state.k0, truth.shape[1])
    early = shown & (k < k0[:, None] + tr.window)
    err2 = np.sum((res.estimates[..., :2] - truth[..., :2]) ** 2, axis=-1)
    inside = position_nees(res.estimates, res.covs, truth) <= INSIDE_95
    bound = position_crlb_trace(block)

    def sums(mask):
        return [int(mask.sum()), float(err2[mask].sum()), float(bound[mask].sum()), int(inside[mask].sum())]

    return {"located": int(located.sum()), "waiting": int((located & waiting).sum()),
            "passages_waiting": int((located & waiting).any(axis=1).sum()), "shown": sums(shown),
            "early": sums(early), "seconds": seconds, "passages": passages}


def summarise(parts):
    tot = {key: np.sum([p[key] for p in parts], axis=0) for key in parts[0]}

    def figures(name):
        n, e2, b2, inside = tot[name]
        return {f"{name}_samples": int(n), f"{name}_rmse_over_crlb": float(np.sqrt(e2 / max(b2, 1e-300))),
                f"{name}_coverage": float(inside / max(n, 1))}

    return {"passages": int(tot["passages"]), "located": int(tot["located"]),
            "initialising": float(tot["waiting"] / max(tot["located"], 1)),
            "passages_initialising": int(tot["passages_waiting"]), **figures("shown"), **figures("early"),
            "seconds_per_passage": float(tot["seconds"] / tot["passages"])}


def main(argv=None):
    args = passage_arguments(__doc__.splitlines()[0], "results/first_track", passages=200,
                             conditions=["clean"]).parse_args(argv)
    out = Path(args.out)
    results = []
    print(f"{'family':<18} {'condition':<9} {'located':>8} {'initialising':>12} {'(passages)':>10} "
          f"{'RMSE/CRLB':>9} {'cover95':>7} {'early':>6} {'RMSE/CRLB':>9} {'cover95':>7} {'s/passage':>9}")
    for family, condition in product(args.family, args.condition):
        r = {"family": family, "condition": condition, **summarise(chunks(args, chunk_stats, family, condition))}
        results.append(r)
        print(f"{family:<18} {condition:<9} {r['located']:>8d} {r['initialising']:>12.2%} "
              f"{r['passages_initialising']:>10d} {r['shown_rmse_over_crlb']:>9.2f} {r['shown_coverage']:>7.3f} "
              f"{r['early_samples']:>6d} {r['early_rmse_over_crlb']:>9.2f} {r['early_coverage']:>7.3f} "
              f"{r['seconds_per_passage']:>9.3f}", flush=True)
    (out / "first_track.json").write_text(json.dumps(results, indent=2) + "\n")
    keys = list(results[0])
    (out / "first_track.csv").write_text(
        "\n".join([",".join(keys)] + [",".join(str(r[k]) for k in keys) for r in results]) + "\n")
    print(f"wrote {out}/first_track.json and .csv")


if __name__ == "__main__":
    main()
