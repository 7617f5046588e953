"""
The demo: one passage, tracked with no prior on where the ship is
==================================================================

``shipsense demo`` simulates a ship passing the default array (three seabed nodes, each with a vector
magnetometer and an electrode envelope triad, and an accelerometer at the first) and tracks it with the
project's tracker.  This page runs the same code as the command, at its full size (it is small already).

Full-size command (the same)::

    shipsense demo --out shipsense-demo
"""

# %%
# Run the demo into a scratch folder: it prints the sensors' table and what the tracker reported at the end.
import tempfile
from pathlib import Path

from shipsense.cli import main
from shipsense.plotting import show_image

out = Path(tempfile.mkdtemp()) / "demo"
assert main(["--quiet", "demo", "--out", str(out)]) == 0


# %%
# ``demo.png``: on the left the true track (red), the estimate by status (green dots: restarts from batch
# refits), the sensors and 2-sigma ellipses; on the right the position error against the reported 2-sigma.
# The estimate starts once the first window has been fitted; an honest tracker's error stays mostly below
# its 2-sigma.
show_image(out / "demo.png")

# %%
# ``measurements.png``: the sensors' traces (field components in SI units, and the bearing).
show_image(out / "measurements.png")

# %%
# ``estimates.csv`` holds the same per sample: state, standard deviations, covariance, status.
print((out / "estimates.csv").read_text().splitlines()[0])
print(*(out / "estimates.csv").read_text().splitlines()[40:43], sep="\n")
