"""SensorArray.measure: the stacked channels of mixed arrays equal the kernels applied sensor by sensor."""

import numpy as np
import pytest

from shipsense.physics.array import SensorArray
from shipsense.physics.electric import Medium, hed_field
from shipsense.physics.magnetic import dipole_field
from shipsense.physics.seismic import bearing

KINDS = [("magnetometer", "vector"), ("magnetometer", "magnitude"), ("magnetometer", "tmi"),
         ("electrode", "vector"), ("electrode", "envelope"), ("electrode", "magnitude"), ("accelerometer", "bearing")]
EARTH = np.array([0.0, 0.5, -np.sqrt(0.75)])


def _per_sensor(arr, medium, q, m, p):
    """The channels built one sensor at a time from the field kernels (independent of measure's stacking)."""
    out = []
    for s, (t, k) in enumerate(zip(arr.types, arr.kinds)):
        pos, R = arr.positions[s], arr.orientations[s]
        if t == "magnetometer":
            B = dipole_field(pos, q, m)
            out += {"vector": list(np.moveaxis(B @ R, -1, 0)), "magnitude": [np.linalg.norm(B, axis=-1)],
                    "tmi": [B @ EARTH]}[k]
        elif t == "electrode":
            E = hed_field(pos, q, p, medium, method="fast") @ R
            out += {"vector": list(np.moveaxis(E, -1, 0)), "envelope": list(np.moveaxis(np.abs(E), -1, 0)),
                    "magnitude": [np.linalg.norm(E, axis=-1)]}[k]
        else:
            out.append(bearing(pos, q))
    return np.stack(np.broadcast_arrays(*out), axis=-1)


@pytest.mark.parametrize("seed", range(8))
def test_mixed_arrays_in_any_sensor_order_match_the_kernels(seed):
    rng = np.random.default_rng(seed)
    S = int(rng.integers(2, 7))
    kinds = [KINDS[i] for i in rng.integers(0, len(KINDS), S)]
    pos = np.column_stack([rng.normal(size=(S, 2)) * 50, np.full(S, -20.0)])
    R = np.stack([np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(S)]) if seed % 2 else None
    medium = Medium()
    arr = SensorArray([f"s{i}" for i in range(S)], [k[0] for k in kinds], [k[1] for k in kinds], pos, R,
                      medium=medium, earth_direction=EARTH)
    q = np.column_stack([rng.normal(size=(6, 2)) * 100, np.full(6, -5.0)]).reshape(2, 3, 3)
    m = rng.normal(size=(2, 3, 3)) * 1e6
    p = np.concatenate([rng.normal(size=(3, 2)) * 100, np.zeros((3, 1))], axis=-1)   # broadcasts over the batch
    y = arr.measure(q, m, p)
    assert y.shape == (2, 3, arr.n_channels)
    np.testing.assert_allclose(y, _per_sensor(arr, medium, q, m, p), rtol=1e-9, atol=1e-30)
