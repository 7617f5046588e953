"""
The wide-prior study: the studies' bank against the global initialiser
=======================================================================

Passages start anywhere in a wide prior (any bearing, a range of start distances, any course past the array),
not near a known point.  Per family (one magnetometer, two magnetometers, electrode envelopes of S1-P2), four
methods: the studies' multiple-initial-value bank, the global initialiser feeding a bank, the same with a
refit after the closest approach, and the project's tracker.  This page runs 10 passages per family instead
of 500, in this process; the full run's table and discussion are in :doc:`../findings/wide`.

Full-size command (about 2 minutes on two local Dask workers)::

    shipsense reproduce wide --out results/wide     # 500 passages per family
"""

# %%
import csv
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from shipsense.cli import main

RUNS = 10
out = Path(tempfile.mkdtemp()) / "wide"
assert main(["--quiet", "reproduce", "wide", "--runs", str(RUNS), "--workers", "0", "--out", str(out)]) == 0
rows = list(csv.DictReader((out / "wide.csv").open()))
print(f"{'family':<18} {'method':<22} {'converged':>9} {'MRMSE_r m':>10} {'NEES':>8}")
for r in rows:
    print(f"{r['family']:<18} {r['method']:<22} {float(r['convergence_rate']):>9.2f} "
          f"{float(r['mrmse_r_m']):>10.2f} {float(r['nees_mean']):>8.2f}")

# %%
# The study writes tables, not figures; this script draws its two headline numbers per family and method:
# the share of passages that converge, and the mean position NEES (2 is honest; log scale).
families = list(dict.fromkeys(r["family"] for r in rows))
methods = list(dict.fromkeys(r["method"] for r in rows))
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5), layout="constrained")
width = 0.8 / len(methods)
for j, method in enumerate(methods):
    conv = [float(next(r for r in rows if r["family"] == f and r["method"] == method)["convergence_rate"])
            for f in families]
    nees = [float(next(r for r in rows if r["family"] == f and r["method"] == method)["nees_mean"])
            for f in families]
    x = np.arange(len(families)) + (j - (len(methods) - 1) / 2) * width
    ax1.bar(x, conv, width, label=method)
    ax2.bar(x, nees, width, label=method)
ax2.axhline(2.0, color="k", ls=":", lw=1, label="consistent (2)")
ax2.set_yscale("log")
for ax, title in ((ax1, "convergence rate"), (ax2, "mean position NEES")):
    ax.set_xticks(np.arange(len(families)), families)
    ax.set_title(f"{title} ({RUNS} passages per family)")
    ax.grid(alpha=0.3, axis="y")
fig.legend(*ax2.get_legend_handles_labels(), loc="outside lower center", ncols=5, fontsize=8)
