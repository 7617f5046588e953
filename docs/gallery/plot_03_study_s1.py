"""
Study S1: electrode envelopes and the PUEKF bank
================================================

The second source study: envelope electrodes (the shaft-rate electric field's envelope per channel) lose the
sign of each component, so one sensor cannot tell mirrored passages apart; three sensors on a line (P1) are
ambiguous, a triangle (P2) is not.  This page runs ``shipsense reproduce S1`` with 10 runs instead of 100; the
full run's numbers and the verdicts are in :doc:`../findings/studies`.

Full-size command::

    shipsense reproduce S1 --out results/S1        # 100 runs, seed 0
"""

# %%
import tempfile
from pathlib import Path

from shipsense.cli import main
from shipsense.plotting import show_image

out = Path(tempfile.mkdtemp()) / "S1"
assert main(["--quiet", "reproduce", "S1", "--runs", "10", "--out", str(out)]) == 0
print((out / "symmetry_table.csv").read_text())


# %%
# Exp. 1, the signal symmetry (``symmetry.png``): the envelopes of four passages mirrored about the axes.
show_image(out / "symmetry.png")

# %%
# Exp. 2, the arrays (``arrays.png``): P1 (collinear) and P2 (a triangle).
show_image(out / "arrays.png")

# %%
# The banks on P1 and P2 (``P1_bars.png``, ``P2_bars.png``): per hypothesis, how often it converges to the
# truth or to the mirror track.
show_image(out / "P1_bars.png")
show_image(out / "P2_bars.png")

# %%
# RMSE over time of the selected track on P1 and P2 (``P1_vs_P2_rmse.png``).
show_image(out / "P1_vs_P2_rmse.png")
