"""shipsense: track ships from their influence fields on seabed sensors, and design the arrays.

Public entry points:

* :func:`shipsense.load_scenario` -- a validated scenario (shipped name or TOML path).
* :func:`shipsense.simulate` -- truth and measurements of passages, batched over runs.
* :mod:`shipsense.physics` -- the field kernels (magnetic dipole, HED in a layered sea,
  envelope chain, seismic bearing, motion and noise models).
"""

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version

from shipsense.envs import register_envs

register_envs()

try:
    __version__ = version("shipsense")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

_LAZY = {"Scenario": "shipsense.config", "ScenarioError": "shipsense.config",
         "load_scenario": "shipsense.config", "shipped_scenarios": "shipsense.config",
         "STATE_LABELS": "shipsense.simulator", "Simulation": "shipsense.simulator",
         "simulate": "shipsense.simulator", "tune_allocator": "shipsense.allocator"}


def __getattr__(name):
    """The public names, imported on first use: ``import shipsense`` itself only registers the environments
    (measured by ``benchmarks/import_time.py``)."""
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'shipsense' has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *_LAZY])

__all__ = ["STATE_LABELS", "Scenario", "ScenarioError", "Simulation", "load_scenario", "shipped_scenarios",
           "simulate", "tune_allocator", "__version__"]
