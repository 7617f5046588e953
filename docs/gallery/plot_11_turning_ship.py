"""
A ship that turns: the motion modes against the constant-velocity filter
========================================================================

The shipped scenario ``S2-turn`` is S2's pair of magnetometers with a ship that turns 90 degrees to port as it
passes the array and then slows down.  Its ``[tracker.motion]`` table turns on the motion modes: each hypothesis
of the tracker's bank runs an interacting multiple model filter over constant velocity, a turn to either side
and a speed change.  This page tracks the nominal passage, draws the figure ``shipsense track`` writes (the
mode probabilities under the error panel), and tracks the same samples with the constant-velocity filter.
The numbers over many passages, with the command that makes them, are on :doc:`../findings/manoeuvres`.

Full-size command (the same passage)::

    shipsense track S2-turn --out turn-tracked
"""

# %%
# Track the nominal passage the way ``shipsense track S2-turn`` does.
import tempfile
from pathlib import Path

import numpy as np

import shipsense
from shipsense.cli import main
from shipsense.plotting import show_image
from shipsense.trackers import Tracker

out = Path(tempfile.mkdtemp()) / "turn"
assert main(["--quiet", "track", "S2-turn", "--out", str(out)]) == 0

# %%
# ``track.png``: the truth (red), the estimate by status (purple while the manoeuvre modes hold most of the
# probability, green at restarts), 2-sigma ellipses; the error against the reported 2-sigma; and the selected
# hypothesis's mode probabilities over time: the turn modes take over during the turn, the speed mode during
# the slow-down, constant velocity on the straight legs.
show_image(out / "track.png")

# %%
# The same samples through both trackers, in Python: the motion modes against constant velocity only.  The
# constant-velocity tracker follows the line the ship was on; once the ship has turned its samples no longer
# fit and it reports ``inconsistent``.
sc = shipsense.load_scenario("S2-turn")
sim = shipsense.simulate(sc, runs=1, seed=0)
for model in ("imm", "cv"):
    result = Tracker(sc, passages=1, motion={"model": model}).track(sim.times, sim.measurements)
    error = np.hypot(*(result.estimates[0, :, :2] - sim.truth[0, :, :2]).T)
    names = result.status_names()[0]
    after = sim.times >= sim.times[-1] / 2
    print(f"{model:3s}: median position error over the second half {np.nanmedian(error[after]):6.2f} m, "
          f"'inconsistent' on {np.mean(names[after] == 'inconsistent'):.0%} of its samples")
