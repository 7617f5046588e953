"""Where the tracker's excess NEES comes from: post-convergence samples split by status, time since the last
refit, outliers, distance to the array, and passage.

Run:  python experiments/tracker_nees_breakdown.py [--family two_magnetometers] [--condition faulty]
      [--passages 200] [--seed 7]

Uses :func:`tracker_consistency.scenario` and the same post-convergence samples as
``experiments/tracker_consistency.py`` (error below 10 m from the sample after which it stays there, while the
tracker reports a track).  Prints coverage of the 95 % ellipse and mean / median position NEES (2 and 1.39 are
consistent) per group, the per-passage coverage quantiles, and the share of samples outside their ellipse that
belong to the worst 10 % of passages.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parent))
import tracker_consistency as tc  # noqa: E402

from shipsense import simulate  # noqa: E402
from shipsense.trackers import Tracker  # noqa: E402
from shipsense.trackers.metrics import converged_until, passage_ends  # noqa: E402
from shipsense.trackers.tracker.results import RESTARTED, STATUSES, TRACKING  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--family", default="two_magnetometers", choices=list(tc.FAMILIES))
    ap.add_argument("--condition", default="faulty", choices=["clean", "faulty"])
    ap.add_argument("--passages", type=int, default=200)
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args(argv)
    sc = tc.scenario(a.family, a.condition)
    sim = simulate(sc, runs=a.passages, seed=a.seed, random=True)
    tr = Tracker(sc, passages=a.passages, sensors=tc.FAMILIES[a.family][1])
    cols = np.isin([c[0] for c in sim.channels], tr.model.array.ids)
    y = sim.measurements[..., cols]
    res = tr.track(sim.times, y)
    truth = tr.model.state_from_truth(sim.truth)
    centre = tr.model.array.positions[:, :2].mean(axis=0)
    conv, err, valid = converged_until(res.estimates, truth, passage_ends(truth, centre, sc.period))
    K = truth.shape[1]
    k = np.arange(K)[None]
    above = np.where(valid, err >= 10.0, False)
    settled = np.where(above.any(axis=1), K - np.argmax(above[:, ::-1], axis=1), 0)
    post = valid & conv[:, None] & (k >= settled[:, None]) & (res.status >= TRACKING)
    d = res.estimates[..., :2] - truth[..., :2]
    q = np.einsum("pki,pkij,pkj->pk", d, np.linalg.inv(res.position_cov), d)
    inside = q <= stats.chi2.ppf(0.95, 2)
    print(f"{a.family} {a.condition}, {a.passages} passages (seed {a.seed}): convergence {conv.mean():.3f}, "
          f"{post.sum()} post-convergence samples, cover95 {inside[post].mean():.3f}, NEES {q[post].mean():.2f} "
          f"(median {np.median(q[post]):.2f})")

    def row(name, m):
        m = m & post
        if m.any():
            print(f"  {name:<26} share {m.sum() / post.sum():.2f}  cover95 {inside[m].mean():.3f}  "
                  f"NEES {q[m].mean():6.2f}  median {np.median(q[m]):.2f}")

    for code in range(TRACKING, len(STATUSES)):
        row(STATUSES[code], res.status == code)
    last = np.maximum.accumulate(np.where(res.status == RESTARTED, k, -1), axis=1)
    since = np.where(last >= 0, k - last, -1)
    for lo, hi in [(0, 1), (1, 3), (3, 6), (6, 11), (11, 21), (21, K)]:
        row(f"{lo}-{hi - 1} samples since refit", (since >= lo) & (since < hi))
    row("no refit yet", since < 0)
    std = np.sqrt(tr.model.R) * tr.model.y_scale
    outlier = (np.nan_to_num(np.abs(y - sim.clean[..., cols])) / std > 4.0).any(axis=-1)
    row("sample with an outlier", outlier)
    row("sample without", ~outlier)
    dist = np.hypot(truth[..., 0] - centre[0], truth[..., 1] - centre[1])
    for lo, hi in [(0, 30), (30, 60), (60, 100), (100, np.inf)]:
        row(f"{lo}-{hi} m from the array", (dist >= lo) & (dist < hi))
    n = post.sum(axis=1)
    out = (post & ~inside).sum(axis=1)
    worst = np.argsort(-out)[:max(1, a.passages // 10)]
    cover = (post & inside).sum(axis=1)[n > 0] / n[n > 0]
    quant = np.round(np.quantile(cover, [0.05, 0.1, 0.25, 0.5, 0.75]), 3)
    share = out[worst].sum() / max(out.sum(), 1)
    print(f"  per-passage cover95 quantiles (5/10/25/50/75 %): {quant}; "
          f"the worst 10 % of passages hold {share:.2f} of the samples outside")


if __name__ == "__main__":
    main()
