"""Forward models: pure, vectorised field kernels in SI units.

Every kernel takes positions and moments with arbitrary leading batch axes and
a trailing axis of 3, broadcasts them against each other, and does no input
validation (that happens once, in :mod:`shipsense.config`).
"""

from shipsense.physics.electric import Medium, hed_field, hed_potential
from shipsense.physics.magnetic import dipole_field, earth_field_direction

__all__ = ["Medium", "dipole_field", "earth_field_direction", "hed_field", "hed_potential"]
