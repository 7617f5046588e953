"""A sweep's tidy results: one row per cell and metric, with 95 % intervals across passages, and the plots.

Metrics (``metric`` column; ``value``, ``ci_lo``, ``ci_hi``, ``n``):

* ``convergence_rate`` over all the cell's passages (Wilson interval);
* ``rmse_m``: root of the mean squared error of the converged passages (the
  interval is the mean's normal interval, then the root);
* ``rmse_over_crlb``, ``nees_mean``, ``nees_coverage``: means over the
  converged passages (normal intervals);
* ``seconds_per_passage``: tracking time (machine-dependent);
* ``ambiguous`` (1 ambiguous, 0 not; ``n`` = 1) and ``min_chi2`` from the
  cell's ambiguity check; its ``verdict`` is a column of every row of the cell.

Every row also has the cell key, the layout, one column per condition key
and a readable ``condition`` label.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from shipsense.sweep.spec import SweepError
from shipsense.sweep.store import write_table
from shipsense.tasks import CHUNKS

Z95 = 1.959963984540054
METRIC_OF = {"convergence": ["convergence_rate"], "rmse": ["rmse_m"], "rmse_over_crlb": ["rmse_over_crlb"],
             "nees_coverage": ["nees_mean", "nees_coverage"], "time": ["seconds_per_passage"],
             "ambiguity": ["ambiguous", "min_chi2"]}
LABELS = {"convergence_rate": "convergence rate", "rmse_m": "RMSE of converged passages [m]",
          "rmse_over_crlb": "RMSE / CRLB", "nees_mean": "mean position NEES (2 = consistent)",
          "nees_coverage": "truth inside the 95 % ellipse", "seconds_per_passage": "tracking time per passage [s]",
          "ambiguous": "ambiguous (1) or not (0)", "min_chi2": "closest other passage [chi-square]"}


def wilson(k: int, n: int) -> tuple[float, float]:
    """95 % Wilson score interval of a proportion ``k / n``."""
    if n == 0:
        return (math.nan, math.nan)
    p = k / n
    d = 1 + Z95**2 / n
    c = (p + Z95**2 / (2 * n)) / d
    h = Z95 * math.sqrt(p * (1 - p) / n + Z95**2 / (4 * n * n)) / d
    return (max(0.0, c - h), min(1.0, c + h))


def _mean_ci(v):
    v = np.asarray(v, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return math.nan, math.nan, math.nan, 0
    m = float(v.mean())
    h = Z95 * float(v.std(ddof=1)) / math.sqrt(v.size) if v.size > 1 else math.nan
    return m, m - h, m + h, int(v.size)


def condition_label(cond: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in cond.items()) or "base"


def cell_metrics(passages, amb) -> list[tuple]:
    """(metric, value, ci_lo, ci_hi, n) rows of one cell from its passage rows and ambiguity row (or None)."""
    rows = []
    if passages is not None and len(passages):
        conv = passages["converged"].to_numpy(bool)
        rows.append(("convergence_rate", float(conv.mean()), *wilson(int(conv.sum()), conv.size), conv.size))
        good = passages[conv]
        m, lo, hi, n = _mean_ci(good["rmse_m"].to_numpy() ** 2)
        rows.append(("rmse_m", math.sqrt(m) if n else math.nan, math.sqrt(max(lo, 0.0)) if n > 1 else math.nan,
                     math.sqrt(hi) if n > 1 else math.nan, n))
        for col in ("rmse_over_crlb", "nees_mean", "nees_coverage"):
            rows.append((col, *_mean_ci(good[col].to_numpy())))
        rows.append(("seconds_per_passage", *_mean_ci(passages["seconds"].to_numpy())))
    if amb is not None:
        v = amb["verdict"]
        rows.append(("ambiguous", float(v == "ambiguous"), math.nan, math.nan, 1))
        rows.append(("min_chi2", float(amb["min_chi2"]), math.nan, math.nan, 1))
    return rows


def summarise(spec, cells, out: Path, csv: bool = False):
    """Read every task's file in ``out/chunks`` and write ``results.parquet`` (+ csv) and ``passages.parquet``."""
    import pandas as pd

    chunks = out / CHUNKS
    frames = [pd.read_parquet(chunks / f"{c.key}-c{i:05d}.parquet")
              for c in cells for i in range(math.ceil(spec.passages / spec.chunk))]
    passages = pd.concat(frames, ignore_index=True).sort_values(["cell", "passage"], kind="stable")
    order = {c.key: c.index for c in cells}
    passages = passages.iloc[np.argsort(passages["cell"].map(order).to_numpy(), kind="stable")]
    amb = {}
    if "ambiguity" in spec.metrics:
        for c in cells:
            amb[c.key] = pd.read_parquet(chunks / f"{c.key}-ambiguity.parquet").iloc[0]
    keys = list(spec.conditions)
    wanted = {m for name in spec.metrics for m in METRIC_OF[name]}
    by_cell = dict(tuple(passages.groupby("cell", sort=False)))
    rows = []
    for c in cells:
        verdict = amb[c.key]["verdict"] if c.key in amb else None
        for metric, value, lo, hi, n in cell_metrics(by_cell.get(c.key), amb.get(c.key)):
            if metric in wanted:
                cond = {k: json.dumps(c.condition[k]) if isinstance(c.condition.get(k), list) else c.condition.get(k)
                        for k in keys}
                rows.append({"cell": c.key, "layout": c.layout, **cond, "condition": condition_label(c.condition),
                             "method": spec.method, "metric": metric, "value": value, "ci_lo": lo, "ci_hi": hi,
                             "n": n, "verdict": verdict})
    results = pd.DataFrame(rows)
    write_table(out / "passages.parquet", passages.reset_index(drop=True))
    write_table(out / "results.parquet", results)
    if csv:
        write_table(out / "results.csv", results)
    plot_results(results, out)
    return results


def plot_results(results, out: Path) -> list[Path]:
    """One PNG per metric: each condition a row, each layout a marker with its 95 % interval."""
    from shipsense.plotting import plt

    paths = []
    layouts = list(dict.fromkeys(results["layout"]))
    conditions = list(dict.fromkeys(results["condition"]))
    colours = plt.get_cmap("tab10")
    for metric, df in results.groupby("metric", sort=False):
        fig, ax = plt.subplots(figsize=(8, 1.2 + 0.35 * len(conditions) * max(1, len(layouts) / 4)),
                               layout="constrained")
        step = 0.8 / max(1, len(layouts))
        for j, lay in enumerate(layouts):
            d = df[df["layout"] == lay].set_index("condition").reindex(conditions)
            yy = np.arange(len(conditions)) - 0.4 + step * (j + 0.5)
            err = np.abs(np.vstack([d["value"] - d["ci_lo"], d["ci_hi"] - d["value"]]))
            ax.errorbar(d["value"], yy, xerr=np.where(np.isfinite(err), err, 0.0), fmt="o", ms=4, capsize=2,
                        color=colours(j % 10), label=lay)
        ax.set_yticks(np.arange(len(conditions)), conditions, fontsize=7)
        ax.invert_yaxis()
        ax.set_xlabel(LABELS.get(metric, metric))
        ax.grid(alpha=0.3, axis="x")
        ax.legend(fontsize=7, title="layout", loc="best")
        path = out / f"{metric}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        paths.append(path)
    return paths


def report(out) -> list[Path]:
    """Re-draw a finished sweep's plots from its stored ``results.parquet``."""
    import pandas as pd

    out = Path(out)
    path = out / "results.parquet"
    if not (out / "sweep.json").is_file() or not path.is_file():
        raise SweepError(f"{out}: no finished sweep here (results.parquet and sweep.json are needed)")
    return plot_results(pd.read_parquet(path), out)
