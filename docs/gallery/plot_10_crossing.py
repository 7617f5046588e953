"""
Two ships crossing: counted, labelled and scored by GOSPA
=========================================================

Two ships cross 30 m apart past S2's pair of vector magnetometers (the shipped scenario ``S2-crossing``: the
second ship crosses the first at right angles, meeting it at the first's closest approach to the array).
Each magnetometer reads the sum of both ships' fields.  The several-ship tracker
(:class:`~shipsense.trackers.ships.ShipsTracker`) follows the first ship with the one-ship tracker, finds
the second on the residual, carries both with a joint filter and ends a ship that has left the array's reach.
This page tracks the scenario's nominal passage; the table over hundreds of random passages, and how it
falls off as the ships come closer, is in :doc:`../findings/ships`.

Full-size command (random passages; a few minutes per hundred passages on two cores)::

    PYTHONPATH=. python experiments/several_ships.py --passages 300
    shipsense track S2-crossing --ships auto --out crossing     # this passage, from the command line
"""

# %%
# Simulate the passage and track it with up to two ships.  A true ship counts (for the number of ships and
# for GOSPA) where its own one-ship position bound is at most 5 m, as in the experiment: a ship far out has a
# field below the noise, and no tracker should be asked to report it.
import sys
from pathlib import Path

import numpy as np

import shipsense
from shipsense.models.field_model import model_from_scenario
from shipsense.plotting import plot_ships
from shipsense.trackers import metrics
from shipsense.trackers.ships import ShipsTracker

sys.path.insert(0, str(Path(shipsense.__file__).resolve().parents[1] / "experiments"))
import several_ships  # noqa: E402

sc = shipsense.load_scenario("S2-crossing")
sim = shipsense.simulate(sc, runs=1)
y = sim.measurements[..., :6]                      # M1 and M2, three components each (not the accelerometer)
tracker = ShipsTracker(sc, sensors=several_ships.SENSORS)
result = tracker.track(sim.times, y)

ships = np.moveaxis(sim.ships, 1, 2)               # (runs, samples, ships, state)
here = several_ships.presence(sc, model_from_scenario(sc, sensors=several_ships.SENSORS), ships)
truth = np.where(here[..., None], ships, np.nan)
half = slice(sim.times.size // 2, None)
g = metrics.gospa(result.estimates[:, half], truth[:, half])
a = metrics.label_assignment(result.estimates, truth)
rmse = metrics.ship_rmse(result.estimates[:, half], truth[:, half], a)
print(f"track 2 born at t = {sim.times[result.born[0, 1]]:.1f} s" if result.born[0, 1] >= 0 else "no second ship")
print(f"second half: right number of ships on {metrics.cardinality_rate(result.estimates[:, half], truth[:, half]):.2f}"
      f" of the samples, mean GOSPA {g.total.mean():.2f} m")
print("true ship -> track:", {j: int(i) + 1 for j, i in enumerate(a[0])}, " second-half RMSE per ship [m]:",
      np.round(rmse[0], 2))

# %%
# Left: the true ships (dashed), each track in its own colour with 2-sigma ellipses (a dot where the track
# begins).  Track 1 is the ship the one-ship tracker found first, track 2 the one born on its residual; the
# labels persist through the crossing.  Right: the number of ships tracked against the true ships that count,
# and GOSPA (c = 20 m) with its parts: a missed or a false ship adds c / sqrt(2) = 14.1 m, so the curve shows
# when the count is wrong as well as how far off the tracks are.
fig = plot_ships(result, tracker.base.array, truth=sim.ships[0], present=here[0].T,
                 title="S2-crossing: two ships, 30 m apart at the crossing (2-sigma ellipses)")
