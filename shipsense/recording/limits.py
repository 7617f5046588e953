r"""The physical range of a recorded value, per sensor kind.

A value outside its sensor's range is not a measurement: a corrupted sample (``1e308``), a value in other
units than SI (nanotesla written as tesla, degrees as radians) or a signed value on a channel that can only be
positive.  A recording that holds one is refused (:class:`~shipsense.recording.samples.RecordingError`), never
tracked as if it were real.

* :data:`FIELD_LIMIT`: the largest magnitude of a value, per sensor type.  A magnetometer's 0.1 T is two
  thousand times the Earth's field and far beyond any magnetometer's range (fluxgates read up to about
  :math:`10^{-4}`-:math:`10^{-3}` T); a ship's anomaly a few metres from its keel is well inside it, and a
  value in nanotesla written as tesla (``98.3`` for 98.3 nT) is outside.  An electrode's 1 V/m is far
  beyond any field in sea water near a ship (micro- to millivolts a metre) and below a value in microvolts
  a metre written as V/m.  A bearing is an angle in radians: beyond :math:`2\pi` it is in degrees.
* :data:`MAGNITUDES`: the kinds whose every channel is a magnitude (an electrode's envelopes and magnitude, a
  magnetometer's magnitude): such a value is never negative.  Additive noise can take a small magnitude
  below zero, so the floor is :math:`-k\,\sigma_j\,s` with :math:`k` = :data:`NEGATIVE_SIGMAS`,
  :math:`\sigma_j` the scenario's noise standard deviation of the channel, and :math:`s` the outliers' scale
  when the scenario's noise model is contaminated (else 1).  A total-field anomaly (``tmi``) is signed.
"""

from __future__ import annotations

import math

import numpy as np

FIELD_LIMIT = {"magnetometer": 0.1, "electrode": 1.0, "accelerometer": 2 * math.pi}
"""Largest magnitude of a value per sensor type, in its SI unit (T, V/m, rad)."""
MAGNITUDES = frozenset({("magnetometer", "magnitude"), ("electrode", "envelope"), ("electrode", "magnitude")})
"""(type, kind) whose channels are magnitudes: never negative (beyond the noise)."""
NEGATIVE_SIGMAS = 5.0
"""A magnitude channel's value may lie this many noise standard deviations below zero (noise, not a sign)."""

_UNIT_HINT = {"magnetometer": "in nT rather than T?", "electrode": "in uV/m or mV/m rather than V/m?",
              "accelerometer": "in degrees rather than radians?"}


def channel_ranges(scenario, array):
    """Per channel of ``array``: the lowest and highest value accepted, ``(low (m,), high (m,))``."""
    types = np.array([array.types[s] for s in array.channel_sensor])
    high = np.array([FIELD_LIMIT[t] for t in types])
    low = -high
    magnitude = np.array([(array.types[s], array.kinds[s]) in MAGNITUDES for s in array.channel_sensor], dtype=bool)
    if magnitude.any():
        noise = scenario.noise
        scale = noise.outlier_scale if noise.model == "contaminated" else 1.0
        low = np.where(magnitude, -NEGATIVE_SIGMAS * scale * np.asarray(scenario.channel_std, dtype=float), low)
    return low, high


def value_problem(scenario, array, cols, values):
    """The first of ``values`` (entries of channel columns ``cols``) outside its channel's range, as
    ``(index, message)``, or None when every value is within range (NaN, a missing value, always is)."""
    low, high = channel_ranges(scenario, array)
    with np.errstate(invalid="ignore"):
        out = (values > high[cols]) | (values < low[cols])
    if not out.any():
        return None
    i = int(np.argmax(out))
    c = int(cols[i])
    sid, name = array.channels[c]
    sensor = int(array.channel_sensor[c])
    kind, type_ = array.kinds[sensor], array.types[sensor]
    unit = array.channel_units[c]
    v = float(values[i])
    if abs(v) > FIELD_LIMIT[type_]:
        return i, (f"value {v:.6g} {unit} of {sid} {name} is beyond a {type_}'s physical range (|value| <= "
                   f"{FIELD_LIMIT[type_]:g} {unit}): a corrupted value, or {_UNIT_HINT[type_]}")
    return i, (f"value {v:.6g} {unit} of {sid} {name} is negative, but a {kind} {type_} channel is a magnitude "
               f"(>= 0; this scenario's noise allows down to {low[c]:.3g} {unit}); a signed field is kind = "
               "\"vector\"")
