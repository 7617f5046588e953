r"""Seeding the hypotheses of the multiple-initial-value bank from the first measurement.

From the first measured field magnitude (the sensor with the largest one:
a documented choice that picks the sensor nearest the ship) and K assumed
source strengths, the far-field dipole range formulas give K ranges,

* magnetic: :math:`|r| = \sqrt[3]{(\mu_0/4\pi)\, 2 |m| / |B|}` (on-axis;
  off-axis the range is over-estimated by at most a factor cbrt(2));
* electric: :math:`|r| = \sqrt[3]{c\, p / (2\pi\sigma_1 |E|)}` with the image
  correction ``c`` (about 2 near the surface);

and the horizontal-range correction :math:`\rho = \sqrt{r^2 - \Delta z^2}`
(zero when ``r < |dz|``).  On each range, ``l`` bearings give ``K l``
positions around that sensor, at bearings measured from +x
counter-clockwise (``bearing_convention = "east"``) or clockwise from north,
+y (``"north"``: the bank of the magnetic source study, scenario S0).
"""

from __future__ import annotations

import numpy as np

from shipsense.physics.magnetic import MU0_OVER_4PI


def field_strength(model, y):
    """Per-sensor field magnitude (..., S) of a first measurement (SI, NaN = missing); NaN for bearings."""
    array = model.array
    y = np.asarray(y, dtype=float)
    sensor = array.channel_sensor
    S = len(array.ids)
    out = np.full(y.shape[:-1] + (S,), np.nan)
    for s in range(S):  # a handful of sensors, once per passage
        if array.types[s] == "accelerometer":
            continue
        v = y[..., sensor == s]
        out[..., s] = np.sqrt(np.nansum(v * v, axis=-1))
        out[..., s] = np.where(np.isnan(v).all(axis=-1), np.nan, out[..., s])
    return out

def seed_ranges(model, y, levels, range_correction=2.0):
    """Sensor index (...), and slant and horizontal ranges (..., K) implied by the first measurement.

    The source type is magnetic when the array has magnetometers, else electric.
    """
    array = model.array
    levels = np.asarray(levels, dtype=float)
    strength = field_strength(model, y)
    magnetic = "magnetometer" in array.types
    use = np.array([t == ("magnetometer" if magnetic else "electrode") for t in array.types])
    strength = np.where(use, strength, np.nan)
    if np.isnan(strength).all(axis=-1).any():
        raise ValueError("the first measurement has no field sample to seed from (all missing)")
    best = np.nanargmax(strength, axis=-1)
    f = np.take_along_axis(strength, best[..., None], axis=-1)
    if magnetic:
        r = np.cbrt(MU0_OVER_4PI * 2.0 * levels / f)
    else:
        r = np.cbrt(range_correction * levels / (2.0 * np.pi * array.medium.sigma_water * f))
    source_z = model.source_z
    dz = np.abs(array.positions[best, 2] - source_z)[..., None]
    rho = np.sqrt(np.clip(r * r - dz * dz, 0.0, None))
    return best, r, rho

def seed_hypotheses(model, y, bank, source_z=None):
    """Initial means (..., K l, n) and covariance (n, n) of the bank, in SI.

    Parameters
    ----------
    model : FieldModel
    y : ndarray, shape (..., m)
        First measurement (SI).
    bank : BankConfig
    source_z : float, optional
        Initial source height for electric models (default: the model's ``source_z``).
    """
    best, _, rho = seed_ranges(model, y, bank.levels, bank.range_correction)
    phi = np.deg2rad(np.asarray(bank.bearings_deg, dtype=float))
    K, L = len(bank.levels), phi.size
    centre = model.array.positions[best, :2]                             # (..., 2)
    unit = [np.sin(phi), np.cos(phi)] if bank.bearing_convention == "north" else [np.cos(phi), np.sin(phi)]
    pos = centre[..., None, None, :] + rho[..., :, None, None] * np.stack(unit, -1)
    pos = pos.reshape(pos.shape[:-3] + (K * L, 2))
    n = model.n
    x0 = np.zeros(pos.shape[:-1] + (n,))
    x0[..., 0:2] = pos
    if bank.initial_course == "towards_array":
        heading = model.array.positions[:, :2].mean(axis=0) - pos
        norm = np.linalg.norm(heading, axis=-1, keepdims=True)
        speed = float(np.hypot(*bank.initial_velocity))
        x0[..., 2:4] = speed * heading / np.where(norm > 0, norm, 1.0)
    else:
        x0[..., 2:4] = bank.initial_velocity
    labels = model.labels                                                  # a moment starts at zero
    if "z" in labels:
        iz = labels.index("z")
        x0[..., iz] = model.source_z if source_z is None else source_z
        # electric levels seed p; in a fused (magnetic + electric) model the levels are magnetic
        x0[..., iz + 1] = bank.p_initial if "mx" in labels else np.repeat(np.asarray(bank.levels, dtype=float), L)
    return x0, np.diag(np.square(bank.state_std(labels)))
