"""State-space and measurement models of a passage: imported by the simulator's users, the trackers, the design
tools and the environments; they import no fitter and no filter.

* :mod:`~shipsense.models.field_model`: :class:`FieldModel` (the array's measurement model over the
  constant-velocity state with the source's moment), :class:`LinearModel`, and the constructors from a scenario.
* :mod:`~shipsense.models.measurement`: the compiled measurement kernel (readings and Jacobians of one state at
  a time, for numba loops).
* :mod:`~shipsense.models.transitions`: the state's transitions over time.
"""

from shipsense.models.field_model import (
    FieldModel,
    LinearModel,
    candidate_model,
    model_from_scenario,
    subset_array,
    subset_model,
)
from shipsense.models.transitions import powers, shared_powers, transitions

__all__ = ["FieldModel", "LinearModel", "candidate_model", "model_from_scenario", "powers", "shared_powers",
           "subset_array", "subset_model", "transitions"]
