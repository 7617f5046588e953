"""Layout studies at scale: ``shipsense sweep`` -- layouts x site conditions x passages, on Dask, resumable.

A sweep file (:mod:`shipsense.sweep.spec`) lists candidate layouts and site
conditions; every (layout, condition) cell is a validated scenario whose
passages are tracked and scored in chunks (:mod:`~shipsense.sweep.cells`,
:mod:`~shipsense.sweep.evaluate`), each chunk a pure task with a seed derived
from the sweep seed and the cell.  :func:`run_sweep` runs them serially or on
a Dask cluster and writes each finished chunk atomically, so an interrupted
sweep resumes where it stopped (:mod:`~shipsense.sweep.runner`); the results
are tidy tables and plots (:mod:`~shipsense.sweep.results`).
"""

from shipsense.sweep.results import report
from shipsense.sweep.runner import SweepRun, run_sweep, sweep_hash
from shipsense.sweep.spec import SweepError, SweepSpec, load_sweep, parse_sweep

EXAMPLE = '''\
# An example layout study (`shipsense sweep --example > sweep.toml`): 6 layouts of vector magnetometers
# x 18 site conditions = 108 cells, 8 passages each; a few minutes on 2 cores.
name = "magnetometer-layouts"
scenario = "S2"          # base scenario: medium, noise, prior, period, tracker
template = "M1"          # the sensor the generated layouts copy
seed = 0
passages = 8             # Monte Carlo passages per cell
chunk = 4                # passages per task
method = "tracker"       # tracker | bank
metrics = ["convergence", "rmse", "rmse_over_crlb", "nees_coverage", "ambiguity", "time"]
combine = "product"      # every combination of the [conditions] lists

[[layouts]]
name = "pair"
generator = "line"
n = 2
spacing = 10.0
angle_deg = 0.0          # an east-west line

[[layouts]]
name = "line-3"
generator = "line"
n = 3
spacing = 10.0
angle_deg = 0.0

[[layouts]]
name = "triangle"
generator = "triangle"
side = 10.0

[[layouts]]
name = "grid-2x2"
generator = "grid"
shape = [2, 2]
spacing = 10.0

[[layouts]]
name = "grid-3x2"
generator = "grid"
shape = [3, 2]
spacing = 8.0

[[layouts]]
name = "line-4"
generator = "line"
n = 4
spacing = 7.0
angle_deg = 90.0         # a north-south line

# [[layouts]]
# name = "designed"
# file = "layout.toml"   # any scenario or layout file, e.g. written by `shipsense design`

[conditions]
noise_scale = [1.0, 3.0, 10.0]        # x the scenario's noise standard deviation
source_scale = [0.3, 1.0, 3.0]        # x the moment of the passages
prior_range = [[50.0, 150.0], [100.0, 300.0]]   # start range of the passages, m
'''
"""An example sweep file (108 cells): what ``shipsense sweep --example`` prints."""

__all__ = ["EXAMPLE", "SweepError", "SweepRun", "SweepSpec", "load_sweep", "parse_sweep", "report", "run_sweep",
           "sweep_hash"]
