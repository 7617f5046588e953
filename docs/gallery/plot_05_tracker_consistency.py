"""
The tracker's consistency: is the reported covariance honest?
=============================================================

The project's tracker against the source studies' bank on random passages of three families (one
magnetometer, S0; two magnetometers, S2's M1 and M2; electrode envelopes, S1-P2), clean and faulty (20 %
outliers of ten standard deviations and 30 % of the values missing).  For each: convergence, RMSE against the
CRLB, the mean position NEES (2 is consistent) and the share of samples inside the reported 95 % ellipse.
This page runs 6 passages per family and condition instead of 1,000; the full table is in
:doc:`../findings/tracker`.

Full-size command (about an hour on two cores)::

    python experiments/tracker_consistency.py --out results/tracker     # 1,000 passages each
"""

# %%
# ``experiments/tracker_consistency.py`` prints one row per family, condition and method and draws the
# calibration curves.
import sys
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

import shipsense

sys.path.insert(0, str(Path(shipsense.__file__).resolve().parents[1] / "experiments"))
import tracker_consistency  # noqa: E402

out = Path(tempfile.mkdtemp())
tracker_consistency.main(["--passages", "6", "--out", str(out)])

# %%
# The calibration curves (``coverage-all.png``): the share of post-convergence samples inside the reported
# ellipse of each probability.  A calibrated tracker lies on the diagonal; one below it is overconfident.
# With 6 passages the curves are rough; at 1,000 the tracker's lie near the diagonal, the bank's far below.
image = plt.imread(out / "coverage-all.png")
fig = plt.figure(figsize=(image.shape[1] / 110, image.shape[0] / 110))
fig.figimage(image, resize=True)
