r"""The joint model of several ships: stacked states, summed measurements.

Fields superpose: a magnetometer or an electrode reads the sum of the fields of every ship in range, so for
:math:`S` ships with states :math:`x_1, \dots, x_S` (each the one-ship state of
:class:`~shipsense.models.field_model.FieldModel`) the joint state and measurement are

.. math::  x = [x_1; \dots; x_S], \qquad y = \sum_{s=1}^{S} h(x_s) + v ,

with the Jacobian :math:`H(x) = [H(x_1), \dots, H(x_S)]`.  The transition is block diagonal (each ship its own
constant-velocity motion and its own process noise).  Magnitude and envelope channels add each ship's reading
as if in phase, as the simulator does (:func:`shipsense.physics.traffic.superposed_readings`).

Seismic bearings do not add: a node hears the louder ship.  The joint model reports, on each bearing channel,
the bearing of the ship **nearest** to that node (the nearer ship is the louder one at equal source levels;
the simulator's rule), and the Jacobian of that ship's bearing; the other ships' columns are zero there.

Every ship's readings and Jacobian come from the one-ship model's own kernels
(:meth:`~shipsense.models.field_model.FieldModel.h` and ``h_and_H``: the compiled measurement kernel); this
module only stacks and adds.  The joint model has no compiled kernel of its own, so the filter units run their
numpy steps on it (:class:`~shipsense.trackers.filters.NumpySteps`), batched over every leading axis.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import block_diag


class JointModel:
    """``ships`` copies of the one-ship model ``base`` in one state, measured by the sum of their readings.

    Parameters
    ----------
    base : FieldModel
        The one-ship model (internal units; its ``A``, ``Q``, ``R``, scales).
    ships : int
        Number of ships ``S`` (>= 1).

    Attributes
    ----------
    n, m : int
        ``S * base.n`` and ``base.m``.
    A, Q : ndarray, shape (n, n)
        Block-diagonal transition and process noise.
    R : ndarray, shape (m,)
        The base model's noise variances (the noise is the sensors', whatever the number of ships).
    """

    def __init__(self, base, ships):
        if int(ships) < 1:
            raise ValueError(f"ships must be at least 1, got {ships!r}")
        self.base, self.ships = base, int(ships)
        S = self.ships
        self.n, self.m = S * base.n, base.m
        self.A = block_diag(*([base.A] * S))
        self.Q = block_diag(*([base.Q] * S))
        self.R = base.R
        self.axial, self.axial_cols = base.axial, base.axial_cols
        self.x_scale = np.tile(base.x_scale, S)
        self.y_scale = base.y_scale
        self.labels = tuple(f"{c}_{s + 1}" for s in range(S) for c in base.labels)
        self.period = base.period
        self._bearing = np.flatnonzero(base.axial)
        sensor = base.array.channel_sensor[self._bearing]
        self._node_xy = np.asarray(base.array.positions, dtype=float)[sensor, :2]       # (b, 2)

    def split(self, x):
        """The ships' states (..., S, n_1) of joint states ``x`` (..., n)."""
        x = np.asarray(x)
        return x.reshape(x.shape[:-1] + (self.ships, self.base.n))

    def _nearest(self, xs):
        """Index (..., b) of the ship nearest to each bearing node, of ship states ``xs`` (..., S, n_1)."""
        d = xs[..., :, None, :2] - self._node_xy                      # (..., S, b, 2)
        return np.argmin(np.sum(d * d, axis=-1), axis=-2)

    def h(self, x):
        """Summed readings (..., m) of joint internal states ``x`` (..., n); bearings: the nearest ship's."""
        xs = self.split(x)
        each = self.base.h(xs)                                         # (..., S, m)
        y = each.sum(axis=-2)
        if self._bearing.size:
            near = self._nearest(xs)
            y[..., self._bearing] = np.take_along_axis(each[..., self._bearing], near[..., None, :], axis=-2)[..., 0, :]
        return y

    def h_and_H(self, x):
        """``(h(x), H(x))``: summed readings (..., m) and the Jacobian (..., m, n), each ship's block its own
        model's Jacobian (on a bearing channel only the nearest ship's block)."""
        xs = self.split(x)
        each, J = self.base.h_and_H(xs)                                # (..., S, m), (..., S, m, n_1)
        y = each.sum(axis=-2)
        if self._bearing.size:
            near = self._nearest(xs)
            y[..., self._bearing] = np.take_along_axis(each[..., self._bearing], near[..., None, :], axis=-2)[..., 0, :]
            keep = np.arange(self.ships)[:, None] == near[..., None, :]  # (..., S, b)
            J[..., self._bearing, :] *= keep[..., None]
        H = np.moveaxis(J, -3, -2).reshape(J.shape[:-3] + (self.m, self.n))
        return y, H

    def H(self, x):
        """The Jacobian (..., m, n) of :meth:`h`."""
        return self.h_and_H(x)[1]

    def residual(self, a, b):
        """``a - b`` with bearing channels wrapped modulo pi (the base model's)."""
        return self.base.residual(a, b)

    def to_internal(self, x_si):
        return np.asarray(x_si, dtype=float) / self.x_scale

    def to_si(self, x):
        return np.asarray(x) * self.x_scale

    @property
    def state_bounds(self):
        """The base model's bounds on every ship's state ``(lo, hi)`` (n,) each, or None."""
        b = self.base.state_bounds
        return None if b is None else (np.tile(b[0], self.ships), np.tile(b[1], self.ships))

    def cov_to_internal(self, P_si):
        """A covariance (..., n, n) in SI units, in internal units."""
        return np.asarray(P_si) / np.outer(self.x_scale, self.x_scale)

    def cov_to_si(self, P):
        """A covariance (..., n, n) in internal units, in SI units."""
        return np.asarray(P) * np.outer(self.x_scale, self.x_scale)
