"""shipsense: track ships from their influence fields on seabed sensors, and design the arrays.

Public entry points:

* :func:`shipsense.load_scenario` -- a validated scenario (shipped name or TOML path).
* :func:`shipsense.simulate` -- truth and measurements of passages, batched over runs.
* :mod:`shipsense.physics` -- the field kernels (magnetic dipole, HED in a layered sea,
  envelope chain, seismic bearing, motion and noise models).
"""

from importlib.metadata import PackageNotFoundError, version

from shipsense.allocator import tune_allocator
from shipsense.config import Scenario, ScenarioError, load_scenario, shipped_scenarios
from shipsense.envs import register_envs
from shipsense.simulator import STATE_LABELS, Simulation, simulate

register_envs()

try:
    __version__ = version("shipsense")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

__all__ = ["STATE_LABELS", "Scenario", "ScenarioError", "Simulation", "load_scenario", "shipped_scenarios",
           "simulate", "tune_allocator", "__version__"]
