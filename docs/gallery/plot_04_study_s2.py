"""
Study S2: two magnetometers, outliers and seismic fusion
========================================================

The third source study: one magnetometer against two, the Huber UKF under outliers, the seismic bearing at
low SNR, and the field trial (three collinear nodes beside a road, misaligned magnetometers, biased bearings)
tracked by the project's tracker.  This page runs ``shipsense reproduce S2`` with 4 runs instead of 100 (and
4 instead of 30 for the field trial); the full run's numbers and the verdicts are in
:doc:`../findings/studies`.

Full-size command::

    shipsense reproduce S2 --out results/S2        # 100 runs (30 for the field trial), seed 0
"""

# %%
import tempfile
from pathlib import Path

from shipsense.cli import main
from shipsense.plotting import show_image

out = Path(tempfile.mkdtemp()) / "S2"
assert main(["--quiet", "reproduce", "S2", "--runs", "4", "--out", str(out)]) == 0
print((out / "one_vs_two.csv").read_text())


# %%
# Exp. 1, one against two magnetometers (``one_vs_two_rmse.png``): RMSE over time from each start offset.
show_image(out / "one_vs_two_rmse.png")

# %%
# Exp. 4, the field trial (``field_trial.png``): the tracked road passages.
show_image(out / "field_trial.png")
