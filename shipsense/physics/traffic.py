r"""Traffic: where a second (third, ...) ship sails relative to the first, and what several ships read together.

Named encounters place a companion ship relative to the lead ship's straight track
:math:`p_0(t) = a + v t` (position :math:`a` at :math:`t = 0`, velocity :math:`v`).  The companion sails at
the velocity

.. math::  v_c = \rho\, R(\theta)\, v ,

with the speed ratio :math:`\rho` and the course change :math:`\theta`: ``crossing`` :math:`\theta = \pm\beta`
(the crossing angle :math:`\beta`, to either side), ``head_on`` :math:`\theta = \pi`, ``overtaking``
:math:`\theta = 0` with :math:`\rho > 1`, ``following`` :math:`\theta = 0`, :math:`\rho = 1`.  The two ships
meet at the time

.. math::  t_c = -\frac{(a - c) \cdot v}{|v|^2} + \tau ,

the lead ship's closest approach to the array centre :math:`c` shifted by the time offset :math:`\tau`; the
companion is then abeam of the lead ship at the separation :math:`d`, across the relative velocity
:math:`w = v_c - v`:

.. math::  p_c(t_c) = p_0(t_c) + d\, \sigma\, \frac{J w}{|w|}, \qquad
           J = \begin{bmatrix} 0 & -1 \\ 1 & 0 \end{bmatrix}, \quad \sigma = \pm 1 ,

so the relative position is :math:`d \sigma J w / |w| + w (t - t_c)`, whose length is smallest, :math:`d`,
at :math:`t_c`: the closest approach of the two ships is :math:`d` at :math:`t_c`.  A follower
(:math:`w = 0`) keeps the distance :math:`d` astern of the lead ship, :math:`p_c(t) = p_0(t) - d\, v / |v|`,
at every time.

Fields superpose: every sensor reads the sum of the ships' noiseless readings,
:math:`y_k = \sum_s h(x_{s,k}) + v_k` (:func:`superposed_readings`).  That is the field itself for vector and
total-field-anomaly channels (linear in the field); for magnitude and envelope channels it is the model the
trackers use (each ship's reading added as if in phase).  Bearings do not add: a seismic node hears the
louder ship, the nearer one at equal source levels, so an axial channel reports the nearest ship's bearing.
"""

from __future__ import annotations

import numpy as np

GEOMETRIES = ("prior", "crossing", "head_on", "overtaking", "following")
"""How a companion ship's passage is made: drawn from the scenario's prior, or a named encounter with the lead
ship (crossing, meeting head-on, overtaking, following)."""


def encounter_time(lead, centre, offset):
    """:math:`t_c` (...,), s: the lead ship's (``lead`` (..., >= 4): x, y, vx, vy) closest approach to
    ``centre`` (2,), m, plus ``offset`` (...,), s."""
    a = lead[..., 0:2] - np.asarray(centre, dtype=float)
    v = lead[..., 2:4]
    return -np.sum(a * v, axis=-1) / np.sum(v * v, axis=-1) + offset


def companion_tracks(lead, centre, geometry, separation, offset, angle, ratio, side):
    r"""Start (..., 2), m, and velocity (..., 2), m/s, of companions of straight lead tracks.

    Parameters
    ----------
    lead : ndarray, shape (..., >= 4)
        Lead ships' x, y (m) at t = 0 and vx, vy (m/s); the speed must be > 0.
    centre : array_like, shape (2,)
        The array's centre, m.
    geometry : ndarray of int, shape (...)
        Index into :data:`GEOMETRIES` (1 to 4; a ``prior`` ship is not made here).
    separation : ndarray, shape (...)
        Closest approach :math:`d` of the two ships (a follower: its distance astern), m.
    offset : ndarray, shape (...)
        Time offset :math:`\tau` of the encounter from the lead ship's closest approach to ``centre``, s.
    angle : ndarray, shape (...)
        Crossing angle :math:`\beta`, rad (used by crossings).
    ratio : ndarray, shape (...)
        Speed ratio :math:`\rho` (a follower: 1).
    side : ndarray, shape (...)
        :math:`\sigma = \pm 1`: the side of the lead ship the companion passes on (and a crossing's turn).

    Returns
    -------
    start, velocity : ndarray, shape (..., 2)
    """
    geometry = np.asarray(geometry)
    theta = np.select([geometry == 1, geometry == 2], [side * angle, np.pi], 0.0)
    rho = np.where(geometry == 4, 1.0, ratio)
    v = lead[..., 2:4]
    c, s = np.cos(theta), np.sin(theta)
    vc = rho[..., None] * np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)
    w = vc - v
    wn = np.linalg.norm(w, axis=-1, keepdims=True)
    moving = wn[..., 0] > 1e-9 * np.linalg.norm(v, axis=-1)
    across = np.stack([-w[..., 1], w[..., 0]], axis=-1) / np.where(moving[..., None], wn, 1.0)
    tc = encounter_time(lead, centre, offset)
    meet = lead[..., 0:2] + v * tc[..., None] + (separation * side)[..., None] * across - vc * tc[..., None]
    astern = lead[..., 0:2] - separation[..., None] * v / np.linalg.norm(v, axis=-1, keepdims=True)
    start = np.where(moving[..., None], meet, astern)
    return start, vc


def superposed_readings(readings, present, axial, nearest):
    """What the sensors read with several ships: the sum of the present ships' readings, the nearest present
    ship's bearing on axial channels.

    Parameters
    ----------
    readings : ndarray, shape (runs, ships, steps, m)
        Each ship's noiseless readings.
    present : ndarray of bool, shape (runs, ships)
        Which ships sail in each run (at least one).
    axial : ndarray of bool, shape (m,)
        Bearing channels.
    nearest : ndarray of int, shape (runs, steps, n_axial)
        The present ship nearest to the sensor of each axial channel (the one it hears), an index into
        ``ships``.

    Returns
    -------
    ndarray, shape (runs, steps, m)
    """
    on = present[:, :, None, None]
    total = np.sum(np.where(on, readings, 0.0), axis=1)
    if np.any(axial):
        total[..., axial] = np.take_along_axis(readings[..., axial], nearest[:, None], axis=1)[:, 0]
    return total
